"""The values the observer holds, ``ybar_i``, as steps over what the nodes measure."""

from __future__ import annotations

from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.errors import InputError
from etobs.estimation.result import EstimationResult
from etobs.estimation.tables import node_sent_values
from etobs.model.quantities import with_unit
from etobs.model.signals import Zero
from etobs.plot.arc import solution_rows
from etobs.plot.figures import _node_name, check_result
from etobs.plot.layout import Drawn, canvas, in_window, runs, shared, time_axes
from etobs.plot.layout import window as check_window


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
    """``(held, measured)`` legend labels of each of the node's components.

    The model's names when it gives them (``"motor angle, held"``), else the paper's
    symbols, 1-based (``ybar_1`` over ``y_1``, in math text).
    """
    pb = result.problem
    ch = pb.layout.channels[node]
    kind = "u" if ch.kind == "u" else "y"
    quantities = [pb.quantities(kind)[k] for k in ch.index]
    noisy = kind == "y" and not isinstance(pb.m, Zero)
    innovation = kind == "y" and pb.hold == "innovation"  # Remark 3: the node sends ytilde - yhat
    out = []
    for k, q in zip(ch.index, quantities, strict=True):
        if q.name:
            measured = q.name + (", measured" if noisy else "") + (" - estimate" if innovation else "")
            out.append((f"{q.name}, held", measured))
            continue
        y = "y" if not noisy else r"\tilde y"
        if kind == "u":
            out.append((rf"$\bar u_{{{k + 1}}}$", f"$u_{{{k + 1}}}$"))
        elif innovation:
            out.append((rf"$\bar y_{{{k + 1}}}$", rf"${y}_{{{k + 1}}} - \hat y_{{{k + 1}}}$"))
        else:
            out.append((rf"$\bar y_{{{k + 1}}}$", f"${y}_{{{k + 1}}}$"))
    return out


def _unit(result: EstimationResult, node: int) -> str:
    """The unit of the node's values, when the model gives one and they share it."""
    pb = result.problem
    ch = pb.layout.channels[node]
    units = {pb.quantities("u" if ch.kind == "u" else "y")[k].unit for k in ch.index}
    return units.pop() if len(units) == 1 else ""


def plot_held_outputs(
    result: EstimationResult, run: Any = 0, nodes: Any = None, *, ax: Any = None, window: Any = None
) -> Drawn:
    """Each node's held values ``ybar_i`` as steps over its measured ``y_i``, transmissions marked.

    One panel per node. Thin line: what the node measures (``y_i``, ``ytilde_i`` with
    noise, ``ytilde_i - yhat_i`` with ``hold="innovation"``, ``u_k`` for an input node);
    thick steps: what the observer holds (``ybar_i``, ``ubar_k``). Ticks along the
    bottom mark the node's transmission instants and dots the values sent, both from
    ``result.transmissions``. With a :class:`~etobs.model.network.Network` the held
    value changes when a packet arrives, after its transmission, or not at all when it
    is lost. Legends use the outputs' names and the panels their unit when the model
    gives them.

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
    run : int or sequence of int
        Which run, or several overlaid (one colour each, named in the legend).
    nodes : int or sequence of int, optional
        Output nodes ``0 .. N-1``, then the input nodes, as in ``result.transmissions``.
        Default: all.
    ax : Axes or sequence of Axes, optional
        One per node drawn; default a new figure.
    window : (float, float), optional
        Draw only ``t0 <= t <= t1``.

    Returns
    -------
    Drawn
        ``fig, axes`` (one per node); artists ``"measured"``, ``"held"``, ``"sent"`` (the
        dots) and ``"ticks"`` (the transmission instants), per run, node and component.

    Examples
    --------
    >>> drawn = plot_held_outputs(result, nodes=[0])
    >>> drawn.artists["held"][0].get_label(), drawn.axes[0].get_ylabel().splitlines()
    ('position, held', ['sensor 1', '[m]'])

    """
    result = check_result(result)
    chosen_runs = runs(result.n_runs, run)
    span = check_window(window)
    chosen = _nodes(result, nodes)
    pb = result.problem
    fig, axes, own = canvas(ax, len(chosen), 1.9 * len(chosen) + 0.8)
    drawn: dict[str, list[Any]] = {"measured": [], "held": [], "sent": [], "ticks": []}
    for r_k, r in enumerate(chosen_runs):
        source = _draw_run(result, r, chosen, axes, span, drawn, r_k, len(chosen_runs))
    overlaid = shared(axes)
    for a, node in zip(axes, chosen, strict=True):
        unit = _unit(result, node)
        if overlaid:  # the nodes' values in one Axes: the unit when they share it
            units = {_unit(result, n) for n in chosen}
            a.set_ylabel(with_unit("", unit).strip() if len(units) == 1 else "")
        else:
            a.set_ylabel("\n".join(filter(None, [_node_name(result, node), with_unit("", unit).strip()])))
        # beside the panel: the steps fill it, and a legend inside would hide some
        a.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", frameon=False)
        a.grid(alpha=0.3)
    time_axes(axes, span)
    exact = source == "arc" or pb.network is None
    if source == "arc":
        note = "from the hybrid arc: exact steps; dots: values sent"
    elif exact:
        note = "steps from the transmission log (exact); measured values on the save grid; dots: values sent"
    else:
        note = "from the save grid: held values at its points (keep arcs for exact steps); dots: values sent"
    if pb.network is not None:
        note += "; held values change on delivery"
    if own:  # on the caller's figure the title is theirs
        axes[0].set_title(note, fontsize="small")
        which = (
            f"run {chosen_runs[0]}" if len(chosen_runs) == 1 else "runs " + ", ".join(map(str, chosen_runs))
        )
        fig.suptitle(f"Held values (steps) over measured values, {which}")
    return Drawn(fig, axes, drawn)


