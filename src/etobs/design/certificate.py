"""What the paper's theorems guarantee for given triggering parameters (sections 5, 6.2, 7.2).

:func:`certify` checks the conditions of Theorem 1 (``sigma_i c_i < 1``, ``d_i > d_i*``)
and reports ``d_i*``, ``delta_i`` and ``nu``; for linear ``alpha`` and ``alpha_i`` it
applies Theorem 2 (the decay rate ``a_U`` and the bound ``mu``); it gives the individual
minimum inter-event time ``tau_i = gamma_i^{-1}(eps_i) / E`` (Theorem 4) for a bound
``E`` on ``|dh_i/dx f_p|`` (eq. (36)) and checks the noise condition
``eps_i > gamma_i(2 m_i)`` (section 7.2). The theorems take ``sigma_i* = sigma_i`` and
``c_i* = c_i`` here, the tightest choice.

The numbers are in the units of the ``gamma_i`` the rules use. When the ISS gains of
the observer are known and quadratic (:class:`~etobs.design.iss.QuadraticISS`,
``gamma_i(s) = k_i s^2``) and the rules use ``ell_i s^2``, Assumption 2 holds for
``V' = lambda V`` with ``lambda = min_i ell_i / k_i``: the same linear rate ``a``,
``gamma'_i = lambda k_i <= ell_i`` and ``theta' = lambda theta`` (Remark 1, made
quantitative by scaling ``V``). That turns ``mu`` into a bound on the estimation error:
``|x - xhat|^2 <= V / lambda_min(P) <= U / (lambda lambda_min(P))``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.design import hypotheses as hyp
from etobs.design.iss import QuadraticISS, plant_disturbance_matrix
from etobs.design.rates import RateEstimate
from etobs.errors import InputError
from etobs.estimation.problem import EstimationProblem
from etobs.model.functions import Linear, Quadratic
from etobs.model.rules import DynamicRule, StaticRule
from etobs.model.signals import Constant, Signal, Sinusoid, Zero

#: Share of the largest admissible rate used by default for ``a_U`` (Theorem 2 needs
#: ``a_i > a_U / (1 - sigma_i c_i)`` strictly; at the limit ``d_i`` is infinite).
DEFAULT_RATE_SHARE = 0.9


@dataclass(frozen=True)
class Condition:
    """One condition of a theorem, for one node (``node is None``: the whole system)."""

    name: str
    holds: bool
    detail: str
    node: int | None = None


@dataclass(frozen=True)
class NodeNumbers:
    """Theorem 1 and 4 numbers of one node (``nan`` where they do not apply)."""

    node: int
    sigma: float
    c: float
    eps: float
    sigma_c: float
    d_star: float
    d: float
    delta: float
    tau: float


@dataclass(frozen=True, repr=False)
class Certificate:
    """The conditions checked and the numbers guaranteed; ``ok`` if every condition holds.

    Attributes
    ----------
    conditions : tuple of Condition
    nodes : tuple of NodeNumbers
    nu : float
        Theorem 1's ``nu = sum_i (1 + d_i c_i) eps_i`` (eq. (26) holds with it).
    nu_inf : float
        Its infimum over admissible ``d_i``: ``sum_i eps_i / (1 - sigma_i c_i)``.
    scale : float
        ``lambda`` of the module docstring (``nan`` without ISS gains).
    a_U, mu : float
        Theorem 2's rate and bound (``nan`` when it does not apply).
    d_U : tuple of float
        Theorem 2's ``d_i`` (item (iv)): ``mu`` bounds ``U = V' + sum d_U[i] eta_i``.
    error_bound : float
        Ultimate bound on ``|x - xhat|`` from Theorem 2 and the ISS gains, for
        ``|v| <= disturbance`` (``nan`` when not available).
    iss : QuadraticISS or None
        The ISS gains the numbers rest on, with the ``P`` they come from and how it was
        found (``None`` when certified without ISS gains). Another ``P`` for the same
        ``L`` gives other gains and another error bound.
    disturbance : float
        The bound on ``|v(t)|`` (Euclidean norm of the plant's disturbance input, as it
        enters ``x' = ... + E_v v``) that ``error_bound`` holds for: the one given, or
        ``sup_t |v(t)|`` of the problem's known ``v`` (``nan`` when neither is known, and
        without ISS gains).
    assumptions : tuple of str
        The hypotheses of the theorems that the numbers rest on and that were not
        checked: complete solutions (Assumption 3), ``E`` as a bound or an estimate,
        a design's region;
        without ISS gains, Assumption 2 for the rules' own ``gamma_i`` (Remark 1).
        The guarantees hold only where they do. Shown in every view of the certificate.

    """

    conditions: tuple[Condition, ...]
    nodes: tuple[NodeNumbers, ...]
    nu: float
    nu_inf: float
    scale: float = math.nan
    a_U: float = math.nan
    mu: float = math.nan
    error_bound: float = math.nan
    d_U: tuple[float, ...] = ()
    notes: tuple[str, ...] = field(default=())
    iss: QuadraticISS | None = None
    disturbance: float = math.nan
    assumptions: tuple[str, ...] = field(default=())

    @property
    def ok(self) -> bool:
        """Whether every condition holds."""
        return all(c.holds for c in self.conditions)

    def failures(self) -> list[Condition]:
        """The conditions that do not hold."""
        return [c for c in self.conditions if not c.holds]

    def to_dict(self) -> dict[str, Any]:
        """Plain data (NaN as ``None``), for ``--json``."""

        def clean(obj: Any) -> Any:
            if isinstance(obj, np.ndarray):
                return clean(obj.tolist())
            if isinstance(obj, float) and not math.isfinite(obj):
                return None
            if isinstance(obj, dict):
                return {k: clean(x) for k, x in obj.items()}
            if isinstance(obj, list | tuple):
                return [clean(x) for x in obj]
            return obj

        return clean({**asdict(self), "ok": self.ok})

    def to_json(self) -> str:
        """:meth:`to_dict` as JSON text."""
        return json.dumps(self.to_dict(), indent=2)

    def format(self) -> str:
        """A human-readable report: each condition, then the guaranteed numbers."""
        lines = ["conditions:"]
        for c in self.conditions:
            where = "" if c.node is None else f" [node {c.node}]"
            lines.append(f"  {'OK  ' if c.holds else 'FAIL'} {c.name}{where}: {c.detail}")
        lines.append("per node (Theorem 1 with sigma* = sigma, c* = c; Theorem 4):")
        lines.append("  node  sigma*c     d*          d           delta       tau [s]")
        for nd in self.nodes:
            nums = (nd.d_star, nd.d, nd.delta)
            lines.append(
                f"  {nd.node:4d}  {nd.sigma_c:<10.4g}"
                + "".join(f"{x:<12.4g}" for x in nums)
                + f"{nd.tau:.4g}"
            )
        lines.append(f"nu = {self.nu:.6g} (infimum over d: {self.nu_inf:.6g})")
        if math.isfinite(self.a_U):
            d_U = ", ".join(f"{x:.6g}" for x in self.d_U)
            lines.append(f"Theorem 2: a_U = {self.a_U:.6g}, mu = {self.mu:.6g}, with d_i = ({d_U})")
        if math.isfinite(self.scale):
            lines.append(f"V' = lambda V with lambda = {self.scale:.6g}")
        if math.isfinite(self.error_bound):
            lines.append(
                f"ultimate bound on |x - xhat|: {self.error_bound:.6g} for |v| <= {self.disturbance:.6g}"
            )
        lines += _rests_on(self.iss)
        lines += [f"assumed (not checked): {a}" for a in self.assumptions]
        lines += [f"note: {n}" for n in self.notes]
        lines.append(f"certificate: {self._verdict()}")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.format()

    def __repr__(self) -> str:
        """A few lines: the verdict, the key figures, the ``P`` the numbers rest on."""
        lines = [f"Certificate: {self._verdict()}"]
        lines += [f"  FAIL {c.name}{_where(c)}: {c.detail}" for c in self.failures()]
        lines.append("  " + ", ".join(f"{k} = {x}" for k, x in self._figures()))
        if self.iss is not None:
            lines.append(f"  rests on ISS gains from P: {self.iss.P_origin or 'given by hand'}")
        lines += [f"  assumed (not checked): {a}" for a in self.assumptions]
        lines += [f"  note: {n}" for n in self.notes]  # what was assumed belongs in the short view too
        return "\n".join(lines)

    def _repr_html_(self) -> str:
        """The same as :meth:`__repr__`, as a small HTML table (for notebooks)."""
        from html import escape

        rows = [("certificate", self._verdict())]
        rows += [(f"FAIL{_where(c)}", f"{c.name}: {c.detail}") for c in self.failures()]
        rows += self._figures()
        if self.iss is not None:
            rows.append(("P", self.iss.P_origin or "given by hand"))
        rows += [("assumed (not checked)", a) for a in self.assumptions]
        rows += [("note", n) for n in self.notes]
        body = "".join(
            f"<tr><th style='text-align:left'>{escape(k)}</th><td>{escape(x)}</td></tr>" for k, x in rows
        )
        return f"<table>{body}</table>"

    def _verdict(self) -> str:
        if not self.ok:
            return f"{len(self.failures())} of {len(self.conditions)} conditions fail"
        if not self.assumptions:
            return "all conditions hold"
        n = len(self.assumptions)
        return f"all conditions hold, under the {n} assumption{'s' if n > 1 else ''} stated (not checked)"

    def _figures(self) -> list[tuple[str, str]]:
        """The guaranteed numbers that are defined, formatted: ``nu``, ``a_U``, ``mu``, the bound, ``tau``."""
        taus = [nd.tau for nd in self.nodes if math.isfinite(nd.tau)]
        figures = [
            ("nu", self.nu),
            ("a_U", self.a_U),
            ("mu", self.mu),
            ("error bound", self.error_bound),
            ("min tau [s]", min(taus) if taus else math.nan),
        ]
        return [(k, f"{x:.4g}") for k, x in figures if math.isfinite(x)]


def _where(c: Condition) -> str:
    return "" if c.node is None else f" [node {c.node}]"


def _rests_on(iss: QuadraticISS | None) -> list[str]:
    """The lines of :meth:`Certificate.format` that name the ISS gains and ``P`` used."""
    if iss is None:
        return []
    k = ", ".join(f"{x:.6g}" for x in iss.k)
    lines = [
        f"rests on the ISS gains (Assumption 2) alpha(s) = {iss.a:.6g} s, theta(s) = {iss.k_v:.6g} s^2, "
        f"gamma_i(s) = k_i s^2 with k = ({k})"
    ]
    if iss.c:
        lines[-1] += f", split constants c_v = {iss.c_v:g}, c = ({', '.join(f'{x:g}' for x in iss.c)})"
    if iss.P is None:
        lines.append(
            f"  from V = xi' P xi with lambda(P) in [{iss.lambda_min_P:.6g}, {iss.lambda_max_P:.6g}]"
        )
        return lines
    lines.append(f"  from V = xi' P xi, P {iss.P_origin or 'given'}:")
    lines += ["    [" + "  ".join(f"{x:11.6g}" for x in row) + "]" for row in np.asarray(iss.P)]
    return lines


def certify(
    problem: EstimationProblem,
    iss: QuadraticISS | None = None,
    *,
    d: Sequence[float] | None = None,
    a_U: float | None = None,
    E: float | Sequence[float] | None = None,
    noise: Sequence[float] | None = None,
    disturbance: float | None = None,
) -> Certificate:
    """Check the theorems' conditions for the rules of ``problem`` and give the guarantees.

    Parameters
    ----------
    problem : EstimationProblem
        Its nodes must use :class:`DynamicRule` or :class:`StaticRule`.
    iss : QuadraticISS, optional
        The observer's ISS gains (needed for Theorem 2 and the error bound).
    d : sequence of float, optional
        ``d_i`` of ``U`` (eq. (24)); default ``2 d_i*`` (``1`` where ``d_i* = 0``).
    a_U : float, optional
        Decay rate asked of Theorem 2, in ``(0, a]``; default the largest admissible
        times :data:`DEFAULT_RATE_SHARE`.
    E : float or sequence of float, optional
        Bound on ``|dh_i/dx f_p|`` along solutions, common or per node (the proof of
        Theorem 4 uses node ``i``'s own bound; see
        :func:`~etobs.design.rates.estimate_output_rate`).
    noise : sequence of float, optional
        Bounds ``m_i`` on each node's measurement noise (section 7.2).
    disturbance : float, optional
        Bound on ``|v(t)|`` at all times, the Euclidean norm of the plant's disturbance
        input ``v`` (eq. (2)) as it enters ``x' = ... + E_v v``, with the ``E_v`` the ISS
        gains were computed for (:func:`~etobs.design.quadratic_iss_gains`); it enters the
        error bound through ``theta``. Default: ``sup_t |v(t)|`` of ``problem.v`` when it
        is known (zero, a constant, a :class:`~etobs.model.signals.Sinusoid`), with a note;
        for a function ``v`` there is no error bound without it. Needs ``iss``.

    Raises
    ------
    InputError
        ``a_U`` or ``disturbance`` without ``iss`` (they serve only Theorem 2 and the
        error bound, which need the ISS gains); ``disturbance`` below ``sup_t |v(t)|``
        of a known ``problem.v``; ISS gains computed for another disturbance input than
        the plant's (``E_v`` of another shape than ``(n_x, n_v)``, or other than the
        matrix :func:`~etobs.design.iss.plant_disturbance_matrix` reads from ``f_p``);
        a problem the theorems do not cover; a bad argument (the message names it).

    """
    if not isinstance(problem, EstimationProblem):
        raise InputError(f"`problem` must be an EstimationProblem; got {type(problem).__name__}")
    _covered(problem)
    rules = _rules(problem)
    N = len(rules)
    ds = None if d is None else [v.real(f"d[{i}]", di, lower=0.0, lower_open=True) for i, di in enumerate(d)]
    if ds is not None and len(ds) != N:
        raise InputError(f"`d` must have one value per node ({N}); got {len(ds)}")
    Es, E_said = _rate_bound(E, N)
    ms, noise_said = _noise_bounds(problem, noise)
    conds: list[Condition] = []
    nodes = []
    nu = nu_inf = 0.0
    for i, r in enumerate(rules):
        sigma, c = (r.sigma, r.c) if isinstance(r, DynamicRule) else (0.0, 0.0)
        sc = sigma * c
        conds.append(Condition("sigma*c < 1 (Theorem 1)", sc < 1, f"sigma*c = {sigma:g}*{c:g} = {sc:.6g}", i))
        if sc < 1:
            d_star = sigma / (1 - sc)
            di = ds[i] if ds is not None else (2 * d_star if d_star > 0 else 1.0)
            conds.append(Condition("d > d* (Theorem 1)", di > d_star, f"d = {di:.6g}, d* = {d_star:.6g}", i))
            delta = di - sigma * (1 + di * c)
            nu += (1 + di * c) * r.eps
            nu_inf += r.eps / (1 - sc)
        else:  # no d_i can satisfy Theorem 1
            d_star = di = delta = nu = nu_inf = math.nan
        # Theorem 4 needs gamma_i^{-1}(eps_i) at the first crossing, and gamma_i of class K up to it
        s_eps = hyp.first_crossing(r.gamma, r.eps)
        conds += _class_k(r, s_eps, i)
        # with noise the gap the rule sees restarts at 0 but |e~| <= E s + 2 m,
        # so it needs (gamma^{-1}(eps) - 2 m) / E (section 7.2's semi-global version)
        reach = s_eps - 2 * ms[i]
        tau = reach / Es[i] if Es is not None and reach > 0 else math.nan
        nodes.append(NodeNumbers(i, sigma, c, r.eps, sc, d_star, di, delta, tau))
        if ms[i] > 0:
            g2m = float(r.gamma(np.array(2 * ms[i])))
            conds.append(
                Condition(
                    "eps > gamma(2 m) (section 7.2)",
                    r.eps > g2m,
                    f"eps = {r.eps:g}, gamma(2m) = {g2m:.6g} with m = {ms[i]:.6g}",
                    i,
                )
            )
    assumed = [_COMPLETE] + ([E_said] if E_said else [])
    out = Certificate(
        conditions=tuple(conds),
        nodes=tuple(nodes),
        nu=nu,
        nu_inf=nu_inf,
        notes=tuple(n for n in [noise_said] if n),
    )
    if iss is None:
        unused = {k: x for k, x in (("a_U", a_U), ("disturbance", disturbance)) if x is not None}
        if unused:  # dropping them would certify without what was asked
            got = ", ".join(f"{k} = {x!r}" for k, x in unused.items())
            raise InputError(
                f"`{next(iter(unused))}` needs `iss`: `a_U` and `disturbance` serve only Theorem 2 and the "
                f"error bound, which rest on the observer's ISS gains; got {got} without `iss` (pass the "
                "gains, e.g. quadratic_iss_gains(...), or leave them out)"
            )
        return replace(out, assumptions=(_ASSUMPTION_2, *assumed))
    if not isinstance(iss, QuadraticISS):
        raise InputError(f"`iss` must be a QuadraticISS; got {type(iss).__name__}")
    notes = _disturbance_input(problem, iss)
    bound, note = _disturbance_bound(problem, disturbance)
    tied, how = hyp.tie_gains(problem, iss)
    conds.append(Condition("ISS gains are the problem's observer and plant (Assumption 2)", tied, how))
    if iss.region is not None:
        assumed.append(
            f"x and xhat stay in the region {iss.region} where the design's slope bounds hold (the ISS "
            "gains and every number here rest on it; etobs.design.runs_leaving(result, region) finds "
            "the runs that leave)"
        )
    out = replace(out, conditions=tuple(conds), notes=(*out.notes, *notes, *([note] if note else [])))
    out = _with_iss(out, rules, iss, a_U, bound, ms)
    return replace(out, disturbance=bound, assumptions=tuple(assumed))


#: Stated on every certificate: the theorems speak of complete solutions (Theorem 3 proves
#: completeness under Assumption 3, forward completeness of the plant, which is not checked).
_COMPLETE = (
    "solutions are complete (the theorems speak of complete solutions; Assumption 3, the plant's "
    "forward completeness, gives it and is not checked)"
)
#: Stated without ISS gains (Remark 1): the rules' gamma_i are then taken as the observer's.
_ASSUMPTION_2 = (
    "Assumption 2 holds with the rules' own gamma_i (no ISS gains given: Remark 1 needs the observer's "
    "gain gamma_i to be O of the rule's; pass iss= to check it and get an error bound)"
)


def _rate_bound(E: Any, N: int) -> tuple[list[float] | None, str]:
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
    Es = [v.real(f"E[{i}]", x, lower=0.0, lower_open=True) for i, x in enumerate(_per_node(E, N))]
    if len(Es) != N:
        raise InputError(f"`E` must be one bound or one per node ({N}); got {len(Es)}")
    shown_E = ", ".join(f"{x:.6g}" for x in Es)
    return Es, (
        f"E = ({shown_E}) bounds |dh_i/dx f_p| along every solution (given as a bound; tau_i holds "
        "where it does)"
    )


def _noise_bounds(problem: EstimationProblem, noise: Sequence[float] | None) -> tuple[list[float], str]:
    """``m_i`` per node (section 7.2) read from ``problem.m``, or the given ``noise`` checked against it.

    Without it a noisy problem was certified as noise-free: lambda not halved and
    ``tau`` too large (0.039 s certified, 0.011 s observed).
    """
    N = problem.n_nodes
    sups = [_sup_norm(problem.m, list(nd.outputs)) for nd in problem.nodes]
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


def _class_k(rule: Any, s_eps: float, i: int) -> list[Condition]:
    """``gamma_i`` and ``alpha_i`` of class K∞, probed unless built in (``alpha_i``: eq. (14)).

    Theorem 4 needs ``gamma_i`` increasing up to its first crossing of ``eps_i`` (dense
    there); Theorems 1-2 need class K∞ (a log-spaced tail beyond).
    """
    ok, how = hyp.probe_class_k(rule.gamma, max(s_eps, 1e-12))
    out = [Condition("gamma_i of class K-infinity (Assumption 2, Theorem 4)", ok, how, i)]
    if isinstance(rule, DynamicRule):
        ok, how = hyp.probe_class_k(rule.alpha, 1.0)
        out.append(Condition("alpha_i of class K-infinity (eq. (14))", ok, how, i))
    return out


def _disturbance_input(problem: EstimationProblem, iss: QuadraticISS) -> list[str]:
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


def _disturbance_bound(problem: EstimationProblem, disturbance: float | None) -> tuple[float, str]:
    """The bound on ``|v|`` for the error bound, and a note saying where it came from ("" if given).

    A known ``problem.v`` is bounded exactly; a ``disturbance`` below that bound is
    refused, since the error bound would not hold for the problem certified.
    """
    sup = _sup_norm(problem.v)
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


def _sup_norm(signal: Signal, rows: list[int] | None = None) -> float | None:
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


def _covered(problem: EstimationProblem) -> None:
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


def _per_node(value: Any, n: int) -> list[Any]:
    if np.ndim(value) == 0:
        return [value] * n
    return list(value)


def _rules(problem: EstimationProblem) -> list[Any]:
    """The nodes' rules, refused unless each is exactly the paper's rule (eq. (16)-(17)).

    A subclass of :class:`DynamicRule` that changes its trigger was certified as the
    paper's rule before (simulated error 3.18 against a bound of 0.348): only the two
    classes themselves are accepted, never through ``isinstance``.
    """
    rules = []
    for i, nd in enumerate(problem.nodes):
        kind = type(nd.rule)
        if kind not in (DynamicRule, StaticRule):
            sub = [b.__name__ for b in (DynamicRule, StaticRule) if isinstance(nd.rule, b)]
            what = f"a subclass of {sub[0]}, which may change the rule" if sub else "another rule"
            raise InputError(
                f"the theorems cover the paper's rule, DynamicRule or StaticRule itself; node {i} "
                f"({nd.name!r}) has a {kind.__name__} ({what}): no certificate is given for it"
            )
        rules.append(nd.rule)
    return rules


def _with_iss(
    cert: Certificate,
    rules: list[Any],
    iss: QuadraticISS,
    a_U: float | None,
    disturbance: float,
    ms: list[float],
) -> Certificate:
    N = len(rules)
    if iss.n_nodes != N:
        raise InputError(f"`iss` has gains for {iss.n_nodes} nodes; the problem has {N}")
    cert = replace(cert, iss=iss)
    conds = list(cert.conditions)
    notes = list(cert.notes)
    quad = all(type(r.gamma) is Quadratic for r in rules)  # a subclass may change the formula
    # With noise the observer's error is e~ + m, and k |e~ + m|^2 <= 2 k |e~|^2 + 2 k m^2:
    # the rule's gain must then dominate 2 lambda k_i, and 2 lambda k_i m_i^2 is added.
    two = 2.0 if any(m > 0 for m in ms) else 1.0
    scale = min(r.gamma.ell / (two * k) for r, k in zip(rules, iss.k, strict=True)) if quad else math.nan
    conds.append(
        Condition(
            "rule gamma_i = ell_i s^2 with quadratic ISS gains (Remark 1)",
            quad,
            f"V' = lambda V, lambda = min_i ell_i / ({two:g} k_i) = {scale:.6g}"
            if quad
            else "a rule gamma is not quadratic",
        )
    )
    linear = all(type(r.alpha) is Linear for r in rules if isinstance(r, DynamicRule))
    if not (quad and linear):
        notes.append("Theorem 2 needs linear alpha_i and quadratic gamma_i: not applied")
        return replace(cert, conditions=tuple(conds), scale=scale, notes=tuple(notes))
    if not math.isfinite(cert.nu):  # item (i) of Theorem 2 is Theorem 1's sigma_i c_i < 1
        notes.append("Theorem 2 not applied: sigma_i c_i < 1 fails")
        return replace(cert, conditions=tuple(conds), scale=scale, notes=tuple(notes))
    limits = [r.alpha.a * (1 - r.sigma * r.c) for r in rules if isinstance(r, DynamicRule) and r.sigma > 0]
    best = min([iss.a, *limits])
    rate = DEFAULT_RATE_SHARE * best if a_U is None else v.real("a_U", a_U, lower=0.0, lower_open=True)
    ok_rate = rate <= iss.a and all(rate < lim for lim in limits)
    conds.append(
        Condition(
            "a_U <= a and a_i > a_U / (1 - sigma_i c_i) (Theorem 2)",
            ok_rate,
            f"a_U = {rate:.6g}, a = {iss.a:.6g}, limits a_i (1 - sigma_i c_i) = "
            + ", ".join(f"{x:.6g}" for x in limits),
        )
    )
    if not ok_rate:
        return replace(cert, conditions=tuple(conds), scale=scale, notes=tuple(notes))
    # item (iv): d_i = sigma_i (1 - sigma_i c_i - a_U / a_i)^(-1); static nodes need no d_i (take 0)
    d2 = [
        r.sigma / (1 - r.sigma * r.c - rate / r.alpha.a)
        if isinstance(r, DynamicRule) and r.sigma > 0
        else 0.0
        for r in rules
    ]
    varsigma = max(di * (r.c if isinstance(r, DynamicRule) else 0.0) for di, r in zip(d2, rules, strict=True))
    mu = (1 + varsigma) * sum(r.eps for r in rules) / rate
    # in units of V' = scale V: theta' = scale k_v; |xi|^2 <= V / lambda_min(P) = V' / (scale lambda_min(P))
    extra = scale * iss.k_v * disturbance**2 + sum(
        2 * scale * k * m**2 for k, m in zip(iss.k, ms, strict=True)
    )
    bound = math.sqrt((mu + extra / rate) / (scale * iss.lambda_min_P))
    if two > 1:
        notes.append("with noise: lambda uses 2 k_i, and sum 2 lambda k_i m_i^2 / a_U enters the error bound")
    return replace(
        cert,
        conditions=tuple(conds),
        scale=scale,
        a_U=rate,
        mu=mu,
        d_U=tuple(d2),
        error_bound=bound,
        notes=tuple(notes),
    )


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
