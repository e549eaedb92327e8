"""The paper's three figures (section 8) from an :class:`~etobs.estimation.EstimationResult`.

Each function draws one run or several overlaid (``run=[0, 3]``, a legend names them),
optionally in a time window (``window=(t0, t1)``), into new axes or the caller's
(``ax=``), and returns a :class:`~etobs.plot.layout.Drawn`: ``fig, axes`` and the artists
by role. States and outputs carry the model's names and units
(:meth:`~etobs.estimation.EstimationProblem.quantities`). ``pyplot`` is never imported.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from etobs._validate import flag
from etobs.errors import InputTypeError
from etobs.estimation.metrics import inter_event_times
from etobs.estimation.result import EstimationResult, Trajectory
from etobs.model.quantities import with_unit
from etobs.plot.layout import Drawn, canvas, in_window, run_color, runs, shared, time_axes, window
from etobs.plot.layout import components as entries


def check_result(result: Any) -> EstimationResult:
    """``result`` checked to be an :class:`~etobs.estimation.EstimationResult`."""
    if not isinstance(result, EstimationResult):
        raise InputTypeError(f"`result` must be an EstimationResult; got {type(result).__name__}")
    return result


def _run(n_runs: int, run: Any) -> int:
    """One run's index, checked against a batch of ``n_runs`` runs."""
    if isinstance(run, bool) or not isinstance(run, int | np.integer):
        raise InputTypeError(f"`run` must be an integer here; got {run!r} ({type(run).__name__})")
    return runs(n_runs, run)[0]


def _node_name(result: EstimationResult, node: int) -> str:
    """How figures name node ``node``: as the tables, reprs and sweeps do (``channel_names``)."""
    return result.problem.channel_names[node]


def _trajectory(result: EstimationResult, run: int, span: tuple[float, float] | None) -> Trajectory:
    """Run ``run`` on the save grid (when kept) or its arc, the points in ``span`` only."""
    if result.solution.grid is not None:
        g = result.on_grid()
        tr = Trajectory(
            t=g.t[run], j=g.j[run], x=g.x[run], z=g.z[run], xhat=g.xhat[run], ybar=g.ybar[run], e=g.e[run],
            eta=g.eta[run],
        )  # fmt: skip
        keep = np.isfinite(tr.x).all(axis=1)
    else:
        tr = result.arc(run)
        keep = np.ones(tr.t.shape, dtype=bool)
    keep &= in_window(tr.t, span, reach=True)  # a point beyond each end: the lines reach the edges
    return Trajectory(**{k: getattr(tr, k)[keep] for k in ("t", "j", "x", "z", "xhat", "ybar", "e", "eta")})


def plot_states(
    result: EstimationResult, run: Any = 0, *, components: Any = None, ax: Any = None, window: Any = None
) -> Drawn:
    """Plant states ``x_k`` and estimates ``xhat_k`` against time, one panel per state.

    Parameters
    ----------
    result : EstimationResult
        With a save grid (drawn from it) or the arcs.
    run : int or sequence of int
        The run, or several overlaid (one colour each, named in the legend).
    components : int or sequence of int, optional
        The states to draw (indices from 0); default all.
    ax : Axes or sequence of Axes, optional
        One per state drawn, to draw into (a figure of the caller's), or one Axes for
        all of them (overlaid, a colour per state, the legend beside it); default a new
        figure.
    window : (float, float), optional
        Draw only ``t0 <= t <= t1``.

    Returns
    -------
    Drawn
        ``fig, axes`` (one per state); artists ``"x"`` and ``"xhat"``, one line per run
        and state. Panels are labelled with the states' names and units.

    Examples
    --------
    >>> fig, axes = plot_states(result, run=[0, 1], window=(0.0, 2.0))
    >>> [ax.get_ylabel() for ax in axes], [float(t) for t in axes[0].get_xlim()]
    (['position [m]', 'velocity [m/s]'], [0.0, 2.0])

    """
    result = check_result(result)
    chosen, span = runs(result.n_runs, run), window_(window)
    every = result.problem.quantities("x")
    chosen_k = entries("components", components, len(every))
    quantities = tuple(every[k] for k in chosen_k)
    n_x = len(quantities)
    fig, axes, own = canvas(ax, n_x, 1.6 * n_x + 0.6)
    overlaid = shared(axes)  # one Axes for every state: a colour per state, units in the legend
    drawn: dict[str, list[Any]] = {"x": [], "xhat": []}
    for r_k, r in enumerate(chosen):
        tr = _trajectory(result, r, span)
        several = f" (run {r})" if len(chosen) > 1 else ""
        for p, (a, q, k) in enumerate(zip(axes, quantities, chosen_k, strict=True)):
            if overlaid:  # a colour per (run, state)
                color = hat_color = f"C{(r_k * n_x + p) % 10}"
            else:
                color = run_color(r_k, len(chosen), "C0")
                hat_color = color if len(chosen) > 1 else "C1"
            unit = q.unit if overlaid else ""  # one Axes for several states: each label has its unit
            hat = f"{q.name} estimate" if q.name else rf"$\hat x_{{{k + 1}}}$"
            label = with_unit(q.label, unit) + several
            drawn["x"] += a.plot(tr.t, tr.x[:, k], color=color, lw=1.2, label=label)
            label = with_unit(hat, unit) + several
            drawn["xhat"] += a.plot(tr.t, tr.xhat[:, k], color=hat_color, lw=1.0, ls="--", label=label)
    for a, q in zip(axes, quantities, strict=True):
        if overlaid:
            units = {q.unit for q in quantities}
            a.set_ylabel(with_unit("x", units.pop()) if len(units) == 1 else "x")
            # beside the panel: several states fill it, and a legend inside would hide some
            a.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", frameon=False)
        else:
            a.set_ylabel(q.axis_label if q.name else with_unit("", q.unit).strip())
            a.legend(loc="upper right", fontsize="small", ncol=2)
        a.grid(alpha=0.3)
    time_axes(axes, span)
    if own:
        fig.suptitle("State $x$ (solid) and state estimate $\\hat x$ (dashed)")
    return Drawn(fig, axes, drawn)