def _draw_run(
    result: EstimationResult,
    run: int,
    chosen: tuple[int, ...],
    axes: np.ndarray,
    span: tuple[float, float] | None,
    drawn: dict[str, list[Any]],
    r_k: int,
    n_runs: int,
) -> str:
    """Draw run ``run`` into ``axes`` (one per node of ``chosen``); returns what the rows came from."""
    t, j, q, kept = solution_rows(result.solution, run)
    if not kept:
        only = ""
        if result.solution.grid_max is not None:
            only = " (it kept only max |x - xhat| over its grid: SaveAt(max_distance=...))"
        raise InputError(
            f"this result kept neither arcs nor a grid of states{only}: simulate with "
            "save=SaveAt(steps=True) (exact steps) or save=SaveAt(grid=...)"
        )
    keep = in_window(t, span, reach=True)  # a point beyond each end: the lines reach the edges
    t, j, q = t[keep], j[keep], q[keep]
    if not t.size:  # nothing saved in or around the window: nothing to draw for this run
        return "grid" if kept == "grid" else "arc"
    source = "grid" if kept == "grid" else "arc"
    measured = _measured(result, t, j, q)
    pb = result.problem
    # from the log alone, without a network: the observer holds what the node last sent
    exact = source == "arc" or pb.network is None
    whole = result.transmissions.select(run=run)
    steps_log = whole[in_window(whole.t, (float(t[0]), float(t[-1])))]  # every change the rows span
    log = whole[in_window(whole.t, span)] if span is not None else whole  # marked: those in the window
    several = f" (run {run})" if n_runs > 1 else ""
    overlaid = shared(axes)  # every node in one Axes: a colour per component, ticks stacked
    # a colour per (run, component): the components of a panel (of all panels when overlaid)
    per_run = sum(pb.layout.channels[n].size for n in chosen) if overlaid else 0
    offset = 0
    for position, (a, node) in enumerate(zip(axes, chosen, strict=True)):
        ch = pb.layout.channels[node]
        sent = log.select(rule=node)
        values = node_sent_values(result, sent, node)
        changes = steps_log.select(rule=node)
        first = offset if overlaid else 0
        for m, (held_label, measured_label) in enumerate(_labels(result, node)):
            color = f"C{(r_k * (per_run or ch.size) + first + m) % 10}"
            drawn["measured"] += a.plot(
                t, measured[node][:, m], color=color, lw=0.8, alpha=0.7, label=measured_label + several
            )
            if source == "arc":  # the arc has the held value on both sides of each jump
                th, held, style = t, q[:, ch.held[m]], "default"
            elif exact:
                th, held = _steps(
                    t, q[:, ch.held[m]], changes.t, node_sent_values(result, changes, node)[:, m]
                )
                style = "steps-post"
            else:  # with a network it changes on delivery: known only at the grid's points
                th, held, style = t, q[:, ch.held[m]], "steps-post"
            drawn["held"] += a.plot(
                th, held, color=color, lw=1.6, drawstyle=style, label=held_label + several
            )
            label = "values sent" + several if m == 0 and not overlaid else None
            drawn["sent"] += a.plot(
                sent.t, values[:, m], ls="none", marker="o", ms=3.5, color=color, label=label
            )
        alone = n_runs == 1 and not overlaid
        tick_color = "k" if alone else f"C{(r_k * (per_run or ch.size) + first) % 10}"
        offset += ch.size
        row = r_k * (len(chosen) if overlaid else 1) + (position if overlaid else 0)
        drawn["ticks"] += a.plot(
            sent.t,
            # just above the bottom edge, clear of the axis ticks; a row per node and run when several
            np.full(len(sent), 0.03 + 0.06 * row),
            ls="none",
            marker="|",
            ms=9,
            mew=1.0,
            color=tick_color,
            transform=a.get_xaxis_transform(),  # x in data, y in axes: the bottom edge
            label=(f"{_node_name(result, node)}: " if overlaid else "")
            + f"transmissions ({len(sent)})"
            + several,
        )
    return source
