"""What a model costs on the engine: time per call of each user function, the slow ones named.

:func:`model_cost` compiles each function the engine calls for a problem on its own (the
plant's ``f_p`` and ``h``, the observer's ``f_o`` and ``psi``, the rules' K-functions, the
signals ``u``, ``v``, ``m`` given as functions: the ``users`` of
:mod:`etobs.estimation._model_source`, by the names its messages use), calls each many
times by address in a compiled loop at one point of the state space, and keeps the fastest
of a few repeats (the least disturbed by other work on the machine). It then solves one
run over a short horizon for the cost of a whole solver step.

The engine compiles these functions into one model, so there a call costs what inlined
code does; a function called here on its own costs that plus a C call (a few ns). The
numbers are for ranking and for sizing work, not for a test: they depend on the machine
and on what else runs on it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.errors import InputError, ModelError
from etobs.estimation.problem import EstimationProblem

#: A function is slow when a call costs more than this many ns: arithmetic on a few
#: numbers costs 10-100 ns a call here (the robot arm's f_p, f_o and h: 20-90 ns); a call
#: that allocates arrays or calls a solver (a 2x2 ``np.linalg.solve``: 400 ns, a
#: python-control system's ``params`` dict: 1 us) costs more, on every stage of every step.
SLOW_NS = 250.0
#: Rows of one compiled loop of calls, and the least time one repeat of them takes.
_ROWS = 256
_TARGET_S = 0.02
#: No repeat makes more calls than this, however fast the function (bounds the loop).
_MAX_CALLS = 10_000_000


@dataclass(frozen=True)
class FunctionCost:
    """The cost of one user function.

    Attributes
    ----------
    name : str
        As etobs's messages name it: ``"f_p"``, ``"h"``, ``"f_o"``, ``"psi"``,
        ``"gamma of node 0"``, ``"signal u"``.
    ns_per_call : float
        Time per call in ns (the fastest of the repeats).
    share : float
        Its part of the sum over the model's functions (per call, not weighted by how
        often the solver calls it).
    slow : bool
        Over :data:`SLOW_NS` per call and over an equal share (``1 / n`` of ``n``
        functions) of their time together.
    note : str
        What is known to make it slow (a python-control system's ``params`` dict).

    """

    name: str
    ns_per_call: float
    share: float
    slow: bool
    note: str = ""


@dataclass(frozen=True)
class ModelCost:
    """:func:`model_cost`'s result: the functions, slowest first, and one solver step.

    Attributes
    ----------
    problem : str
        The problem's plant name.
    functions : tuple of FunctionCost
        Slowest first.
    us_per_step : float
        Wall time of one engine step (accepted or rejected) of one run, in us, on the run
        over ``[t0, t0 + horizon]``.
    steps_per_second : float
        Steps per second of simulated time on that run.
    horizon : float
        The length of that run.

    """

    problem: str
    functions: tuple[FunctionCost, ...]
    us_per_step: float
    steps_per_second: float
    horizon: float

    @property
    def slow(self) -> tuple[str, ...]:
        """Names of the slow functions (:attr:`FunctionCost.slow`), slowest first."""
        return tuple(f.name for f in self.functions if f.slow)

    def seconds_for(self, t_end: float, runs: int = 1) -> float:
        """Wall seconds that ``runs`` runs over ``t_end`` simulated seconds would take on one thread.

        At the pace of the measured run: an estimate, good when the runs transmit about as
        often as that run did.
        """
        return self.us_per_step * 1e-6 * self.steps_per_second * float(t_end) * int(runs)

    def __repr__(self) -> str:
        lines = [f"ModelCost of {self.problem!r} on the engine (time per call, slowest first):"]
        width = max(len(f.name) for f in self.functions) if self.functions else 0
        for f in self.functions:
            flag = "  slow" if f.slow else ""
            note = f"  ({f.note})" if f.note else ""
            lines.append(f"  {f.name:<{width}}  {f.ns_per_call:10.1f} ns  {100 * f.share:5.1f} %{flag}{note}")
        lines.append(
            f"  one solver step: {self.us_per_step:.2f} us; {self.steps_per_second:.4g} steps per simulated "
            f"second (a run over {self.horizon:g} s)"
        )
        if self.slow:
            lines.append(
                f"  slow: {', '.join(self.slow)} (over {SLOW_NS:g} ns a call and over an equal share): "
                "write it with scalar arithmetic, without allocating arrays or calling solvers per call "
                "(docs/models.md)"
            )
        return "\n".join(lines)


def model_cost(
    problem: EstimationProblem,
    x0: Any = None,
    *,
    z0: Any = None,
    horizon: float = 10.0,
    repeats: int = 3,
    clock: Callable[[], float] = time.perf_counter,
) -> ModelCost:
    """Time each user function of ``problem`` per call on the engine, and one solver step.

    Parameters
    ----------
    problem : EstimationProblem
        A problem the engine runs (:func:`etobs.estimation.compiled.engine_support`).
    x0 : array_like, shape (n_x,), optional
        The plant state the functions are called at, and the measured run's initial
        state (default zero).
    z0 : array_like, shape (n_z,), optional
        The observer state they are called at (default zero).
    horizon : float
        Length of the measured run (``> 0``).
    repeats : int
        Repeats of each measurement; the fastest is kept.
    clock : callable
        Wall clock in seconds (injectable).

    Returns
    -------
    ModelCost
        Its repr is a table; ``.slow`` names the slow functions.

    Raises
    ------
    InputError
        A problem the engine does not run, or a bad argument (named).
    ModelError
        A function that cannot be compiled, or fails at the point it is called at.

    Examples
    --------
    The robot arm's K-functions are etobs's own (no user code), so only the plant's and
    the observer's functions are timed:

    >>> from etobs.examples import robot_arm
    >>> cost = model_cost(robot_arm(), [3, 2, 3, -2], horizon=0.1, repeats=1)
    >>> sorted(f.name for f in cost.functions)
    ['f_o', 'f_p', 'h']

    """
    from etobs.compile.functions import compile_function
    from etobs.estimation import _model_source as ms
    from etobs.estimation.compiled import engine_support
    from etobs.model.rules import engine_form_of

    if not isinstance(problem, EstimationProblem):
        raise InputError(f"`problem` must be an EstimationProblem; got {type(problem).__name__}")
    why = engine_support(problem)
    if why:
        raise InputError(f"`problem`: the cost report times the engine, and {why}")
    pl, ob = problem.plant, problem.observer
    x = v.vector("x0", np.zeros(pl.n_x) if x0 is None else x0, pl.n_x)
    z = v.vector("z0", np.zeros(ob.n_z) if z0 is None else z0, ob.n_z)
    horizon = v.real("horizon", horizon, lower=0.0, lower_open=True)
    repeats = v.integer("repeats", repeats, lower=1, upper=100)
    src = ms.model_source(problem, [engine_form_of(ch.rule) for ch in problem.layout.channels])
    h = compile_function(pl.h, src.specs["H"], "h")
    y = _calls(h.address, 0.0, [x], pl.params, pl.n_y, "h")
    t0 = 0.0
    inputs = {  # the arrays each kind of function is called with (the rest: a scalar)
        "F_P": ([x, np.zeros(pl.n_u), np.zeros(pl.n_v)], pl.params),
        "H": ([x], pl.params),
        "F_O": ([z, np.zeros(pl.n_u), y, y], ob.params),
        "PSI": ([z], ob.params),
    }
    measured = []
    for glob, fn in src.users.items():
        spec, name = src.specs[glob], src.names[glob]
        cf = compile_function(fn, spec, name)
        arrays, params = inputs.get(glob, ([], np.zeros(0)))
        # a K-function is called with its argument s as `t` (s = 1); a signal with t = t0
        at = 1.0 if glob.startswith("K") else t0
        ns = _per_call(cf.address, at, arrays, params, spec.n_out, name, repeats, clock)
        measured.append((name, ns, _note(fn)))
    return _report(problem, measured, _step_cost(problem, x, z, horizon, repeats, clock), horizon)


def _per_call(
    address: int,
    t: float,
    arrays: list[np.ndarray],
    params: np.ndarray,
    n_out: int,
    name: str,
    repeats: int,
    clock: Callable[[], float],
) -> float:
    """Time per call in ns of the function at ``address``: the fastest of ``repeats`` timed loops."""
    from etobs.compile.batch import batch_call

    args = _rows(t, arrays, params, n_out)
    _check(batch_call(address, 0, *args), name, n_out)  # warm, and a failure named
    best = np.inf
    for _ in range(repeats):
        calls = 0
        start = clock()
        elapsed = 0.0
        while elapsed < _TARGET_S and calls < _MAX_CALLS:
            batch_call(address, 0, *args)
            calls += _ROWS
            elapsed = clock() - start
        best = min(best, elapsed / calls)
    return float(best * 1e9)


def _rows(t: float, arrays: list[np.ndarray], params: np.ndarray, n_out: int) -> tuple[Any, ...]:
    ins = [np.ascontiguousarray(np.broadcast_to(a, (_ROWS, a.size)), dtype=float) for a in arrays]
    ins += [np.zeros((_ROWS, 0))] * (4 - len(ins))
    p = np.ascontiguousarray(params, dtype=float)
    return (np.full(_ROWS, t), *ins, p, np.empty((_ROWS, max(n_out, 1))))


def _calls(
    address: int, t: float, arrays: list[np.ndarray], params: np.ndarray, n_out: int, name: str
) -> Any:
    """One call's result (the first row)."""
    from etobs.compile.batch import batch_call

    args = _rows(t, arrays, params, n_out)
    _check(batch_call(address, 0, *args), name, n_out)
    return args[-1][0].copy()


def _check(status: int, name: str, n_out: int) -> None:
    if status != 1:
        from etobs.compile.functions import describe_failure

        raise ModelError(describe_failure(name, status, n_out) + " at the point the cost report calls it at")


def _note(fn: Any) -> str:
    from etobs.compile.functions import ORIGIN

    origin = getattr(fn, ORIGIN, "")
    if "python-control" in origin:
        return "a python-control system: every call builds its params dict, docs/models.md"
    return ""


def _step_cost(
    problem: EstimationProblem,
    x: np.ndarray,
    z: np.ndarray,
    horizon: float,
    repeats: int,
    clock: Callable[[], float],
) -> tuple[float, float]:
    """(us per step, steps per simulated second) of one engine run over ``horizon``.

    The fixed cost of a ``simulate`` call (the initial state, the result), measured on a
    run over no time, is taken off, unless it is over 90 % of the run's time (then the
    step's time is bounded by the whole: a longer ``horizon`` measures it better); each is
    the fastest of ``repeats``.
    """
    from etobs.estimation.simulate import simulate
    from etobs.hybrid.options import SaveAt

    def timed(t_end: float) -> tuple[float, Any]:
        start = clock()
        res = simulate(problem, x, t_end, z0=z, save=SaveAt(steps=False), backend="engine", progress=False)
        return clock() - start, res.solution

    timed(0.0)  # the model compiled and the kernel loaded before the clock starts
    fixed = min(timed(0.0)[0] for _ in range(repeats))
    runs = [timed(horizon) for _ in range(repeats)]
    wall, sol = min(runs, key=lambda r: r[0])
    steps = int(sol.n_steps[0] + sol.n_rejected[0])
    reached = float(sol.t_final[0]) if sol.t_final[0] > 0 else horizon
    net = wall - fixed
    if net < 0.1 * wall:  # a short run lost in the fixed cost's noise: wall / steps bounds a step
        net = wall
    return net / max(steps, 1) * 1e6, steps / reached


def _report(
    problem: EstimationProblem,
    measured: list[tuple[str, float, str]],
    step: tuple[float, float],
    horizon: float,
) -> ModelCost:
    times = np.array([ns for _, ns, _ in measured])
    total = float(times.sum()) if times.size else 0.0
    functions = tuple(
        FunctionCost(
            name=name,
            ns_per_call=ns,
            share=ns / total if total > 0 else 0.0,
            slow=bool(ns > SLOW_NS and ns * len(measured) > total),
            note=note,
        )
        for name, ns, note in sorted(measured, key=lambda m: -m[1])
    )
    return ModelCost(problem.plant.name, functions, step[0], step[1], horizon)
