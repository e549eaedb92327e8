"""The triggering rules as a sensor node runs them: sampled, standard library only.

A node reads its output every ``T`` seconds (samples ``t_k = k T``) and decides at each
sample, on ``e_k = ybar - y(t_k)``, whether to send. The rules are given as plain data
(a simulator rule's :meth:`~etobs.model.rules.TriggerRule.sensor_spec` gives it), e.g.::

    {"kind": "dynamic", "gamma": ["quadratic", 5.0], "alpha": ["linear", 2.0],
     "sigma": 600.0, "c": 0.001, "b": 1.0, "eps": 10.0, "eta0": 10.0}

**Discretization of the eta filter.** Between samples the node knows only ``e_k``, so
``gamma(|e|)`` is held over ``[t_k, t_k + T)`` (zero-order hold, the value after the
decision: ``0`` if the node just sent). With ``alpha(s) = a s`` eq. (14) is then solved
exactly over one period:

    eta_{k+1} = exp(-a T) eta_k + c gamma(|e_k|) (1 - exp(-a T)) / a.

Other ``alpha`` are integrated with 20 classical Runge--Kutta substeps per period (local
error ``O((T/20)^5)``; :func:`etobs.formulas.eta_period`). Every kind of
:data:`etobs.formulas.RULE_KINDS` runs so (the generalized rule's ``alpha_check`` as
``alpha``); a clock counts samples. The formulas are those the simulator runs
(:mod:`etobs.formulas`, standard library only). Against the continuous
rule of the paper the sampled rule differs in two ways: it checks the trigger only at
samples, so a transmission comes up to ``T`` late and the gap can exceed the threshold by
up to ``E_i T`` (``E_i`` a bound on ``|d/dt y_i|``); and the filter sees ``gamma(|e|)``
held, not its continuous value, an error of at most ``c T sup |d/dt gamma(|e|)|`` per
period in ``eta'``. Both vanish as ``T -> 0``. The decision at a sample is: send when
``gamma(|e_k|) >= sigma alpha(eta_k) + eps`` (eq. (15)), then ``eta <- b eta`` (eq. (14)).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from types import SimpleNamespace
from typing import Any

from etobs import formulas as fm
from etobs.errors import InputError

#: A K-function as a node runs it: its kind and two numbers (:mod:`etobs.formulas`).
KFn = tuple[fm.KKind, float, float]


class RuleSpecError(ValueError):
    """A rule specification is not valid; the message names the key."""


def _number(spec: Mapping[str, Any], key: str, limits: fm.Number | None = None) -> float:
    """``spec[key]``, a finite number within ``limits`` (``>= 0`` when none are given)."""
    if key not in spec:
        raise RuleSpecError(f"rule spec: missing key `{key}`")
    value = spec[key]
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise RuleSpecError(f"rule spec: `{key}` must be a finite number; got {value!r}")
    why = (limits or fm.Number(key, lower=0.0)).refusal(float(value))
    if why:
        raise RuleSpecError(f"rule spec: `{key}` {why}; got {value!r}")
    return float(value)


def k_function(spec: Any, key: str, constant: bool = False) -> KFn:
    """``["linear", a]`` (a s), ``["quadratic", ell]`` (ell s^2), ``["power", k, p]`` (k s^p).

    A K-function kind of :data:`etobs.formulas.K_KINDS` and its numbers; a positive number
    where the slot allows a constant (``constant``).
    """
    kinds = {name: k for name, k in fm.K_KINDS.items() if k is not fm.CONSTANT}
    if constant and isinstance(spec, int | float) and not isinstance(spec, bool):
        return fm.CONSTANT, _number({key: spec}, key, fm.CONSTANT.numbers[0]), 0.0
    shown = " or ".join(
        f"[{', '.join([repr(k.name), *(n.name for n in k.numbers)])}]" for k in kinds.values()
    )
    if spec is None:
        raise RuleSpecError(f"rule spec: missing key `{key}`")
    if not isinstance(spec, Sequence) or isinstance(spec, str) or not spec:
        raise RuleSpecError(f"rule spec: `{key}` must be a list like {shown}; got {spec!r}")
    name, *args = spec
    try:
        kind: fm.KKind | None = fm.k_kind(name)
    except InputError:
        kind = None
    if kind is None or kind is fm.CONSTANT or len(args) != len(kind.numbers):
        raise RuleSpecError(f"rule spec: `{key}` must be {shown}; got {spec!r}")
    vals = [
        _number({f"{key}[{i + 1}]": a}, f"{key}[{i + 1}]", n)  # named as in the spec: gamma[1]
        for i, (n, a) in enumerate(zip(kind.numbers, args, strict=True))
    ]
    return kind, vals[0], vals[1] if len(vals) > 1 else 0.0


class SampledRule:
    """A node's rule at sampling period ``period``: ``decide`` once per sample.

    Parameters
    ----------
    spec : mapping
        The rule as plain data (see the module docstring): a kind of
        :data:`etobs.formulas.RULE_KINDS` by name, its K-functions, numbers and initial state.
    period : float
        Sampling period ``T > 0`` (seconds).

    """

    def __init__(self, spec: Mapping[str, Any], period: float) -> None:
        if not isinstance(spec, Mapping):
            raise RuleSpecError(f"rule spec must be a mapping; got {type(spec).__name__}")
        self.period = _number({"period": period}, "period", fm.Number("period", lower=0.0, lower_open=True))
        name = spec.get("kind")
        try:
            self.kind = fm.rule_kind(name)
        except InputError:
            raise RuleSpecError(
                f"rule spec: `kind` must be one of {', '.join(fm.RULE_KINDS)}; got {name!r}"
            ) from None
        self.k = {
            slot.name: k_function(spec.get(slot.name), slot.name, slot.constant) for slot in self.kind.slots
        }
        self.numbers = {n.name: _number(spec, n.name, n) for n in self.kind.numbers}
        # what the kind's formulas read (etobs.formulas.evaluator): numbers and K-functions by name
        self._rule = SimpleNamespace(
            **self.numbers,
            **{
                slot: kv[1] if kv[0] is fm.CONSTANT else functools.partial(kv[0].value, kv[1], kv[2])
                for slot, kv in self.k.items()
            },
        )
        initial = self.kind.initial
        self.eta = _number(spec, initial) if self.kind.state == "eta" and initial else 0.0
        if self.kind.state == "clock":
            own = self.numbers[self.kind.period or ""]
            every = own / self.period
            self.every = max(1, round(every))
            if abs(every - self.every) > 1e-9 * max(1.0, every):
                raise RuleSpecError(
                    f"rule spec: a periodic rule's period must be a multiple of the sampling period "
                    f"{self.period:g}; got {spec[self.kind.period or '']!r}"
                )
            first = _number(spec, "first") if "first" in spec else own
            # fire at the sample of time `first`, then every `every` samples (as PeriodicRule)
            self.count = self.every - round(first / self.period) - 1

    def decide(self, e: Sequence[float], y: Sequence[float]) -> bool:
        """Whether to send at this sample, given the gap ``e = ybar - y`` and ``y``.

        Advances the rule's state over the period that follows.
        """
        if self.kind.state == "clock":  # a clock counts samples (exact multiples of T)
            self.count += 1
            fire = self.count >= self.every
            if fire:
                self.count = 0
            return fire
        r, ym = fm.norm(e), (fm.norm(y) if self.kind.reads_y else None)
        decay = self.k[self.kind.decay] if self.kind.decay else None  # the filter's decay K-function
        fire, self.eta = fm.sample_decision(self.kind, self._rule, r, ym, self.eta, self.period, decay)
        return fire
