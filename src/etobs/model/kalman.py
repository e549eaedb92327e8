"""Continuous-time extended Kalman filter as an :class:`Observer` (state and covariance in ``z``).

For ``x' = f(t, x, u) + v``, ``y = h(x) + m`` with noise intensities ``Qn`` and ``R``, the
filter run on the held outputs ``ybar`` is (Kalman--Bucy, linearized at the estimate)::

    xhat' = f(t, xhat, u) + K (ybar - h(xhat)),      K = P H' R^{-1}
    P'    = F P + P F' + Qn - P H' R^{-1} H P,

with ``F = df/dx`` and ``H = dh/dx`` at ``xhat``. ``z = (xhat, vec(P))`` has
``n_x + n_x^2`` entries and ``psi(z) = xhat``. The EKF is one of the observers the paper
names as satisfying its Assumption 2 under conditions (section 3.2, after Bernard et
al. 2022); etobs does not check those conditions for it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.errors import InputError
from etobs.model.observer import Observer

Field = Callable[[float, np.ndarray, np.ndarray], np.ndarray]
Output = Callable[[np.ndarray], np.ndarray]

#: Relative step of the central differences (as for a finite-difference Jacobian).
_ROOT_EPS = float(np.sqrt(np.finfo(float).eps))


def extended_kalman_filter(
    f: Field,
    h: Output,
    *,
    n_x: int,
    Qn: Any,
    R: Any,
    jac_f: Callable[[float, np.ndarray, np.ndarray], np.ndarray] | None = None,
    jac_h: Callable[[np.ndarray], np.ndarray] | None = None,
    name: str = "extended Kalman filter",
) -> Observer:
    """An EKF observer; start it with ``z0 = ekf_initial_state(xhat0, P0)``.

    The observer's ``f_o(t, z, u, ybar, yhat)`` is written for one run, with numpy on
    1-D arrays, and calls ``f``, ``h`` and the Jacobians: etobs compiles it with them.

    Parameters
    ----------
    f : callable
        ``f(t, x, u) -> (n_x,)`` for one run, the model without disturbance.
    h : callable
        ``h(x) -> (n_y,)`` for one run.
    n_x : int
    Qn : array_like, shape (n_x, n_x)
        Process-noise intensity (symmetric positive semi-definite).
    R : array_like, shape (n_y, n_y)
        Measurement-noise intensity (symmetric positive definite).
    jac_f, jac_h : callable, optional
        One-run Jacobians ``jac_f(t, x, u) -> (n_x, n_x)`` and ``jac_h(x) -> (n_y, n_x)``;
        default: central differences of ``f`` and ``h``.

    Examples
    --------
    >>> import numpy as np
    >>> ekf = extended_kalman_filter(lambda t, x, u: -x, lambda x: x, n_x=1, Qn=[[1.0]], R=[[1.0]])
    >>> ekf.n_z
    2
    >>> ekf.call_f_o(0.0, np.array([1.0, 2.0]), np.zeros(0), np.array([3.0]), np.array([1.0])).tolist()
    [3.0, -7.0]

    """
    v.function("f", f)
    v.function("h", h)
    if jac_f is not None:
        v.function("jac_f", jac_f)
    if jac_h is not None:
        v.function("jac_h", jac_h)
    n = v.integer("n_x", n_x, lower=1)
    Qm = np.ascontiguousarray(_sym_psd("Qn", v.matrix("Qn", Qn, (n, n)), strict=False), dtype=float)
    Rm = np.ascontiguousarray(_sym_psd("R", v.matrix("R", R, (None, None)), strict=True), dtype=float)
    R_inv = np.ascontiguousarray(np.linalg.inv(Rm))
    n_y = Rm.shape[0]
    jf = _difference_jac_f(f, n) if jac_f is None else jac_f
    jh = _difference_jac_h(h, n, n_y) if jac_h is None else jac_h

    def f_o(t: float, z: np.ndarray, u: np.ndarray, ybar: np.ndarray, yhat: np.ndarray) -> np.ndarray:
        xhat = z[:n].copy()
        P = np.ascontiguousarray(z[n:]).reshape((n, n))
        F = np.ascontiguousarray(jf(t, xhat, u))
        H = np.ascontiguousarray(jh(xhat))
        K = P @ np.ascontiguousarray(H.T) @ R_inv  # K = P H' R^-1
        dx = f(t, xhat, u) + K @ (ybar - yhat)
        dP = F @ P + P @ np.ascontiguousarray(F.T) + Qm - K @ Rm @ np.ascontiguousarray(K.T)
        dP = 0.5 * (dP + dP.T)  # keep P symmetric to rounding
        out = np.empty(n + n * n)
        out[:n] = dx
        out[n:] = np.ascontiguousarray(dP).reshape(n * n)
        return out

    def psi(z: np.ndarray) -> np.ndarray:
        return z[:n]

    return Observer(f_o=f_o, n_z=n + n * n, psi=psi, name=name)


def _perturbed(x: np.ndarray, j: int) -> tuple[np.ndarray, np.ndarray]:
    """``x`` moved up and down along ``e_j`` by the central-difference step."""
    step = _ROOT_EPS * max(1.0, abs(x[j]))
    up = x.copy()
    up[j] += step
    down = x.copy()
    down[j] -= step
    return up, down


def _difference_jac_f(f: Field, n: int) -> Callable[[float, np.ndarray, np.ndarray], np.ndarray]:
    """Central-difference Jacobian ``df/dx`` of a one-run ``f(t, x, u)``, shape ``(n, n)``."""

    def jac(t: float, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        J = np.empty((n, n))
        for j in range(n):
            up, down = _perturbed(x, j)
            col = (f(t, up, u) - f(t, down, u)) / (up[j] - down[j])
            for i in range(n):
                J[i, j] = col[i]
        return J

    return jac


def _difference_jac_h(h: Output, n: int, n_y: int) -> Callable[[np.ndarray], np.ndarray]:
    """Central-difference Jacobian ``dh/dx`` of a one-run ``h(x)``, shape ``(n_y, n)``."""

    def jac(x: np.ndarray) -> np.ndarray:
        J = np.empty((n_y, n))
        for j in range(n):
            up, down = _perturbed(x, j)
            col = (h(up) - h(down)) / (up[j] - down[j])
            for i in range(n_y):
                J[i, j] = col[i]
        return J

    return jac


def ekf_initial_state(xhat0: Any, P0: Any) -> np.ndarray:
    """``z0 = (xhat0, vec(P0))`` for :func:`extended_kalman_filter`."""
    x = v.vector("xhat0", xhat0)
    P = _sym_psd("P0", v.matrix("P0", P0, (x.size, x.size)), strict=True)
    return np.concatenate([x, P.reshape(-1)])


def _sym_psd(name: str, M: np.ndarray, *, strict: bool) -> np.ndarray:
    if M.shape[0] != M.shape[1] or not np.allclose(M, M.T):
        raise InputError(f"`{name}` must be a symmetric matrix; got shape {M.shape}")
    low = float(np.linalg.eigvalsh(M).min())
    if low < 0 or (strict and low == 0):
        kind = "positive definite" if strict else "positive semi-definite"
        raise InputError(f"`{name}` must be {kind}; its smallest eigenvalue is {low:.3g}")
    return M
