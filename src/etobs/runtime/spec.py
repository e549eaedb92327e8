"""Turn the simulator's rule objects into the plain data a sensor node runs."""

from __future__ import annotations

from typing import Any

from etobs.errors import InputError
from etobs.model.functions import KFunction, Linear, Power, Quadratic
from etobs.model.rules import DynamicRule, PeriodicRule, RelativeRule, StaticRule, TriggerRule


def _k(fn: KFunction, what: str) -> list[Any]:
    if isinstance(fn, Linear):
        return ["linear", fn.a]
    if isinstance(fn, Quadratic):
        return ["quadratic", fn.ell]
    if isinstance(fn, Power):
        return ["power", fn.k, fn.p]
    raise InputError(
        f"a sensor node runs Linear, Quadratic or Power functions; `{what}` is {type(fn).__name__}"
    )


def rule_spec(rule: TriggerRule) -> dict[str, Any]:
    """The rule as a sensor node's :class:`~etobs.runtime.sampled_rule.SampledRule` takes it."""
    if isinstance(rule, DynamicRule):
        return {
            "kind": "dynamic",
            "gamma": _k(rule.gamma, "gamma"),
            "alpha": _k(rule.alpha, "alpha"),
            "sigma": rule.sigma,
            "c": rule.c,
            "b": rule.b,
            "eps": rule.eps,
            "eta0": rule.eta0,
        }
    if isinstance(rule, StaticRule):
        return {"kind": "static", "gamma": _k(rule.gamma, "gamma"), "eps": rule.eps}
    if isinstance(rule, RelativeRule):
        return {"kind": "relative", "rho": rule.rho, "eps": rule.eps}
    if isinstance(rule, PeriodicRule):
        return {"kind": "periodic", "period": rule.period, "first": rule.first}
    raise InputError(
        f"a sensor node runs DynamicRule, StaticRule, RelativeRule or PeriodicRule; got {type(rule).__name__}"
    )
