"""Class-K∞ functions used as ``alpha_i`` and ``gamma_i`` in the triggering rules.

All act elementwise on arrays of non-negative reals. ``Linear(a)`` is ``a*s`` and
``Quadratic(ell)`` is ``ell*s**2`` (the paper's ``𝔩_i s^2``); :class:`Custom` wraps any
user function of one float after a sanity check that it is zero at zero and increasing.
Each knows its engine form (:meth:`KFunction.engine_form`): its kind and two numbers, or
the user's function to compile. The built-in ones are a kind of
:data:`etobs.formulas.K_KINDS` (:class:`Builtin`): their formulas are the ones the
engine and the sensor nodes also run.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, TypeVar

import numpy as np

from etobs import _validate as v
from etobs.errors import InputError
from etobs.formulas import CONSTANT, K_KINDS, LINEAR, POWER, QUADRATIC, KKind


class KFunction(ABC):
    """A class-K∞ function ``[0, ∞) → [0, ∞)``: continuous, zero at zero, increasing, unbounded.

    The interface of ``alpha_i`` and ``gamma_i``: :class:`Linear`, :class:`Quadratic`,
    :class:`Power` (etobs' kinds, which the engine and a sensor node run) and
    :class:`Custom` (a function of your own) implement it.

    Examples
    --------
    >>> from etobs import Custom, KFunction, Linear
    >>> isinstance(Linear(2.0), KFunction), Linear(2.0).engine_form()[1:]
    (True, (2.0, 0.0, None))
    >>> Custom(lambda s: s**3).engine_form()[0] is None  # no kind: the engine compiles the function
    True

    """

    @abstractmethod
    def __call__(self, s: np.ndarray) -> np.ndarray:
        """Evaluate elementwise."""

    @abstractmethod
    def inverse(self, r: np.ndarray) -> np.ndarray:
        """Evaluate the inverse function elementwise."""

    @abstractmethod
    def engine_form(self) -> tuple[KKind | None, float, float, Callable[[float], float] | None]:
        """``(kind, k1, k2, fn)``: its kind and numbers, or ``None`` and the user function to compile."""

    def sensor_spec(self, what: str) -> list[Any]:
        """The function as a sensor node's rule spec gives it (``["linear", a]`` ...).

        ``what`` names it in the error for a function a sensor node does not run.
        """
        kind, k1, k2, _ = self.engine_form()
        if kind is None:
            raise InputError(
                f"a sensor node runs the K-functions of etobs' kinds ({', '.join(K_KINDS)}); "
                f"`{what}` is {type(self).__name__}"
            )
        return [kind.name, k1, k2][: 1 + len(kind.numbers)]


@dataclass(frozen=True)
class Builtin(KFunction):
    """A K-function of a kind of :data:`etobs.formulas.K_KINDS`: its fields are the kind's numbers.

    A subclass is a frozen dataclass that sets ``kind`` and has one field per number of
    the kind, in order; validation, evaluation, inverse, printing and every other form
    come from the kind (:mod:`etobs.formulas`).
    """

    kind: ClassVar[KKind]

    def __post_init__(self) -> None:
        for n in self.kind.numbers:
            object.__setattr__(self, n.name, v.real(n.name, getattr(self, n.name), **n.limits()))
        vals = [float(getattr(self, n.name)) for n in self.kind.numbers]
        # ``k1, k2`` once (not a field: the reference evaluates the function at every step)
        object.__setattr__(self, "_k12", (vals[0], vals[1] if len(vals) > 1 else 0.0))

    def _numbers(self) -> tuple[float, float]:
        k12: tuple[float, float] = self.__dict__["_k12"]
        return k12

    def __call__(self, s: np.ndarray) -> np.ndarray:
        k1, k2 = self._numbers()
        return self.kind.value(k1, k2, np.asarray(s, dtype=float))

    def inverse(self, r: np.ndarray) -> np.ndarray:
        if self.kind.inverse is None:
            raise InputError(f"{type(self).__name__} has no inverse")
        k1, k2 = self._numbers()
        return self.kind.inverse(k1, k2, np.asarray(r, dtype=float))

    def engine_form(self) -> tuple[KKind, float, float, None]:
        return (self.kind, *self._numbers(), None)

    def __str__(self) -> str:
        return self.kind.text.format(**{n.name: getattr(self, n.name) for n in self.kind.numbers})


@dataclass(frozen=True)
class Linear(Builtin):
    """``a * s`` with ``a > 0``: the paper's ``alpha_i``.

    Parameters
    ----------
    a : float
        The slope, ``> 0``.

    Examples
    --------
    >>> from etobs import Linear
    >>> alpha = Linear(2.0)
    >>> alpha([0.0, 1.5]).tolist(), alpha.inverse(3.0).item(), str(alpha)
    ([0.0, 3.0], 1.5, '2*s')

    """

    a: float
    kind: ClassVar[KKind] = LINEAR


@dataclass(frozen=True)
class Quadratic(Builtin):
    """``ell * s**2`` with ``ell > 0`` (the paper's ``𝔩 s²``): ``gamma_i`` of section 8.

    Parameters
    ----------
    ell : float
        The coefficient, ``> 0``.

    Examples
    --------
    >>> from etobs import Quadratic
    >>> gamma = Quadratic(5.0)
    >>> gamma(2.0).item(), gamma.inverse(20.0).item(), str(gamma)
    (20.0, 2.0, '5*s^2')

    """

    ell: float
    kind: ClassVar[KKind] = QUADRATIC


@dataclass(frozen=True)
class Power(Builtin):
    """``k * s**p`` with ``k > 0`` and ``p > 0``.

    Parameters
    ----------
    k : float
        The coefficient, ``> 0``.
    p : float
        The exponent, ``> 0``.

    Examples
    --------
    >>> from etobs import Power
    >>> f = Power(3.0, 1.5)
    >>> f(4.0).item(), round(f.inverse(24.0).item(), 12), str(f)
    (24.0, 4.0, '3*s^1.5')

    """

    k: float
    p: float
    kind: ClassVar[KKind] = POWER


_C = TypeVar("_C", bound=type)


def declared(base: _C, registry: Mapping[str, object], what: str) -> dict[str, _C]:
    """The classes of etobs below ``base`` that declare a kind (``kind = ...``), by the kind's name.

    In the order of ``registry``; a kind declared twice, or a kind without a class, raises
    (a kind is declared with its class).
    """
    out: dict[str, _C] = {}
    todo = list(base.__subclasses__())
    while todo:
        cls = todo.pop()
        todo += cls.__subclasses__()
        if "kind" in cls.__dict__ and cls.__module__.startswith("etobs."):
            name = cls.__dict__["kind"].name
            if name in out:
                raise InputError(f"{what} kind {name!r} has two classes: {out[name]} and {cls}")
            out[name] = cls
    missing = set(registry) - set(out)
    if missing:
        raise InputError(f"{what} kinds without a class in etobs.model: {', '.join(sorted(missing))}")
    return {name: out[name] for name in registry}


def k_classes() -> dict[str, type[Builtin]]:
    """The K-function classes of etobs by kind name (the kinds of :data:`etobs.formulas.K_KINDS`).

    The constant weight (``CONSTANT``) has none: a number stands for it.
    """
    kinds = {name: k for name, k in K_KINDS.items() if k is not CONSTANT}
    return declared(Builtin, kinds, "K-function")


_PROBE = np.array([0.0, 1e-3, 0.1, 1.0, 10.0, 1e3])


@dataclass(frozen=True)
class Custom(KFunction):
    """A user class-K∞ function of one float.

    Parameters
    ----------
    fn : callable
        ``fn(s) -> r`` for a float ``s >= 0`` (numpy or ``math``; etobs compiles it).
    inv : callable, optional
        Its inverse, float to float; when absent, :meth:`inverse` solves ``fn(s) = r``
        numerically.
    name : str
        Shown in reports.

    Examples
    --------
    >>> import math
    >>> Custom(lambda s: s * math.sqrt(s))(np.array([4.0])).tolist()
    [8.0]

    """

    fn: Callable[[float], float]
    inv: Callable[[float], float] | None = None
    name: str = field(default="custom")

    def __post_init__(self) -> None:
        v.function("fn", self.fn)
        if self.inv is not None:
            v.function("inv", self.inv)
        try:
            vals = np.array([float(self.fn(float(s))) for s in _PROBE])
        except Exception as exc:  # the user's function: any error means the same to them
            raise InputError(
                f"`fn` must map a float s >= 0 to a float (written for one value, not an array); "
                f"at s in {_PROBE.tolist()} it raised {type(exc).__name__}: {exc}"
            ) from exc
        if not np.all(np.isfinite(vals)):
            raise InputError(f"`fn` must give finite values; at s={_PROBE.tolist()} it gives {vals.tolist()}")
        if vals[0] != 0.0 or np.any(np.diff(vals) <= 0):
            raise InputError(
                f"`fn` must be a class-K∞ function (zero at 0, increasing); at s={_PROBE.tolist()} "
                f"it gives {vals.tolist()}"
            )

    def __call__(self, s: np.ndarray) -> np.ndarray:
        arr = np.asarray(s, dtype=float)
        return np.array([float(self.fn(float(x))) for x in arr.reshape(-1)]).reshape(arr.shape)

    def engine_form(self) -> tuple[None, float, float, Callable[[float], float]]:
        return None, 0.0, 0.0, self.fn

    def inverse(self, r: np.ndarray) -> np.ndarray:
        if self.inv is not None:
            arr = np.asarray(r, dtype=float)
            return np.array([float(self.inv(float(x))) for x in arr.reshape(-1)]).reshape(arr.shape)
        from scipy.optimize import brentq

        def one(ri: float) -> float:
            if ri <= 0:
                return 0.0
            hi = 1.0
            while float(self.fn(hi)) < ri and hi < 1e300:
                hi *= 2.0
            root: float = brentq(lambda s: float(self.fn(s)) - ri, 0.0, hi, xtol=1e-14)
            return root

        out: np.ndarray = np.vectorize(one, otypes=[float])(np.asarray(r, dtype=float))
        return out

    def __str__(self) -> str:
        return self.name


def as_kfunction(name: str, value: object) -> KFunction:
    """Accept a :class:`KFunction` or a plain callable (wrapped in :class:`Custom`)."""
    if isinstance(value, KFunction):
        return value
    if callable(value):
        return Custom(value, name=name)
    raise InputError(f"`{name}` must be a KFunction (e.g. Linear(2.0), Quadratic(5.0)); got {value!r}")
