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

from dataclasses import dataclass

import numpy as np

from etobs.errors import InputError, ModelError
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
    try:
        fns = compile_module(src.text, {**src.users, **src.helpers}, ("est",), "estimation model")
    except ModelError:
        # name the user function at fault: each compiled on its own raises a ModelError naming it
        for glob, fn in src.users.items():
            compile_function(fn, src.specs[glob], src.names[glob])
        raise
    params = np.concatenate(src.numbers) if src.numbers else np.zeros(0)
    names = problem.rule_names
    system = CompiledSystem(
        n=lay.n,
        n_rules=len(names),
        addresses=(fns[0].address,) * 3,  # one function for flow, guard and jump
        n_params=params.size,
        n_work=src.n_work,
        n_flow=lay.n_flow,
        rule_names=names,
        function_names=ms.FUNCTIONS,
        log_columns=lay.sent_columns,  # the values sent, for the transmissions table
        keep=fns,
    )
    return CompiledProblem(system=system, params=params)
