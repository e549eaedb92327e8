"""The paper's three figures (section 8) from an :class:`~etobs.estimation.EstimationResult`.

Each function returns the :class:`matplotlib.figure.Figure` and its axes; nothing is
shown or saved here. ``pyplot`` is never imported, so these work headless.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from etobs._validate import shown
from etobs.errors import InputError, InputTypeError
from etobs.estimation.metrics import inter_event_times
from etobs.estimation.result import EstimationResult, Trajectory


def _figure(nrows: int, height: float, height_ratios: list[float] | None = None) -> tuple[Any, Any]:
    try:
        from matplotlib.figure import Figure
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("plotting needs matplotlib: pip install 'etobs[plot]'") from exc
    fig = Figure(figsize=(7.0, height), layout="constrained")
    grid = {"height_ratios": height_ratios} if height_ratios is not None else None
    axes = fig.subplots(nrows, 1, sharex=True, squeeze=False, gridspec_kw=grid)[:, 0]
    return fig, axes


def _run(n_runs: int, run: Any) -> int:
    """``run`` checked against a batch of ``n_runs`` runs."""
    if isinstance(run, bool) or not isinstance(run, int | np.integer):
        raise InputTypeError(f"`run` must be an integer; got {shown(run)} ({type(run).__name__})")
    if not 0 <= run < n_runs:
        raise InputError(f"`run` must be in 0..{n_runs - 1}; got {run}")
    return int(run)


def _node_name(result: EstimationResult, node: int) -> str:
    """How figures name node ``node``: as the tables, reprs and sweeps do (``channel_names``)."""
    return result.problem.channel_names[node]


def _trajectory(result: EstimationResult, run: int) -> Trajectory:
    run = _run(result.n_runs, run)
    if result.solution.grid is not None:
        g = result.on_grid()
        keep = np.isfinite(g.x[run]).all(axis=1)
        return Trajectory(
            t=g.t[run][keep],
            j=g.j[run][keep],
            x=g.x[run][keep],
            z=g.z[run][keep],
            xhat=g.xhat[run][keep],
            ybar=g.ybar[run][keep],
            e=g.e[run][keep],
            eta=g.eta[run][keep],
        )
    return result.arc(run)


def plot_states(result: EstimationResult, run: int = 0) -> tuple[Any, np.ndarray]:
    """Plant states ``x_k`` and estimates ``xhat_k`` against time, one panel per state."""
    tr = _trajectory(result, run)
    n_x = tr.x.shape[-1]
    fig, axes = _figure(n_x, 1.6 * n_x + 0.6)
    for k, ax in enumerate(axes):
        ax.plot(tr.t, tr.x[:, k], color="C0", lw=1.2, label=f"$x_{k + 1}$")
        ax.plot(tr.t, tr.xhat[:, k], color="C1", lw=1.0, ls="--", label=rf"$\hat x_{k + 1}$")
        ax.legend(loc="upper right", fontsize="small", ncol=2)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("t [s]")
    fig.suptitle("State $x$ and state estimate $\\hat x$")
    return fig, axes


def plot_error(result: EstimationResult, run: int = 0, *, log: bool = True) -> tuple[Any, Any]:
    """Norm of the estimation error ``|x - xhat|`` against time."""
    tr = _trajectory(result, run)
    fig, axes = _figure(1, 3.0)
    ax = axes[0]
    ax.plot(tr.t, tr.error, color="C3", lw=1.0)
    if log:
        ax.set_yscale("log")
    ax.set_xlabel("t [s]")
    ax.set_ylabel(r"$|x - \hat x|$")
    ax.grid(alpha=0.3, which="both")
    fig.suptitle(r"Norm of the state estimation error $|\xi| = |x - \hat x|$")
    return fig, ax


def plot_inter_event_times(
    result: EstimationResult, run: int = 0, *, logy: bool = False
) -> tuple[Any, np.ndarray]:
    """Time since the node's previous transmission, at each transmission, one panel per node.

    ``logy``: a logarithmic time axis, so that millisecond intervals stay visible next to
    gaps of seconds.
    """
    run = _run(result.n_runs, run)
    N = result.n_nodes
    fig, axes = _figure(N, 1.8 * N + 0.6)
    for i, ax in enumerate(axes):
        times = result.transmission_times(run, i)
        gaps = inter_event_times(result, run, i)
        name = _node_name(result, i)
        if gaps.size:
            ax.stem(times[1:], gaps, basefmt=" ")
            ax.axhline(gaps.min(), color="C3", lw=0.8, ls=":", label=f"min {gaps.min():.3f} s")
            ax.legend(loc="upper right", fontsize="small")
        ax.set_ylabel(f"{name}\n[s]")
        if logy:
            ax.set_yscale("log")
        ax.grid(alpha=0.3, which="both" if logy else "major")
    axes[-1].set_xlabel("t [s]")
    fig.suptitle("Inter-transmission times")
    return fig, axes
