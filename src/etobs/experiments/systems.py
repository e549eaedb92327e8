"""Resolve a spec's ``system.factory`` and build the problem of one row and scenario."""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

from etobs.estimation.problem import EstimationProblem
from etobs.examples.registry import resolve_factory
from etobs.experiments.spec import SpecError, SweepSpec


def factory_kwargs(spec: SweepSpec, row: int, scenario: int) -> dict[str, Any]:
    """Keyword arguments of one row under one scenario: fixed, then row, then scenario."""
    return {**spec.fixed, **spec.rows[row], **spec.scenarios[scenario].params}


def check_factory(spec: SweepSpec) -> None:
    """Fail early, naming the key, when a row or scenario passes an unknown argument.

    The factory itself is not called here: it runs in the workers.
    """
    _check_arguments(spec, resolve_factory(spec.factory))


def _check_arguments(spec: SweepSpec, fn: Callable[..., EstimationProblem]) -> None:
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):  # builtins without a signature: checked when called
        return
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in sig.parameters.values()):
        return
    for r in range(len(spec.rows)):
        for s in range(len(spec.scenarios)):
            for key in factory_kwargs(spec, r, s):
                if key not in sig.parameters:
                    raise SpecError(
                        f"parameter `{key}` (row {r}, scenario {spec.scenarios[s].name!r}) is not an "
                        f"argument of the factory {spec.factory!r}; it takes: {', '.join(sig.parameters)}"
                    )


def build_problem(spec: SweepSpec, row: int, scenario: int) -> EstimationProblem:
    """The estimation problem of ``row`` under ``scenario``."""
    problem = resolve_factory(spec.factory)(**factory_kwargs(spec, row, scenario))
    n = len(spec.initial_states.low)
    if isinstance(problem, EstimationProblem) and problem.plant.n_x != n:
        raise SpecError(
            f"`initial_states.low` and `.high` have {n} entries but the plant has n_x = {problem.plant.n_x}"
        )
    if not isinstance(problem, EstimationProblem):
        raise SpecError(
            f"the factory {spec.factory!r} returned {type(problem).__name__}, not an EstimationProblem"
        )
    return problem
