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

The engine models the paper's base setting with every built-in rule (dynamic, static
and send-on-delta, periodic, relative, generalized), any K-function and any signal.
:func:`engine_support` says why a problem is not covered (input nodes, the observer-copy
hold or a network, until they move to the engine; or a rule of the user's own).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from etobs.errors import InputError, ModelError
from etobs.estimation.problem import EstimationProblem
from etobs.hybrid.compiled import CompiledSystem
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
        what
        for what, on in (
            ("input nodes (section 7.3)", bool(problem.input_nodes)),
            (f"hold={problem.hold!r} (Remark 3)", problem.hold != "output"),
            ("a network (delay, loss)", problem.network is not None),
        )
        if on
    ]
    for i, nd in enumerate(problem.nodes):
        if engine_form_of(nd.rule) is None:
            used.append(f"node {i}'s rule {type(nd.rule).__name__} (a rule of your own)")
    if used:
        return "the engine models the base setting with etobs' rules; this problem uses " + ", ".join(used)
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
        raise InputError(f"backend='engine': {why}; use backend='numpy' or 'scipy'")
    forms = [engine_form_of(nd.rule) for nd in problem.nodes]
    src = ms.model_source(problem, forms)  # type: ignore[arg-type] - engine_support checked them
    try:
        fns = compile_module(src.text, src.users, ("est",), "estimation model")
    except ModelError:
        # name the user function at fault: each compiled on its own raises a ModelError naming it
        for glob, fn in src.users.items():
            compile_function(fn, src.specs[glob], src.names[glob])
        raise
    params = np.concatenate(src.numbers) if src.numbers else np.zeros(0)
    system = CompiledSystem(
        n=problem.layout.n,
        n_rules=problem.n_nodes,
        addresses=(fns[0].address,) * 3,  # one function for flow, guard and jump
        n_params=params.size,
        n_work=src.n_work,
        rule_names=tuple(nd.name or f"node{i}" for i, nd in enumerate(problem.nodes)),
        function_names=ms.FUNCTIONS,
        keep=fns,
    )
    return CompiledProblem(system=system, params=params)
