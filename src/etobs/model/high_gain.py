"""High-gain observer for single-output systems in observability normal form.

For ``x_1' = x_2, ..., x_{n-1}' = x_n, x_n' = phi(t, x, u)`` with ``y = x_1`` (a chain of
integrators with a nonlinearity in the last equation), the observer
``xhat' = f(t, xhat, u) + L (ybar - xhat_1)`` (``f`` written for one run) with
``L = (theta k_1, theta^2 k_2, ..., theta^n k_n)`` has error dynamics
``theta``-times faster than those of the Hurwitz companion matrix of ``k``; for
``theta`` large enough (globally Lipschitz ``phi``) it satisfies Assumption 2 with
quadratic gains (Khalil & Praly 2014). The default ``k`` places every eigenvalue of the
companion matrix at ``-1`` (binomial coefficients).
"""

from __future__ import annotations

from collections.abc import Callable
from math import comb
from typing import Any

import numpy as np
from numpy.typing import NDArray

from etobs import _validate as v
from etobs.errors import InputError
from etobs.model.observer import Observer, luenberger


def high_gain_gain(n_x: int, theta: float, k: Any = None) -> np.ndarray:
    """``L = (theta k_1, ..., theta^n k_n)``, shape ``(n_x, 1)``.

    Examples
    --------
    >>> high_gain_gain(3, 10.0).ravel().tolist()  # k = (3, 3, 1): (s + 1)^3
    [30.0, 300.0, 1000.0]

    """
    n = v.integer("n_x", n_x, lower=1)
    th = v.real("theta", theta, lower=0.0, lower_open=True)
    kk: NDArray[np.float64] = (
        np.array([comb(n, i) for i in range(1, n + 1)], dtype=float) if k is None else v.vector("k", k, n)
    )
    # the companion matrix of k, [-k | I; 0], must be Hurwitz
    Ac = np.zeros((n, n))
    Ac[:, 0] = -kk
    Ac[: n - 1, 1:] = np.eye(n - 1)
    if np.linalg.eigvals(Ac).real.max() >= 0:
        raise InputError(f"`k` must make the companion matrix Hurwitz; got k = {kk.tolist()}")
    return (th ** np.arange(1, n + 1) * kk)[:, None]


def high_gain_observer(
    f: Callable[[float, np.ndarray, np.ndarray], np.ndarray],
    n_x: int,
    theta: float,
    *,
    k: Any = None,
    name: str = "high-gain",
) -> Observer:
    """The high-gain observer of the module docstring (``z = xhat``, output ``y = x_1``).

    ``f(t, x, u) -> (n_x,)`` is the model for one run (1-D arrays, numpy or ``math``);
    the observer's ``f_o(t, z, u, ybar, yhat) = f(t, z, u) + L (ybar - yhat)`` calls it
    and etobs compiles both.

    Examples
    --------
    >>> obs = high_gain_observer(lambda t, x, u: np.array([x[1], -x[0]]), 2, 10.0)
    >>> obs.call_f_o(0.0, np.zeros(2), np.zeros(0), np.array([1.0]), np.array([0.0])).tolist()
    [20.0, 100.0]

    """
    return luenberger(f, high_gain_gain(n_x, theta, k), name=name)
