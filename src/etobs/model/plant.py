"""The plant ``x' = f_p(t, x, u, v)``, ``y = h(x)`` (eq. (2)), written for one run."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.compile.functions import with_params
from etobs.errors import InputTypeError

PlantFn = Callable[..., np.ndarray]
OutputFn = Callable[..., np.ndarray]


@dataclass(frozen=True)
class Plant:
    """A nonlinear plant, written for one run (as for ``scipy.integrate.solve_ivp``).

    Parameters
    ----------
    f_p : callable
        ``f_p(t, x, u, v) -> x'``: ``t`` a float, ``x`` of shape ``(n_x,)``, ``u`` of
        shape ``(n_u,)``, ``v`` of shape ``(n_v,)``; returns shape ``(n_x,)``. Write it
        with numpy or ``math``: etobs compiles it (and every function it calls).
    h : callable
        ``h(x) -> y`` of shape ``(n_y,)``; continuously differentiable.
    n_x, n_y : int
        State and output dimensions (``>= 1``).
    n_u, n_v : int
        Known input and unknown disturbance dimensions (``>= 0``).
    name : str
    params : array_like, optional
        A parameter vector, as python-control's ``params``: when given, ``f_p`` and
        ``h`` take it as their last argument (``f_p(t, x, u, v, p)``, ``h(x, p)``).
        Numbers kept here, not in the functions' code, change without a recompile.

    Examples
    --------
    >>> import numpy as np
    >>> vdp = Plant(lambda t, x, u, v, p: np.array([x[1], p[0] * (1 - x[0] ** 2) * x[1] - x[0]]),
    ...             lambda x, p: x[:1], n_x=2, n_y=1, params=[1.0])
    >>> vdp.call_f_p(0.0, np.array([2.0, 0.0]), np.zeros(0), np.zeros(0)).tolist()
    [0.0, -2.0]

    """

    f_p: PlantFn
    h: OutputFn
    n_x: int
    n_y: int
    n_u: int = 0
    n_v: int = 0
    name: str = "plant"
    params: Any = None

    def __post_init__(self) -> None:
        for name in ("f_p", "h"):
            fn = getattr(self, name)
            if type(fn).__module__.partition(".")[0] == "control":  # a system is callable too
                raise InputTypeError(
                    f"`{name}` is a python-control {type(fn).__name__}, not a function: build the plant "
                    "with etobs.python_control_plant(sys, disturbances=...), or from matrices with "
                    "etobs.linear_plant(A, B, C)"
                )
            v.function(name, fn)
        v.integer("n_x", self.n_x, lower=1)
        v.integer("n_y", self.n_y, lower=1)
        v.integer("n_u", self.n_u, lower=0)
        v.integer("n_v", self.n_v, lower=0)
        object.__setattr__(self, "params", v.params("params", self.params))

    def call_f_p(self, t: float, x: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``f_p`` of one run, with ``params`` when there are any."""
        return with_params(self.f_p, self.params, t, x, u, v)  # type: ignore[no-any-return]

    def call_h(self, x: np.ndarray) -> np.ndarray:
        """``h`` of one run, with ``params`` when there are any."""
        return with_params(self.h, self.params, x)  # type: ignore[no-any-return]
