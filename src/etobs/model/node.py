"""A sensor node: the outputs it measures and its triggering rule."""

from __future__ import annotations

from dataclasses import dataclass

from etobs import _validate as v
from etobs.errors import InputTypeError
from etobs.model.rules import TriggerRule


@dataclass(frozen=True)
class Node:
    """Sensor node ``i``: owns the outputs ``y[outputs]`` (the set ``I_i``) and a rule.

    Nodes are indexed from 0 in code (node 0 is the paper's sensor 1).
    """

    outputs: tuple[int, ...]
    rule: TriggerRule
    name: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "outputs", v.index_tuple("outputs", self.outputs))
        if not isinstance(self.rule, TriggerRule):
            raise InputTypeError(
                f"`rule` must be a TriggerRule (DynamicRule, StaticRule, PeriodicRule); "
                f"got {type(self.rule).__name__}"
            )
