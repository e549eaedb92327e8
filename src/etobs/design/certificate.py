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
from etobs.design import _bounds as _b
from etobs.design import hypotheses as hyp
from etobs.design.iss import QuadraticISS
from etobs.errors import InputError
from etobs.estimation.problem import EstimationProblem
from etobs.model.functions import Linear, Quadratic
from etobs.model.rules import DynamicRule

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
    sampled : tuple of float or None
        Each node's sampling period when the problem's nodes sample their rules
        (:class:`~etobs.model.Sampled`; ``None`` for a continuous one), else empty: the
        conditions are then the continuous rules' and the figures those that carry over
        (see the note).

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
    sampled: tuple[float | None, ...] = field(default=())

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
        sampled = " of the continuous rules (nodes sample them: see the note)" if any(self.sampled) else ""
        if not self.ok:
            return f"{len(self.failures())} of {len(self.conditions)} conditions{sampled} fail"
        if not self.assumptions:
            return f"all conditions{sampled} hold"
        n = len(self.assumptions)
        under = f"under the {n} assumption{'s' if n > 1 else ''} stated (not checked)"
        return f"all conditions{sampled} hold, {under}"

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
    _b.covered(problem)
    rules = _b.rules(problem)
    periods = _b.sampled(problem)
    if any(T is not None for T in periods):
        return _sampled(
            certify(_b.continuous(problem), iss, d=d, a_U=a_U, E=E, noise=noise, disturbance=disturbance),
            periods,
        )
    N = len(rules)
    ds = None if d is None else [v.real(f"d[{i}]", di, lower=0.0, lower_open=True) for i, di in enumerate(d)]
    if ds is not None and len(ds) != N:
        raise InputError(f"`d` must have one value per node ({N}); got {len(ds)}")
    Es, E_said = _b.rate_bound(E, N)
    ms, noise_said = _b.noise_bounds(problem, noise)
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
    notes = _b.disturbance_input(problem, iss)
    bound, note = _b.disturbance_bound(problem, disturbance)
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


def _sampled(cert: Certificate, periods: list[float | None]) -> Certificate:
    """The certificate of the continuous rules, as far as it holds for the nodes that sample them.

    Checked: the continuous rule's conditions. What carries over: a sampled node sends
    only at samples, so its inter-event time is at least ``T_i``; and only when
    ``gamma_i(|e_i|) >= eps_i`` at a sample (its filter stays ``>= 0``), which after a
    transmission (``e_i = 0``) takes at least Theorem 4's ``tau_i`` when ``E`` bounds the
    output's rate: ``tau_i`` becomes ``max(T_i, tau_i)``.

    What does not: the decrease of ``U`` of Theorems 1 and 2 (with ``nu``, ``mu``) and the
    error bound assume that ``gamma_i(|e_i|)`` never exceeds the threshold, which between
    samples it may (by up to ``gamma_i`` of ``E_i T_i`` more gap); they are left out
    (``nan``), said in a note.
    """
    nodes = tuple(
        nd if T is None else replace(nd, tau=max(T, nd.tau) if math.isfinite(nd.tau) else T)
        for nd, T in zip(cert.nodes, periods, strict=True)
    )
    which = ", ".join(f"node {i} at T = {T:g} s" for i, T in enumerate(periods) if T is not None)
    note = (
        f"sampled rules ({which}): the conditions are the continuous rules'; for a sampled node tau_i is "
        "max(T_i, tau_i) (it sends only at samples, and only once gamma_i(|e_i|) >= eps_i); Theorem 1's and "
        "2's decrease of U (nu, mu) and the error bound are not proven for sampled rules (between samples "
        "gamma_i(|e_i|) may exceed the threshold) and are left out"
    )
    return replace(
        cert,
        nodes=nodes,
        nu=math.nan,
        nu_inf=math.nan,
        a_U=math.nan,
        mu=math.nan,
        error_bound=math.nan,
        d_U=(),
        notes=(*cert.notes, note),
        sampled=tuple(periods),
    )


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
