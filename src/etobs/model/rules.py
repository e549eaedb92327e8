"""Triggering rules of the sensor nodes.

A rule sees only its own node: the gap ``e_i = ybar_i - ytilde_i`` between the value
last sent and the current measurement, its own internal state ``s_i`` (``eta_i`` for
the paper's dynamic rule, a clock for the periodic rule, nothing for the static rule)
and, for rules that need it, the current measurement ``y = ytilde_i`` itself (the
relative-threshold rule). It defines

* ``derivative(t, e, s, y)``: ``s_i'`` along flows;
* ``trigger(t, e, s, y)``: the trigger function; the node transmits when it is ``>= 0``;
* ``reset(t, s)``: ``s_i+`` at the node's own transmission.

All methods are vectorized over runs: ``t`` has shape ``(B,)``, ``e`` and ``y``
``(B, n_yi)`` and ``s`` ``(B, n_state)``. ``y`` may be omitted (``None``) for every
rule that does not read it. An input node (section 7.3) runs the same rules on
``e_u = ubar - u``.

etobs' rules are each a kind of :data:`etobs.formulas.RULE_KINDS` (:class:`KindRule`):
their batched methods (for the scipy reference and for evaluating results), their engine
form (:meth:`TriggerRule.engine_form`, compiled into the engine's model) and their sensor
spec (:meth:`TriggerRule.sensor_spec`, the plain data a stdlib-only sensor node runs) all
derive from the kind's descriptor and compute with its one implementation of the
formulas, so what you simulate is what you deploy.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from etobs import _validate as v
from etobs import formulas as fm
from etobs.errors import InputError
from etobs.model.functions import KFunction, Linear, as_kfunction, declared


@dataclass(frozen=True)
class EngineForm:
    """A rule as the engine runs it: its kind, its numbers and its K-functions by slot.

    ``numbers`` maps the kind's numbers to values; ``kfunctions`` maps its slots to a
    :class:`~etobs.model.functions.KFunction` or a constant (a slot that allows one).
    """

    kind: fm.RuleKind
    numbers: dict[str, float]
    kfunctions: dict[str, KFunction | float]
    sampled: tuple[float, float] | None = None  # (period, phase) of a Sampled rule


def _norm(e: NDArray[np.float64]) -> NDArray[np.float64]:
    """Euclidean norm of each row: ``|e_i|``."""
    if e.shape[1] == 1:
        return np.abs(e[:, 0])
    squares: NDArray[np.float64] = np.einsum("ij,ij->i", e, e)
    return np.sqrt(squares)


class TriggerRule(ABC):
    """Interface of a node's triggering rule (see the module docstring).

    A rule that reads the current measurement sets ``reads_y = True``; only then is
    ``y=`` passed, so rules written as ``trigger(t, e, s)`` keep working.

    Examples
    --------
    etobs' rules implement it; a rule of your own does too (the scipy reference runs it):

    >>> import numpy as np
    >>> from etobs import DynamicRule, Linear, Quadratic, TriggerRule
    >>> rule = DynamicRule(gamma=Quadratic(5), alpha=Linear(2), sigma=600, c=0.001, eps=10, eta0=10)
    >>> isinstance(rule, TriggerRule), rule.n_state, rule.initial_state().tolist()
    (True, 1, [10.0])
    >>> rule.trigger(np.zeros(1), np.array([[2.0]]), np.array([[0.0]])).tolist()  # 5*2^2 - 10
    [10.0]

    """

    reads_y: ClassVar[bool] = False

    @property
    @abstractmethod
    def n_state(self) -> int:
        """Size of the rule's internal state."""

    @property
    def n_own(self) -> int:
        """Entries of the state that are the rule's filter or clock (the first ones; ``eta`` first)."""
        return self.n_state

    @abstractmethod
    def initial_state(self) -> np.ndarray:
        """The internal state at ``t = 0``, shape ``(n_state,)``."""

    @abstractmethod
    def derivative(
        self, t: np.ndarray, e: np.ndarray, s: np.ndarray, y: np.ndarray | None = None
    ) -> np.ndarray:
        """``s'`` along flows, shape ``(B, n_state)``."""

    @abstractmethod
    def trigger(self, t: np.ndarray, e: np.ndarray, s: np.ndarray, y: np.ndarray | None = None) -> np.ndarray:
        """Trigger function, shape ``(B,)``: transmit when ``>= 0``."""

    @abstractmethod
    def reset(self, t: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Internal state right after the node's own transmission."""

    def engine_form(self) -> EngineForm | None:
        """The rule as the engine runs it, or ``None`` for a rule the engine does not know."""
        return None

    def sensor_spec(self) -> dict[str, Any]:
        """The rule as a sensor node's :class:`~etobs.runtime.sampled_rule.SampledRule` takes it.

        Raises
        ------
        InputError
            For a rule a sensor node does not run.

        """
        raise InputError(
            f"a sensor node runs the rules of etobs' kinds ({', '.join(fm.RULE_KINDS)}); "
            f"got {type(self).__name__}, a rule of your own"
        )


def engine_form_of(rule: TriggerRule) -> EngineForm | None:
    """``rule.engine_form()`` for a kind of etobs or one sampled, else ``None`` (``registered``)."""
    sampled = type(rule).__dict__.get("samples_kind_rule") is True  # etobs.model.sampled.Sampled itself
    return rule.engine_form() if registered(rule) or sampled else None


def registered(rule: TriggerRule) -> bool:
    """Whether ``rule`` is one of etobs' kinds as declared: its own class names a registered kind.

    A subclass of a built-in rule that changes its trigger, or a class naming a kind of
    its own, is a rule of your own: the engine and the sensor node do not run it (they
    would run its parent, or fail), the scipy reference does.
    """
    kind = type(rule).__dict__.get("kind")
    return isinstance(kind, fm.RuleKind) and fm.RULE_KINDS.get(kind.name) is kind


class KindRule(TriggerRule):
    """A rule of a kind of :data:`etobs.formulas.RULE_KINDS`: everything but its fields derives from the kind.

    A subclass is a frozen dataclass that sets ``kind`` and has one field per K-function
    slot and per number of the kind (and ``eta0`` for a filter state, ``first`` for a
    clock). Validation, the state, the batched methods (the reference solver's), the
    engine form and the sensor spec are the kind's formulas (:mod:`etobs.formulas`).
    """

    kind: ClassVar[fm.RuleKind]

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "kind" in cls.__dict__:
            cls.reads_y = cls.kind.reads_y

    def __post_init__(self) -> None:
        for slot in self.kind.slots:
            value = getattr(self, slot.name)
            if slot.constant and isinstance(value, int | float) and not isinstance(value, bool):
                value = v.real(slot.name, value, **fm.CONSTANT.numbers[0].limits())
            else:
                value = as_kfunction(slot.name, value)
            object.__setattr__(self, slot.name, value)
        for n in self.kind.numbers:
            object.__setattr__(self, n.name, v.real(n.name, getattr(self, n.name), **n.limits()))
        if self.kind.initial is not None:
            name = self.kind.initial
            object.__setattr__(self, name, v.real(name, getattr(self, name), lower=0.0))

    @property
    def n_state(self) -> int:
        return 0 if self.kind.state == "none" else 1

    def initial_state(self) -> np.ndarray:
        name = self.kind.initial  # the field of the subclass that sets it: eta0, first
        if name is None:
            return np.empty(0)
        if self.kind.state == "clock":
            return np.array([getattr(self, self.kind.period or "") - getattr(self, name)])
        return np.array([getattr(self, name)])

    def _apply(self, what: str, e: np.ndarray | None, s: np.ndarray, y: np.ndarray | None) -> np.ndarray:
        """The kind's formula ``what`` on a batch, as a ``(B,)`` array (:func:`etobs.formulas.evaluator`)."""
        formula: fm.Formula = getattr(self.kind, what)
        reads = formula.reads
        state = s[:, 0] if "s" in reads else None
        norm_e = _norm(e) if e is not None and "e" in reads else None
        norm_y = _norm(y) if y is not None and "y" in reads else None
        out = fm.evaluator(formula, self.kind.constants)(self, norm_e, norm_y, state)
        if isinstance(out, np.ndarray) and out.shape == (s.shape[0],):
            return out
        return np.full(s.shape[0], out, dtype=float)  # a constant (a clock's flow and reset)

    def derivative(
        self, t: np.ndarray, e: np.ndarray, s: np.ndarray, y: np.ndarray | None = None
    ) -> np.ndarray:
        if self.kind.flow is None:
            return np.empty((t.shape[0], 0))
        return self._apply("flow", e, s, y)[:, None]

    def trigger(self, t: np.ndarray, e: np.ndarray, s: np.ndarray, y: np.ndarray | None = None) -> np.ndarray:
        if self.kind.reads_y and y is None:
            raise InputError(f"{type(self).__name__}.trigger needs the current measurement `y`; got None")
        return self._apply("trigger", e, s, y)

    def reset(self, t: np.ndarray, s: np.ndarray) -> np.ndarray:
        if self.kind.reset is None:
            return s
        return self._apply("reset", None, s, None)[:, None]

    def engine_form(self) -> EngineForm:
        numbers = {n.name: float(getattr(self, n.name)) for n in self.kind.numbers}
        return EngineForm(
            self.kind, numbers, {slot.name: getattr(self, slot.name) for slot in self.kind.slots}
        )

    def sensor_spec(self) -> dict[str, Any]:
        if not registered(self):
            return super().sensor_spec()  # refused: a rule of your own
        spec: dict[str, Any] = {"kind": self.kind.name}
        for slot in self.kind.slots:
            fn = getattr(self, slot.name)
            spec[slot.name] = fn if isinstance(fn, float) else fn.sensor_spec(slot.name)
        spec.update(self.engine_form().numbers)
        if self.kind.initial is not None:
            spec[self.kind.initial] = float(getattr(self, self.kind.initial))
        return spec


def rule_classes() -> dict[str, type[KindRule]]:
    """The rule classes of etobs by kind name: each kind of :data:`etobs.formulas.RULE_KINDS` and its class.

    Raises
    ------
    InputError
        When a kind has no class or two (a kind must be declared with its class).

    """
    # importing this module ran etobs/model/__init__.py, which defines every class of etobs
    return declared(KindRule, fm.RULE_KINDS, "rule")


@dataclass(frozen=True)
class DynamicRule(KindRule):
    """The paper's dynamic triggering rule, eq. (14)--(15).

    ``eta' = -alpha(eta) + c*gamma(|e|)`` along flows, ``eta+ = b*eta`` at the node's
    transmission, and transmission when ``gamma(|e|) >= sigma*alpha(eta) + eps``.

    Parameters
    ----------
    gamma : KFunction
        ``gamma_i``, e.g. ``Quadratic(5.0)`` for ``5 s²``.
    alpha : KFunction
        ``alpha_i``, e.g. ``Linear(2.0)``.
    sigma : float
        ``sigma_i >= 0``; ``sigma = 0`` gives the static absolute-threshold rule.
    c : float
        ``c_i >= 0``.
    b : float
        ``b_i`` in ``[0, 1]``.
    eps : float
        ``eps_i > 0`` (prevents Zeno behaviour).
    eta0 : float
        ``eta_i(0) >= 0``.

    Examples
    --------
    The robot arm's first node:

    >>> from etobs.model import DynamicRule, Linear, Quadratic
    >>> rule = DynamicRule(gamma=Quadratic(5), alpha=Linear(2), sigma=600, c=0.001, b=1, eps=10, eta0=10)
    >>> rule.sigma * rule.c < 1  # the condition of Theorem 1
    True

    """

    gamma: KFunction
    alpha: KFunction = field(default_factory=lambda: Linear(1.0))
    sigma: float = 0.0
    c: float = 0.0
    b: float = 1.0
    eps: float = 1.0
    eta0: float = 0.0
    kind: ClassVar[fm.RuleKind] = fm.DYNAMIC


class StatelessRule(TriggerRule):
    """Base of rules of your own without internal state: nothing flows, nothing is reset."""

    @property
    def n_state(self) -> int:
        return 0

    def initial_state(self) -> np.ndarray:
        return np.empty(0)

    def derivative(
        self, t: np.ndarray, e: np.ndarray, s: np.ndarray, y: np.ndarray | None = None
    ) -> np.ndarray:
        return np.empty((t.shape[0], 0))

    def reset(self, t: np.ndarray, s: np.ndarray) -> np.ndarray:
        return s


@dataclass(frozen=True)
class StaticRule(KindRule):
    """Absolute-threshold rule ``gamma(|e|) >= eps`` (eq. (15) with ``sigma = 0``).

    It has no internal state; it transmits exactly when :class:`DynamicRule` with
    ``sigma = 0`` and the same ``gamma`` and ``eps`` does.

    Parameters
    ----------
    gamma : KFunction
        ``gamma_i``, e.g. ``Quadratic(5.0)``.
    eps : float
        The threshold ``eps_i > 0``.

    Examples
    --------
    ``5 |e|^2 >= 10``, i.e. ``|e| >= 1.414``:

    >>> from etobs import Quadratic, StaticRule
    >>> rule = StaticRule(gamma=Quadratic(5.0), eps=10.0)
    >>> (rule.trigger(np.zeros(2), np.array([[1.0], [1.5]]), np.empty((2, 0))) >= 0).tolist()
    [False, True]

    """

    gamma: KFunction
    eps: float
    kind: ClassVar[fm.RuleKind] = fm.STATIC


def send_on_delta(delta: float) -> StaticRule:
    """Send-on-delta: transmit when ``|e| = |ybar - ytilde| >= delta``.

    It is the static rule with ``gamma(s) = s`` and ``eps = delta``.

    >>> send_on_delta(0.1).trigger(np.zeros(1), np.array([[0.25]]), np.empty((1, 0))).round(12).tolist()
    [0.15]

    """
    return StaticRule(gamma=Linear(1.0), eps=v.real("delta", delta, lower=0.0, lower_open=True))


@dataclass(frozen=True)
class PeriodicRule(KindRule):
    """Time-triggered baseline: transmit at ``first, first + period, first + 2*period, ...``.

    The internal state is a clock ``tau`` with ``tau' = 1``, reset to ``0`` at each
    transmission; the trigger function is ``tau - period``.

    Parameters
    ----------
    period : float
        Sampling period, ``> 0``.
    first : float, optional
        Time of the first transmission, ``>= 0`` (default: ``period``).

    Examples
    --------
    >>> from etobs import PeriodicRule
    >>> rule = PeriodicRule(period=0.25)
    >>> rule.first, rule.initial_state().tolist()  # the clock starts at period - first
    (0.25, [0.0])

    """

    period: float
    first: float | None = None
    kind: ClassVar[fm.RuleKind] = fm.PERIODIC

    def __post_init__(self) -> None:
        if self.first is None:
            object.__setattr__(self, "first", self.period)
        super().__post_init__()


@dataclass(frozen=True)
class RelativeRule(KindRule):
    """Relative-threshold baseline: transmit when ``|e| >= rho |ytilde| + eps``.

    The threshold scales with the size of the measurement, a common rule in the
    event-triggered literature (not in the paper). ``eps > 0`` keeps a floor so that the
    rule does not fire continuously near ``y = 0``. It has no internal state and reads
    the current measurement ``y`` (required).

    Parameters
    ----------
    rho : float
        Relative threshold, ``> 0`` (e.g. ``0.05`` for 5 %).
    eps : float
        Absolute floor, ``> 0``.

    Examples
    --------
    >>> RelativeRule(rho=0.1, eps=0.01).trigger(np.zeros(1), np.array([[0.5]]), np.empty((1, 0)),
    ...                                          y=np.array([[3.0]])).round(12).tolist()
    [0.19]

    """

    rho: float
    eps: float
    kind: ClassVar[fm.RuleKind] = fm.RELATIVE
