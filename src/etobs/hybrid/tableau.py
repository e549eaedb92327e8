"""Embedded Runge--Kutta pairs with dense output, applied to a batch of runs.

The coefficients are the published ones of Dormand & Prince (1980, the 5(4) pair with
Shampine's 4th-order continuous extension) and of Hairer, Nørsett & Wanner (1993,
DOP853 with its 7th-order continuous extension). We read them from the public class
attributes of :class:`scipy.integrate.RK45` and :class:`scipy.integrate.DOP853` so that
no long decimal table is retyped; ``tests/hybrid/test_tableau.py`` checks the order of
each pair and of its interpolant against closed-form solutions.

Every array carries the batch on its leading axis: ``y`` has shape ``(M, n)``, the
stage array ``K`` shape ``(stages, M, n)`` and ``h`` shape ``(M,)``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.integrate import DOP853, RK45

Flow = Callable[[np.ndarray, np.ndarray], np.ndarray]


def _combine(w: np.ndarray, K: np.ndarray) -> np.ndarray:
    """``sum_k w[k] * K[k]`` for stage arrays ``K`` (k, M, n); ``w`` may be 2-D (rows).

    Elementwise multiply-adds in a fixed order, skipping zero weights: unlike a BLAS
    product, the result of each run is then bit-for-bit independent of the batch size
    and of the other runs in the batch.
    """
    if w.ndim == 2:
        return np.stack([_combine(row, K) for row in w])
    nz = np.flatnonzero(w)
    if nz.size == 0:
        return np.zeros(K.shape[1:])
    acc = w[nz[0]] * K[nz[0]]
    for k in nz[1:]:
        acc += w[k] * K[k]
    return acc


@dataclass(frozen=True)
class Tableau:
    """An explicit embedded RK pair with first-same-as-last stage and dense output."""

    name: str
    order: int
    error_order: int
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    e: np.ndarray
    e_low: np.ndarray | None
    dense_a: np.ndarray | None
    dense_c: np.ndarray | None
    dense_d: np.ndarray

    @property
    def stages(self) -> int:
        """Number of stages of one step (the FSAL stage excluded)."""
        return self.b.shape[0]

    def step(
        self, flow: Flow, t: np.ndarray, y: np.ndarray, f: np.ndarray, h: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Take one step of size ``h`` from ``(t, y)`` with ``f = flow(t, y)``.

        Returns
        -------
        K : ndarray, shape (stages + 1, M, n)
            Stage derivatives; the last one is ``flow(t + h, y_new)``.
        y_new : ndarray, shape (M, n)

        """
        s = self.stages
        K = np.empty((s + 1, *y.shape))
        K[0] = f
        hc = h[:, None]
        for i in range(1, s):
            dy = _combine(self.a[i, :i], K)
            K[i] = flow(t + self.c[i] * h, y + hc * dy)
        y_new = y + hc * _combine(self.b, K)
        K[s] = flow(t + h, y_new)
        return K, y_new

    def error_norm(
        self, K: np.ndarray, h: np.ndarray, y: np.ndarray, y_new: np.ndarray, rtol: float, atol: float
    ) -> np.ndarray:
        """Scaled RMS error norm of each run (accept the step where it is ``<= 1``)."""
        scale = atol + rtol * np.maximum(np.abs(y), np.abs(y_new))
        n = y.shape[1]
        err = _combine(self.e, K) / scale
        if self.e_low is None:
            return np.abs(h) * np.sqrt(np.einsum("ij,ij->i", err, err) / n)
        # DOP853: the 5th-order estimate is corrected by the 3rd-order one (Hairer et al.)
        err3 = _combine(self.e_low, K) / scale
        e5 = np.einsum("ij,ij->i", err, err)
        e3 = np.einsum("ij,ij->i", err3, err3)
        denom = e5 + 0.01 * e3
        with np.errstate(invalid="ignore", divide="ignore"):
            out = np.abs(h) * e5 / np.sqrt(denom * n)
        return np.where(denom == 0.0, 0.0, out)

    def dense(
        self, flow: Flow, t: np.ndarray, y: np.ndarray, y_new: np.ndarray, K: np.ndarray, h: np.ndarray
    ) -> np.ndarray:
        """Coefficients of the continuous extension of the steps just taken.

        Returns an array ``Q`` of shape ``(P, M, n)`` read by :meth:`evaluate`.
        """
        hc = h[:, None]
        if self.dense_a is None:
            # Dormand--Prince 5(4): y(θ) = y0 + h Σ_k (K^T P)_k θ^(k+1)
            return hc[None] * _combine(self.dense_d.T, K)
        s = self.stages + 1
        Kx = np.empty((s + self.dense_a.shape[0], *y.shape))
        Kx[:s] = K
        for r, (arow, cr) in enumerate(zip(self.dense_a, self.dense_c, strict=True)):
            m = s + r
            Kx[m] = flow(t + cr * h, y + hc * _combine(arow[:m], Kx))
        dy = y_new - y
        Q = np.empty((7, *y.shape))
        Q[0] = dy
        Q[1] = hc * K[0] - dy
        Q[2] = 2.0 * dy - hc * (K[-1] + K[0])
        Q[3:] = hc[None] * _combine(self.dense_d, Kx)
        return Q

    def evaluate(self, Q: np.ndarray, y: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """Evaluate the continuous extension at ``θ ∈ [0, 1]`` of each row.

        ``Q`` has shape ``(P, M, n)``, ``y`` (the step start) ``(M, n)`` and ``theta``
        ``(M,)``; returns ``(M, n)``.
        """
        th = theta[:, None]
        if self.dense_a is None:
            acc = np.zeros_like(y)
            for k in range(Q.shape[0] - 1, -1, -1):
                acc = (acc + Q[k]) * th
            return y + acc
        acc = np.zeros_like(y)
        one_minus = 1.0 - th
        for i, k in enumerate(range(Q.shape[0] - 1, -1, -1)):
            acc += Q[k]
            acc *= th if i % 2 == 0 else one_minus
        return y + acc


def _dopri5() -> Tableau:
    s = RK45.n_stages
    a = np.zeros((s, s))
    a[:, : RK45.A.shape[1]] = RK45.A
    return Tableau(
        name="dopri5",
        order=5,
        error_order=4,
        a=a,
        b=np.asarray(RK45.B, float),
        c=np.asarray(RK45.C, float),
        e=np.asarray(RK45.E, float),
        e_low=None,
        dense_a=None,
        dense_c=None,
        dense_d=np.asarray(RK45.P, float),
    )


def _dop853() -> Tableau:
    s = DOP853.n_stages
    return Tableau(
        name="dop853",
        order=8,
        error_order=7,
        a=np.asarray(DOP853.A[:s, :s], float),
        b=np.asarray(DOP853.B, float),
        c=np.asarray(DOP853.C[:s], float),
        e=np.asarray(DOP853.E5, float),
        e_low=np.asarray(DOP853.E3, float),
        dense_a=np.asarray(DOP853.A_EXTRA, float),
        dense_c=np.asarray(DOP853.C_EXTRA, float),
        dense_d=np.asarray(DOP853.D, float),
    )


TABLEAUS: dict[str, Tableau] = {"dopri5": _dopri5(), "dop853": _dop853()}
