"""The observer service's trace (``etobs serve --trace``) against time."""

from __future__ import annotations

from typing import Any

import numpy as np

from etobs.plot.figures import _figure


def plot_trace(trace: dict[str, np.ndarray], reference: Any = None) -> tuple[Any, np.ndarray]:
    """Estimate ``xhat_k`` of a service trace (:func:`~etobs.runtime.server.read_trace`), one panel per state.

    ``reference`` (a :class:`~etobs.runtime.replay.Replay`) adds the offline reference's
    estimate, dashed.
    """
    n_x = trace["xhat"].shape[1]
    fig, axes = _figure(n_x, 1.6 * n_x + 0.6)
    for k, ax in enumerate(axes):
        ax.plot(trace["t"], trace["xhat"][:, k], color="C1", lw=1.2, label=rf"$\hat x_{k + 1}$ (service)")
        if reference is not None:
            ax.plot(reference.t, reference.xhat[:, k], color="k", lw=0.8, ls="--", label="offline reference")
        ax.legend(loc="upper right", fontsize="small", ncol=2)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("t [s] (service time)")
    fig.suptitle("Estimate of the observer service")
    return fig, axes
