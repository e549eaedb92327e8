"""The kinds of triggering rule and K-function: each declared once, with its arithmetic.

A **kind** is one descriptor: its numbers (names and limits), the K-function slots it
uses, and its formulas written as plain scalar Python (standard library only). Every
other form is derived from the descriptor, never written again:

* the engine's generated model (:mod:`etobs.estimation._model_source`) calls the
  formulas by name (numba compiles and inlines them) with arguments it reads from the
  descriptor;
* the rule and K-function objects (:mod:`etobs.model.rules`, :mod:`etobs.model.functions`)
  validate their fields against the declared numbers and evaluate the same formulas on
  numpy arrays (plain arithmetic works elementwise), for the reference solver and for
  evaluating results;
* the stdlib-only sensor node (:mod:`etobs.runtime.sampled_rule`) parses a rule spec by
  the kind's name and numbers and calls the formulas as is;
* the comparison spec's rule kinds (:mod:`etobs.experiments.compare_spec`) and the
  docs' table of kinds (``docs/extensions.md``, checked by a test) are the registries
  :data:`RULE_KINDS` and :data:`K_KINDS`.

An unknown kind is an error on every path (:func:`rule_kind`, :func:`k_kind`), never a
fallback value. Adding a kind is one descriptor here and one frozen class in
:mod:`etobs.model` that names it; ``tests/model/test_kinds.py`` walks the registries
and fails for a kind without its forms.

A rule's formulas read named arguments (:class:`Formula`): ``"e"`` is ``|e_i|``, ``"y"``
``|ytilde_i|`` (the current measurement), ``"s"`` the rule's scalar state, ``"gamma(e)"``
the K-function of slot ``gamma`` at ``|e_i|`` (``"alpha(s)"`` at the state), and any
other name one of the kind's numbers.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any, Protocol, TypeAlias, TypedDict, TypeVar

from etobs.errors import InputError

if TYPE_CHECKING:  # for the annotations only: the sensor node runs without numpy
    import numpy as np
    from numpy.typing import NDArray

#: What the formulas compute on, elementwise: floats (the sensor node, the engine's
#: compiled model) or float arrays (the rule objects, on a batch of runs).
R = TypeVar("R", float, "NDArray[np.float64]")
#: One of them, where a function takes either (:func:`apply`).
Value: TypeAlias = "float | NDArray[np.float64]"


class Limits(TypedDict):
    """A number's limits, as the keyword arguments of :func:`etobs._validate.real`."""

    lower: float | None
    upper: float | None
    lower_open: bool
    upper_open: bool


@dataclass(frozen=True)
class Number:
    """A number a kind takes, with its limits (``lower <= value <= upper``, open where said)."""

    name: str
    lower: float | None = None
    upper: float | None = None
    lower_open: bool = False
    upper_open: bool = False

    def limits(self) -> Limits:
        """The limits as keyword arguments of :func:`etobs._validate.real`."""
        return {
            "lower": self.lower,
            "upper": self.upper,
            "lower_open": self.lower_open,
            "upper_open": self.upper_open,
        }

    def refusal(self, value: float) -> str:
        """Why ``value`` is out of the limits (``""`` when it is in them)."""
        lo, hi = self.lower, self.upper
        if lo is not None and (value < lo or (self.lower_open and value == lo)):
            return f"must be {'>' if self.lower_open else '>='} {lo:g}"
        if hi is not None and (value > hi or (self.upper_open and value == hi)):
            return f"must be {'<' if self.upper_open else '<='} {hi:g}"
        return ""


def _positive(name: str) -> Number:
    """A number that must be > 0."""
    return Number(name, lower=0.0, lower_open=True)


# ---- K-functions ---------------------------------------------------------------------


def linear(k1: float, k2: float, s: R) -> R:
    """``k1 s``."""
    return k1 * s


def linear_inverse(k1: float, k2: float, r: R) -> R:
    """``r / k1``."""
    return r / k1


