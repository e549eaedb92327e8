"""Resolve a spec's ``system.factory``, check its arguments and build a group's problem."""

from __future__ import annotations

import inspect
from collections.abc import Iterable
from typing import Any

from etobs._spec import SpecError
from etobs.estimation.problem import EstimationProblem
from etobs.examples.registry import resolve_factory


def check_arguments(factory: str, calls: Iterable[tuple[str, dict[str, Any]]]) -> None:
    """Fail early, naming the key, when a call ``(where, kwargs)`` passes an unknown argument.

    The factory itself is not called here (in a sweep, it runs in the workers).
    """
    fn = resolve_factory(factory)
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):  # builtins without a signature: checked when called
        return
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in sig.parameters.values()):
        return
    for where, kwargs in calls:
        for key in kwargs:
            if key not in sig.parameters:
                raise SpecError(
                    f"parameter `{key}` ({where}) is not an argument of the factory "
                    f"{factory!r}; it takes: {', '.join(sig.parameters)}"
                )


def build(factory: str, kwargs: dict[str, Any], n_x: int, where: str) -> EstimationProblem:
    """``factory(**kwargs)``, checked to be an :class:`EstimationProblem` with ``n_x`` states.

    ``where`` names the arguments' origin in errors (``"system.params"``, ``"row 0, ..."``).
    """
    fn = resolve_factory(factory)
    try:
        problem = fn(**kwargs)
    except TypeError as exc:
        if not _fits(fn, kwargs):
            raise SpecError(
                f"the arguments {', '.join(kwargs) or '(none)'} ({where}) do not fit the factory "
                f"{factory!r}: {exc}"
            ) from exc
        raise
    if not isinstance(problem, EstimationProblem):
        kind = type(problem).__name__
        raise SpecError(f"the factory {factory!r} returned {kind}, not an EstimationProblem")
    if problem.plant.n_x != n_x:
        raise SpecError(
            f"`initial_states.low` and `.high` have {n_x} entries but the plant has n_x = {problem.plant.n_x}"
        )
    return problem


def _fits(fn: Any, kwargs: dict[str, Any]) -> bool:
    """Whether ``kwargs`` bind to ``fn``'s signature (so a TypeError came from inside it)."""
    try:
        inspect.signature(fn).bind(**kwargs)
    except TypeError:
        return False
    except ValueError:  # no signature
        return True
    return True
