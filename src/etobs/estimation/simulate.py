"""The front door: :func:`simulate` an event-triggered estimator for one or many runs."""

from __future__ import annotations

import contextlib
from dataclasses import replace
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs._progress import horizon_bar, progress_shown
from etobs.errors import InputError
from etobs.estimation.problem import EstimationProblem
from etobs.estimation.result import EstimationResult
from etobs.hybrid.checks import check_backend
from etobs.hybrid.options import SaveAt, SolverOptions, checked_options, checked_save
from etobs.hybrid.reference import solve_reference
from etobs.hybrid.solution import GridMax


def simulate(
    problem: EstimationProblem,
    x0: Any,
    t_end: float,
    *,
    z0: Any = None,
    e0: Any = None,
    t0: float = 0.0,
    options: SolverOptions | None = None,
    save: SaveAt | None = None,
    backend: str = "auto",
    run_ids: Any = None,
    progress: bool | None = None,
) -> EstimationResult:
    """Simulate the event-triggered observer (eq. (16)--(22)) from one or many initial states.

    Parameters
    ----------
    problem : EstimationProblem
    x0 : array_like, shape (n_x,) or (B, n_x)
        Plant initial state of each run.
    t_end : float
        End of the horizon.
    z0 : array_like, shape (n_z,) or (B, n_z), optional
        Observer initial state (default zero).
    e0 : array_like, shape (n_y,) or (B, n_y), optional
        Initial network-induced error, ``ybar(t0) = ytilde(t0) + e0`` (default zero).
    t0 : float
        Start time.
    options : SolverOptions, optional
        Solver settings (tolerances, jump limit, event sampling).
    save : SaveAt, optional
        What to keep: full arcs (default) and/or states on a time grid. With
        ``SaveAt(grid=g, max_distance="estimation_error")`` only each run's
        ``max |x - xhat|`` over ``g`` is kept, computed while the run is solved (what a
        sweep needs, without the grid's memory); :func:`max_estimation_error` reads it.
    backend : {"auto", "engine", "scipy"}
        ``"engine"``: the compiled solver (:mod:`etobs.estimation.compiled`), 16 runs side
        by side per thread, with the model's functions compiled; it runs every etobs rule and
        extension. ``"scipy"``: the ``solve_ivp`` reference, which calls your Python
        functions as they are (any Python). ``"auto"`` (default) is the engine, or the
        reference for a rule of your own (a ``TriggerRule`` the engine cannot compile) or a
        python-control system whose code cannot be compiled (an ``InterconnectedSystem``);
        the result's ``backend`` and ``backend_reason`` say which and why. ``"numba"`` is
        an earlier name of ``"engine"``; the batched numpy solver (``"numpy"``,
        ``"fast"``) was retired.
    run_ids : array_like of int, shape (B,), optional
        With a network: the index of each run in its random streams (default
        ``0 .. B-1``). A sweep passes the runs' global indices, so that a run's packets do
        not depend on how the sweep was chunked.
    progress : bool or None
        A progress bar on stderr by simulated time (``etobs._progress.horizon_bar``:
        the runs' mean time reached and the wall time left, so a single long run shows
        too): ``None`` (default) shows it when stderr is a terminal and the solve takes
        more than a second; ``True`` or ``False`` force it on or off. On the engine the
        time advances every 0.2 s; the scipy reference reports whole runs.

    Returns
    -------
    EstimationResult

    Examples
    --------
    >>> from etobs.examples import robot_arm
    >>> res = simulate(robot_arm(), [3, 2, 3, -2], 1.0)
    >>> res.status_labels()
    ['completed']

    """
    if not isinstance(problem, EstimationProblem):
        raise InputError(f"`problem` must be an EstimationProblem; got {type(problem).__name__}")
    backend, reason = choose_backend(problem, check_backend(backend))
    options, save = checked_options(options), checked_save(save)
    p, o = problem.plant, problem.observer
    t0 = v.real("t0", t0)
    t_end = v.real("t_end", t_end)
    if t_end < t0:
        raise InputError(f"`t_end` must be >= t0 = {t0:g}; got {t_end:g}")
    X0 = v.batch("x0", x0, p.n_x)
    B = X0.shape[0]
    Z0 = _broadcast("z0", np.zeros(o.n_z) if z0 is None else z0, o.n_z, B)
    E0 = _broadcast("e0", np.zeros(p.n_y) if e0 is None else e0, p.n_y, B)
    ids = None
    if run_ids is not None:
        ids = np.asarray(run_ids)
        if ids.shape != (B,) or not np.issubdtype(ids.dtype, np.integer) or np.any(ids < 0):
            raise InputError(f"`run_ids` must be {B} non-negative integers (one per run); got {run_ids!r}")
    if progress is not None and not isinstance(progress, bool):
        raise InputError(
            "`progress` must be None (a bar when stderr is a terminal), True or False; "
            f"got {type(progress).__name__} {progress!r}"
        )
    q0 = problem.initial_state(X0, Z0, E0, t0, ids)
    solver_save, after, notes = _estimation_error_save(problem, save)
    if backend == "engine":
        from etobs.estimation.compiled import compile_problem
        from etobs.hybrid.compiled import solve_compiled

        cp = compile_problem(problem)  # before the bar: it counts runs solved, not the compile
    # no bar, no tqdm import and no callback when it is off: the engine then solves the
    # batch on this thread
    bar = horizon_bar(B, t0, t_end, "simulate", enabled=progress) if progress_shown(progress) else None
    with bar if bar is not None else contextlib.nullcontext():
        kw = {"options": options, "save": solver_save, "progress": None if bar is None else bar.update}
        if backend == "engine":
            sol = solve_compiled(cp.system, q0, (t0, t_end), params=cp.params, **kw)
        else:
            sol = solve_reference(problem.hybrid_system(), q0, (t0, t_end), **kw)
    res = EstimationResult(problem=problem, solution=sol, backend_reason=reason, notes=notes)
    if after:  # the error needs psi, which the solver does not know: reduce the kept grid
        from etobs.estimation.metrics import max_estimation_error

        g = sol.grid
        assert g is not None
        value = max_estimation_error(res, (float(g.t[0]), float(g.t[-1]))) if g.t.size else np.full(B, np.nan)
        sol = replace(sol, grid=None, grid_max=GridMax(g.t, value))
        res = replace(res, solution=sol)
    return res