def quadratic(k1: float, k2: float, s: R) -> R:
    """``k1 s^2`` (the paper's ``𝔩_i s^2``)."""
    return k1 * (s * s)


def quadratic_inverse(k1: float, k2: float, r: R) -> R:
    """``sqrt(r / k1)``."""
    out: R = (r / k1) ** 0.5  # a float (typeshed: Any, for a complex power of a negative float)
    return out


def power(k1: float, k2: float, s: R) -> R:
    """``k1 s^k2``."""
    out: R = k1 * s**k2  # s >= 0: a float (typeshed: Any, for a complex power of a negative float)
    return out


def power_inverse(k1: float, k2: float, r: R) -> R:
    """``(r / k1)^(1 / k2)``."""
    out: R = (r / k1) ** (1.0 / k2)  # r >= 0: as in quadratic_inverse
    return out


def constant(k1: float, k2: float, s: R) -> R:
    """The constant ``k1`` (same shape as ``s``): a weight ``d'`` given as a number."""
    return k1 + 0.0 * s


class KFormula(Protocol):
    """A K-function formula or its inverse: ``(k1, k2, s) -> r``, on a float or elementwise."""

    def __call__(self, k1: float, k2: float, s: R, /) -> R: ...


@dataclass(frozen=True)
class KKind:
    """A kind of K-function: ``value(k1, k2, s)`` with its one or two numbers ``k1, k2``.

    Attributes
    ----------
    name : str
        How specs name it (``["linear", 2.0]`` in a sensor spec).
    numbers : tuple of Number
        Its numbers, in the order of ``k1, k2``.
    value, inverse : callable
        The function and its inverse, ``(k1, k2, s) -> r``, on floats or arrays.
    text : str
        How it prints, formatted with its numbers by name (``"{a:g}*s"``).

    """

    name: str
    numbers: tuple[Number, ...]
    value: KFormula
    inverse: KFormula | None
    text: str


LINEAR = KKind("linear", (_positive("a"),), linear, linear_inverse, "{a:g}*s")
QUADRATIC = KKind("quadratic", (_positive("ell"),), quadratic, quadratic_inverse, "{ell:g}*s^2")
POWER = KKind("power", (_positive("k"), _positive("p")), power, power_inverse, "{k:g}*s^{p:g}")
#: Not a class-K function: the constant weight ``d'`` of the generalized rule given as a number.
CONSTANT = KKind("constant", (_positive("value"),), constant, None, "{value:g}")

#: The K-function kinds by name: what a spec may write and the engine compiles.
K_KINDS: dict[str, KKind] = {k.name: k for k in (LINEAR, QUADRATIC, POWER, CONSTANT)}


_K = TypeVar("_K")


def _lookup(registry: dict[str, _K], name: object, what: str) -> _K:
    """The kind called ``name`` in ``registry``; any other name raises, naming ``what`` and the kinds."""
    kind = registry.get(name) if isinstance(name, str) else None
    if kind is None:
        raise InputError(f"unknown {what} kind {name!r}; the kinds are {', '.join(registry)}")
    return kind


def k_kind(name: object) -> KKind:
    """The K-function kind called ``name`` (an unknown name raises: there is no fallback)."""
    return _lookup(K_KINDS, name, "K-function")


# ---- rules ---------------------------------------------------------------------------


def dynamic_flow(gamma_e: R, alpha_eta: R, c: float) -> R:
    """``eta' = -alpha(eta) + c gamma(|e|)`` (eq. (14))."""
    return -alpha_eta + c * gamma_e


def dynamic_trigger(gamma_e: R, alpha_eta: R, sigma: float, eps: float) -> R:
    """``gamma(|e|) - sigma alpha(eta) - eps``: the node sends when it is ``>= 0`` (eq. (15))."""
    return gamma_e - sigma * alpha_eta - eps


