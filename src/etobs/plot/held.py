"""The values the observer holds, ``ybar_i``, as steps over what the nodes measure."""

from __future__ import annotations

from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.errors import InputError, InputTypeError
from etobs.estimation.result import EstimationResult
from etobs.model.signals import Zero
from etobs.plot.arc import solution_rows
from etobs.plot.figures import _figure, _node_name, _run


def _nodes(result: EstimationResult, nodes: Any) -> tuple[int, ...]:
    pb = result.problem
    C = pb.n_channels
    if nodes is None:
        return tuple(range(C))
    chosen = v.index_tuple("nodes", nodes, what="node")
    for i in chosen:
        if i >= C:
            inputs = f" and {C - pb.n_nodes} input nodes ({pb.n_nodes}..{C - 1})" if C > pb.n_nodes else ""
            raise InputError(
                f"`nodes` names node {i}, which does not exist: the problem has {pb.n_nodes} output nodes "
                f"(0..{pb.n_nodes - 1}){inputs}"
            )
    return chosen


def _measured(result: EstimationResult, t: np.ndarray, j: np.ndarray, q: np.ndarray) -> list[np.ndarray]:
    """What each node compares its held value with, one ``(K, size)`` array per node.

    ``ytilde_i`` (``ytilde_i - yhat_i`` in the observer-copy hold) is ``ybar_i - e_i``
    with ``e`` as :meth:`EstimationResult.arc` computes it (eq. (49)); an input node's
    is ``u``.
    """
    pb = result.problem
    tr = result._trajectory(t, j, q)
    y = tr.ybar - tr.e
    u = pb.u(np.asarray(t, dtype=float)) if pb.input_nodes else None
    return [y[:, ch.index] if ch.kind == "y" else u[:, ch.index] for ch in pb.layout.channels]  # type: ignore[index]


def _labels(result: EstimationResult, node: int) -> list[tuple[str, str]]:
    """``(held, measured)`` legend labels of each of the node's components (1-based, as the paper)."""
    pb = result.problem
    ch = pb.layout.channels[node]
    if ch.kind == "u":
        return [(rf"$\bar u_{{{k + 1}}}$", f"$u_{{{k + 1}}}$") for k in ch.index]
    y = "y" if isinstance(pb.m, Zero) else r"\tilde y"
    if pb.hold == "innovation":  # Remark 3: the node sends ytilde - yhat
        return [(rf"$\bar y_{{{k + 1}}}$", rf"${y}_{{{k + 1}}} - \hat y_{{{k + 1}}}$") for k in ch.index]
    return [(rf"$\bar y_{{{k + 1}}}$", f"${y}_{{{k + 1}}}$") for k in ch.index]


def plot_held_outputs(result: EstimationResult, run: int = 0, nodes: Any = None) -> tuple[Any, np.ndarray]:
    """Each node's held values ``ybar_i`` as steps over its measured ``y_i``, transmissions marked.

    One panel per node. Thin line: what the node measures (``y_i``, ``ytilde_i`` with
    noise, ``ytilde_i - yhat_i`` with ``hold="innovation"``, ``u_k`` for an input node);
    thick steps: what the observer holds (``ybar_i``, ``ubar_k``). Ticks along the
    bottom mark the node's transmission instants (``result.transmissions``); from an
    arc, dots mark the values sent. With a :class:`~etobs.model.network.Network` the
    held value changes when a packet arrives, after its transmission, or not at all
    when it is lost.

    Parameters
    ----------
    result : EstimationResult
        With the arcs kept (``SaveAt(steps=True)``): exact steps, and the values sent.
        Else from the save grid (``SaveAt(grid=...)``): the held values are known only at
        the grid's points, so each step is drawn at the first grid point after its
        transmission; the transmission instants are exact. The first panel's title says
        which.
    run : int
        Which run.
    nodes : int or sequence of int, optional
        Output nodes ``0 .. N-1``, then the input nodes, as in ``result.transmissions``.
        Default: all.

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of Axes, one per node

    Examples
    --------
    >>> fig, axes = plot_held_outputs(result, nodes=[0])  # doctest: +SKIP

    """
    if not isinstance(result, EstimationResult):
        raise InputTypeError(f"`result` must be an EstimationResult; got {type(result).__name__}")
    run = _run(result.n_runs, run)
    chosen = _nodes(result, nodes)
    t, j, q, kept = solution_rows(result.solution, run)
    if not kept:
        sol = result.solution
        only = (
            " (it kept only max |x - xhat| over its grid: SaveAt(max_distance=...))" if sol.grid_max else ""
        )
        raise InputError(
            f"this result kept neither arcs nor a grid of states{only}: simulate with "
            "save=SaveAt(steps=True) (exact steps) or save=SaveAt(grid=...)"
        )
    source = "grid" if kept == "grid" else "arc"
    measured = _measured(result, t, j, q)
    pb = result.problem
    fig, axes = _figure(len(chosen), 1.9 * len(chosen) + 0.8)
    log = result.transmissions.select(run=run)
    for ax, node in zip(axes, chosen, strict=True):
        ch = pb.layout.channels[node]
        sent = log.select(rule=node)
        # the value sent at (t_k, j_k) is what the node measured just before its jump
        before = np.searchsorted(j, sent.j, side="right") - 1
        for m, (held_label, measured_label) in enumerate(_labels(result, node)):
            color = f"C{m % 10}"
            ax.plot(t, measured[node][:, m], color=color, lw=0.8, alpha=0.7, label=measured_label)
            # from an arc, the held value on both sides of each jump draws an exact step;
            # on a grid, each value holds from its point to the next
            style = "default" if source == "arc" else "steps-post"
            ax.plot(t, q[:, ch.held[m]], color=color, lw=1.6, drawstyle=style, label=held_label)
            if source == "arc":
                label = "values sent" if m == 0 else None
                ax.plot(
                    sent.t, measured[node][before, m], ls="none", marker="o", ms=3.5, color=color, label=label
                )
        ax.plot(
            sent.t,
            np.full(len(sent), 0.03),  # just above the bottom edge, clear of the axis ticks
            ls="none",
            marker="|",
            ms=9,
            mew=1.0,
            color="k",
            transform=ax.get_xaxis_transform(),  # x in data, y in axes: the bottom edge
            label=f"transmissions ({len(sent)})",
        )
        ax.set_ylabel(_node_name(result, node))
        # beside the panel: the steps fill it, and a legend inside would hide some
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", frameon=False)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("t [s]")
    if source == "arc":
        note = "from the hybrid arc: exact steps; dots: values sent"
    else:
        note = "from the save grid: steps at its points (keep arcs for exact steps); ticks exact"
    if pb.network is not None:
        note += "; held values change on delivery"
    axes[0].set_title(note, fontsize="small")
    fig.suptitle(f"Held values (steps) over measured values, run {run}")
    return fig, axes
