"""The observer ``z' = f_o(t, z, u, ybar, yhat)``, ``xhat = psi(z)`` (eq. (3), (7)), for one run."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from etobs import _validate as v
from etobs.compile.functions import with_params
from etobs.model.quantities import Quantity, names, quantities

ObserverFn = Callable[..., np.ndarray]


@dataclass(frozen=True)
class Observer:
    """A continuous-time observer, run on the held outputs ``ybar``, written for one run.

    Parameters
    ----------
    f_o : callable
        ``f_o(t, z, u, ybar, yhat) -> z'`` on 1-D arrays (``z`` of shape ``(n_z,)``);
        numpy or ``math``, compiled by etobs.
    n_z : int
        Observer state dimension (``>= n_x``; an EKF carries its covariance in ``z``).
    psi : callable, optional
        ``psi(z) -> xhat`` of shape ``(n_x,)``; default: the first ``n_x`` entries.
    name : str
    params : array_like, optional
        A parameter vector: when given, ``f_o`` and ``psi`` take it as their last
        argument (``f_o(t, z, u, ybar, yhat, p)``, ``psi(z, p)``); numbers kept here
        change without a recompile.
    state_names, state_units : sequence of str, optional
        Names and units of the entries of ``z`` (``n_z`` each), for tables, the xarray
        Dataset and plots. Default: the symbols ``z_1 .. z_nz``, no unit.

    Attributes
    ----------
    gain_shape : tuple of int or None
        Shape ``(n_x, n_y)`` of the gain ``L`` of an observer built by :func:`luenberger`
        or :func:`~etobs.model.linear.linear_luenberger` (``None`` otherwise): its rows
        are ``n_z`` and its columns the outputs ``f_o`` expects, so a problem with a
        plant of another ``n_y`` or ``n_x`` is refused naming ``L``.

    Examples
    --------
    A Luenberger observer of ``x' = -x`` written by hand, its gain ``L = 2`` carried in
    ``params`` (another gain compiles nothing new):

    >>> import numpy as np
    >>> from etobs import Observer
    >>> obs = Observer(f_o=lambda t, z, u, ybar, yhat, p: -z + p[0] * (ybar - yhat), n_z=1, params=[2.0])
    >>> obs.call_f_o(0.0, np.array([1.0]), np.zeros(0), np.array([3.0]), np.array([1.0])).tolist()
    [3.0]

    """

    f_o: ObserverFn
    n_z: int
    psi: Callable[..., np.ndarray] | None = None
    name: str = "observer"
    params: Any = None
    state_names: tuple[str, ...] | None = None
    state_units: tuple[str, ...] | None = None
    gain_shape: tuple[int, int] | None = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        v.function("f_o", self.f_o)
        v.integer("n_z", self.n_z, lower=1)
        if self.psi is not None:
            v.function("psi", self.psi)
        object.__setattr__(self, "params", v.params("params", self.params))
        for key in ("state_names", "state_units"):
            object.__setattr__(self, key, names(key, getattr(self, key), self.n_z))

    def quantities(self) -> tuple[Quantity, ...]:
        """The entries of ``z`` with their names and units (symbols ``z_1 ..`` without names).

        Returns
        -------
        tuple of Quantity
            One per entry of ``z``.

        """
        return quantities("z", self.n_z, self.state_names, self.state_units)

    def call_f_o(
        self, t: float, z: np.ndarray, u: np.ndarray, ybar: np.ndarray, yhat: np.ndarray
    ) -> np.ndarray:
        """``f_o`` of one run, with ``params`` when there are any."""
        return with_params(self.f_o, self.params, t, z, u, ybar, yhat)  # type: ignore[no-any-return]

    def call_psi(self, z: np.ndarray, n_x: int) -> np.ndarray:
        """``xhat = psi(z)`` of one run (the first ``n_x`` entries of ``z`` without ``psi``)."""
        if self.psi is None:
            return z[:n_x]
        return with_params(self.psi, self.params, z)  # type: ignore[no-any-return]


def luenberger(f: Callable[..., np.ndarray], L: Any, *, name: str = "luenberger") -> Observer:
    """Luenberger observer ``xhat' = f(t, xhat, u) + L (ybar - yhat)`` with ``z = xhat``.

    Parameters
    ----------
    f : callable
        Model vector field ``f(t, x, u) -> (n_x,)`` for one run (the plant without
        disturbance).
    L : array_like, shape (n_x, n_y)
        Observer gain.

    Returns
    -------
    Observer
        With ``n_z = n_x`` and ``psi`` the identity.

    Examples
    --------
    >>> import numpy as np
    >>> obs = luenberger(lambda t, x, u: -x, L=[[2.0], [0.0]])
    >>> obs.call_f_o(0.0, np.ones(2), np.zeros(0), np.array([3.0]), np.array([1.0])).tolist()
    [3.0, -1.0]

    """
    v.function("f", f)
    gain = np.ascontiguousarray(v.matrix("L", L, (None, None)))
    n_x, n_y = gain.shape

    def f_o(
        t: float,
        z: NDArray[np.float64],
        u: NDArray[np.float64],
        ybar: NDArray[np.float64],
        yhat: NDArray[np.float64],
        p: NDArray[np.float64],
    ) -> NDArray[np.float64]:
        # L is in `params`, not in the closure: another gain compiles nothing, and a large one
        # (1000 x 1000) is not frozen into the machine code, which numba then cannot cache
        dx = f(t, z, u)  # a 1-D array, a list or a tuple (as the README allows): added entry by entry
        out = p.reshape((n_x, n_y)) @ (ybar - yhat)
        for i in range(n_x):
            out[i] += dx[i]
        return out

    return with_gain(Observer(f_o=f_o, n_z=n_x, name=name, params=gain.ravel()), gain)


def with_gain(observer: Observer, gain: np.ndarray) -> Observer:
    """``observer``, recording that ``f_o`` multiplies ``ybar - yhat`` by the gain ``L`` (``gain_shape``)."""
    object.__setattr__(observer, "gain_shape", (int(gain.shape[0]), int(gain.shape[1])))
    return observer