def eta_reset(eta: R, b: float) -> R:
    """``eta+ = b eta`` at the node's own transmission (eq. (14))."""
    return b * eta


def static_trigger(gamma_e: R, eps: float) -> R:
    """``gamma(|e|) - eps`` (eq. (15) with ``sigma = 0``)."""
    return gamma_e - eps


def relative_trigger(e: R, y: R, rho: float, eps: float) -> R:
    """``|e| - rho |y| - eps``: the relative-threshold rule."""
    return e - rho * y - eps


def clock_flow() -> float:
    """``tau' = 1``: a clock."""
    return 1.0


def clock_reset() -> float:
    """``tau+ = 0`` at the node's own transmission."""
    return 0.0


def periodic_trigger(tau: R, period: float) -> R:
    """``tau - period``: the clock ``tau`` (``tau' = 1``, reset to 0) reaches the period."""
    return tau - period


def generalized_flow(gamma_check_e: R, alpha_check_eta: R) -> R:
    """``eta' = -alpha_check(eta) + gamma_check(|e|)`` (eq. (44))."""
    return -alpha_check_eta + gamma_check_e


def generalized_trigger(
    gamma_e: R, weight: R, gamma_check_e: R, alpha_check_eta: R, sigma: float, eps: float
) -> R:
    """``gamma(|e|) + d'(eta) gamma_check(|e|) - sigma d'(eta) alpha_check(eta) - eps`` (eq. (45)).

    The paper prints (45) with ``<=``; the node sends when this is ``>= 0``, the reading
    under which a node at ``e = 0`` does not send.
    """
    return gamma_e + weight * gamma_check_e - sigma * weight * alpha_check_eta - eps


def split_arg(arg: str) -> tuple[str, str] | None:
    """``"gamma(e)"`` -> ``("gamma", "e")``; ``None`` for an argument that is not a K-function's."""
    if not arg.endswith(")") or "(" not in arg:
        return None
    slot, _, at = arg[:-1].partition("(")
    return slot, at


_GIVEN = ("e", "y", "s")


@dataclass(frozen=True)
class Formula:
    """A formula of a rule and the names of its arguments, in order (module docstring).

    ``plan`` is the arguments read once: ``(0, i, -1)`` the ``i``-th of ``e, y, s``,
    ``(1, name, -1)`` a number, ``(2, slot, i)`` the K-function of ``slot`` at the
    ``i``-th of ``e, y, s``; ``reads`` the names of ``e, y, s`` it reads.
    """

    fn: Callable[..., float | NDArray[np.float64]]
    args: tuple[str, ...]
    plan: tuple[tuple[int, str | int, int], ...] = field(init=False, repr=False, compare=False)
    reads: frozenset[str] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        plan: list[tuple[int, str | int, int]] = []
        for arg in self.args:
            split = split_arg(arg)
            if arg in _GIVEN:
                plan.append((0, _GIVEN.index(arg), -1))
            elif split is None:
                plan.append((1, arg, -1))
            elif split[1] in _GIVEN:
                plan.append((2, split[0], _GIVEN.index(split[1])))
            else:
                raise InputError(
                    f"the argument {arg!r} of {self.fn.__name__}: K-functions are read at e, y or s"
                )
        object.__setattr__(self, "plan", tuple(plan))
        read = {_GIVEN[a] for w, a, _ in plan if w == 0 and isinstance(a, int)}
        object.__setattr__(self, "reads", frozenset(read | {_GIVEN[i] for w, _, i in plan if w == 2}))


@dataclass(frozen=True)
class Slot:
    """A K-function slot of a rule; ``constant`` when a positive number may stand for it."""

    name: str
    constant: bool = False


