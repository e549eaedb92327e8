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

Each rule knows its forms: these batched methods (for the scipy reference and for
evaluating results), its engine form (:meth:`TriggerRule.engine_form`, compiled into the
engine's model) and its sensor spec (:meth:`TriggerRule.sensor_spec`, the plain data a
stdlib-only sensor node runs). All three compute with the one implementation of the
formulas in :mod:`etobs.formulas`, so what you simulate is what you deploy.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from etobs import _validate as v
from etobs import formulas as fm
from etobs.errors import InputError
from etobs.model.functions import KFunction, Linear, as_kfunction

#: Rule kind codes of the engine form (see :mod:`etobs.estimation._model_source`).
DYNAMIC, STATIC, PERIODIC, RELATIVE, GENERALIZED = 0, 1, 2, 3, 4


@dataclass(frozen=True)
class EngineForm:
    """A rule as the engine runs it: its kind, its numbers and its K-functions.

    ``numbers`` maps ``sigma, c, b, eps, rho, period`` to values (those the kind uses);
    ``kfunctions`` are the slots ``(gamma, alpha, gamma_check, d')``, ``None`` when unused,
    a :class:`~etobs.model.functions.KFunction` or a constant.
    """

    kind: int
    numbers: dict[str, float]
    kfunctions: tuple[Any, Any, Any, Any] = (None, None, None, None)


def _norm(e: np.ndarray) -> np.ndarray:
    """Euclidean norm of each row: ``|e_i|``."""
    if e.shape[1] == 1:
        return np.abs(e[:, 0])
    return np.sqrt(np.einsum("ij,ij->i", e, e))


class TriggerRule(ABC):
    """Interface of a node's triggering rule (see the module docstring).

    A rule that reads the current measurement sets ``reads_y = True``; only then is
    ``y=`` passed, so rules written as ``trigger(t, e, s)`` keep working.
    """

    reads_y: ClassVar[bool] = False

    @property
    @abstractmethod
    def n_state(self) -> int:
        """Size of the rule's internal state."""

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
        """The rule as the engine runs it, or ``None`` for a rule the engine does not know.

        Only a class that defines ``engine_form`` itself is run by the engine: a subclass
        of a built-in rule that changes its trigger but not its engine form would
        otherwise run as its parent (see :func:`engine_form_of`).
        """
        return None

    def sensor_spec(self) -> dict[str, Any]:
        """The rule as a sensor node's :class:`~etobs.runtime.sampled_rule.SampledRule` takes it.

        Raises
        ------
        InputError
            For a rule a sensor node does not run.

        """
        raise InputError(
            "a sensor node runs DynamicRule, StaticRule, RelativeRule or PeriodicRule; "
            f"got {type(self).__name__}"
        )


def engine_form_of(rule: TriggerRule) -> EngineForm | None:
    """``rule.engine_form()`` when the rule's own class defines it, else ``None``."""
    if "engine_form" not in type(rule).__dict__:
        return None
    return rule.engine_form()


class EtaRule(TriggerRule):
    """Base of the rules with a scalar filter state ``eta`` reset as ``eta+ = b*eta``.

    Subclasses are frozen dataclasses with fields ``b``, ``eps`` and ``eta0``.
    """

    b: float
    eps: float
    eta0: float

    def _check_eta_params(self) -> None:
        """Validate ``b`` in [0, 1], ``eps > 0`` and ``eta0 >= 0`` (frozen: set in place)."""
        object.__setattr__(self, "b", v.real("b", self.b, lower=0.0, upper=1.0))
        object.__setattr__(self, "eps", v.real("eps", self.eps, lower=0.0, lower_open=True))
        object.__setattr__(self, "eta0", v.real("eta0", self.eta0, lower=0.0))

    @property
    def n_state(self) -> int:
        return 1

    def initial_state(self) -> np.ndarray:
        return np.array([self.eta0])

    def reset(self, t: np.ndarray, s: np.ndarray) -> np.ndarray:
        return fm.eta_reset(s, self.b)  # eq. (14)


@dataclass(frozen=True)
class DynamicRule(EtaRule):
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

    def __post_init__(self) -> None:
        object.__setattr__(self, "gamma", as_kfunction("gamma", self.gamma))
        object.__setattr__(self, "alpha", as_kfunction("alpha", self.alpha))
        object.__setattr__(self, "sigma", v.real("sigma", self.sigma, lower=0.0))
        object.__setattr__(self, "c", v.real("c", self.c, lower=0.0))
        self._check_eta_params()

    def derivative(
        self, t: np.ndarray, e: np.ndarray, s: np.ndarray, y: np.ndarray | None = None
    ) -> np.ndarray:
        return fm.dynamic_flow(self.gamma(_norm(e)), self.alpha(s[:, 0]), self.c)[:, None]  # eq. (14)

    def trigger(self, t: np.ndarray, e: np.ndarray, s: np.ndarray, y: np.ndarray | None = None) -> np.ndarray:
        return fm.dynamic_trigger(self.gamma(_norm(e)), self.alpha(s[:, 0]), self.sigma, self.eps)  # (15)

    def engine_form(self) -> EngineForm:
        numbers = {"sigma": self.sigma, "c": self.c, "b": self.b, "eps": self.eps}
        return EngineForm(DYNAMIC, numbers, (self.gamma, self.alpha, None, None))

    def sensor_spec(self) -> dict[str, Any]:
        return {
            "kind": "dynamic",
            "gamma": self.gamma.sensor_spec("gamma"),
            "alpha": self.alpha.sensor_spec("alpha"),
            "sigma": self.sigma,
            "c": self.c,
            "b": self.b,
            "eps": self.eps,
            "eta0": self.eta0,
        }


