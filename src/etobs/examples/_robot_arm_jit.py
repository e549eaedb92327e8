"""numba-compiled single-run versions of the robot arm's plant and observer.

Imported only when numba is installed (see :func:`etobs.examples.robot_arm.robot_arm`).
They handle any number of arms side by side (``n_x = 4 * n_arms``; the outputs are
``x_1, x_2`` of each arm), so :func:`robot_arm_network` uses them too. Each operation
is the one of the numpy functions in :mod:`etobs.examples.robot_arm`, in the same order.
"""

from __future__ import annotations

import numba
import numpy as np

from etobs.examples.robot_arm import SECTOR, A, B, G

_A = np.array(A)
_B = np.array(B)
_G = np.array(G)


@numba.njit
def _model(x, u, off, out, out_off):
    """``A x + B u + G*3.3*sin(x_3)`` of the arm at ``x[off:off+4]`` (eq. (57) model part)."""
    nl = SECTOR * np.sin(x[off + 2])
    for i in range(4):
        acc = x[off] * _A[i, 0]
        for k in range(1, 4):
            acc += x[off + k] * _A[i, k]
        out[out_off + i] = acc + u * _B[i] + nl * _G[i]


@numba.njit
def f_p(t, x, u, v, theta, out):
    """Plant ``x' = A x + B u + G*3.3*sin(x_3) + v`` of every arm."""
    u0 = u[0] if u.shape[0] else 0.0
    for a in range(x.shape[0] // 4):
        _model(x, u0, 4 * a, out, 4 * a)
    for i in range(x.shape[0]):
        out[i] += v[i]


@numba.njit
def h(x, theta, out):
    """``y = (x_1, x_2)`` of every arm."""
    for a in range(x.shape[0] // 4):
        out[2 * a] = x[4 * a]
        out[2 * a + 1] = x[4 * a + 1]


@numba.njit
def f_o(t, z, u, ybar, yhat, theta, out):
    """Observer (57) on the held outputs; ``theta`` is the gain ``L`` (4 x 2) row by row."""
    u0 = u[0] if u.shape[0] else 0.0
    for a in range(z.shape[0] // 4):
        _model(z, u0, 4 * a, out, 4 * a)
        r0 = ybar[2 * a] - yhat[2 * a]
        r1 = ybar[2 * a + 1] - yhat[2 * a + 1]
        for i in range(4):
            out[4 * a + i] += r0 * theta[2 * i] + r1 * theta[2 * i + 1]
