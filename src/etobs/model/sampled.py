"""A rule run at samples, as a sensor node runs it: :class:`Sampled`.

A real sensor node reads its output every ``T`` seconds and decides only then
(:mod:`etobs.runtime.sampled_rule`). ``Sampled(rule, period=T, phase=phi)`` is that node
in the simulator: at each sample ``t_k = phi + k T`` it decides on ``e_k`` and advances
its filter over the period with the one implementation the sensor node runs
(:func:`etobs.formulas.sample_decision`, :func:`etobs.formulas.eta_period`), so a
simulation, a sweep, a comparison or a tuning of the sampled rule gives the
transmissions the deployed node makes on the same samples.

In the hybrid model a sampled node has two jump rules: its *sample* (the guard
``t - t_k``; the jump decides, advances the filter and, when the rule fires, marks a
transmission as due) and its *transmission* (the guard ``due - 1/2``; the jump sends,
``ybar_i <- ytilde_i``, and clears the mark), both at ``t_k``. Its state is the rule's own
(``eta`` for the dynamic rule, constant between samples: the value the filter has at the
next sample), the index ``k`` of its next sample and the mark. Samples are jumps of the
hybrid time ``j`` (they count towards ``max_jumps``) but not transmissions.

What the theorems say of it: the continuous rule's certificate does not carry over as
is (see ``docs/runtime.md``). The inter-event time is at least ``T`` by construction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, ClassVar

import numpy as np

from etobs import _validate as v
from etobs import formulas as fm
from etobs.errors import InputError, InputTypeError
from etobs.model.rules import EngineForm, KindRule, TriggerRule, registered

#: The rule kinds a sampled node runs: those with no state or a filter (a clock samples already).
_KINDS = tuple(name for name, k in fm.RULE_KINDS.items() if k.state != "clock")


@dataclass(frozen=True)
class Sampled(TriggerRule):
    """``rule`` decided at samples ``t_k = phase + k period`` only, as a sensor node runs it.

    Parameters
    ----------
    rule : KindRule
        A rule of etobs' kinds a sensor node runs (:meth:`~etobs.model.rules.TriggerRule.sensor_spec`):
        :class:`~etobs.model.DynamicRule`, :class:`~etobs.model.StaticRule`,
        :class:`~etobs.model.RelativeRule` or :class:`~etobs.model.GeneralizedRule`, with
        linear, quadratic or power K-functions. A :class:`~etobs.model.PeriodicRule` is
        sampled already.
    period : float
        Sampling period ``T > 0`` (seconds).
    phase : float, optional
        Time of the first sample, in ``[0, period)`` (default ``0``: a node that samples
        at ``0, T, 2T, ...`` as :func:`etobs.runtime.sensor.run` does).

    Examples
    --------
    The robot arm's first node, sampled every 5 ms:

    >>> from etobs.model import DynamicRule, Linear, Quadratic, Sampled
    >>> rule = DynamicRule(gamma=Quadratic(5), alpha=Linear(2), sigma=600, c=0.001, b=1, eps=10, eta0=10)
    >>> Sampled(rule, period=0.005).n_state  # eta, the next sample's index, the transmission mark
    3

    """

    rule: TriggerRule
    period: float
    phase: float = 0.0
    #: A rule of etobs (:func:`etobs.model.rules.engine_form_of`): the engine runs it.
    samples_kind_rule: ClassVar[bool] = True

    def __post_init__(self) -> None:
        if not isinstance(self.rule, TriggerRule):
            raise InputTypeError(f"`rule` must be a TriggerRule; got {type(self.rule).__name__}")
        if isinstance(self.rule, Sampled):
            raise InputError("`rule` is Sampled already: give the rule it samples")
        if not (isinstance(self.rule, KindRule) and registered(self.rule)):
            raise InputError(
                f"Sampled runs the rules a sensor node runs ({', '.join(_KINDS)}); "
                f"got {type(self.rule).__name__}, a rule of your own"
            )
        if self.rule.kind.state == "clock":
            raise InputError(
                "Sampled: a PeriodicRule sends at fixed times already; give it a period that is a multiple "
                "of the node's sampling period instead"
            )
        self.rule.sensor_spec()  # a K-function a sensor node does not run (Custom) is refused here, named
        period = v.real("period", self.period, lower=0.0, lower_open=True)
        phase = v.real("phase", self.phase, lower=0.0)
        if not phase < period:
            raise InputError(f"`phase` must be in [0, period) = [0, {period:g}); got {phase!r}")
        object.__setattr__(self, "period", period)
        object.__setattr__(self, "phase", phase)

    @property
    def base(self) -> KindRule:
        """The rule it samples."""
        assert isinstance(self.rule, KindRule)
        return self.rule

    @property
    def reads_y(self) -> bool:  # type: ignore[override]
        return self.base.reads_y

    @property
    def n_own(self) -> int:
        """Entries of its state that are the sampled rule's own (``eta``): the first ones."""
        return self.base.n_state

    @property
    def n_state(self) -> int:
        return self.base.n_state + 2

    def initial_state(self) -> np.ndarray:
        return np.concatenate([self.base.initial_state(), [0.0, 0.0]])

    def first_sample(self, t0: float) -> int:
        """The index ``k`` of the first sample at or after ``t0`` (as :func:`etobs.runtime.sensor.run`)."""
        return max(0, math.ceil((t0 - self.phase) / self.period - 1e-9))

    def derivative(
        self, t: np.ndarray, e: np.ndarray, s: np.ndarray, y: np.ndarray | None = None
    ) -> np.ndarray:
        return np.zeros((t.shape[0], self.n_state))  # the filter moves at samples only

    def trigger(self, t: np.ndarray, e: np.ndarray, s: np.ndarray, y: np.ndarray | None = None) -> np.ndarray:
        """The transmission's guard: ``due - 1/2`` (the sample at ``t_k`` marked it due)."""
        return s[:, -1] - 0.5

    def reset(self, t: np.ndarray, s: np.ndarray) -> np.ndarray:
        """After the transmission: the mark cleared (the sample reset the filter already)."""
        out = s.copy()
        out[:, -1] = 0.0
        return out

    def sample_guard(self, t: np.ndarray, s: np.ndarray) -> np.ndarray:
        """``t - t_k``, ``t_k = phase + k period`` the next sample (``k`` in the state)."""
        return t - (self.phase + s[:, -2] * self.period)

    def decay(self) -> tuple[fm.KKind, float, float] | None:
        """The kind of the filter's decay K-function and its numbers (:func:`etobs.formulas.eta_period`)."""
        kind = self.base.kind
        if kind.decay is None:
            return None
        k, k1, k2, _ = getattr(self.base, kind.decay).engine_form()
        assert k is not None  # sensor_spec() refused a K-function of no kind
        return k, k1, k2

    def sample(self, e: np.ndarray, s: np.ndarray, y: np.ndarray | None) -> np.ndarray:
        """The state after the sample at ``t_k`` of each run: the decision, the filter, the next ``k``.

        The runs one by one through :func:`etobs.formulas.sample_decision`, on the norms a
        sensor node computes (:func:`etobs.formulas.norm`).
        """
        kind, decay, out = self.base.kind, self.decay(), s.copy()
        for r in range(s.shape[0]):
            norm_e = fm.norm(e[r].tolist())  # as a sensor node computes it
            norm_y = fm.norm(y[r].tolist()) if y is not None and kind.reads_y else None
            eta = float(s[r, 0]) if kind.state == "eta" else 0.0
            fire, eta = fm.sample_decision(kind, self.base, norm_e, norm_y, eta, self.period, decay)
            if kind.state == "eta":
                out[r, 0] = eta
            out[r, -2] = s[r, -2] + 1.0
            out[r, -1] = 1.0 if fire else 0.0
        return out

    def engine_form(self) -> EngineForm:
        return replace(self.base.engine_form(), sampled=(self.period, self.phase))

    def sensor_spec(self) -> dict[str, Any]:
        """The rule a sensor node runs at ``period``: the spec of its sampled rule (:mod:`etobs.runtime`)."""
        return self.base.sensor_spec()