class StatelessRule(TriggerRule):
    """Base of the rules without internal state: nothing flows, nothing is reset."""

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
class StaticRule(StatelessRule):
    """Absolute-threshold rule ``gamma(|e|) >= eps`` (eq. (15) with ``sigma = 0``).

    It has no internal state; it transmits exactly when :class:`DynamicRule` with
    ``sigma = 0`` and the same ``gamma`` and ``eps`` does.
    """

    gamma: KFunction
    eps: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "gamma", as_kfunction("gamma", self.gamma))
        object.__setattr__(self, "eps", v.real("eps", self.eps, lower=0.0, lower_open=True))

    def trigger(self, t: np.ndarray, e: np.ndarray, s: np.ndarray, y: np.ndarray | None = None) -> np.ndarray:
        return fm.static_trigger(self.gamma(_norm(e)), self.eps)

    def engine_form(self) -> EngineForm:
        return EngineForm(STATIC, {"eps": self.eps}, (self.gamma, None, None, None))

    def sensor_spec(self) -> dict[str, Any]:
        return {"kind": "static", "gamma": self.gamma.sensor_spec("gamma"), "eps": self.eps}


def send_on_delta(delta: float) -> StaticRule:
    """Send-on-delta: transmit when ``|e| = |ybar - ytilde| >= delta``.

    It is the static rule with ``gamma(s) = s`` and ``eps = delta``.

    >>> send_on_delta(0.1).trigger(np.zeros(1), np.array([[0.25]]), np.empty((1, 0))).round(12).tolist()
    [0.15]

    """
    return StaticRule(gamma=Linear(1.0), eps=v.real("delta", delta, lower=0.0, lower_open=True))


@dataclass(frozen=True)
class PeriodicRule(TriggerRule):
    """Time-triggered baseline: transmit at ``first, first + period, first + 2*period, ...``.

    The internal state is a clock ``tau`` with ``tau' = 1``, reset to ``0`` at each
    transmission; the trigger function is ``tau - period``.

    Parameters
    ----------
    period : float
        Sampling period, ``> 0``.
    first : float, optional
        Time of the first transmission, ``>= 0`` (default: ``period``).

    """

    period: float
    first: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "period", v.real("period", self.period, lower=0.0, lower_open=True))
        first = self.period if self.first is None else self.first
        object.__setattr__(self, "first", v.real("first", first, lower=0.0))

    @property
    def n_state(self) -> int:
        return 1

    def initial_state(self) -> np.ndarray:
        assert self.first is not None  # set in __post_init__
        return np.array([self.period - self.first])

    def derivative(
        self, t: np.ndarray, e: np.ndarray, s: np.ndarray, y: np.ndarray | None = None
    ) -> np.ndarray:
        return np.ones_like(s)

    def trigger(self, t: np.ndarray, e: np.ndarray, s: np.ndarray, y: np.ndarray | None = None) -> np.ndarray:
        return fm.periodic_trigger(s[:, 0], self.period)

    def reset(self, t: np.ndarray, s: np.ndarray) -> np.ndarray:
        return np.zeros_like(s)

    def engine_form(self) -> EngineForm:
        return EngineForm(PERIODIC, {"period": self.period})

    def sensor_spec(self) -> dict[str, Any]:
        return {"kind": "periodic", "period": self.period, "first": self.first}


@dataclass(frozen=True)
class RelativeRule(StatelessRule):
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

    >>> RelativeRule(rho=0.1, eps=0.01).trigger(np.zeros(1), np.array([[0.5]]), np.empty((1, 0)),
    ...                                          y=np.array([[3.0]])).round(12).tolist()
    [0.19]

    """

    rho: float
    eps: float
    reads_y: ClassVar[bool] = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "rho", v.real("rho", self.rho, lower=0.0, lower_open=True))
        object.__setattr__(self, "eps", v.real("eps", self.eps, lower=0.0, lower_open=True))

    def trigger(self, t: np.ndarray, e: np.ndarray, s: np.ndarray, y: np.ndarray | None = None) -> np.ndarray:
        if y is None:
            raise InputError("RelativeRule.trigger needs the current measurement `y`; got None")
        return fm.relative_trigger(_norm(e), _norm(y), self.rho, self.eps)

    def engine_form(self) -> EngineForm:
        return EngineForm(RELATIVE, {"rho": self.rho, "eps": self.eps})

    def sensor_spec(self) -> dict[str, Any]:
        return {"kind": "relative", "rho": self.rho, "eps": self.eps}