@dataclass(frozen=True)
class RuleKind:
    """A kind of triggering rule: its numbers, K-function slots, state and formulas.

    Attributes
    ----------
    name : str
        How specs name it (``kind = "dynamic"``).
    numbers : tuple of Number
        The numbers its formulas read, in the order the engine stores them.
    slots : tuple of Slot
        Its K-function slots (``gamma``, ``alpha`` ...).
    state : {"none", "eta", "clock"}
        Its scalar state: none, a filter ``eta`` (initial value ``eta0``, ``>= 0``) or a
        clock (initial value ``period - first``).
    trigger : Formula
        The trigger function: the node sends when it is ``>= 0``.
    flow, reset : Formula or None
        The state's derivative along flows and its value after the node's own
        transmission (``None`` without a state).
    decay : str or None
        For an ``eta`` state whose flow is ``-K(eta) + F(|e|)``, the slot of ``K``: a sensor
        node solves the flow exactly over a sampling period when that K-function is linear.
    period : str or None
        For a clock, the number that is its period (a sensor node counts samples).

    """

    name: str
    numbers: tuple[Number, ...]
    slots: tuple[Slot, ...]
    state: str
    trigger: Formula
    flow: Formula | None = None
    reset: Formula | None = None
    decay: str | None = None
    period: str | None = None

    @property
    def initial(self) -> str | None:
        """The name of the number that sets the initial state (``eta0``, ``first``), if any."""
        return {"eta": "eta0", "clock": "first"}.get(self.state)

    @cached_property
    def reads_y(self) -> bool:
        """Whether a formula reads the current measurement ``|ytilde_i|``."""
        return any("y" in f.args for f in self.formulas())

    def formulas(self) -> tuple[Formula, ...]:
        """The kind's formulas: trigger, then flow and reset when it has a state."""
        return tuple(f for f in (self.trigger, self.flow, self.reset) if f is not None)

    def number_names(self) -> tuple[str, ...]:
        """The names of its numbers."""
        return tuple(n.name for n in self.numbers)

    @cached_property
    def constants(self) -> frozenset[str]:
        """The slots a number may stand for (:attr:`Slot.constant`)."""
        return frozenset(slot.name for slot in self.slots if slot.constant)


_SIGMA = Number("sigma", lower=0.0)
_C = Number("c", lower=0.0)
_B = Number("b", lower=0.0, upper=1.0)
_EPS = _positive("eps")

DYNAMIC = RuleKind(  # eq. (14)-(15)
    "dynamic",
    (_SIGMA, _C, _B, _EPS),
    (Slot("gamma"), Slot("alpha")),
    "eta",
    trigger=Formula(dynamic_trigger, ("gamma(e)", "alpha(s)", "sigma", "eps")),
    flow=Formula(dynamic_flow, ("gamma(e)", "alpha(s)", "c")),
    reset=Formula(eta_reset, ("s", "b")),
    decay="alpha",
)
STATIC = RuleKind("static", (_EPS,), (Slot("gamma"),), "none", Formula(static_trigger, ("gamma(e)", "eps")))
PERIODIC = RuleKind(
    "periodic",
    (_positive("period"),),
    (),
    "clock",
    trigger=Formula(periodic_trigger, ("s", "period")),
    flow=Formula(clock_flow, ()),
    reset=Formula(clock_reset, ()),
    period="period",
)
RELATIVE = RuleKind(
    "relative",
    (_positive("rho"), _EPS),
    (),
    "none",
    Formula(relative_trigger, ("e", "y", "rho", "eps")),
)
GENERALIZED = RuleKind(  # section 7.1, eq. (44)-(45)
    "generalized",
    (Number("sigma", lower=0.0, upper=1.0, lower_open=True, upper_open=True), _B, _EPS),
    (Slot("gamma"), Slot("gamma_check"), Slot("alpha_check"), Slot("d_prime", constant=True)),
    "eta",
    trigger=Formula(
        generalized_trigger, ("gamma(e)", "d_prime(s)", "gamma_check(e)", "alpha_check(s)", "sigma", "eps")
    ),
    flow=Formula(generalized_flow, ("gamma_check(e)", "alpha_check(s)")),
    reset=Formula(eta_reset, ("s", "b")),
    decay="alpha_check",
)

