"""The observer service's trace (``etobs serve --trace``) against time."""

from __future__ import annotations

from typing import Any

import numpy as np

from etobs.plot.layout import Drawn, canvas, in_window, shared, time_axes
from etobs.plot.layout import window as check_window


def plot_trace(
    trace: dict[str, np.ndarray], reference: Any = None, *, ax: Any = None, window: Any = None
) -> Drawn:
    """Estimate ``xhat_k`` of a service trace (:func:`~etobs.runtime.server.read_trace`), one panel per state.

    Parameters
    ----------
    trace : dict
        As :func:`~etobs.runtime.server.read_trace` returns it (``t``, ``xhat``).
    reference : Replay, optional
        Adds the offline reference's estimate (:class:`~etobs.runtime.replay.Replay`),
        dashed.
    ax : Axes or sequence of Axes, optional
        One per state; default a new figure.
    window : (float, float), optional
        Draw only ``t0 <= t <= t1`` (service time).

    Returns
    -------
    Drawn
        ``fig, axes``; artists ``"service"`` and ``"reference"``, one line per state.

    Examples
    --------
    A trace as :func:`~etobs.runtime.server.read_trace` returns it (here made up):

    >>> import numpy as np
    >>> trace = {"t": np.linspace(0.0, 1.0, 11), "xhat": np.zeros((11, 2))}
    >>> fig, axes = plot_trace(trace, window=(0.0, 0.5))
    >>> len(axes), [float(t) for t in axes[0].get_xlim()]
    (2, [0.0, 0.5])

    """
    span = check_window(window)
    n_x = trace["xhat"].shape[1]
    fig, axes, own = canvas(ax, n_x, 1.6 * n_x + 0.6)
    drawn: dict[str, list[Any]] = {"service": [], "reference": []}
    keep = in_window(trace["t"], span, reach=True)
    overlaid = shared(axes)  # every state in one Axes: a colour per state, the reference dashed in it
    for k, a in enumerate(axes):
        color = f"C{k % 10}" if overlaid else "C1"
        drawn["service"] += a.plot(
            trace["t"][keep],
            trace["xhat"][keep, k],
            color=color,
            lw=1.2,
            label=rf"$\hat x_{k + 1}$ (service)",
        )
        if reference is not None:
            ref = in_window(reference.t, span, reach=True)
            label = "offline reference" + (rf" $\hat x_{k + 1}$" if overlaid else "")
            dashed = {"color": color if overlaid else "k", "lw": 0.8, "ls": "--", "label": label}
            drawn["reference"] += a.plot(reference.t[ref], reference.xhat[ref, k], **dashed)
        a.legend(loc="upper right", fontsize="small", ncol=2)
        a.grid(alpha=0.3)
    time_axes(axes, span, "t [s] (service time)")
    if own:
        fig.suptitle("Estimate of the observer service")
    return Drawn(fig, axes, drawn)
