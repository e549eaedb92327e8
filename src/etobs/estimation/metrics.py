"""The paper's metrics (section 8): transmissions, inter-event times, estimation error."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from etobs import _validate as v
from etobs.errors import InputError
from etobs.hybrid.solution import max_over_grid

if TYPE_CHECKING:  # a result's tables call these: the result is above, named for types only
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


_NODES = ("outputs", "inputs", "all")


def _node_range(result: EstimationResult, nodes: str) -> tuple[int, int]:
    """First node index and count of the node set ``nodes``."""
    if nodes not in _NODES:
        raise InputError(f"`nodes` must be one of {_NODES}; got {nodes!r}")
    n, c = result.n_nodes, result.problem.n_channels
    return {"outputs": (0, n), "inputs": (n, c - n), "all": (0, c)}[nodes]


def transmission_counts(
    result: EstimationResult, window: Any = None, *, nodes: str = "outputs"
) -> np.ndarray:
    """Transmissions of each node in ``window`` (closed; default the whole horizon).

    Parameters
    ----------
    result : EstimationResult
    window : (float, float), optional
    nodes : {"outputs", "inputs", "all"}
        The output nodes, the input nodes (section 7.3), or both (outputs first).

    Returns
    -------
    ndarray of int, shape (B, number of nodes)

    Examples
    --------
    The robot arm from the paper's ``x0``, 10 s: each node's transmissions, then those of
    the first 5 s:

    >>> import numpy as np
    >>> from etobs import SaveAt, simulate
    >>> from etobs.examples import robot_arm
    >>> grid = SaveAt(grid=np.linspace(0.0, 10.0, 1001))
    >>> res = simulate(robot_arm(), [3.0, 2.0, 3.0, -2.0], 10.0, save=grid)
    >>> from etobs import transmission_counts
    >>> transmission_counts(res).tolist(), transmission_counts(res, (0.0, 5.0)).tolist()
    ([[16, 16]], [[4, 9]])

    """
    lo, hi = _window(window, result)
    first, count = _node_range(result, nodes)
    log = result.transmissions
    keep = (log.t >= lo) & (log.t <= hi) & (log.rule >= first) & (log.rule < first + count)
    out = np.zeros((result.n_runs, count), dtype=np.int64)
    np.add.at(out, (log.run[keep], log.rule[keep] - first), 1)
    return out


def input_transmission_counts(result: EstimationResult, window: Any = None) -> np.ndarray:
    """Transmissions of each input node (section 7.3), counted apart from the outputs'.

    Same as ``transmission_counts(result, window, nodes="inputs")``.

    Parameters
    ----------
    result : EstimationResult
    window : (float, float), optional
        Closed time window; default the whole horizon.

    Returns
    -------
    ndarray of int, shape (B, number of input nodes)

    Examples
    --------
    A problem without input nodes has none to count:

    >>> import numpy as np
    >>> from etobs import SaveAt, simulate
    >>> from etobs.examples import robot_arm
    >>> grid = SaveAt(grid=np.linspace(0.0, 10.0, 1001))
    >>> res = simulate(robot_arm(), [3.0, 2.0, 3.0, -2.0], 10.0, save=grid)
    >>> from etobs import input_transmission_counts
    >>> input_transmission_counts(res).shape
    (1, 0)

    """
    return transmission_counts(result, window, nodes="inputs")


def inter_event_times(result: EstimationResult, run: int, node: int) -> np.ndarray:
    """Times between consecutive transmissions of ``node`` in ``run``.

    Parameters
    ----------
    result : EstimationResult
    run, node : int
        The run of the batch and the node (output nodes, then input nodes).

    Returns
    -------
    ndarray, shape (transmissions - 1,)

    Examples
    --------
    >>> import numpy as np
    >>> from etobs import SaveAt, simulate
    >>> from etobs.examples import robot_arm
    >>> grid = SaveAt(grid=np.linspace(0.0, 10.0, 1001))
    >>> res = simulate(robot_arm(), [3.0, 2.0, 3.0, -2.0], 10.0, save=grid)
    >>> from etobs import inter_event_times
    >>> inter_event_times(res, 0, 0).round(3)[:4].tolist()
    [0.574, 0.386, 0.514, 1.916]

    """
    return np.diff(result.transmission_times(run, node))


def min_inter_event_time(result: EstimationResult, *, nodes: str = "outputs") -> np.ndarray:
    """Smallest time between two transmissions of the same node.

    Parameters
    ----------
    result : EstimationResult
    nodes : {"outputs", "inputs", "all"}
        As in :func:`transmission_counts`.

    Returns
    -------
    ndarray, shape (B, number of nodes)
        NaN where a node transmitted fewer than twice. ``nodes`` as in
        :func:`transmission_counts`.

    Examples
    --------
    The paper reports 0.201 s and 0.112 s on 30 s (section 8); on the first 10 s:

    >>> import numpy as np
    >>> from etobs import SaveAt, simulate
    >>> from etobs.examples import robot_arm
    >>> grid = SaveAt(grid=np.linspace(0.0, 10.0, 1001))
    >>> res = simulate(robot_arm(), [3.0, 2.0, 3.0, -2.0], 10.0, save=grid)
    >>> from etobs import min_inter_event_time
    >>> min_inter_event_time(res).round(4).tolist()
    [[0.2007, 0.1115]]

    """
    first, count = _node_range(result, nodes)
    log = result.transmissions
    keep = (log.rule >= first) & (log.rule < first + count)
    run, node, t = log.run[keep], log.rule[keep] - first, log.t[keep]
    # one pass over the log (a loop over runs and nodes was quadratic in the batch):
    # group each node's transmissions in time order, and take the gaps within a group
    order = np.lexsort((t, node, run))
    run, node, t = run[order], node[order], t[order]
    same = (run[1:] == run[:-1]) & (node[1:] == node[:-1])
    out = np.full((result.n_runs, count), np.inf)
    np.minimum.at(out, (run[1:][same], node[1:][same]), np.diff(t)[same])
    out[np.isinf(out)] = np.nan  # fewer than two transmissions
    return out


_BLOCK_BYTES = 4 * 2**20


def max_estimation_error(result: EstimationResult, window: Any) -> np.ndarray:
    """``max |x - xhat|`` over the save-grid points in ``window``, per run.

    The maximum is taken on the grid given to ``SaveAt(grid=...)``; state that grid
    with the figure (the robot-arm demo uses a 1 ms grid). A result simulated with
    ``SaveAt(grid=g, max_distance="estimation_error")`` kept only this maximum over
    ``g``: the window must then contain every point of ``g``.

    Parameters
    ----------
    result : EstimationResult
        Simulated with a save grid (``SaveAt(grid=...)``).
    window : (float, float)
        Closed time window.

    Returns
    -------
    ndarray, shape (B,)
        NaN for runs that stopped before reaching the window.

    Examples
    --------
    >>> import numpy as np
    >>> from etobs import SaveAt, simulate
    >>> from etobs.examples import robot_arm
    >>> grid = SaveAt(grid=np.linspace(0.0, 10.0, 1001))
    >>> res = simulate(robot_arm(), [3.0, 2.0, 3.0, -2.0], 10.0, save=grid)
    >>> from etobs import max_estimation_error
    >>> max_estimation_error(res, (5.0, 10.0)).round(3).tolist()
    [6.889]

    """
    lo, hi = _window(window, result)
    g = result.solution.grid
    kept = result.solution.grid_max
    if g is None and kept is not None:
        inside = (kept.t >= lo) & (kept.t <= hi)
        if kept.t.size and np.all(inside):
            return kept.value.copy()
        raise InputError(
            f"this result kept only max |x - xhat| over its grid ({kept.t.size} points on "
            f"[{kept.t[0]:g}, {kept.t[-1]:g}] s), which the window [{lo:g}, {hi:g}] does not cover "
            "whole: simulate with SaveAt(grid=...) and no max_distance to take other windows"
            if kept.t.size
            else "this result kept max |x - xhat| over an empty grid"
        )
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
            out[a : a + block] = max_over_grid(err)
    return out
