"""The values the observer holds, ``ybar_i``, as steps over what the nodes measure."""

from __future__ import annotations

from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.errors import InputError, InputTypeError
from etobs.estimation.result import EstimationResult
from etobs.estimation.tables import node_sent_values
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
    """What each node measures, to compare with what it sent: one ``(K, size)`` array per node.

    ``ytilde_i`` (``ytilde_i - yhat_i`` in the observer-copy hold) is ``ybar_i - e_i``
    with ``e`` as :meth:`EstimationResult.arc` computes it (eq. (49)); an input node's
    is ``u``.
    """
    pb = result.problem
    tr = result.trajectory(t, j, q)
    y = tr.ybar - tr.e
    u = pb.u(np.asarray(t, dtype=float)) if pb.input_nodes else None
    return [y[:, ch.index] if ch.kind == "y" else u[:, ch.index] for ch in pb.layout.channels]  # type: ignore[index]


def _steps(
    t: np.ndarray, held: np.ndarray, t_sent: np.ndarray, sent: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The held value as a ``steps-post`` line: ``held[0]`` at ``t[0]``, then each value sent.

    Without a network the observer holds what the node last sent (eq. (5)), so the
    transmissions log gives the steps exactly, at their instants, whatever the grid.
    At a transmission time the grid keeps the value before the jump, so a transmission at
    ``t[0]`` is a step there too.
    """
    after = t_sent >= t[0]
    t_sent, sent = t_sent[after], sent[after]
    end = max(t[-1], t_sent[-1]) if t_sent.size else t[-1]
    last = sent[-1:] if sent.size else held[:1]
    return np.concatenate([t[:1], t_sent, [end]]), np.concatenate([held[:1], sent, last])


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
    bottom mark the node's transmission instants and dots the values sent, both from
    ``result.transmissions``. With a :class:`~etobs.model.network.Network` the held
    value changes when a packet arrives, after its transmission, or not at all when it
    is lost.

    Parameters
    ----------
    result : EstimationResult
        With the arcs kept (``SaveAt(steps=True)``): exact steps and measured values
        along the solver's steps (and the grid's points when kept too). Else from the save
        grid (``SaveAt(grid=...)``): the measured values at its points, and the steps
        exact from the transmission log (the observer holds what the node last sent,
        eq. (5)), except with a network, where the held values are known only at the
        grid's points (each step drawn at the first point after it). The first panel's
        title says which.
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
        only = ""
        if result.solution.grid_max is not None:
            only = " (it kept only max |x - xhat| over its grid: SaveAt(max_distance=...))"
        raise InputError(
            f"this result kept neither arcs nor a grid of states{only}: simulate with "
            "save=SaveAt(steps=True) (exact steps) or save=SaveAt(grid=...)"
        )
    source = "grid" if kept == "grid" else "arc"
    measured = _measured(result, t, j, q)
    pb = result.problem
    # from the log alone, without a network: the observer holds what the node last sent
    exact = source == "arc" or pb.network is None
    fig, axes = _figure(len(chosen), 1.9 * len(chosen) + 0.8)
    log = result.transmissions.select(run=run)
    for ax, node in zip(axes, chosen, strict=True):
        ch = pb.layout.channels[node]
        sent = log.select(rule=node)
        values = node_sent_values(result, sent, node)
        for m, (held_label, measured_label) in enumerate(_labels(result, node)):
            color = f"C{m % 10}"
            ax.plot(t, measured[node][:, m], color=color, lw=0.8, alpha=0.7, label=measured_label)
            if source == "arc":  # the arc has the held value on both sides of each jump
                th, held, style = t, q[:, ch.held[m]], "default"
            elif exact:
                th, held = _steps(t, q[:, ch.held[m]], sent.t, values[:, m])
                style = "steps-post"
            else:  # with a network it changes on delivery: known only at the grid's points
                th, held, style = t, q[:, ch.held[m]], "steps-post"
            ax.plot(th, held, color=color, lw=1.6, drawstyle=style, label=held_label)
            label = "values sent" if m == 0 else None
            ax.plot(sent.t, values[:, m], ls="none", marker="o", ms=3.5, color=color, label=label)
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
    elif exact:
        note = "steps from the transmission log (exact); measured values on the save grid; dots: values sent"
    else:
        note = "from the save grid: held values at its points (keep arcs for exact steps); dots: values sent"
    if pb.network is not None:
        note += "; held values change on delivery"
    axes[0].set_title(note, fontsize="small")
    fig.suptitle(f"Held values (steps) over measured values, run {run}")
    return fig, axes
