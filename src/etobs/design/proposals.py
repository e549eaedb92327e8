"""Rule parameters chosen to meet a requested guarantee of Theorem 1 or Theorem 2."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from etobs import _validate as v
from etobs.design.iss import QuadraticISS
from etobs.errors import InputError
from etobs.model.functions import Linear, Quadratic
from etobs.model.rules import DynamicRule


@dataclass(frozen=True)
class RuleProposal:
    """Rule parameters chosen to meet a requested ``nu`` (Theorem 1) or ``a_U, mu`` (Theorem 2).

    ``rules`` are ready for :class:`~etobs.model.Node`; ``gamma_i`` is the observer's ISS
    gain ``k_i s^2`` itself, so the certificate applies with ``lambda = 1`` (``1/2`` with
    noise, section 7.2).
    """

    rules: tuple[DynamicRule, ...]
    d: tuple[float, ...]
    nu: float = math.nan
    a_U: float = math.nan
    mu: float = math.nan


def propose_rules(
    iss: QuadraticISS,
    *,
    sigma: Sequence[float],
    c: Sequence[float],
    nu: float | None = None,
    a_U: float | None = None,
    mu: float | None = None,
    a: Sequence[float] | None = None,
    b: float = 1.0,
    eta0: float = 0.0,
) -> RuleProposal:
    """Choose ``eps_i`` (and ``alpha_i``) so that the theorems give a requested guarantee.

    Give either ``nu`` (Theorem 1: ``sum_i (1 + d_i c_i) eps_i = nu`` with ``d_i = 2 d_i*``,
    equal shares per node) or ``a_U`` and ``mu`` (Theorem 2: ``a_i = 2 a_U / (1 - sigma_i
    c_i)`` unless given, ``eps_i = a_U mu / ((1 + varsigma) N)``). ``sigma_i c_i < 1`` is
    required.

    What ``sigma_i`` buys: at a fixed ``eps_i`` a larger ``sigma_i`` holds transmissions
    back (fewer on the robot arm and a linear chain). At a fixed guarantee, however,
    ``eps_i`` falls as ``sigma_i c_i`` grows: it is divided by ``1 + d_i c_i`` (``nu``) or
    ``1 + varsigma`` (``a_U, mu``), and with the default ``d_i`` and ``a_i`` both are
    ``1 + 2 sigma_i c_i / (1 - sigma_i c_i)``. On those two systems that outweighed the
    gain: for the same guarantee, ``sigma_i c_i = 0.9`` sent about 3.4 times as many
    transmissions over 30 s as ``0.1``, and ``sigma_i = 0`` (a static rule) the fewest
    of ``sigma_i c_i`` in 0, 0.1, 0.3, ..., 0.9 (``tests/design/test_propose_rules.py``
    keeps the comparison). Compare candidates by simulation.

    This is the quick start: one certified design in one call. To find the certified
    design that sends least for an accuracy budget (simulated or certified), give this
    one as a reference to :func:`etobs.tuning.tune` (``etobs tune SPEC``, docs/tuning.md),
    which searches ``sigma``, ``c``, ``eps``, ``a``, ``ell``, ``b``, ``eta0`` and the
    observer gain with the certificate as a hard constraint.

    Raises
    ------
    InputError
        When neither or both targets are given, ``sigma_i c_i >= 1``, ``a_U > a``, or a
        given ``a_i`` is too small for ``a_U`` (the message names the node).

    """
    N = iss.n_nodes
    sig = [v.real(f"sigma[{i}]", x, lower=0.0) for i, x in enumerate(sigma)]
    cs = [v.real(f"c[{i}]", x, lower=0.0) for i, x in enumerate(c)]
    if len(sig) != N or len(cs) != N:
        raise InputError(f"`sigma` and `c` need one value per node ({N}); got {len(sig)} and {len(cs)}")
    for i, (s_, c_) in enumerate(zip(sig, cs, strict=True)):
        if s_ * c_ >= 1:
            raise InputError(f"node {i}: sigma*c must be < 1 (Theorem 1); got {s_:g}*{c_:g} = {s_ * c_:g}")
    if (nu is None) == (a_U is None and mu is None) or (nu is None and (a_U is None or mu is None)):
        raise InputError("give either `nu` (Theorem 1) or both `a_U` and `mu` (Theorem 2)")
    if nu is not None:
        v.real("nu", nu, lower=0.0, lower_open=True)
        alphas = _alphas(a, N) or [1.0] * N
        d = [2 * s_ / (1 - s_ * c_) if s_ > 0 else 1.0 for s_, c_ in zip(sig, cs, strict=True)]
        eps = [nu / (N * (1 + di * c_)) for di, c_ in zip(d, cs, strict=True)]
        out = {"nu": nu}
    else:
        rate = v.real("a_U", a_U, lower=0.0, lower_open=True, upper=iss.a)
        bound = v.real("mu", mu, lower=0.0, lower_open=True)
        alphas = _alphas(a, N) or [2 * rate / (1 - s_ * c_) for s_, c_ in zip(sig, cs, strict=True)]
        for i, (s_, c_, ai) in enumerate(zip(sig, cs, alphas, strict=True)):
            if ai <= rate / (1 - s_ * c_):
                raise InputError(
                    f"node {i}: a must be > a_U / (1 - sigma*c) = {rate / (1 - s_ * c_):.6g}; got {ai:g}"
                )
        d = [s_ / (1 - s_ * c_ - rate / ai) for s_, c_, ai in zip(sig, cs, alphas, strict=True)]
        varsigma = max(di * c_ for di, c_ in zip(d, cs, strict=True))
        eps = [rate * bound / ((1 + varsigma) * N)] * N
        out = {"a_U": rate, "mu": bound}
    rules = tuple(
        DynamicRule(gamma=Quadratic(k), alpha=Linear(ai), sigma=s_, c=c_, b=b, eps=e, eta0=eta0)
        for k, ai, s_, c_, e in zip(iss.k, alphas, sig, cs, eps, strict=True)
    )
    return RuleProposal(rules=rules, d=tuple(d), **out)


def _alphas(a: Sequence[float] | None, n: int) -> list[float]:
    """The given ``a_i`` (validated), or ``[]`` when none are given."""
    if a is None:
        return []
    out = [v.real(f"a[{i}]", x, lower=0.0, lower_open=True) for i, x in enumerate(a)]
    if len(out) != n:
        raise InputError(f"`a` must have one value per node ({n}); got {len(out)}")
    return out
