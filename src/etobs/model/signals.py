"""Time signals: the known input ``u(t)``, disturbance ``v(t)`` and noise ``m(t)``.

A signal maps a time vector ``t`` of shape ``(B,)`` to values of shape ``(B, dim)``;
users give their own as a one-run function ``fn(t) -> (dim,)`` (:class:`FunctionSignal`).
Each signal knows its engine form (:meth:`Signal.engine_form`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from etobs import _validate as v
from etobs.errors import ModelError

#: Kind codes of the engine form (see :mod:`etobs.estimation._model_source`).
ZERO, CONSTANT, SINUSOID, FUNCTION = 0, 1, 2, 3


class Signal(ABC):
    """A vector signal of dimension ``dim``."""

    dim: int

    @abstractmethod
    def __call__(self, t: np.ndarray) -> np.ndarray:
        """Values at times ``t`` (B,), shape ``(B, dim)``."""

    @abstractmethod
    def engine_form(self) -> tuple[int, np.ndarray, Callable[[float], np.ndarray] | None]:
        """``(kind, numbers, fn)``: the kind code, its numbers, the function to compile or None."""


@dataclass(frozen=True)
class Zero(Signal):
    """The zero signal of dimension ``dim``: no input, no disturbance or no noise.

    Parameters
    ----------
    dim : int
        Its dimension, ``>= 0``.

    Examples
    --------
    >>> from etobs import Zero
    >>> Zero(2)(np.array([0.0, 1.0])).tolist()
    [[0.0, 0.0], [0.0, 0.0]]

    """

    dim: int

    def __post_init__(self) -> None:
        v.integer("dim", self.dim, lower=0)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        return np.zeros((t.shape[0], self.dim))

    def engine_form(self) -> tuple[int, np.ndarray, None]:
        return ZERO, np.zeros(0), None


@dataclass(frozen=True)
class Constant(Signal):
    """A constant vector: ``value`` at every time.

    Parameters
    ----------
    value : array_like, shape (dim,)
        The signal's value.

    Examples
    --------
    A constant wind ``v = 0.5``:

    >>> from etobs import Constant
    >>> Constant([0.5])(np.array([0.0, 7.0])).tolist(), Constant([0.5]).dim
    ([[0.5], [0.5]], 1)

    """

    value: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "value", v.vector("value", self.value))

    @property
    def dim(self) -> int:  # type: ignore[override]
        return int(self.value.shape[0])

    def __call__(self, t: np.ndarray) -> np.ndarray:
        return np.broadcast_to(self.value, (t.shape[0], self.dim))

    def engine_form(self) -> tuple[int, np.ndarray, None]:
        return CONSTANT, np.array(self.value), None


@dataclass(frozen=True)
class Sinusoid(Signal):
    """``amplitude * sin(omega * t + phase) + offset``, with a vector amplitude.

    Parameters
    ----------
    amplitude : array_like, shape (dim,)
        One amplitude per component.
    omega : float
        Angular frequency (rad/s).
    phase : float, optional
        Phase (rad), default ``0``.
    offset : float or array_like, optional
        Added to every component (one number) or per component; default ``0``.

    Examples
    --------
    The robot arm's measurement noise ``m(t) = 0.01 (0, 1) sin(0.3 t)``:

    >>> m = Sinusoid(amplitude=[0.0, 0.01], omega=0.3)
    >>> m(np.array([0.0])).tolist()
    [[0.0, 0.0]]

    """

    amplitude: np.ndarray
    omega: float
    phase: float = 0.0
    offset: np.ndarray | float = 0.0

    def __post_init__(self) -> None:
        amp = v.vector("amplitude", self.amplitude)
        object.__setattr__(self, "amplitude", amp)
        object.__setattr__(self, "omega", v.real("omega", self.omega))
        object.__setattr__(self, "phase", v.real("phase", self.phase))
        off = np.broadcast_to(np.asarray(self.offset, dtype=float), amp.shape).copy()
        object.__setattr__(self, "offset", v.vector("offset", off, amp.shape[0]))

    @property
    def dim(self) -> int:  # type: ignore[override]
        return int(self.amplitude.shape[0])

    @property
    def bound(self) -> float:
        """A bound on ``|value(t)|`` (Euclidean norm) for all ``t``."""
        return float(np.linalg.norm(np.abs(self.amplitude) + np.abs(self.offset)))

    def __call__(self, t: np.ndarray) -> np.ndarray:
        out: np.ndarray = np.sin(self.omega * t + self.phase)[:, None] * self.amplitude + self.offset
        return out

    def engine_form(self) -> tuple[int, np.ndarray, None]:
        return SINUSOID, np.concatenate([self.amplitude, self.offset, [self.omega, self.phase]]), None


@dataclass(frozen=True)
class FunctionSignal(Signal):
    """A user signal ``fn(t) -> (dim,)`` for one time ``t`` (a float), checked at construction.

    Write it with numpy or ``math``: etobs compiles it.

    Parameters
    ----------
    fn : callable
        ``fn(t)`` for a float ``t``, returning a 1-D array of ``dim`` values.
    dim : int
        The signal's dimension.

    Examples
    --------
    >>> s = FunctionSignal(lambda t: np.array([np.cos(t), 1.0]), dim=2)
    >>> s(np.array([0.0, np.pi])).round(12).tolist()
    [[1.0, 1.0], [-1.0, 1.0]]

    """

    fn: Callable[[float], np.ndarray]
    dim: int

    def __post_init__(self) -> None:
        v.function("fn", self.fn)
        v.integer("dim", self.dim, lower=0)
        out = np.asarray(self.fn(0.0), dtype=float)
        if out.shape != (self.dim,):
            raise ModelError(
                f"signal function `fn` returned shape {out.shape} for t = 0.0; expected ({self.dim},): "
                "write it for one time t (a float), returning a 1-D array"
            )

    def __call__(self, t: np.ndarray) -> np.ndarray:
        return np.array([np.asarray(self.fn(float(ti)), dtype=float) for ti in t]).reshape(
            t.shape[0], self.dim
        )

    def engine_form(self) -> tuple[int, np.ndarray, Callable[[float], np.ndarray]]:
        return FUNCTION, np.zeros(0), self.fn


def as_signal(name: str, value: object, dim: int, size: str = "") -> Signal:
    """Accept ``None`` (zero), a :class:`Signal`, a constant vector or a callable.

    ``size`` names the plant's dimension that ``dim`` is (``"n_v"``), for the message.
    """
    if value is None:
        return Zero(dim)
    if isinstance(value, Signal):
        sig = value
    elif callable(value):
        sig = FunctionSignal(value, dim)
    else:
        sig = Constant(v.vector(name, value))
    if sig.dim != dim:
        from etobs.errors import InputError

        hint = ""
        if size in ("n_u", "n_v"):
            hint = (
                f" (the plant's `{size}`): give the plant `{size}={sig.dim}` (Plant(..., {size}={sig.dim}))"
            )
            if dim:
                hint += f" or a `{name}` of dimension {dim}"
        elif size:
            hint = f" (the plant's `{size}`, one value per output)"
        raise InputError(f"`{name}` has dimension {sig.dim}; expected {dim}{hint}")
    return sig
