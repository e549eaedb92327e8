"""Build a group's problem from a spec's ``system.factory`` and check the arguments it gets.

The factory is resolved, refused unless marked with :func:`etobs.factory`, and called by
:mod:`etobs.examples.registry` (shared with ``etobs check`` and ``etobs serve``).
"""

from __future__ import annotations

from typing import Any

from etobs._spec import SpecError
from etobs.estimation.problem import EstimationProblem
from etobs.examples.registry import check_arguments, make_problem, resolve_factory

__all__ = ["build", "check_arguments", "resolve_factory"]


def build(factory: str, kwargs: dict[str, Any], n_x: int, where: str) -> EstimationProblem:
    """``factory(**kwargs)``, checked to be an :class:`EstimationProblem` with ``n_x`` states.

    ``where`` names the arguments' origin in errors (``"system.params"``, ``"row 0, ..."``).
    """
    problem = make_problem(factory, kwargs, where)
    if problem.plant.n_x != n_x:
        raise SpecError(
            f"`initial_states.low` and `.high` have {n_x} entries but the plant has n_x = {problem.plant.n_x}"
        )
    return problem
