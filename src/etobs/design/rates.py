"""Estimates of the bound ``E`` on ``|dh_i/dx f_p|`` (eq. (36)) from simulations."""

from __future__ import annotations

from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.estimation.problem import EstimationProblem
from etobs.estimation.simulate import simulate
from etobs.hybrid.options import SaveAt, SolverOptions


def estimate_output_rate(
    problem: EstimationProblem,
    x0: Any,
    t_end: float,
    *,
    grid_step: float = 1e-3,
    options: SolverOptions | None = None,
    progress: bool | None = None,
) -> np.ndarray:
    """Largest ``|d y_i / dt| = |dh_i/dx f_p(x, u, v)|`` seen on simulated runs, per node.

    Theorem 4's ``tau_i = gamma_i^{-1}(eps_i) / E`` needs a bound ``E`` on this rate along
    the solutions; this estimates it on a grid of the simulated plant states (a lower
    estimate of the true bound: use a margin, or a bound derived from the model when one
    is known). The derivative is a central difference of ``h`` along ``f_p``.

    Parameters
    ----------
    problem : EstimationProblem
    x0 : array_like, shape (n_x,) or (B, n_x)
        Plant initial states of the runs.
    t_end : float
    grid_step : float
        Spacing of the time grid on which the rate is evaluated.
    options : SolverOptions, optional
        Solver settings of the simulation.
    progress : bool or None
        A progress bar on stderr counting the runs simulated (the long part), as in
        :func:`~etobs.simulate`: ``None`` (default) shows it when stderr is a terminal
        and the work takes over a second.

    Returns
    -------
    ndarray, shape (N,)
        The largest rate seen for each node (norm over the node's outputs).

    """
    v.real("t_end", t_end, lower=0.0, lower_open=True)
    v.real("grid_step", grid_step, lower=0.0, lower_open=True)
    grid = np.arange(0.0, t_end + grid_step / 2, grid_step)
    res = simulate(
        problem, x0, t_end, options=options, save=SaveAt(steps=False, grid=grid), progress=progress
    )
    traj = res.on_grid()
    x = traj.x.reshape(-1, problem.plant.n_x)
    t = np.broadcast_to(grid, traj.t.shape).reshape(-1)
    ok = np.all(np.isfinite(x), axis=1)
    x, t = x[ok], t[ok]
    calls = problem.calls()  # the one-run f_p and h on every grid point (compiled when numba can)
    f = calls.f_p(t, x, problem.u(t), problem.v(t))
    # step relative to the state's size, as for a finite-difference Jacobian
    h = np.sqrt(np.finfo(float).eps) * np.maximum(1.0, np.linalg.norm(x, axis=1, keepdims=True))
    h = h / np.maximum(np.linalg.norm(f, axis=1, keepdims=True), 1e-300)
    ydot = (calls.h(x + h * f) - calls.h(x - h * f)) / (2 * h)
    return np.array([np.max(np.linalg.norm(ydot[:, list(nd.outputs)], axis=1)) for nd in problem.nodes])
