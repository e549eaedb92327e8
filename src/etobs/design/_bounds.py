"""The problem's side of a certificate: what it covers, its rules, and the bounds read from its signals.

:func:`~etobs.design.certify` takes from here the paper's rules (refusing anything else),
``E`` as a stated bound or a named estimate, the noise bounds ``m_i`` (section 7.2) and
the disturbance bound, both read from the problem's signals when they are known.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.design.iss import QuadraticISS, plant_disturbance_matrix
from etobs.design.rates import RateEstimate
from etobs.errors import InputError
from etobs.estimation.problem import EstimationProblem
from etobs.model.rules import DynamicRule, StaticRule
from etobs.model.sampled import Sampled
from etobs.model.signals import Constant, Signal, Sinusoid, Zero


def rate_bound(E: Any, N: int) -> tuple[list[float] | None, str]:
    """``E_i`` per node (or ``None``), and the assumption ``tau_i`` then rests on, in words."""
    if E is None:
        return None, ""
    if isinstance(E, RateEstimate):
        if len(E.E) != N:
            raise InputError(f"`E` estimates the rate of {len(E.E)} nodes; the problem has {N}")
        shown_E = ", ".join(f"{x:.6g}" for x in E.E)
        return list(E.E), (
            f"E = ({shown_E}) is an estimate, not a bound: {E.how}; tau_i is a minimum inter-event time only "
            "along solutions whose output rate |dy_i/dt| stays below E_i"
        )
    Es = [v.real(f"E[{i}]", x, lower=0.0, lower_open=True) for i, x in enumerate(per_node(E, N))]
    if len(Es) != N:
        raise InputError(f"`E` must be one bound or one per node ({N}); got {len(Es)}")
    shown_E = ", ".join(f"{x:.6g}" for x in Es)
    return Es, (
        f"E = ({shown_E}) bounds |dh_i/dx f_p| along every solution (given as a bound; tau_i holds "
        "where it does)"
    )


def noise_bounds(problem: EstimationProblem, noise: Sequence[float] | None) -> tuple[list[float], str]:
    """``m_i`` per node (section 7.2) read from ``problem.m``, or the given ``noise`` checked against it.

    Without it a noisy problem was certified as noise-free: lambda not halved and
    ``tau`` too large (0.039 s certified, 0.011 s observed).
    """
    N = problem.n_nodes
    sups = [sup_norm(problem.m, list(nd.outputs)) for nd in problem.nodes]
    what = type(problem.m).__name__
    if noise is None:
        if any(m is None for m in sups):
            raise InputError(
                f"problem.m is a function ({what}), which certify cannot bound: give `noise`, a bound m_i on "
                "each node's measurement noise (section 7.2)"
            )
        ms = [float(m) for m in sups]  # type: ignore[arg-type]
        said = ", ".join(f"{m:.6g}" for m in ms)
        return ms, (
            f"noise not given: m_i = sup_t |m_i(t)| = ({said}) of problem.m ({what})" if any(ms) else ""
        )
    if len(noise) != N:
        raise InputError(f"`noise` must have one bound per node ({N}); got {len(noise)}")
    ms = [v.real(f"noise[{i}]", x, lower=0.0) for i, x in enumerate(noise)]
    for i, (m, sup) in enumerate(zip(ms, sups, strict=True)):
        if sup is not None and m < sup * (1 - 1e-12):
            raise InputError(
                f"`noise[{i}]` = {m:g} is below sup_t |m_{i}(t)| = {sup:.6g} of the problem's m ({what}): "
                f"tau and the error bound would not hold for this problem; give noise[{i}] >= {sup:.6g}, "
                "or leave `noise` out to use it"
            )
    if any(m is None for m in sups):
        return (
            ms,
            f"noise = {ms} is taken as a bound on |m_i(t)|; problem.m is a function ({what}), not checked",
        )
    return ms, ""


def disturbance_input(problem: EstimationProblem, iss: QuadraticISS) -> list[str]:
    """Refuse ISS gains computed for another disturbance input than the plant's (notes otherwise).

    ``theta`` bounds the effect of ``v`` on the error only for the ``E_v`` it was
    computed with: gains for ``x' = ... + v`` on a plant ``x' = ... + 30 e_4 v`` gave a
    bound of 0.68 where the error reached 1.6.
    """
    plant = problem.plant
    if plant.n_v == 0:  # no disturbance input: theta does not enter the error bound
        return []
    if iss.E_v is None:
        return [
            "the ISS gains carry no E_v (given by hand): theta(s) = k_v s^2 is taken as the bound on the "
            f"effect of |v| on the error, however v enters the plant {plant.name!r}"
        ]
    default = iss.E_v.shape[0] == iss.E_v.shape[1] and np.array_equal(iss.E_v, np.eye(iss.E_v.shape[0]))
    made_for = "the identity, quadratic_iss_gains' default" if default else f"shape {iss.E_v.shape}"
    fix = (
        "compute the gains with the plant's disturbance matrix, quadratic_iss_gains(..., E_v=...) "
        "(`observer.E_v` in an `etobs check` spec)"
    )
    if iss.E_v.shape != (plant.n_x, plant.n_v):
        raise InputError(
            f"`iss` was computed for a disturbance entering as x' = ... + E_v v with E_v {made_for}; the "
            f"plant {plant.name!r} has n_x = {plant.n_x} states and n_v = {plant.n_v} disturbance inputs, "
            f"so E_v must have shape ({plant.n_x}, {plant.n_v}): {fix}"
        )
    E_p = plant_disturbance_matrix(plant)
    if not np.allclose(E_p, iss.E_v, rtol=1e-9, atol=1e-12 * max(1.0, float(np.abs(E_p).max()))):
        raise InputError(
            f"`iss` was computed for a disturbance entering as x' = ... + E_v v with E_v {made_for} "
            f"{np.asarray(iss.E_v).tolist()}; the plant {plant.name!r} has E_v = {E_p.tolist()} (read from "
            f"f_p(0, 0, 0, e_j) - f_p(0, 0, 0, 0)): {fix}"
        )
    return []


def disturbance_bound(problem: EstimationProblem, disturbance: float | None) -> tuple[float, str]:
    """The bound on ``|v|`` for the error bound, and a note saying where it came from ("" if given).

    A known ``problem.v`` is bounded exactly; a ``disturbance`` below that bound is
    refused, since the error bound would not hold for the problem certified.
    """
    sup = sup_norm(problem.v)
    what = type(problem.v).__name__
    if disturbance is None:
        if sup is None:
            return math.nan, (
                f"problem.v is a function ({what}), which certify cannot bound: no error bound without "
                "`disturbance` (a bound on |v(t)|)"
            )
        note = (
            f"disturbance not given: the error bound is for |v| <= sup_t |v(t)| = {sup:.6g}, "
            f"of problem.v ({what})"
        )
        return sup, note if sup > 0 else ""
    d = v.real("disturbance", disturbance, lower=0.0)
    if sup is None:
        return (
            d,
            f"disturbance = {d:g} is taken as a bound on |v(t)|; problem.v is a function ({what}), "
            "not checked",
        )
    if d < sup * (1 - 1e-12):
        raise InputError(
            f"`disturbance` = {d:g} is below sup_t |v(t)| = {sup:.6g} of the problem's v ({what}): the error "
            f"bound would not hold for this problem; give disturbance >= {sup:.6g}, or leave it out to use it"
        )
    return d, ""


def sup_norm(signal: Signal, rows: list[int] | None = None) -> float | None:
    """``sup_t |v(t)|`` (Euclidean norm of the components ``rows``) of a known signal, else ``None``.

    For a sinusoid ``a sin(w t + p) + o`` the norm is convex in ``s = sin(w t + p)``, so
    its sup over ``s`` in ``[-1, 1]`` is at ``s = +-1`` (``Sinusoid.bound``, which sums
    ``|a| + |o|`` per component, is larger and would refuse valid values).
    """
    pick = slice(None) if rows is None else rows
    if isinstance(signal, Zero):
        return 0.0
    if isinstance(signal, Constant):
        return float(np.linalg.norm(np.asarray(signal.value)[pick]))
    if isinstance(signal, Sinusoid):
        a, o = np.asarray(signal.amplitude)[pick], np.asarray(signal.offset)[pick]
        if signal.omega == 0:  # s = sin(phase) for all t
            return float(np.linalg.norm(a * math.sin(signal.phase) + o))
        return float(max(np.linalg.norm(o + a), np.linalg.norm(o - a)))
    return None


def covered(problem: EstimationProblem) -> None:
    """Refuse, naming the reason, a problem the paper's results do not cover.

    The theorems hold for output nodes that hold ``y_i`` (eq. (5)) and reach the
    observer at once, whole. A certificate for anything else would be a false
    guarantee: the observer-copy hold shortens the inter-event times by orders of
    magnitude on the robot arm, a lossy or delayed network raises the error, and input
    nodes need Assumption 4's gain ``gamma_u``, which ``certify`` does not take.
    """
    why = []
    if problem.hold == "innovation":
        why.append(
            "the observer-copy hold (nodes send ytilde - yhat; the paper's rules hold y_i, eq. (5), "
            "and Remark 3 discusses the copy without results for it)"
        )
    if problem.input_nodes:
        why.append(
            f"{len(problem.input_nodes)} input node(s) (section 7.3: Assumption 4's ISS gain gamma_u "
            "and the input rule's conditions, which certify does not check)"
        )
    if problem.network is not None:
        ideal = [ln.instant and (ln.loss is None or ln.loss.rate == 0) for ln in problem.network.links]
        lossy = [i for i, ok in enumerate(ideal) if not ok]
        if lossy:
            where = "every node" if len(ideal) == 1 else f"node(s) {lossy}"
            why.append(
                f"a network with loss or delay on {where} (the theorems assume every "
                "transmission reaches the observer at once; see docs/extensions.md)"
            )
    if why:
        raise InputError(
            "the paper's results (Theorems 1-4) do not cover this problem, so no certificate is given: "
            + "; ".join(why)
        )


def per_node(value: Any, n: int) -> list[Any]:
    if np.ndim(value) == 0:
        return [value] * n
    return list(value)


def rules(problem: EstimationProblem) -> list[Any]:
    """The nodes' rules, refused unless each is exactly the paper's rule (eq. (16)-(17)).

    A subclass of :class:`DynamicRule` that changes its trigger was certified as the
    paper's rule before (simulated error 3.18 against a bound of 0.348): only the two
    classes themselves are accepted, never through ``isinstance``.
    """
    rules = []
    for i, nd in enumerate(problem.nodes):
        rule = nd.rule.rule if type(nd.rule) is Sampled else nd.rule  # the rule it samples: see sampled()
        kind = type(rule)
        if kind not in (DynamicRule, StaticRule):
            sub = [b.__name__ for b in (DynamicRule, StaticRule) if isinstance(nd.rule, b)]
            what = f"a subclass of {sub[0]}, which may change the rule" if sub else "another rule"
            raise InputError(
                f"the theorems cover the paper's rule, DynamicRule or StaticRule itself; node {i} "
                f"({nd.name!r}) has a {kind.__name__} ({what}): no certificate is given for it"
            )
        rules.append(rule)
    return rules


def continuous(problem: EstimationProblem) -> EstimationProblem:
    """``problem`` with each sampled node's rule in place of its :class:`~etobs.model.Sampled` one."""
    nodes = tuple(replace(nd, rule=nd.rule.rule) if type(nd.rule) is Sampled else nd for nd in problem.nodes)
    return replace(problem, nodes=nodes)


def sampled(problem: EstimationProblem) -> list[float | None]:
    """Each node's sampling period (:class:`~etobs.model.Sampled`), ``None`` for a continuous rule."""
    return [nd.rule.period if type(nd.rule) is Sampled else None for nd in problem.nodes]