def plot_error(
    result: EstimationResult, run: Any = 0, *, log: bool = True, ax: Any = None, window: Any = None
) -> Drawn:
    """Norm of the estimation error ``|x - xhat|`` against time.

    Parameters
    ----------
    result : EstimationResult
    run : int or sequence of int
        The run, or several overlaid (named in the legend).
    log : bool
        Logarithmic value axis.
    ax : Axes, optional
        To draw into; default a new figure.
    window : (float, float), optional
        Draw only ``t0 <= t <= t1``.

    Returns
    -------
    Drawn
        ``fig, ax``; artists ``"error"``, one line per run.

    Examples
    --------
    >>> drawn = plot_error(result, run=[0, 1], log=False)
    >>> [line.get_label() for line in drawn.artists["error"]]
    ['run 0', 'run 1']

    """
    result = check_result(result)
    chosen, span = runs(result.n_runs, run), window_(window)
    flag("log", log)
    fig, axes, own = canvas(ax, 1, 3.0)
    a = axes[0]
    lines: list[Any] = []
    for r_k, r in enumerate(chosen):
        tr = _trajectory(result, r, span)
        label = f"run {r}" if len(chosen) > 1 else None
        lines += a.plot(tr.t, tr.error, color=run_color(r_k, len(chosen), "C3"), lw=1.0, label=label)
    if log:
        a.set_yscale("log")
    a.set_ylabel(r"$|x - \hat x|$")
    a.grid(alpha=0.3, which="both")
    if len(chosen) > 1:
        a.legend(fontsize="small")
    time_axes(axes, span)
    if own:
        fig.suptitle(r"Norm of the state estimation error $|\xi| = |x - \hat x|$")
    return Drawn(fig, a, {"error": lines})


def plot_inter_event_times(
    result: EstimationResult, run: Any = 0, *, logy: bool = False, ax: Any = None, window: Any = None
) -> Drawn:
    """Time since the node's previous transmission, at each transmission, one panel per node.

    Parameters
    ----------
    result : EstimationResult
    run : int or sequence of int
        The run, or several overlaid (markers, one colour per run, named in the legend).
    logy : bool
        A logarithmic time axis, so that millisecond intervals stay visible next to gaps
        of seconds.
    ax : Axes or sequence of Axes, optional
        One per node; default a new figure.
    window : (float, float), optional
        Only the transmissions at ``t0 <= t <= t1`` (each with its gap to the previous
        one, which may lie before ``t0``).

    Returns
    -------
    Drawn
        ``fig, axes`` (one per node); artists ``"gaps"`` (one stem container, or with
        several runs one marker line, per run and node) and ``"min"`` (the dotted line
        at each node's smallest gap).

    Examples
    --------
    >>> fig, axes = plot_inter_event_times(result, logy=True)
    >>> [ax.get_yscale() for ax in axes]
    ['log', 'log']

    """
    result = check_result(result)
    chosen, span = runs(result.n_runs, run), window_(window)
    flag("logy", logy)
    N = result.n_nodes
    fig, axes, own = canvas(ax, N, 1.8 * N + 0.6)
    drawn: dict[str, list[Any]] = {"gaps": [], "min": []}
    overlaid = shared(axes)  # every node in one Axes: markers, a colour and a label per node
    for i, a in enumerate(axes):
        smallest = np.inf
        name = _node_name(result, i)
        for r_k, r in enumerate(chosen):
            times = result.transmission_times(r, i)[1:]
            gaps = inter_event_times(result, r, i)
            keep = in_window(times, span)
            times, gaps = times[keep], gaps[keep]
            if not gaps.size:
                continue
            smallest = min(smallest, float(gaps.min()))
            if len(chosen) == 1 and not overlaid:
                drawn["gaps"].append(a.stem(times, gaps, basefmt=" "))
            else:
                color = f"C{(r_k * N + i) % 10}" if overlaid else run_color(r_k, len(chosen), "C0")
                marker = "os^Dv<>"[(r_k * N + i if overlaid else r_k) % 7]
                label = ", ".join(([name] if overlaid else []) + ([f"run {r}"] if len(chosen) > 1 else []))
                drawn["gaps"] += a.plot(
                    times, gaps, ls="none", marker=marker, ms=4, mfc="none", color=color, label=label
                )
        if np.isfinite(smallest):
            drawn["min"].append(
                a.axhline(
                    smallest,
                    color=f"C{i % 10}" if overlaid else "C3",
                    lw=0.8,
                    ls=":",
                    label=(f"{name}: " if overlaid else "") + f"min {smallest:.3g} s",
                )
            )
            a.legend(loc="upper right", fontsize="small")
        a.set_ylabel("inter-event time [s]" if overlaid else f"{name}\n[s]")
        if logy:
            a.set_yscale("log")
        a.grid(alpha=0.3, which="both" if logy else "major")
    time_axes(axes, span)
    if own:
        fig.suptitle("Inter-transmission times")
    return Drawn(fig, axes, drawn)


window_ = window  # the parameter `window` shadows the checker inside the functions
