"""The plant ``x' = f_p(t, x, u, v)``, ``y = h(x)`` (eq. (2)), written for one run."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.compile.functions import with_params
from etobs.errors import InputError, InputTypeError
from etobs.model.quantities import Quantity, names, quantities

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
    state_names, output_names, input_names : sequence of str, optional
        Names of the entries of ``x`` (``n_x`` names), ``y`` (``n_y``) and ``u``
        (``n_u``): tables, the xarray Dataset and the plots use them. Default: the
        paper's symbols (``x_1``, ``y_1``, ``u_1``).
    state_units, output_units, input_units : sequence of str, optional
        Their units (``"rad"``, ``"m/s"``), shown with them (``"motor angle [rad]"``).
        Default: none.

    Examples
    --------
    >>> import numpy as np
    >>> vdp = Plant(lambda t, x, u, v, p: np.array([x[1], p[0] * (1 - x[0] ** 2) * x[1] - x[0]]),
    ...             lambda x, p: x[:1], n_x=2, n_y=1, params=[1.0])
    >>> vdp.call_f_p(0.0, np.array([2.0, 0.0]), np.zeros(0), np.zeros(0)).tolist()
    [0.0, -2.0]

    Named, with units:

    >>> vdp = Plant(vdp.f_p, vdp.h, n_x=2, n_y=1, params=[1.0], state_names=["position", "velocity"],
    ...             state_units=["m", "m/s"])
    >>> [q.axis_label for q in vdp.quantities("x")]
    ['position [m]', 'velocity [m/s]']
    >>> vdp.quantities("y")[0].label
    '$y_{1}$'

    """

    f_p: PlantFn
    h: OutputFn
    n_x: int
    n_y: int
    n_u: int = 0
    n_v: int = 0
    name: str = "plant"
    params: Any = None
    state_names: tuple[str, ...] | None = None
    state_units: tuple[str, ...] | None = None
    output_names: tuple[str, ...] | None = None
    output_units: tuple[str, ...] | None = None
    input_names: tuple[str, ...] | None = None
    input_units: tuple[str, ...] | None = None

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
        for vector, size in (("state", self.n_x), ("output", self.n_y), ("input", self.n_u)):
            for kind in ("names", "units"):
                key = f"{vector}_{kind}"
                object.__setattr__(self, key, names(key, getattr(self, key), size))

    def quantities(self, vector: str) -> tuple[Quantity, ...]:
        """The entries of ``vector`` (``"x"``, ``"y"`` or ``"u"``) with their names and units.

        Parameters
        ----------
        vector : {"x", "y", "u"}

        Returns
        -------
        tuple of Quantity
            One per entry, in order.

        """
        which = {"x": ("state", self.n_x), "y": ("output", self.n_y), "u": ("input", self.n_u)}
        if vector not in which:
            raise InputError(f"`vector` must be 'x', 'y' or 'u'; got {vector!r}")
        key, size = which[vector]
        return quantities(vector, size, getattr(self, f"{key}_names"), getattr(self, f"{key}_units"))

    def call_f_p(self, t: float, x: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``f_p`` of one run, with ``params`` when there are any."""
        return with_params(self.f_p, self.params, t, x, u, v)  # type: ignore[no-any-return]

    def call_h(self, x: np.ndarray) -> np.ndarray:
        """``h`` of one run, with ``params`` when there are any."""
        return with_params(self.h, self.params, x)  # type: ignore[no-any-return]
