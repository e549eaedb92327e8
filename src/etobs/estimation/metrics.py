"""The paper's metrics (section 7): transmissions, inter-event times, estimation error."""

from __future__ import annotations

from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.errors import InputError
from etobs.estimation.result import EstimationResult


def _window(window: Any, result: EstimationResult) -> tuple[float, float]:
    if window is None:
        return result.solution.t_span
    try:
        lo, hi = window
    except (TypeError, ValueError) as exc:
        raise InputError(f"`window` must be a pair (t_start, t_stop); got {window!r}") from exc
    lo, hi = v.real("window[0]", lo), v.real("window[1]", hi)
    if hi < lo:
        raise InputError(f"`window` must satisfy t_start <= t_stop; got ({lo:g}, {hi:g})")
    return lo, hi


def transmission_counts(result: EstimationResult, window: Any = None) -> np.ndarray:
    """Transmissions of each node in ``window`` (closed; default the whole horizon).

    Returns
    -------
    ndarray of int, shape (B, N)

    """
    lo, hi = _window(window, result)
    log = result.transmissions
    keep = (log.t >= lo) & (log.t <= hi) & (log.rule < result.n_nodes)
    out = np.zeros((result.n_runs, result.n_nodes), dtype=np.int64)
    np.add.at(out, (log.run[keep], log.rule[keep]), 1)
    return out


def input_transmission_counts(result: EstimationResult, window: Any = None) -> np.ndarray:
    """Transmissions of each input node (section 6.3) in ``window``, counted apart from the outputs'.

    Returns
    -------
    ndarray of int, shape (B, number of input nodes)

    """
    lo, hi = _window(window, result)
    log = result.transmissions
    n = result.n_nodes
    keep = (log.t >= lo) & (log.t <= hi) & (log.rule >= n)
    out = np.zeros((result.n_runs, len(result.problem.input_nodes)), dtype=np.int64)
    np.add.at(out, (log.run[keep], log.rule[keep] - n), 1)
    return out


def inter_event_times(result: EstimationResult, run: int, node: int) -> np.ndarray:
    """Times between consecutive transmissions of ``node`` in ``run``."""
    return np.diff(result.transmission_times(run, node))


def min_inter_event_time(result: EstimationResult) -> np.ndarray:
    """Smallest time between two transmissions of the same node.

    Returns
    -------
    ndarray, shape (B, N)
        NaN where a node transmitted fewer than twice.

    """
    out = np.full((result.n_runs, result.n_nodes), np.nan)
    log = result.transmissions
    for b in range(result.n_runs):
        for i in range(result.n_nodes):
            d = np.diff(log.t[(log.run == b) & (log.rule == i)])
            if d.size:
                out[b, i] = d.min()
    return out


_BLOCK_BYTES = 4 * 2**20


def max_estimation_error(result: EstimationResult, window: Any) -> np.ndarray:
    """``max |x - xhat|`` over the save-grid points in ``window``, per run.

    The maximum is taken on the grid given to ``SaveAt(grid=...)``; state that grid
    with the figure (the robot-arm demo uses a 1 ms grid).

    Returns
    -------
    ndarray, shape (B,)
        NaN for runs that stopped before reaching the window.

    """
    lo, hi = _window(window, result)
    g = result.solution.grid
    if g is None:
        result.on_grid()  # raises the error that says how to keep a grid
    assert g is not None
    cols = np.flatnonzero((g.t >= lo) & (g.t <= hi))
    if not cols.size:
        raise InputError(f"the save grid has no point in the window [{lo:g}, {hi:g}]")
    # Only x and xhat = psi(z) on the window's points: the grid is sorted, so the
    # window is a slice. A sweep keeps ~10^4 points per run, so runs are taken a few at
    # a time: the temporaries stay small (big ones cost fresh pages on every call).
    lay, q = result.problem.layout, g.x[:, cols[0] : cols[-1] + 1]
    block = max(1, _BLOCK_BYTES // (8 * q.shape[1] * q.shape[2]))
    out = np.empty(q.shape[0])
    for a in range(0, q.shape[0], block):
        qb = q[a : a + block]
        z = qb[..., lay.z]
        with np.errstate(invalid="ignore"):
            xhat = result.problem.psi(z.reshape(-1, z.shape[-1])).reshape(*z.shape[:-1], -1)
            dx = qb[..., lay.x] - xhat
            err = np.sqrt(np.einsum("bgi,bgi->bg", dx, dx))
            out[a : a + block] = np.where(
                np.all(np.isfinite(err), axis=1), np.max(np.nan_to_num(err, nan=-np.inf), axis=1), np.nan
            )
    return out
