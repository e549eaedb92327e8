"""The plant ``x' = f_p(t, x, u, v)``, ``y = h(x)`` (eq. (2))."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from etobs import _validate as v

PlantFn = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]
OutputFn = Callable[[np.ndarray], np.ndarray]


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

    """

    f_p: PlantFn
    h: OutputFn
    n_x: int
    n_y: int
    n_u: int = 0
    n_v: int = 0
    name: str = "plant"

    def __post_init__(self) -> None:
        v.function("f_p", self.f_p)
        v.function("h", self.h)
        v.integer("n_x", self.n_x, lower=1)
        v.integer("n_y", self.n_y, lower=1)
        v.integer("n_u", self.n_u, lower=0)
        v.integer("n_v", self.n_v, lower=0)