#: The rule kinds by name: what a spec may write and the engine compiles.
RULE_KINDS: dict[str, RuleKind] = {k.name: k for k in (DYNAMIC, STATIC, PERIODIC, RELATIVE, GENERALIZED)}


def rule_kind(name: object) -> RuleKind:
    """The rule kind called ``name`` (an unknown name raises: there is no fallback)."""
    return _lookup(RULE_KINDS, name, "rule")


def evaluator(
    formula: Formula, constants: frozenset[str] = frozenset()
) -> Callable[[Any, Value | None, Value | None, Value | None], Value]:
    """``formula`` as a function ``(rule, e, y, s)``: a rule object, ``|e_i|``, ``|ytilde_i|``, the state.

    The one reading of a formula's arguments (module docstring), for the batched rules
    (numpy arrays) and the sensor node (floats): ``rule.<number>`` is a number and
    ``rule.<slot>`` the K-function of a slot, a callable, or for the slots named in
    ``constants`` possibly a number standing for a constant (:func:`k_at`). Written as
    Python text from the plan and compiled once per formula, as the engine's model is
    (:mod:`etobs.estimation._model_source`), so that it costs what the formula written by
    hand does.
    """
    key = (id(formula), constants)
    done = _EVALUATORS.get(key)
    if done is not None:
        return done
    parts = []
    for what, a, at in formula.plan:
        if what == 0:
            parts.append(_GIVEN[int(a)])
        elif what == 1:
            parts.append(f"rule.{a}")
        elif a in constants:
            parts.append(f"K(rule.{a}, {_GIVEN[at]})")
        else:
            parts.append(f"rule.{a}({_GIVEN[at]})")
    text = f"def {formula.fn.__name__}(rule, e, y, s):\n    return F({', '.join(parts)})\n"
    namespace: dict[str, Any] = {"F": formula.fn, "K": k_at}
    exec(compile(text, f"<etobs formula {formula.fn.__name__}>", "exec"), namespace)
    _EVALUATORS[key] = namespace[formula.fn.__name__]
    return _EVALUATORS[key]


def k_at(fn: Any, at: R) -> R:
    """The K-function ``fn`` at ``at``; a number ``fn`` stands for the constant (:data:`CONSTANT`)."""
    if isinstance(fn, float):
        return constant(fn, 0.0, at)
    out: R = fn(at)
    return out


#: The evaluators by (formula, constant slots); the formulas are the registries' own, never freed.
_EVALUATORS: dict[
    tuple[int, frozenset[str]], Callable[[Any, Value | None, Value | None, Value | None], Value]
] = {}


# ---- integration over a sampling period ----------------------------------------------


def norm(values: Any) -> float:
    """``|v|``: the square root of the sum of squares, added in order from ``0.0``.

    A sampled node's norm (the sensor node's, the simulator's and the generated C's: the
    engine's model sums the same way). Not ``sum``, which compensates its rounding
    from Python 3.12 on.
    """
    acc = 0.0
    for x in values:
        acc += x * x
    return math.sqrt(acc)


def rk4_stepper(f: Callable[..., Any]) -> Callable[..., Any]:
    """The classical Runge--Kutta step of ``y' = f(t, y, *args)``: ``step(t, y, h, *args) = y(t + h)``.

    ``y`` is a float or an array; the one fixed-step integrator of etobs (the sensor's
    filter, :func:`eta_period`; the observer service, :func:`rk4_step`). A closure over
    ``f``, so that numba compiles it with ``f`` a constant.
    """

    def step(t: float, y: Any, h: float, *args: Any) -> Any:
        k1 = f(t, y, *args)
        k2 = f(t + h / 2, y + h / 2 * k1, *args)
        k3 = f(t + h / 2, y + h / 2 * k2, *args)
        k4 = f(t + h, y + h * k3, *args)
        return y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    return step


