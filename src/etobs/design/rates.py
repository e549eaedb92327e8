"""Estimates of the bound ``E`` on ``|dh_i/dx f_p|`` (eq. (36)) from simulations."""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.errors import InputError
from etobs.estimation.problem import EstimationProblem
from etobs.estimation.simulate import simulate
from etobs.hybrid.options import SaveAt, SolverOptions, step_grid


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
    grid = step_grid(0.0, t_end, grid_step)
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


#: Most grid points (runs x (t_end / grid_step + 1)) :func:`sample_output_rate` keeps: the
#: plant states on the grid are held in memory (8 n_x bytes each, 160 MB for 4 states) and
#: each run costs a simulation; ``runs = 1e8`` ended in a MemoryError, ``1e7`` ran for minutes.
MAX_GRID_POINTS = 5_000_000
#: The box's ``2^n_x`` corners are sampled up to this many states (1024 corners).
MAX_CORNER_STATES = 10


@dataclass(frozen=True)
class RateEstimate:
    """``E`` per node estimated on simulations: a lower estimate of the bound Theorem 4 needs.

    :func:`~etobs.design.certify` takes it as ``E`` and names it as an estimate in the
    certificate, with ``how`` and what ``tau_i`` then means.

    Attributes
    ----------
    E : tuple of float
        The largest rate seen per node times ``margin``.
    seen : tuple of float
        The largest rate seen per node.
    margin : float
    how : str
        How it was sampled, in words.

    """

    E: tuple[float, ...]
    seen: tuple[float, ...]
    margin: float
    how: str


def sample_output_rate(
    problem: EstimationProblem,
    low: Any,
    high: Any,
    *,
    runs: int = 20,
    t_end: float = 30.0,
    margin: float = 1.2,
    seed: int = 0,
    grid_step: float = 1e-2,
    progress: bool | None = None,
) -> RateEstimate:
    """Estimate ``E`` from runs started at the corners of a box and at seeded points inside it.

    The corners are where the largest rates of the robot arm were (113.0 and 984.5 where
    20 random runs saw 92.6 and 807.6); they are all sampled when the plant has at most
    :data:`MAX_CORNER_STATES` states (said in :attr:`RateEstimate.how` otherwise). The
    observer and ``eta0`` do not enter: the plant runs on its own ``u(t)`` and ``v(t)``.

    Raises
    ------
    InputError
        A bad box or number, or more than :data:`MAX_GRID_POINTS` grid points in all.

    """
    lo, hi = v.vector("low", low), v.vector("high", high)
    n_x = problem.plant.n_x
    if lo.shape != (n_x,) or hi.shape != lo.shape or np.any(hi < lo):
        raise InputError(
            f"`low` and `high` must be {n_x} numbers each with low <= high; got {lo.tolist()} and "
            f"{hi.tolist()}"
        )
    runs = v.integer("runs", runs, lower=1)
    v.real("t_end", t_end, lower=0.0, lower_open=True)
    v.real("margin", margin, lower=1.0)
    v.real("grid_step", grid_step, lower=0.0, lower_open=True)
    corners = 2**n_x if n_x <= MAX_CORNER_STATES else 0
    points = (runs + corners) * (t_end / grid_step + 1)
    if points > MAX_GRID_POINTS:
        raise InputError(
            f"`runs` = {runs} (plus {corners} corners) over t_end = {t_end:g} asks for {points:.3g} grid "
            f"points ((runs + corners) x (t_end / {grid_step:g} + 1)); the limit is {MAX_GRID_POINTS:.3g}: "
            "lower runs or t_end"
        )
    rng = np.random.default_rng(v.integer("seed", seed, lower=0))
    x0 = [lo + rng.uniform(size=(runs, n_x)) * (hi - lo)]
    if corners:
        x0.append(np.array(list(itertools.product(*zip(lo, hi, strict=True)))))
    seen = estimate_output_rate(problem, np.vstack(x0), t_end, grid_step=grid_step, progress=progress)
    where = f"the box [{lo.tolist()}, {hi.tolist()}]"
    how = (
        f"the largest |dy_i/dt| seen on {runs} seeded runs (seed {seed}) in {where}"
        + (f" and its {corners} corners" if corners else f" (its 2^{n_x} corners not sampled)")
        + f", on a {grid_step:g} s grid up to t = {t_end:g} s, times the margin {margin:g}"
    )
    return RateEstimate(
        E=tuple(margin * float(e) for e in seen), seen=tuple(map(float, seen)), margin=margin, how=how
    )
