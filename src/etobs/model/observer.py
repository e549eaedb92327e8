"""The observer ``z' = f_o(t, z, u, ybar, yhat)``, ``xhat = psi(z)`` (eq. (3), (7))."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.errors import InputError, InputTypeError

ObserverFn = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class JitObserver:
    """The observer's functions for one run, compiled with numba (for ``backend="numba"``).

    Parameters
    ----------
    f_o : numba-compiled function
        ``f_o(t, z, u, ybar, yhat, theta, out)`` writes ``z'`` (shape ``(n_z,)``) into ``out``.
    psi : numba-compiled function, optional
        ``psi(z, theta, out)`` writes ``xhat`` (shape ``(n_x,)``); required when the
        observer has ``psi``.
    theta : array_like, optional
        Parameters passed to both (e.g. the gain ``L`` flattened), so that changing them
        does not recompile.

    """

    f_o: Any
    psi: Any = None
    theta: Any = ()

    def __post_init__(self) -> None:
        v.function("f_o", self.f_o)
        if self.psi is not None:
            v.function("psi", self.psi)
        object.__setattr__(self, "theta", np.array(self.theta, dtype=float).reshape(-1))


@dataclass(frozen=True)
class Observer:
    """A continuous-time observer, run on the held outputs ``ybar``.

    Parameters
    ----------
    f_o : callable
        ``f_o(t, z, u, ybar, yhat) -> z'``, all arrays with the batch on axis 0.
    n_z : int
        Observer state dimension (``>= n_x``; an EKF carries its covariance in ``z``).
    psi : callable, optional
        ``psi(z) -> xhat`` of shape ``(B, n_x)``; default: the first ``n_x`` entries.
    name : str

    """

    f_o: ObserverFn
    n_z: int
    psi: Callable[[np.ndarray], np.ndarray] | None = None
    name: str = "observer"
    jit: JitObserver | None = None

    def __post_init__(self) -> None:
        v.function("f_o", self.f_o)
        v.integer("n_z", self.n_z, lower=1)
        if self.psi is not None:
            v.function("psi", self.psi)
        if self.jit is not None:
            if not isinstance(self.jit, JitObserver):
                raise InputTypeError(f"`jit` must be a JitObserver; got {type(self.jit).__name__}")
            if (self.jit.psi is None) != (self.psi is None):
                raise InputError("`jit.psi` must be given exactly when `psi` is (both or neither)")


def luenberger(
    f: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray], L: Any, *, name: str = "luenberger"
) -> Observer:
    """Luenberger observer ``xhat' = f(t, xhat, u) + L (ybar - yhat)`` with ``z = xhat``.

    Parameters
    ----------
    f : callable
        Model vector field ``f(t, x, u) -> (B, n_x)`` (the plant without disturbance).
    L : array_like, shape (n_x, n_y)
        Observer gain.

    """
    v.function("f", f)
    gain = v.matrix("L", L, (None, None))

    def f_o(t: np.ndarray, z: np.ndarray, u: np.ndarray, ybar: np.ndarray, yhat: np.ndarray) -> np.ndarray:
        return f(t, z, u) + (ybar - yhat) @ gain.T

    return Observer(f_o=f_o, n_z=gain.shape[0], name=name)
