"""Vectorized bracketing root finder used to locate events on the dense output."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

# A bracket always shrinks by at least half every second iteration (bisection
# fallback), so 200 iterations reach any xtol above 2**-100 of the initial width.
_MAX_ITER = 200


def bracket_root(
    fun: Callable[[np.ndarray, np.ndarray], np.ndarray],
    lo: np.ndarray,
    hi: np.ndarray,
    f_lo: np.ndarray,
    f_hi: np.ndarray,
    xtol: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Shrink brackets ``[lo, hi]`` with ``fun(lo) < 0 <= fun(hi)`` to width ``<= xtol``.

    Regula falsi with the Illinois modification, with the trial point kept at least
    ``xtol/2`` inside the bracket (so a root next to an end closes the bracket at once)
    and a bisection whenever the previous trial did not halve the bracket.

    Parameters
    ----------
    fun : callable
        ``fun(rows, x) -> values`` evaluates problem ``rows`` (indices into the inputs)
        at abscissae ``x``; both have shape ``(K,)``.
    lo, hi, f_lo, f_hi, xtol : ndarray, shape (M,)
        Brackets, function values at their ends, and tolerances.

    Returns
    -------
    lo, hi : ndarray, shape (M,)
        Final brackets; ``fun(hi) >= 0`` and ``fun(lo) < 0`` still hold.

    """
    lo, hi = lo.astype(float).copy(), hi.astype(float).copy()
    f_lo, f_hi = f_lo.astype(float).copy(), f_hi.astype(float).copy()
    side = np.zeros(lo.shape, dtype=np.int8)  # -1: last trial replaced lo, +1: hi
    width_before = hi - lo
    for it in range(_MAX_ITER):
        open_ = np.flatnonzero(hi - lo > xtol)
        if open_.size == 0:
            break
        a, b, fa, fb = lo[open_], hi[open_], f_lo[open_], f_hi[open_]
        w = b - a
        with np.errstate(invalid="ignore", divide="ignore"):
            x = b - fb * w / (fb - fa)
        bisect = ~np.isfinite(x) | ((it % 2 == 1) & (w > 0.5 * width_before[open_]))
        x = np.where(bisect, 0.5 * (a + b), x)
        half = 0.5 * xtol[open_]
        x = np.clip(x, a + np.minimum(half, 0.5 * w), b - np.minimum(half, 0.5 * w))
        if it % 2 == 0:
            width_before[open_] = w
        fx = fun(open_, x)
        right = fx >= 0
        # Illinois: halve the stored value at the end that stays twice in a row.
        keep_lo = right & (side[open_] == 1)
        keep_hi = ~right & (side[open_] == -1)
        f_lo[open_[keep_lo]] *= 0.5
        f_hi[open_[keep_hi]] *= 0.5
        hi[open_[right]] = x[right]
        f_hi[open_[right]] = fx[right]
        lo[open_[~right]] = x[~right]
        f_lo[open_[~right]] = fx[~right]
        side[open_] = np.where(right, 1, -1)
    return lo, hi
