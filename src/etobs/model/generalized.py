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
from typing import ClassVar

import numpy as np

from etobs import formulas as fm
from etobs.model.functions import KFunction, Linear
from etobs.model.rules import KindRule


@dataclass(frozen=True)
class GeneralizedRule(KindRule):
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

    kind: ClassVar[fm.RuleKind] = fm.GENERALIZED

    def weight(self, eta: np.ndarray) -> np.ndarray:
        """``d'(eta)``."""
        return np.asarray(fm.k_at(self.d_prime, np.asarray(eta, dtype=float)))
