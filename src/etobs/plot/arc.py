"""Hybrid arcs in hybrid time ``(t, j)``, drawn as the HyEQ toolbox draws them.

The HyEQ toolbox (Sanfelice et al.; ``plotflows``, ``plotTimeDomain``,
``HybridPlotBuilder``) draws a hybrid arc's flows as solid lines and connects the values
before and after each jump with a dashed line. We keep that convention and show the jump
index ``j`` in a second panel, the hybrid time domain ``j`` against ``t`` (HyEQ's
``plotTimeDomain``), rather than in a 3-D ``(t, j, x)`` view (``plotHarc``): an
estimator makes hundreds of transmissions, which a 3-D view squeezes into an unreadable
ribbon, while two panels sharing the ``t`` axis keep both the values and the jump
instants legible at any count.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.errors import InputError, InputTypeError
from etobs.estimation.result import EstimationResult
from etobs.hybrid.solution import HybridArc, HybridSolution
from etobs.model.quantities import with_unit
from etobs.plot.figures import _node_name, _run
from etobs.plot.layout import Drawn, canvas, in_window, run_color, runs, shared, time_axes
from etobs.plot.layout import components as entries
from etobs.plot.layout import window as check_window

#: What ``plot_hybrid_arc`` can draw from an :class:`EstimationResult`, with its label.
_VARIABLES = {
    "error": r"$|x - \hat x|$",
    "x": "x",
    "xhat": r"\hat x",
    "z": "z",
    "ybar": r"\bar y",
    "e": "e",
    "eta": r"\eta",
}


@dataclass(frozen=True)
class _Rows:
    """One run's points in hybrid-time order: ``values[k]`` at ``(t[k], j[k])``."""

    t: np.ndarray
    j: np.ndarray
    values: np.ndarray  # (K, m)
    labels: tuple[str, ...]
    refined: bool  # whether the save grid's points were added to the arc's