def rk4_step(f: Callable[[float, R], R], t: float, y: R, h: float) -> R:
    """One classical Runge--Kutta step of ``y' = f(t, y)`` from ``(t, y)``: ``y(t + h)``."""
    out: R = rk4_stepper(f)(t, y, h)
    return out


#: Runge--Kutta substeps per sampling period of a filter whose decay is not linear.
ETA_SUBSTEPS = 20


@functools.cache
def eta_period(decay: KKind) -> Callable[[float, float, float, float, float], float]:
    """``eta`` after one sampling period of ``eta' = drive - K(eta)``, ``K`` of kind ``decay``.

    The sampled rule's filter (eq. (14) with ``gamma(|e|)`` held over the period, so that
    ``drive = c gamma(|e_k|)`` is constant): ``(eta, drive, k1, k2, period) -> eta_{k+1}``
    with ``k1, k2`` the numbers of ``K``. The one implementation of the discretization,
    run as is by the sensor node (:mod:`etobs.runtime.sampled_rule`) and the reference,
    compiled into the engine's model:

    * ``K(s) = a s`` (:data:`LINEAR`): exact,
      ``exp(-a T) eta + drive (1 - exp(-a T)) / a``;
    * otherwise :data:`ETA_SUBSTEPS` classical Runge--Kutta substeps of
      ``drive - K(max(eta, 0))`` (local error ``O((T/20)^5)``), ``eta`` kept ``>= 0``.

    A function per kind (cached), with ``K`` a constant of it, so that numba compiles it
    without function arguments.
    """
    if decay is LINEAR:

        def eta_exact(eta: float, drive: float, k1: float, k2: float, period: float) -> float:
            d = math.exp(-k1 * period)
            return d * eta + drive * (1.0 - d) / k1

        return eta_exact
    K = decay.value

    def rate(t: float, s: float, drive: float, k1: float, k2: float) -> float:
        return drive - K(k1, k2, max(s, 0.0))

    step = rk4_stepper(rate)

    def eta_substeps(eta: float, drive: float, k1: float, k2: float, period: float) -> float:
        h = period / ETA_SUBSTEPS
        for k in range(ETA_SUBSTEPS):
            eta = step(k * h, eta, h, drive, k1, k2)
        return max(eta, 0.0)

    return eta_substeps


def sample_decision(
    kind: RuleKind,
    rule: Any,
    e: float,
    y: float | None,
    s: float,
    period: float,
    decay: tuple[KKind, float, float] | None,
) -> tuple[bool, float]:
    """Whether a node of ``kind`` sends at a sample, and its filter state at the next sample.

    The sampled rule (eq. (14)--(15) at a sampling period): send when the trigger is
    ``>= 0`` at ``(|e_k|, |y_k|, eta_k)``; on sending ``eta <- reset(eta)`` and ``|e| = 0``;
    then ``eta`` over the period with ``|e|`` held (:func:`eta_period`; ``decay`` is the
    kind's decay K-function and its numbers, ``None`` for a kind without a filter).
    ``rule`` is what :func:`evaluator` reads.
    The one implementation for the sensor node and the simulator's reference; the
    engine's model and the generated C code follow these steps on the same formulas
    (and are checked against it bit for bit).
    """
    fire = float(evaluator(kind.trigger, kind.constants)(rule, e, y, s)) >= 0.0
    if kind.state != "eta":
        return fire, s
    assert kind.flow is not None and kind.reset is not None and decay is not None  # an eta state has them
    if fire:
        s = float(evaluator(kind.reset, kind.constants)(rule, e, y, s))  # eq. (14), jump
        e = 0.0
    drive = float(evaluator(kind.flow, kind.constants)(rule, e, y, 0.0))  # -K(0) + F(|e|) = F(|e|)
    dk, k1, k2 = decay
    return fire, eta_period(dk)(s, drive, k1, k2, period)
