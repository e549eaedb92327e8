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

    Parameters
    ----------
    outputs : sequence of int
        The indices of ``y`` the node measures and sends (the nodes' sets partition ``y``).
    rule : TriggerRule
        When it sends: :class:`~etobs.model.DynamicRule` (eq. (14)--(15)) or another rule.
    name : str, optional
        How tables, results and figures name it (default ``node<i>``).

    Examples
    --------
    The robot arm's first node, measuring ``y_1``:

    >>> from etobs import DynamicRule, Linear, Node, Quadratic
    >>> rule = DynamicRule(gamma=Quadratic(5), alpha=Linear(2), sigma=600, c=0.001, eps=10, eta0=10)
    >>> Node([0], rule, name="sensor 1").outputs
    (0,)

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


@dataclass(frozen=True)
class InputNode:
    """An input node (section 7.3): sends the plant input ``u[inputs]`` to the observer.

    The observer then runs on the held ``ubar`` in place of ``u`` for these components,
    eq. (50), and the node transmits by its own rule acting on ``e_u = ubar - u``,
    eq. (53)--(54) (e.g. a :class:`~etobs.model.DynamicRule` with ``gamma_u``,
    ``alpha_u``, ``sigma_u``, ``c_u``, ``b_u``, ``eps_u``). Components of ``u`` that no
    input node sends reach the observer exactly, as in the base setting.

    Parameters
    ----------
    inputs : sequence of int
        The indices of ``u`` it sends.
    rule : TriggerRule
        Its rule, acting on ``e_u = ubar - u``.
    name : str, optional
        How results name it (default ``input<i>``).

    Examples
    --------
    >>> from etobs import InputNode, StaticRule, Linear
    >>> InputNode([0], StaticRule(gamma=Linear(1.0), eps=0.05)).inputs
    (0,)

    """

    inputs: tuple[int, ...]
    rule: TriggerRule
    name: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "inputs", v.index_tuple("inputs", self.inputs, "input"))
        if not isinstance(self.rule, TriggerRule):
            raise InputTypeError(f"`rule` must be a TriggerRule; got {type(self.rule).__name__}")