def hybrid_order(t: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Indices sorting points by hybrid time: by ``j``, then ``t``.

    ``j`` first: at a jump time ``t`` both ``(t, j)`` and ``(t, j + 1)`` exist, and the
    point before the jump must come first.
    """
    return np.lexsort((t, j))


def solution_rows(sol: HybridSolution, run: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """Run ``run``'s points ``(t, j, q)`` in hybrid-time order, and what they come from.

    The arc (``"arc"``) holds the state at step ends and on both sides of every jump, so
    its flows are chords between steps that may be long; the save grid's points lie on
    the same solution (dense output; at a jump time, the value before the jump), so when
    both were kept they are merged (``"arc+grid"``): smoother flows, the same jumps
    (HyEQ's ``Refine`` does the same). ``"grid"``: only the grid (no jump drawn exactly);
    ``""``: neither was kept.
    """
    parts, kept = [], []
    if sol.arcs is not None:
        arc = sol.arcs[run]
        parts.append((arc.t, arc.j, arc.x))
        kept.append("arc")
    if sol.grid is not None:
        g = sol.grid
        keep = g.j[run] >= 0  # -1 outside the horizon or after the run stopped
        parts.append((g.t[keep], g.j[run][keep], g.x[run][keep]))
        kept.append("grid")
    if not parts:
        return np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros((0, sol.x_final.shape[1])), ""
    t, j, q = (np.concatenate(p) for p in zip(*parts, strict=True))
    order = hybrid_order(t, j)
    return t[order], j[order], q[order], "+".join(kept)


def _estimation_rows(result: EstimationResult, run: int, what: str, components: Any) -> _Rows:
    if what not in _VARIABLES:
        raise InputError(f"`what` must be one of {sorted(_VARIABLES)}; got {what!r}")
    if result.solution.arcs is None:
        result.arc(run)  # raises, saying how to keep the arcs
    t, j, q, kept = solution_rows(result.solution, run)
    tr, refined = result.trajectory(t, j, q), kept == "arc+grid"
    if what == "error":
        if components is not None:
            raise InputError(
                "`components` selects entries of a vector; `what='error'` is the scalar |x - xhat|"
            )
        return _Rows(tr.t, tr.j, tr.error[:, None], (_VARIABLES["error"],), refined)
    values = getattr(tr, what)
    if what == "eta":
        stateful = [i for i in range(values.shape[1]) if np.isfinite(values[:, i]).any()]
        if components is None:
            if not stateful:
                raise InputError("`what='eta'`: no node's rule has a state eta (static or periodic rules)")
            comps = tuple(stateful)
        else:
            comps = entries("components", components, values.shape[1])
            for i in comps:
                if i not in stateful:
                    raise InputError(
                        f"`components` names node {i} ({_node_name(result, i)}), whose rule has no state eta"
                    )
        labels = tuple(rf"$\eta$ ({_node_name(result, i)})" for i in comps)
    else:
        comps = entries("components", components, values.shape[1])
        labels = tuple(_label(result, what, k) for k in comps)
    return _Rows(tr.t, tr.j, values[:, comps], labels, refined)


def _label(result: EstimationResult, what: str, k: int) -> str:
    """Legend label of entry ``k`` of ``what``: the model's name for it, else the paper's symbol."""
    q = result.problem.quantities(what)[k]
    if not q.name:
        return f"${_VARIABLES[what]}_{{{k + 1}}}$"
    suffix = {"x": "", "xhat": " estimate", "z": "", "ybar": ", held", "e": ", error e"}[what]
    return with_unit(q.name + suffix, q.unit)


def _hybrid_rows(result: HybridSolution | HybridArc, run: int, what: str, components: Any) -> _Rows:
    if what != "x":
        raise InputError(
            f"`what` must be 'x' for a {type(result).__name__} (it holds only the state x); got {what!r}"
        )
    if isinstance(result, HybridArc):
        if run != 0:
            raise InputError(f"`run` must be 0 for a HybridArc (one run); got {run}")
        t, j, x, kept = result.t, result.j, result.x, "arc"
    else:
        run = _run(result.n_runs, run)
        if result.arcs is None:
            raise InputError("this solution kept no arcs: solve with save=SaveAt(steps=True)")
        t, j, x, kept = solution_rows(result, run)
    comps = entries("components", components, x.shape[1])
    return _Rows(t, j, x[:, comps], tuple(f"$x_{{{k + 1}}}$" for k in comps), kept == "arc+grid")


def flows_and_jumps(t: np.ndarray, j: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split points in hybrid-time order into flows and jumps.

    Returns ``(tf, yf, jumps)``: ``tf, yf`` are ``t, y`` with a NaN between consecutive
    flow intervals (so one line draws every flow and none crosses a jump), and
    ``jumps[k] = [[t, y before], [t, y after]]`` for each jump, shape ``(J, 2, 2)``.
    """
    at = np.flatnonzero(np.diff(j) != 0)  # point at..at+1 is a jump
    tf = np.insert(np.asarray(t, dtype=float), at + 1, np.nan)
    yf = np.insert(np.asarray(y, dtype=float), at + 1, np.nan)
    jumps = np.stack(
        [np.stack([t[at], y[at]], axis=-1), np.stack([t[at + 1], y[at + 1]], axis=-1)], axis=1
    ).astype(float)
    return tf, yf, jumps.reshape(-1, 2, 2)


def _draw(
    ax: Any,
    t: np.ndarray,
    j: np.ndarray,
    y: np.ndarray,
    flow: Any,
    jump: Any,
    label: str,
    drawn: dict[str, list[Any]],
) -> None:
    """Flows solid, jumps dashed (HyEQ's convention); one artist each, added to ``drawn``."""
    from matplotlib.collections import LineCollection

    tf, yf, jumps = flows_and_jumps(t, j, y)
    drawn["flows"] += ax.plot(tf, yf, color=flow, lw=1.2, label=label)
    drawn["jumps"].append(
        ax.add_collection(LineCollection(list(jumps), colors=[jump], linestyles="--", linewidths=0.9))
    )


def plot_hybrid_arc(
    result: EstimationResult | HybridSolution | HybridArc,
    run: Any = 0,
    *,
    what: str | None = None,
    components: Any = None,
    log: bool | None = None,
    ax: Any = None,
    window: Any = None,
) -> Drawn:
    """One run's hybrid arc in hybrid time ``(t, j)``: flows solid, jumps dashed (HyEQ).

    The top panel draws the chosen variable against ``t``; each jump is a dashed segment
    from the value before it to the value after it, at the jump's time. The bottom panel
    is the hybrid time domain, ``j`` against ``t``, drawn the same way: each step up is a
    jump (for an estimator, a transmission, or with a network a packet's delivery).

    Parameters
    ----------
    result : EstimationResult, HybridSolution or HybridArc
        Simulated with ``save=SaveAt(steps=True)`` (the default). When the save grid was
        kept too, its points are added to the arc's to draw the flows smoothly (the
        title says so); the jumps are the arc's.
    run : int or sequence of int
        Which run (0 for a HybridArc), or several overlaid: one colour per run, flows
        and jumps alike, named in the legend.
    what : str, optional
        For an EstimationResult: ``"error"`` (default, ``|x - xhat|``), ``"x"``,
        ``"xhat"``, ``"z"``, ``"ybar"``, ``"e"`` (``e = ybar - ytilde``, eq. (49)) or
        ``"eta"`` (one curve per node with a dynamic rule). For a HybridSolution or a
        HybridArc: ``"x"`` (default), the hybrid state. Entries carry the model's names
        and units when it gives them.
    components : int or sequence of int, optional
        Entries of the variable to draw (indices from 0; for ``"eta"``, nodes). Default:
        all.
    log : bool, optional
        Logarithmic value axis; default only for ``"error"``, as in :func:`plot_error`.
    ax : sequence of two Axes, optional
        The variable's and the hybrid time domain's; default a new figure.
    window : (float, float), optional
        Draw only the points with ``t0 <= t <= t1`` (and the jumps between them).

    Returns
    -------
    Drawn
        ``fig, axes`` (the variable against ``t``, then ``j`` against ``t``); artists
        ``"flows"`` and ``"jumps"`` (a line and a collection per run and entry) and
        ``"domain"`` (the ``j`` panel's, per run).

    Examples
    --------
    >>> fig, (ax, ax_j) = plot_hybrid_arc(result, what="eta")
    >>> len(ax.get_lines()), ax_j.get_ylabel()  # a curve per node, j below
    (2, 'j')

    """
    if what is not None and not isinstance(what, str):
        raise InputTypeError(f"`what` must be a string; got {v.shown(what)} ({type(what).__name__})")
    span = check_window(window)
    if isinstance(result, EstimationResult):
        chosen = runs(result.n_runs, run)
        name = what or "error"
        rows = [_estimation_rows(result, r, name, components) for r in chosen]
    elif isinstance(result, HybridSolution | HybridArc):
        if isinstance(result, HybridArc):
            try:
                chosen = runs(1, run)
            except InputError:
                raise InputError(f"`run` must be 0 for a HybridArc (one run); got {v.shown(run)}") from None
        else:
            chosen = runs(result.n_runs, run)
        rows = [_hybrid_rows(result, r, what or "x", components) for r in chosen]
        name = "x"
    else:
        raise InputTypeError(
            "`result` must be an EstimationResult, a HybridSolution or a HybridArc; "
            f"got {type(result).__name__}"
        )
    if log is not None:
        v.flag("log", log)
    rows = [_in(rs, span) for rs in rows]
    fig, axes, own = canvas(ax, 2, 4.4, height_ratios=[3.0, 1.0])
    if shared(axes):
        raise InputError("`ax` must be two Axes for plot_hybrid_arc: the variable's, then j's; got one")
    top, ax_j = axes
    drawn: dict[str, list[Any]] = {"flows": [], "jumps": [], "domain": []}
    single = rows[0].values.shape[1] == 1
    n_jumps = 0
    for r_k, (r, rs) in enumerate(zip(chosen, rows, strict=True)):
        several = f" (run {r})" if len(chosen) > 1 else ""
        for k, label in enumerate(rs.labels):
            # one variable: HyEQ's colours (blue flows, red jumps); several: one colour each
            if len(chosen) > 1:  # a colour per (run, entry)
                flow = jump = f"C{(r_k * len(rs.labels) + k) % 10}"
            else:
                flow = "C0" if single else f"C{k % 10}"
                jump = "C3" if single else flow
            _draw(top, rs.t, rs.j, rs.values[:, k], flow, jump, label + several, drawn)
        color = "0.25" if len(chosen) == 1 else run_color(r_k, len(chosen), "C0")
        part: dict[str, list[Any]] = {"flows": [], "jumps": []}
        _draw(ax_j, rs.t, rs.j, rs.j, color, "C3" if len(chosen) == 1 else color, "j" + several, part)
        drawn["domain"] += part["flows"] + part["jumps"]
        n_jumps += int(np.count_nonzero(np.diff(rs.j)))
    if log if log is not None else name == "error":
        top.set_yscale("log")
    top.autoscale_view()
    top.set_ylabel(rows[0].labels[0] if single else f"${_VARIABLES[name]}$")
    if not single or len(chosen) > 1:
        top.legend(loc="upper right", fontsize="small", ncol=min(4, len(rows[0].labels)))
    top.grid(alpha=0.3, which="both")
    ax_j.autoscale_view()
    ax_j.set_ylabel("j")
    time_axes(axes, span)
    ax_j.yaxis.get_major_locator().set_params(integer=True)
    ax_j.grid(alpha=0.3)
    if own:
        note = ", flows refined with the save grid" if rows[0].refined else ""
        which = f"run {chosen[0]}" if len(chosen) == 1 else "runs " + ", ".join(map(str, chosen))
        fig.suptitle(f"Hybrid arc of {which}: flows solid, {n_jumps} jumps dashed{note}")
    return Drawn(fig, axes, drawn)


def _in(rows: _Rows, span: tuple[float, float] | None) -> _Rows:
    """The rows with ``t`` in ``span``."""
    if span is None:
        return rows
    keep = in_window(rows.t, span, reach=True)  # hybrid order is time order: the flows reach the edges
    return _Rows(rows.t[keep], rows.j[keep], rows.values[keep], rows.labels, rows.refined)
