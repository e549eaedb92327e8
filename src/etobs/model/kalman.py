"""Continuous-time extended Kalman filter as an :class:`Observer` (state and covariance in ``z``).

For ``x' = f(t, x, u) + v``, ``y = h(x) + m`` with noise intensities ``Qn`` and ``R``, the
filter run on the held outputs ``ybar`` is (Kalman--Bucy, linearized at the estimate)::

    xhat' = f(t, xhat, u) + K (ybar - h(xhat)),      K = P H' R^{-1}
    P'    = F P + P F' + Qn - P H' R^{-1} H P,

with ``F = df/dx`` and ``H = dh/dx`` at ``xhat``. ``z = (xhat, vec(P))`` has
``n_x + n_x^2`` entries and ``psi(z) = xhat``. The EKF is one of the observers the paper
names as satisfying its Assumption 1 under conditions (section 3, after Bernard et
al. 2022); etobs does not check those conditions for it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.errors import InputError
from etobs.model.observer import Observer

Field = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
Output = Callable[[np.ndarray], np.ndarray]


def extended_kalman_filter(
    f: Field,
    h: Output,
    *,
    n_x: int,
    Qn: Any,
    R: Any,
    jac_f: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None = None,
    jac_h: Callable[[np.ndarray], np.ndarray] | None = None,
    name: str = "extended Kalman filter",
) -> Observer:
    """An EKF observer; start it with ``z0 = ekf_initial_state(xhat0, P0)``.

    Parameters
    ----------
    f : callable
        ``f(t, x, u) -> (B, n_x)``, the model without disturbance (batched).
    h : callable
        ``h(x) -> (B, n_y)``.
    n_x : int
    Qn : array_like, shape (n_x, n_x)
        Process-noise intensity (symmetric positive semi-definite).
    R : array_like, shape (n_y, n_y)
        Measurement-noise intensity (symmetric positive definite).
    jac_f, jac_h : callable, optional
        Jacobians ``(B, n_x, n_x)`` and ``(B, n_y, n_x)``; default: central differences.

    Examples
    --------
    >>> import numpy as np
    >>> ekf = extended_kalman_filter(lambda t, x, u: -x, lambda x: x, n_x=1, Qn=[[1.0]], R=[[1.0]])
    >>> ekf.n_z
    2

    """
    v.function("f", f)
    v.function("h", h)
    n = v.integer("n_x", n_x, lower=1)
    Qm = _sym_psd("Qn", v.matrix("Qn", Qn, (n, n)), strict=False)
    Rm = _sym_psd("R", v.matrix("R", R, (None, None)), strict=True)
    R_inv = np.linalg.inv(Rm)
    jf = jac_f or (lambda t, x, u: _jacobian(lambda xx: f(t, xx, u), x))
    jh = jac_h or (lambda x: _jacobian(h, x))

    def f_o(t: np.ndarray, z: np.ndarray, u: np.ndarray, ybar: np.ndarray, yhat: np.ndarray) -> np.ndarray:
        B = z.shape[0]
        xhat = z[:, :n]
        P = z[:, n:].reshape(B, n, n)
        F = jf(t, xhat, u)
        H = jh(xhat)
        K = P @ np.swapaxes(H, 1, 2) @ R_inv  # K = P H' R^-1
        dx = f(t, xhat, u) + np.einsum("bij,bj->bi", K, ybar - yhat)
        dP = F @ P + P @ np.swapaxes(F, 1, 2) + Qm - K @ Rm @ np.swapaxes(K, 1, 2)
        dP = 0.5 * (dP + np.swapaxes(dP, 1, 2))  # keep P symmetric to rounding
        return np.concatenate([dx, dP.reshape(B, n * n)], axis=1)

    return Observer(f_o=f_o, n_z=n + n * n, psi=lambda z: z[:, :n], name=name)


def ekf_initial_state(xhat0: Any, P0: Any) -> np.ndarray:
    """``z0 = (xhat0, vec(P0))`` for :func:`extended_kalman_filter`."""
    x = v.vector("xhat0", xhat0)
    P = _sym_psd("P0", v.matrix("P0", P0, (x.size, x.size)), strict=True)
    return np.concatenate([x, P.reshape(-1)])


def _jacobian(fn: Callable[[np.ndarray], np.ndarray], x: np.ndarray) -> np.ndarray:
    """Central-difference Jacobian of a batched function, shape ``(B, m, n)``."""
    n = x.shape[1]
    cols = []
    for j in range(n):
        step = np.sqrt(np.finfo(float).eps) * np.maximum(1.0, np.abs(x[:, j]))
        dx = np.zeros_like(x)
        dx[:, j] = step
        cols.append((fn(x + dx) - fn(x - dx)) / (2 * step[:, None]))
    return np.stack(cols, axis=2)


def _sym_psd(name: str, M: np.ndarray, *, strict: bool) -> np.ndarray:
    if M.shape[0] != M.shape[1] or not np.allclose(M, M.T):
        raise InputError(f"`{name}` must be a symmetric matrix; got shape {M.shape}")
    low = float(np.linalg.eigvalsh(M).min())
    if low < 0 or (strict and low == 0):
        kind = "positive definite" if strict else "positive semi-definite"
        raise InputError(f"`{name}` must be {kind}; its smallest eigenvalue is {low:.3g}")
    return M
