"""The estimation problem as a :class:`~etobs.hybrid.compiled.CompiledSystem` (the engine).

The hybrid model (16)--(22) is the one of :meth:`EstimationProblem.hybrid_system`,
written out for the problem's structure (sizes, which outputs each node sends, rule,
K-function and signal kinds) as Python source that calls the user's functions
(:mod:`etobs.estimation._model_source`) and compiled into one C function that the
kernel calls by address. numba compiles the user's functions into it, so a call costs
what inlined code does. The machine code is cached on disk by the source and the user
functions' fingerprints; the problem's numbers (the plant's and observer's ``params``,
signal amplitudes, rule parameters) travel in the run's parameter vector, so problems
that differ only in numbers share the compiled model.

The engine models every problem etobs builds: every built-in rule (dynamic, static and
send-on-delta, periodic, relative, generalized), any K-function and signal, measurement
noise, input nodes (section 7.3), the observer-copy hold (Remark 3) and networks (delay,
loss, reordering, capacity; each packet's fate drawn as :mod:`etobs.model.fates` says, so
the engine and the reference draw the same). :func:`engine_support` says why a problem is
not covered: a rule of the user's own, or a plant whose code numba cannot compile by its
construction (a python-control ``InterconnectedSystem``, :mod:`etobs.model.python_control`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np

from etobs.errors import InputError, ModelError, PerformanceWarning
from etobs.estimation.problem import EstimationProblem
from etobs.hybrid.compiled import CompiledSystem
from etobs.model.python_control import PYTHON_ONLY
from etobs.model.rules import engine_form_of


@dataclass(frozen=True)
class CompiledProblem:
    """An estimation problem ready for the engine.

    Attributes
    ----------
    system : CompiledSystem
    params : ndarray
        The problem's parameter vector (one run's row).

    """

    system: CompiledSystem
    params: np.ndarray


def engine_support(problem: EstimationProblem) -> str:
    """Why the engine cannot run ``problem`` (``""`` when it can)."""
    used = [
        f"node {ch.name!r}'s rule {type(ch.rule).__name__} (a rule of your own)"
        for ch in problem.layout.channels
        if engine_form_of(ch.rule) is None
    ]
    if used:
        return "the engine runs etobs' rules; this problem uses " + ", ".join(used)
    # a plant whose code is known not to compile (etobs.model.python_control marks it)
    why = getattr(problem.plant.f_p, PYTHON_ONLY, "")
    if why:
        return f"the plant {problem.plant.name!r} {why}"
    return ""


def compile_problem(problem: EstimationProblem) -> CompiledProblem:
    """Compile (or reuse) the problem's model with the user's functions in it, for the engine.

    Raises
    ------
    InputError
        When the problem uses something the engine does not model (:func:`engine_support`).
    ModelError
        When a user function cannot be compiled (the message names it).

    """
    from etobs.compile.functions import compile_function, compile_module
    from etobs.estimation import _model_source as ms

    why = engine_support(problem)
    if why:
        raise InputError(f"backend='engine': {why}; use backend='scipy' (the reference runs any Python)")
    lay = problem.layout
    forms = [engine_form_of(ch.rule) for ch in lay.channels]
    src = ms.model_source(problem, forms)  # type: ignore[arg-type] - engine_support checked them
    functions = {**src.users, **src.helpers}
    one, why = None, ""
    try:  # LLVM inlines your functions (each compiled and cached on its own): the fastest compile
        one = compile_module(src.text, functions, ("est",), "estimation model", inline=False)[0]
    except ModelError as exc:
        why = str(exc)
    if one is None:
        # name the user function at fault: each compiled on its own raises a ModelError naming it
        for glob, fn in src.users.items():
            compile_function(fn, src.specs[glob], src.names[glob])
        raise ModelError(why)
    params = np.concatenate(src.numbers) if src.numbers else np.zeros(0)
    names = problem.rule_names
    system = CompiledSystem(
        n=lay.n,
        n_rules=len(names),
        addresses=(one.address,) * 3,  # one function for flow, guard and jump
        # and its lane form, compiled when a batch first fills a thread's lanes
        lane_form=partial(_lane_form, problem, src, functions, one, params) if src.lanes else None,
        lane_width=ms.LANE_WIDTH,
        n_params=params.size,
        n_work=src.n_work,
        n_flow=lay.n_flow,
        rule_names=names,
        function_names=ms.FUNCTIONS,
        log_columns=lay.sent_columns,  # the values sent, for the transmissions table
        keep=(one,),
    )
    return CompiledProblem(system=system, params=params)


#: Each compiled model's lane forms (by its one-run form's address and ``shared``): address, or 0.
_LANE_FORMS: dict[tuple[int, bool], tuple[int, Any]] = {}


def _lane_form(
    problem: EstimationProblem,
    src: Any,
    functions: dict[str, Any],
    one: Any,
    params: np.ndarray,
    shared: bool = True,
) -> int:
    """Compile (once per model, form and process) and check a lane form; its address or 0.

    ``shared``: the form for lanes whose parameters are all equal (``est_lanes_shared``),
    else the one that reads a row per lane (``est_lanes``); each is compiled when first
    asked for. Your functions inlined by numba (vector code), else by LLVM (numba cannot
    inline some closures: said with the note). A lane form that does not compile (it
    passes a run's state as a strided view: a function that reshapes it does not) leaves
    the model without one, said once: the engine then calls the one-run form lane by lane.
    """
    from etobs.compile.functions import compile_module

    key = (int(one.address), bool(shared))
    if key in _LANE_FORMS:
        return _LANE_FORMS[key][0]
    entry = "est_lanes_shared" if shared else "est_lanes"
    lanes, why, not_inlined = None, "", ""
    for inline in (True, False):
        try:
            lanes = compile_module(src.text, functions, (entry,), "estimation model", inline=inline)[0]
            break
        except ModelError as exc:
            why = why or str(exc).removeprefix("the estimation model cannot be compiled: ")
            not_inlined = why
    if lanes is None:
        _say_once(
            f"etobs: this model has no lane form ({why}): the engine calls its one-run form lane by lane, "
            "which gives the same numbers 2-4 times slower; a function that needs a contiguous state "
            "(reshape) can take np.ascontiguousarray(x) (docs/solver.md)"
        )
        _LANE_FORMS[key] = (0, None)
        return 0
    address = _checked_lanes((one, lanes), problem, src, params, len(problem.rule_names), not_inlined)
    _LANE_FORMS[key] = (address, lanes)  # keeps the compiled function alive
    return address


def _checked_lanes(
    fns: Any, problem: EstimationProblem, src: Any, params: np.ndarray, n_rules: int, not_inlined: str
) -> int:
    """The lane form's address, once it gives every lane the one-run form's numbers (else 0).

    Checked once per compiled model (:mod:`etobs.estimation._lane_probe`), with one
    warning when it does not agree (a compiler fault: the engine then calls the one-run
    form lane by lane) and one when it is not vector code (naming the functions and
    what in them keeps it so, with its measured cost).
    """
    from etobs.estimation import _lane_probe as lp
    from etobs.estimation._model_source import LANE_WIDTH

    address = int(fns[1].address)
    probe = lp.LaneProbe(fns[0], fns[1], _probe_states(problem, LANE_WIDTH), src.n_work + 1, n_rules, params)
    if not probe.agrees():
        _say_once(
            "etobs: the lane form of this model's compiled code does not compute what its one-run form "
            "does (a compiler fault; please report it); the engine calls the one-run form lane by lane, "
            "which gives the right numbers 2-4 times slower",
            RuntimeWarning,
        )
        return 0
    # what keeps the lane form from being vector code, read from the user's functions (a
    # timing alone would depend on the machine's load); its cost is measured to be said
    found = [f"numba could not inline the model's functions into it ({not_inlined})"] if not_inlined else []
    found += lp.blockers(src.users, src.names)
    said = ("not vector code", int(fns[0].address))  # once per model, for either lane form
    if found and said not in _SAID:
        one, lane = probe.cost()
        _say_once(
            f"etobs: this model's lane form is not vector code: {'; '.join(found)}. Its flow costs "
            f"{lane:.0f} ns per run and call in the lane form, {one:.0f} ns for one run alone (vector code "
            "costs a fraction of it); the numbers are the same. Tuples of floats and math/np sin, cos, "
            "sqrt and abs vectorize (docs/solver.md)",
            key=said,
        )
    return address


def _probe_states(problem: EstimationProblem, W: int) -> np.ndarray:
    """``W`` hybrid states of ``problem`` at ``t = 0`` from random plant, observer and output errors."""
    rng = np.random.default_rng(0)
    pl, ob = problem.plant, problem.observer
    X, Z = rng.uniform(-1.0, 1.0, (W, pl.n_x)), rng.uniform(-1.0, 1.0, (W, ob.n_z))
    try:
        return problem.initial_state(X, Z, rng.uniform(-0.1, 0.1, (W, pl.n_y)), 0.0)
    except Exception:  # a model that refuses these states (its own checks): the plant at rest
        return problem.initial_state(np.zeros((W, pl.n_x)), np.zeros((W, ob.n_z)), np.zeros((W, pl.n_y)), 0.0)


_SAID: set[Any] = set()


def _say_once(message: str, category: type[Warning] = PerformanceWarning, key: Any = None) -> None:
    """A warning, once per process and ``key`` (default: the message): a sweep compiles in every chunk."""
    key = message if key is None else key
    if key not in _SAID:
        _SAID.add(key)
        warnings.warn(message, category, stacklevel=4)
