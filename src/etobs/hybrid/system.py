"""A hybrid system in the form the solvers accept.

The system is ``x' = flow(t, x)`` while every event function is negative, and
``x+ = jump(k, t, x)`` when event function ``k`` is ``>= 0``. The solvers know nothing
else about it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from etobs import _validate as v

FlowFn = Callable[[np.ndarray, np.ndarray], np.ndarray]
GuardFn = Callable[[np.ndarray, np.ndarray], np.ndarray]
JumpFn = Callable[[int, np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class HybridSystem:
    """A batched hybrid system with ``n_rules`` jump rules.

    Parameters
    ----------
    n : int
        State dimension.
    n_rules : int
        Number of jump rules (event functions).
    flow : callable
        ``flow(t, x) -> dx``; ``t`` has shape ``(B,)``, ``x`` and ``dx`` shape ``(B, n)``.
    guard : callable
        ``guard(t, x) -> g`` of shape ``(B, n_rules)``; rule ``k`` may jump where
        ``g[:, k] >= 0`` and the system flows while every ``g < 0``.
    jump : callable
        ``jump(k, t, x) -> x+`` applies rule ``k`` to the rows given, shape ``(M, n)``.
    rule_names : tuple of str, optional
        Names of the rules, used in messages and logs.
    n_flow : int, optional
        When given, only the entries ``0 .. n_flow-1`` change along flows; the others
        (counters, buffers, identifiers) have zero derivative. The fast solver then
        leaves them out of its error norm, so that they do not dilute the tolerance.

    """

    n: int
    n_rules: int
    flow: FlowFn
    guard: GuardFn
    jump: JumpFn
    rule_names: tuple[str, ...] = ()
    n_flow: int | None = None

    def __post_init__(self) -> None:
        v.integer("n", self.n, lower=1)
        v.integer("n_rules", self.n_rules, lower=0)
        if self.n_flow is not None:
            v.integer("n_flow", self.n_flow, lower=1)
            if self.n_flow > self.n:
                from etobs.errors import InputError

                raise InputError(f"`n_flow` must be <= n = {self.n}; got {self.n_flow}")
        v.function("flow", self.flow)
        v.function("guard", self.guard)
        v.function("jump", self.jump)
        if not self.rule_names:
            object.__setattr__(self, "rule_names", tuple(f"rule{k}" for k in range(self.n_rules)))
        elif len(self.rule_names) != self.n_rules:
            from etobs.errors import InputError

            raise InputError(
                f"`rule_names` has {len(self.rule_names)} names; expected n_rules={self.n_rules}"
            )
