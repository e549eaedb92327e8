"""The search space of a tuning: Optuna distributions and the factory arguments of a candidate."""

from __future__ import annotations

from typing import Any

from etobs.tuning.spec import OBSERVER_VARIABLE, Parameter, TuneSpec, factory_defaults


def variables(param: Parameter, n_nodes: int) -> list[str]:
    """The names of the searched variables of ``param``: ``sigma_0, sigma_1`` per node, else ``sigma``."""
    if param.per == "node":
        return [f"{param.name}_{i}" for i in range(n_nodes)]
    return [param.name]


def distributions(spec: TuneSpec, n_nodes: int) -> dict[str, Any]:
    """Every searched variable's Optuna distribution (the observer choice is one more)."""
    from optuna.distributions import CategoricalDistribution, FloatDistribution

    out: dict[str, Any] = {}
    for p in spec.parameters:
        for name in variables(p, n_nodes):
            if p.categorical:
                out[name] = CategoricalDistribution(list(p.choices))
            else:
                out[name] = FloatDistribution(p.low, p.high, log=p.log)
    if len(spec.observers) > 1:
        out[OBSERVER_VARIABLE] = CategoricalDistribution(list(spec.observers))
    return out


def factory_kwargs(spec: TuneSpec, values: dict[str, Any], n_nodes: int) -> dict[str, Any]:
    """The factory's arguments of a candidate (``values`` by variable), without ``system.fixed``.

    A ``per = "node"`` or ``"shared"`` parameter is given as a list with one value per
    node; ``"scalar"`` as the value itself.
    """
    out: dict[str, Any] = {}
    for p in spec.parameters:
        names = variables(p, n_nodes)
        if p.per == "node":
            out[p.name] = [_plain(values[n]) for n in names]
        elif p.per == "shared":
            out[p.name] = [_plain(values[names[0]])] * n_nodes
        else:
            out[p.name] = _plain(values[names[0]])
    return out


def observer_of(spec: TuneSpec, values: dict[str, Any]) -> str | None:
    """The name of the candidate's observer (``""`` for a single ``[observer]``; ``None``: none)."""
    if not spec.observers:
        return None
    if len(spec.observers) == 1:
        return next(iter(spec.observers))
    return str(values[OBSERVER_VARIABLE])


def start_values(spec: TuneSpec, n_nodes: int, params: dict[str, Any]) -> dict[str, Any] | None:
    """The variables of a known design, or ``None`` when it lies outside the search space.

    The design is the factory called with ``system.fixed`` and ``params`` (``{}``: the
    start design, the factory's defaults); it is a trial of the search when each
    searched value lies in its box (shared values equal across nodes) and it sets no
    other argument than the searched ones.
    """
    if set(params) - {p.name for p in spec.parameters}:
        return None
    defaults = {**factory_defaults(spec.factory), **params}
    out: dict[str, Any] = {}
    for p in spec.parameters:
        if p.name not in defaults:
            return None
        value = defaults[p.name]
        items = (
            list(value)
            if isinstance(value, (list, tuple))
            else [value] * (n_nodes if p.per != "scalar" else 1)
        )
        if p.per == "scalar" and isinstance(value, (list, tuple)):
            return None
        if p.per != "scalar" and len(items) != n_nodes:
            return None
        if p.per == "shared" and len(set(items)) != 1:
            return None
        for name, x in zip(variables(p, n_nodes), items, strict=False):
            if p.categorical:
                if x not in p.choices:
                    return None
            elif not isinstance(x, (int, float)) or not p.low <= x <= p.high:
                return None
            out[name] = x if p.categorical else float(x)
    if len(spec.observers) > 1:
        out[OBSERVER_VARIABLE] = next(iter(spec.observers))
    return out


def _plain(x: Any) -> Any:
    """A Python number for a numpy one (specs and JSON take plain values)."""
    return x.item() if hasattr(x, "item") else x
