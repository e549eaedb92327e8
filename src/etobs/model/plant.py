"""The plant ``x' = f_p(t, x, u, v)``, ``y = h(x)`` (eq. (2))."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.errors import InputTypeError

PlantFn = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]
OutputFn = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class JitPlant:
    """The plant's functions for one run, compiled with numba (for ``backend="numba"``).

    Parameters
    ----------
    f_p : numba-compiled function
        ``f_p(t, x, u, v, theta, out)`` writes ``x'`` (shape ``(n_x,)``) into ``out``.
    h : numba-compiled function
        ``h(x, theta, out)`` writes ``y`` (shape ``(n_y,)``) into ``out``.
    theta : array_like, optional
        Parameters passed to both (so that changing them does not recompile).

    """

    f_p: Any
    h: Any
    theta: Any = ()

    def __post_init__(self) -> None:
        v.function("f_p", self.f_p)
        v.function("h", self.h)
        object.__setattr__(self, "theta", np.array(self.theta, dtype=float).reshape(-1))


@dataclass(frozen=True)
class Plant:
    """A nonlinear plant, vectorized over runs.

    Parameters
    ----------
    f_p : callable
        ``f_p(t, x, u, v) -> x'`` with ``t`` of shape ``(B,)``, ``x`` ``(B, n_x)``,
        ``u`` ``(B, n_u)``, ``v`` ``(B, n_v)``; returns ``(B, n_x)``.
    h : callable
        ``h(x) -> y`` of shape ``(B, n_y)``; continuously differentiable.
    n_x, n_y : int
        State and output dimensions (``>= 1``).
    n_u, n_v : int
        Known input and unknown disturbance dimensions (``>= 0``).
    name : str
    jit : JitPlant, optional
        numba-compiled single-run versions of ``f_p`` and ``h`` for the compiled
        backend (``simulate(..., backend="numba")``).

    """

    f_p: PlantFn
    h: OutputFn
    n_x: int
    n_y: int
    n_u: int = 0
    n_v: int = 0
    name: str = "plant"
    jit: JitPlant | None = None

    def __post_init__(self) -> None:
        v.function("f_p", self.f_p)
        v.function("h", self.h)
        v.integer("n_x", self.n_x, lower=1)
        v.integer("n_y", self.n_y, lower=1)
        v.integer("n_u", self.n_u, lower=0)
        v.integer("n_v", self.n_v, lower=0)
        if self.jit is not None and not isinstance(self.jit, JitPlant):
            raise InputTypeError(f"`jit` must be a JitPlant; got {type(self.jit).__name__}")