def _estimation_error_save(
    problem: EstimationProblem, save: SaveAt | None
) -> tuple[SaveAt | None, bool, tuple]:
    """The solver's ``SaveAt`` for ``max_distance="estimation_error"``, and whether to reduce after.

    With ``xhat = z[:n_x]`` (no ``psi``) the error ``|x - xhat|`` is a distance between
    entries of the state, which the solvers fold as they go; with a ``psi`` the grid's
    states are kept and reduced after the solve, and the result's notes say so.
    """
    if save is None or save.max_distance is None:
        return save, False, ()
    if save.max_distance != "estimation_error":
        raise InputError(
            "`save.max_distance` of an estimation problem must be 'estimation_error' (max |x - xhat|); "
            f"got {save.max_distance!r}"
        )
    lay, n_x = problem.layout, problem.plant.n_x
    if problem.observer.psi is None:
        x = range(lay.x.start, lay.x.stop)
        z = range(lay.z.start, lay.z.start + n_x)
        return replace(save, max_distance=(tuple(x), tuple(z))), False, ()
    note = (
        "max_distance='estimation_error': the observer's psi is not compiled into the solver, so the "
        "grid's states were kept and max |x - xhat| taken after the solve (memory grows with the grid)"
    )
    return replace(save, max_distance=None), True, (note,)


def choose_backend(problem: EstimationProblem, backend: str = "auto") -> tuple[str, str]:
    """The backend ``simulate`` uses for ``problem``, and why (the one place ``"auto"`` is decided)."""
    if backend != "auto":
        return backend, "asked for"
    from etobs.estimation.compiled import engine_support

    why = engine_support(problem)
    if why:
        return "scipy", f"auto: {why}, so the scipy reference runs it (one run at a time, in Python)"
    return "engine", "auto: the engine models this problem"


def _broadcast(name: str, value: Any, n: int, B: int) -> np.ndarray:
    arr = v.batch(name, value, n)
    if arr.shape[0] == 1:
        return np.repeat(arr, B, axis=0)
    if arr.shape[0] != B:
        raise InputError(f"`{name}` has {arr.shape[0]} runs but x0 has {B}; give one row or {B} rows")
    return arr
