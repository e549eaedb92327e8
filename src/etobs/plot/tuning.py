"""The front of a tuning: transmissions per node and second against the error."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from etobs.plot.layout import Drawn, canvas

if TYPE_CHECKING:
    from etobs.tuning.result import TuningResult


def plot_front(result: TuningResult, *, log: bool = True, ax: Any = None) -> Drawn:
    """Every simulated trial, the feasible front, the start design and the references.

    Feasible trials (certified, within the budget and every constraint) are filled;
    the others (not certified, over the budget or pruned) are grey, the pruned ones at
    their figures on the first share of runs. The front is a step line; each front
    point's held-out figures are joined to it by a thin line. A simulated budget is a
    horizontal line, a certified one (it bounds the certificate's error bound, not the
    simulated error on the axis) is in the title. Lower left is better.

    Parameters
    ----------
    result : TuningResult
        From :func:`~etobs.tuning.tune` (``etobs tune``).
    log : bool
        Logarithmic axes.
    ax : Axes, optional
        To draw into; default a new figure.

    Returns
    -------
    Drawn
        ``fig, ax``; artists ``"trials"`` (one marker line per group of trials),
        ``"front"`` (the step line and its points) and ``"references"``.

    Examples
    --------
    >>> fig, ax = plot_front(tuning_result)  # doctest: +SKIP

    """
    fig, axes, own = canvas(ax, 1, 4.6, width=7.0 * 1.35)  # room for the legend on the right
    ax = axes[0]
    drawn: dict[str, list[Any]] = {"trials": [], "front": [], "references": []}

    def pts(rows: list[dict[str, Any]], x: str = "transmissions_rate", y: str = "error") -> tuple[list, list]:
        # on log axes a point at 0 (a design that sent nothing) cannot be drawn: it is not counted
        keep = [r for r in rows if _shown(r.get(x), log) and _shown(r.get(y), log)]
        return [r[x] for r in keep], [r[y] for r in keep]

    groups = [
        (
            "not certified",
            [r for r in result.trials if r["evaluated"] == "full" and not r["certified"]],
            "x",
            "0.55",
        ),
        (
            "certified, over budget or a constraint",
            [r for r in result.trials if r["evaluated"] == "full" and r["certified"] and not r["feasible"]],
            "o",
            "0.7",
        ),
        (
            "pruned (first share of runs)",
            [r for r in result.trials if r["evaluated"] == "pruned"],
            ".",
            "0.8",
        ),
        ("certified, within budget", [r for r in result.trials if r["feasible"]], "o", "C0"),
    ]
    for label, rows, marker, color in groups:
        x, y = pts(rows)
        if x:
            drawn["trials"] += ax.plot(
                x, y, marker=marker, ls="none", color=color, ms=5, label=f"{label} ({len(x)})", alpha=0.8
            )
    x, y = pts(result.front)
    if x:
        drawn["front"] += ax.step(x, y, where="post", color="C3", lw=1.2, label=f"front ({len(x)})")
        drawn["front"] += ax.plot(x, y, "o", color="C3", ms=7)
        for r in result.front:
            hx, hy = r.get("holdout_transmissions_rate"), r.get("holdout_error")
            if _shown(hx, log) and _shown(hy, log):
                ax.plot([r["transmissions_rate"], hx], [r["error"], hy], color="C3", lw=0.6, alpha=0.6)
                ax.plot(hx, hy, "s", mfc="none", color="C3", ms=6)
        ax.plot([], [], "s", mfc="none", color="C3", label="front on held-out runs")
    colors = ["C1", "C2", "C4", "C5", "C6", "C8", "C9"]  # not C0 (feasible) nor C3 (the front)
    for k, r in enumerate(result.references):
        if _shown(r.get("transmissions_rate"), log) and _shown(r.get("error"), log):
            star = r["name"] == "start"
            drawn["references"] += ax.plot(
                r["transmissions_rate"],
                r["error"],
                "*" if star else "D",
                color=colors[k % len(colors)],
                ms=13 if star else 7,
                mec="k",
                ls="none",
                label=f"{r['name']}{'' if r.get('certified') else ' (not certified)'}",
            )
    if result.budget_kind == "simulated":  # a certified budget bounds another figure: in the title
        ax.axhline(result.budget, color="k", ls="--", lw=0.8, label=f"budget {result.budget:.4g}")
    if log:
        from matplotlib.ticker import NullFormatter

        ax.set_xscale("log")
        ax.set_yscale("log")
        for axis in (ax.xaxis, ax.yaxis):  # the minor labels of a short log axis overlap
            axis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("transmissions per node and second (mean over runs)")
    ax.set_ylabel("simulated error statistic")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    budget = f"; certified bound <= {result.budget:.4g}" if result.budget_kind == "certified" else ""
    title = (
        f"Tuning {result.summary.get('name', '')}: {len(result.trials)} trials, "
        f"{len(result.front)} on the front{budget}"
    )
    if own:
        fig.suptitle(title)
    elif budget:  # the certified budget is not on the axes: the caller's figure needs it too
        ax.set_title(budget.lstrip("; "), fontsize="small")
    return Drawn(fig, ax, drawn)


def _finite(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _shown(x: Any, log: bool) -> bool:
    """Whether ``x`` can be drawn: finite, and positive on a log axis."""
    return _finite(x) and (x > 0 or not log)
