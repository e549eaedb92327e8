"""Time signals: the known input ``u(t)``, disturbance ``v(t)`` and noise ``m(t)``.

A signal maps a time vector ``t`` of shape ``(B,)`` to values of shape ``(B, dim)``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from etobs import _validate as v
from etobs.errors import ModelError


class Signal(ABC):
    """A vector signal of dimension :attr:`dim`."""

    dim: int

    @abstractmethod
    def __call__(self, t: np.ndarray) -> np.ndarray:
        """Values at times ``t`` (B,), shape ``(B, dim)``."""


@dataclass(frozen=True)
class Zero(Signal):
    """The zero signal of dimension ``dim``."""

    dim: int

    def __post_init__(self) -> None:
        v.integer("dim", self.dim, lower=0)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        return np.zeros((t.shape[0], self.dim))


@dataclass(frozen=True)
class Constant(Signal):
    """A constant vector."""

    value: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "value", v.vector("value", self.value))

    @property
    def dim(self) -> int:  # type: ignore[override]
        return self.value.shape[0]

    def __call__(self, t: np.ndarray) -> np.ndarray:
        return np.broadcast_to(self.value, (t.shape[0], self.dim))


@dataclass(frozen=True)
class Sinusoid(Signal):
    """``amplitude * sin(omega * t + phase) + offset``, with a vector amplitude.

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
        return self.amplitude.shape[0]

    @property
    def bound(self) -> float:
        """A bound on ``|value(t)|`` (Euclidean norm) for all ``t``."""
        return float(np.linalg.norm(np.abs(self.amplitude) + np.abs(self.offset)))

    def __call__(self, t: np.ndarray) -> np.ndarray:
        return np.sin(self.omega * t + self.phase)[:, None] * self.amplitude + self.offset


@dataclass(frozen=True)
class FunctionSignal(Signal):
    """A user signal ``fn(t) -> (B, dim)``, checked on first construction."""

    fn: Callable[[np.ndarray], np.ndarray]
    dim: int

    def __post_init__(self) -> None:
        v.function("fn", self.fn)
        v.integer("dim", self.dim, lower=0)
        out = np.asarray(self.fn(np.zeros(2)), dtype=float)
        if out.shape != (2, self.dim):
            raise ModelError(
                f"signal function returned shape {out.shape} for t of shape (2,); expected (2, {self.dim})"
            )

    def __call__(self, t: np.ndarray) -> np.ndarray:
        return np.asarray(self.fn(t), dtype=float)


def as_signal(name: str, value: object, dim: int) -> Signal:
    """Accept ``None`` (zero), a :class:`Signal`, a constant vector or a callable."""
    if value is None:
        return Zero(dim)
    if isinstance(value, Signal):
        sig = value
    elif callable(value):
        sig = FunctionSignal(value, dim)  # type: ignore[arg-type]
    else:
        sig = Constant(v.vector(name, value))
    if sig.dim != dim:
        from etobs.errors import InputError

        raise InputError(f"`{name}` has dimension {sig.dim}; expected {dim}")
    return sig
