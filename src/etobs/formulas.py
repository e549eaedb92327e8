"""The triggering rules' arithmetic, written once as plain scalar Python (standard library only).

One implementation of each formula, run three ways:

* the engine's generated model (:mod:`etobs.estimation._model_source`) has numba
  compile these functions into itself (they are small: numba inlines them);
* the rule and K-function objects (:mod:`etobs.model.rules`, :mod:`etobs.model.functions`)
  call them on numpy arrays (plain arithmetic works elementwise), for the reference
  solver and for evaluating results;
* the stdlib-only sensor node (:mod:`etobs.runtime.sampled_rule`) calls them as is.

The K-functions are given by a kind code and two numbers ``(k1, k2)``; a user's
``Custom`` function is called directly by each of the three and is not here.
"""

from __future__ import annotations

import math
from typing import Any

#: K-function kinds (their numbers ``k1, k2``): ``k1 s``, ``k1 s^2``, ``k1 s^k2``, a
#: user function, the constant ``k1`` (a weight ``d'`` given as a number).
LINEAR, QUADRATIC, POWER, CUSTOM, CONSTANT = 0, 1, 2, 3, 4
#: How a sensor spec names the kinds a sensor node runs (:mod:`etobs.runtime.sampled_rule`).
SENSOR_NAMES = {"linear": LINEAR, "quadratic": QUADRATIC, "power": POWER}


def k_value(kind: int, k1: float, k2: float, s: Any) -> Any:
    """The K-function of ``kind`` with numbers ``k1, k2`` at ``s`` (a float or an array)."""
    if kind == LINEAR:
        return k1 * s
    if kind == QUADRATIC:
        return k1 * (s * s)
    if kind == POWER:
        return k1 * s**k2
    return k1 + 0.0 * s  # CONSTANT (same shape as s)


def dynamic_flow(gamma_e: Any, alpha_eta: Any, c: float) -> Any:
    """``eta' = -alpha(eta) + c gamma(|e|)`` (eq. (14))."""
    return -alpha_eta + c * gamma_e


def dynamic_trigger(gamma_e: Any, alpha_eta: Any, sigma: float, eps: float) -> Any:
    """``gamma(|e|) - sigma alpha(eta) - eps``: the node sends when it is ``>= 0`` (eq. (15))."""
    return gamma_e - sigma * alpha_eta - eps


def eta_reset(eta: Any, b: float) -> Any:
    """``eta+ = b eta`` at the node's own transmission (eq. (14))."""
    return b * eta


def static_trigger(gamma_e: Any, eps: float) -> Any:
    """``gamma(|e|) - eps`` (eq. (15) with ``sigma = 0``)."""
    return gamma_e - eps


def relative_trigger(e: Any, y: Any, rho: float, eps: float) -> Any:
    """``|e| - rho |y| - eps``: the relative-threshold rule."""
    return e - rho * y - eps


def periodic_trigger(tau: Any, period: float) -> Any:
    """``tau - period``: the clock ``tau`` (``tau' = 1``, reset to 0) reaches the period."""
    return tau - period


def generalized_flow(gamma_check_e: Any, alpha_check_eta: Any) -> Any:
    """``eta' = -alpha_check(eta) + gamma_check(|e|)`` (eq. (44))."""
    return -alpha_check_eta + gamma_check_e


def generalized_trigger(
    gamma_e: Any, weight: Any, gamma_check_e: Any, alpha_check_eta: Any, sigma: float, eps: float
) -> Any:
    """``gamma(|e|) + d'(eta) gamma_check(|e|) - sigma d'(eta) alpha_check(eta) - eps`` (eq. (45)).

    The paper prints (45) with ``<=``; the node sends when this is ``>= 0``, the reading
    under which a node at ``e = 0`` does not send.
    """
    return gamma_e + weight * gamma_check_e - sigma * weight * alpha_check_eta - eps


def eta_after_period(
    eta: float, forcing: float, alpha_kind: int, a1: float, a2: float, period: float
) -> float:
    """``eta`` after one sampling period of ``eta' = -alpha(eta) + forcing``, ``forcing`` held.

    Exact for ``alpha(s) = a1 s``; otherwise 20 classical Runge--Kutta substeps (local
    error ``O((T/20)^5)``), with ``eta`` kept ``>= 0``.
    """
    if alpha_kind == LINEAR:
        decay = math.exp(-a1 * period)
        return decay * eta + forcing * (1.0 - decay) / a1
    h = period / 20

    def f(s: float) -> float:
        return -k_value(alpha_kind, a1, a2, max(s, 0.0)) + forcing

    for _ in range(20):
        k1 = f(eta)
        k2 = f(eta + 0.5 * h * k1)
        k3 = f(eta + 0.5 * h * k2)
        k4 = f(eta + h * k3)
        eta += h * (k1 + 2 * k2 + 2 * k3 + k4) / 6
    return max(eta, 0.0)
