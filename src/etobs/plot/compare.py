"""The trade-off figure of a rule comparison: transmissions against estimation error."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from etobs.plot.layout import Drawn, canvas

if TYPE_CHECKING:
    from etobs.experiments.compare import Comparison

_MARKERS = "osD^v<>Ph*X"


def plot_tradeoff(comparison: Comparison, *, log: bool = True, ax: Any = None) -> Drawn:
    """Mean transmissions (all nodes, in the window) against mean ``max |x - xhat|``.

    One point per (rule, network): colour by rule, marker by network. A vertical bar
    reaches the worst run's error. Lower left is better. Markers are hollow, and each
    rule's smaller than the one before, so rules whose figures coincide stay visible as
    nested markers (two rules that send alike hid each other).

    Parameters
    ----------
    comparison : Comparison
        From :func:`~etobs.experiments.compare.compare` (``etobs compare``).
    log : bool
        Logarithmic error axis.
    ax : Axes, optional
        To draw into; default a new figure.

    Returns
    -------
    Drawn
        ``fig, ax``; artists ``"points"`` (one marker per rule and network) and
        ``"bars"`` (the bars to the worst run).

    Examples
    --------
    >>> fig, ax = plot_tradeoff(comparison)  # doctest: +SKIP

    """
    rows = comparison.table()
    rules = list(dict.fromkeys(r["rule"] for r in rows))
    networks = list(dict.fromkeys(r["network"] for r in rows))
    fig, axes, own = canvas(ax, 1, 4.2)
    ax = axes[0]
    drawn: dict[str, list[Any]] = {"points": [], "bars": []}
    for r in rows:
        x, y, top = r["transmissions total"], r["error mean"], r["error max"]
        if not (np.isfinite(x) and np.isfinite(y)):
            continue
        color = f"C{rules.index(r['rule']) % 10}"
        marker = _MARKERS[networks.index(r["network"]) % len(_MARKERS)]
        drawn["bars"] += ax.plot([x, x], [y, top], color=color, lw=0.8, alpha=0.6)
        ms = max(12.0 - 2.0 * rules.index(r["rule"]), 4.0)  # nested where points coincide
        drawn["points"] += ax.plot(x, y, marker=marker, color=color, ls="none", ms=ms, mfc="none", mew=1.5)
    for k, name in enumerate(rules):  # legend entries: rules by colour, networks by marker
        ax.plot([], [], color=f"C{k % 10}", lw=4, label=name)
    for k, name in enumerate(networks):
        ax.plot([], [], color="0.3", marker=_MARKERS[k % len(_MARKERS)], ls="none", label=f"network: {name}")
    if log:
        ax.set_yscale("log")
    m = comparison.spec.metrics
    ax.set_xlabel(
        f"transmissions of all nodes on [{m.transmissions_window[0]:g}, {m.transmissions_window[1]:g}] s"
    )
    ax.set_ylabel(rf"max $|x - \hat x|$ on [{m.error_window[0]:g}, {m.error_window[1]:g}] s")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize="small", loc="best")
    if own:
        fig.suptitle(
            f"Transmissions against estimation error "
            f"({comparison.spec.initial_states.runs} runs: mean, bar to max)"
        )
    return Drawn(fig, ax, drawn)
