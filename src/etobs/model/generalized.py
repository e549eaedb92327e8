"""The generalized dynamic rule of section 7.1 (eq. (44)--(45)).

``eta' = -alpha_check(eta) + gamma_check(|e|)`` along flows, ``eta+ = b eta`` at the
node's transmission, and transmission when (the paper prints (45) with ``<=``, under which
a node would send at ``e = 0`` and not when ``|e|`` grows; etobs reads it with ``>=``, as (15))::

    gamma(|e|) + d'(eta) gamma_check(|e|) >= sigma d'(eta) alpha_check(eta) + eps     (45)

where ``d'`` (the paper's fraktur d) is non-decreasing, continuous, and zero only at
zero, ``d(s) = int_0^s d'``, and ``sigma`` is in ``(0, 1)``. The Lyapunov function is
then ``U = V + sum_i d_i(eta_i)`` (section 7.1).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from etobs import _validate as v
from etobs import formulas as fm
from etobs.model.functions import KFunction, Linear, as_kfunction
from etobs.model.rules import GENERALIZED, EngineForm, EtaRule, _norm


@dataclass(frozen=True)
class GeneralizedRule(EtaRule):
    """Section 7.1's rule: any ``alpha_check``, ``gamma_check`` and weight ``d'``.

    Parameters
    ----------
    gamma : KFunction
        ``gamma_i`` of Assumption 2.
    gamma_check, alpha_check : KFunction
        The filter ``eta' = -alpha_check(eta) + gamma_check(|e|)`` (eq. (44));
        ``alpha_check`` defaults to ``Linear(1.0)``.
    d_prime : KFunction or float
        The weight ``d'(eta)``: a KFunction or a positive constant.
    sigma : float
        In ``(0, 1)``.
    eps : float
        ``> 0``.
    b : float
        ``eta+ = b eta`` at the node's transmission, in ``[0, 1]``.
    eta0 : float
        ``eta(0) >= 0``.

    Examples
    --------
    With ``d' = d`` constant, ``gamma_check = c gamma`` and ``alpha_check = alpha``,
    (45) reads ``(1 + d c) gamma(|e|) >= sigma d alpha(eta) + eps``:

    >>> import numpy as np
    >>> from etobs.model import Linear, Quadratic
    >>> r = GeneralizedRule(gamma=Quadratic(1.0), alpha_check=Linear(2.0), gamma_check=Quadratic(0.5),
    ...                     d_prime=4.0, sigma=0.5, eps=1.0)
    >>> float(r.trigger(np.zeros(1), np.array([[1.0]]), np.array([[1.0]]))[0])  # 1 + 4*0.5 - 0.5*4*2 - 1
    -2.0

    """

    gamma: KFunction
    gamma_check: KFunction
    alpha_check: KFunction = field(default_factory=lambda: Linear(1.0))
    d_prime: KFunction | float = 1.0
    sigma: float = 0.5
    eps: float = 1.0
    b: float = 1.0
    eta0: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "gamma", as_kfunction("gamma", self.gamma))
        object.__setattr__(self, "alpha_check", as_kfunction("alpha_check", self.alpha_check))
        object.__setattr__(self, "gamma_check", as_kfunction("gamma_check", self.gamma_check))
        if isinstance(self.d_prime, int | float) and not isinstance(self.d_prime, bool):
            object.__setattr__(self, "d_prime", v.real("d_prime", self.d_prime, lower=0.0, lower_open=True))
        else:
            object.__setattr__(self, "d_prime", as_kfunction("d_prime", self.d_prime))
        object.__setattr__(
            self, "sigma", v.real("sigma", self.sigma, lower=0.0, upper=1.0, lower_open=True, upper_open=True)
        )
        self._check_eta_params()

    def weight(self, eta: np.ndarray) -> np.ndarray:
        """``d'(eta)``."""
        if isinstance(self.d_prime, float):
            return np.full_like(eta, self.d_prime)
        return self.d_prime(eta)

    def derivative(
        self, t: np.ndarray, e: np.ndarray, s: np.ndarray, y: np.ndarray | None = None
    ) -> np.ndarray:
        return fm.generalized_flow(self.gamma_check(_norm(e)), self.alpha_check(s[:, 0]))[:, None]  # (44)

    def trigger(self, t: np.ndarray, e: np.ndarray, s: np.ndarray, y: np.ndarray | None = None) -> np.ndarray:
        # eq. (45), read with >= (see etobs.formulas.generalized_trigger)
        eta, r = s[:, 0], _norm(e)
        w = self.weight(eta)
        return fm.generalized_trigger(
            self.gamma(r), w, self.gamma_check(r), self.alpha_check(eta), self.sigma, self.eps
        )

    def engine_form(self) -> EngineForm:
        numbers = {"sigma": self.sigma, "b": self.b, "eps": self.eps}
        return EngineForm(
            GENERALIZED, numbers, (self.gamma, self.alpha_check, self.gamma_check, self.d_prime)
        )
