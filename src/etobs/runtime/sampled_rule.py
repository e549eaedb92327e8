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
error ``O((T/20)^5)``; :func:`etobs.formulas.eta_after_period`). The formulas are those
the simulator runs (:mod:`etobs.formulas`, standard library only). Against the continuous
rule of the paper the sampled rule differs in two ways: it checks the trigger only at
samples, so a transmission comes up to ``T`` late and the gap can exceed the threshold by
up to ``E_i T`` (``E_i`` a bound on ``|d/dt y_i|``); and the filter sees ``gamma(|e|)``
held, not its continuous value, an error of at most ``c T sup |d/dt gamma(|e|)|`` per
period in ``eta'``. Both vanish as ``T -> 0``. The decision at a sample is: send when
``gamma(|e_k|) >= sigma alpha(eta_k) + eps`` (eq. (15)), then ``eta <- b eta`` (eq. (14)).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from etobs import formulas as fm

#: A K-function as a node runs it: its kind and two numbers (:func:`etobs.formulas.k_value`).
KFn = tuple[int, float, float]


class RuleSpecError(ValueError):
    """A rule specification is not valid; the message names the key."""


def _number(spec: Mapping[str, Any], key: str, *, lower: float = 0.0, strict: bool = False) -> float:
    if key not in spec:
        raise RuleSpecError(f"rule spec: missing key `{key}`")
    value = spec[key]
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise RuleSpecError(f"rule spec: `{key}` must be a finite number; got {value!r}")
    if value < lower or (strict and value == lower):
        raise RuleSpecError(f"rule spec: `{key}` must be {'>' if strict else '>='} {lower:g}; got {value!r}")
    return float(value)


def k_function(spec: Any, key: str) -> KFn:
    """``["linear", a]`` (a s), ``["quadratic", ell]`` (ell s^2) or ``["power", k, p]`` (k s^p)."""
    if not isinstance(spec, Sequence) or isinstance(spec, str) or not spec:
        raise RuleSpecError(f"rule spec: `{key}` must be a list like ['linear', 2.0]; got {spec!r}")
    kind, *args = spec
    shapes = {"linear": 1, "quadratic": 1, "power": 2}
    if kind not in shapes or len(args) != shapes[kind]:
        raise RuleSpecError(
            f"rule spec: `{key}` must be ['linear', a], ['quadratic', ell] or ['power', k, p]"
        )
    vals = [_number({"v": a}, "v", strict=True) for a in args]
    return fm.SENSOR_NAMES[kind], vals[0], vals[1] if len(vals) > 1 else 0.0


def _k(fn: KFn, s: float) -> float:
    return float(fm.k_value(fn[0], fn[1], fn[2], s))


def _norm(v: Sequence[float]) -> float:
    return math.sqrt(sum(x * x for x in v))


class SampledRule:
    """A node's rule at sampling period ``period``: :meth:`decide` once per sample.

    Parameters
    ----------
    spec : mapping
        The rule as plain data (see the module docstring); kinds ``dynamic``,
        ``static``, ``periodic``, ``relative``.
    period : float
        Sampling period ``T > 0`` (seconds).

    """

    def __init__(self, spec: Mapping[str, Any], period: float) -> None:
        if not isinstance(spec, Mapping):
            raise RuleSpecError(f"rule spec must be a mapping; got {type(spec).__name__}")
        self.period = _number({"period": period}, "period", strict=True)
        self.kind = spec.get("kind")
        if self.kind == "dynamic":
            self.gamma = k_function(spec.get("gamma"), "gamma")
            self.alpha = k_function(spec.get("alpha"), "alpha")
            self.sigma, self.c = _number(spec, "sigma"), _number(spec, "c")
            self.b, self.eps = _number(spec, "b"), _number(spec, "eps", strict=True)
            if self.b > 1:
                raise RuleSpecError(f"rule spec: `b` must be <= 1; got {self.b!r}")
            self.eta = _number(spec, "eta0")
        elif self.kind == "static":
            self.gamma = k_function(spec.get("gamma"), "gamma")
            self.eps = _number(spec, "eps", strict=True)
        elif self.kind == "relative":
            self.rho, self.eps = _number(spec, "rho", strict=True), _number(spec, "eps", strict=True)
        elif self.kind == "periodic":
            every = _number(spec, "period", strict=True) / self.period
            self.every = max(1, round(every))
            if abs(every - self.every) > 1e-9 * max(1.0, every):
                raise RuleSpecError(
                    f"rule spec: a periodic rule's period must be a multiple of the sampling period "
                    f"{self.period:g}; got {spec['period']!r}"
                )
            first = _number(spec, "first") if "first" in spec else float(spec["period"])
            # fire at the sample of time `first`, then every `every` samples (as PeriodicRule)
            self.count = self.every - round(first / self.period) - 1
        else:
            raise RuleSpecError(
                f"rule spec: `kind` must be dynamic, static, periodic or relative; got {self.kind!r}"
            )

    def decide(self, e: Sequence[float], y: Sequence[float]) -> bool:
        """Whether to send at this sample, given the gap ``e = ybar - y`` and ``y``.

        Advances the rule's state over the period that follows.
        """
        r = _norm(e)
        if self.kind == "periodic":
            self.count += 1
            fire = self.count >= self.every
            if fire:
                self.count = 0
            return fire
        if self.kind == "static":
            return fm.static_trigger(_k(self.gamma, r), self.eps) >= 0.0
        if self.kind == "relative":
            return fm.relative_trigger(r, _norm(y), self.rho, self.eps) >= 0.0
        fire = fm.dynamic_trigger(_k(self.gamma, r), _k(self.alpha, self.eta), self.sigma, self.eps) >= 0.0
        if fire:
            self.eta = fm.eta_reset(self.eta, self.b)  # eq. (14), jump
            r = 0.0
        # eq. (14) over the period, gamma(|e|) held
        self.eta = fm.eta_after_period(self.eta, self.c * _k(self.gamma, r), *self.alpha, self.period)
        return fire
