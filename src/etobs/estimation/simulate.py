"""The front door: :func:`simulate` an event-triggered estimator for one or many runs."""

from __future__ import annotations

from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.errors import InputError
from etobs.estimation.problem import EstimationProblem
from etobs.estimation.result import EstimationResult
from etobs.hybrid.options import SaveAt, SolverOptions
from etobs.hybrid.reference import solve_reference
from etobs.hybrid.solver import check_backend


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
        What to keep: full arcs (default) and/or states on a time grid.
    backend : {"auto", "engine", "scipy"}
        ``"engine"``: the compiled solver (:mod:`etobs.estimation.compiled`), one run per
        thread, with the model's functions compiled; it runs every etobs rule and
        extension. ``"scipy"``: the ``solve_ivp`` reference, which calls your Python
        functions as they are (any Python). ``"auto"`` (default) is the engine, or the
        reference for a rule of your own (a ``TriggerRule`` the engine cannot compile);
        the result's ``backend`` and ``backend_reason`` say which and why. ``"numba"`` is
        an earlier name of ``"engine"``; the batched numpy solver (``"numpy"``,
        ``"fast"``) was retired.
    run_ids : array_like of int, shape (B,), optional
        With a network: the index of each run in its random streams (default
        ``0 .. B-1``). A sweep passes the runs' global indices, so that a run's packets do
        not depend on how the sweep was chunked.

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
    q0 = problem.initial_state(X0, Z0, E0, t0, ids)
    if backend == "engine":
        from etobs.estimation.compiled import compile_problem
        from etobs.hybrid.compiled import solve_compiled

        cp = compile_problem(problem)
        sol = solve_compiled(cp.system, q0, (t0, t_end), params=cp.params, options=options, save=save)
    else:
        sol = solve_reference(problem.hybrid_system(), q0, (t0, t_end), options=options, save=save)
    return EstimationResult(problem=problem, solution=sol, backend_reason=reason)


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
