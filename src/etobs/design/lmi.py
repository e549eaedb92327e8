"""Observer gains from linear matrix inequalities (section 8; cvxpy, optional extra ``design``).

The plant ``x' = A x + B u + G phi(H x)`` has a nonlinearity whose slope lies in a known
interval (a sector/slope bound). Along the estimation error ``xi = x - xhat`` of the
Luenberger observer ``xhat' = A xhat + B u + G phi(H xhat) + L (y - C xhat)``, the
nonlinearity contributes ``G s(t) H xi`` with ``s(t)`` in the slope interval, so the error
matrix lies in the polytope with vertices ``A + G s_k H - L C``. A common quadratic
Lyapunov function ``V(xi) = xi' P xi`` for all vertices is found from the LMIs (the
paper's section 8, after Zemouche & Boutayeb 2008)::

    P (A + A_k) - W C + (P (A + A_k) - W C)' <= -Q   at every vertex A_k,   P > 0,

with ``W = P L``, hence ``L = P^{-1} W``. Strict inequalities are imposed with an explicit
margin, and the answer is re-checked with eigenvalues after the solve.
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.design.hypotheses import Region
from etobs.errors import DesignError, InputError

#: Objectives of :func:`observer_gain`.
OBJECTIVES = ("min_gain", "max_decay")


@dataclass(frozen=True)
class ObserverGain:
    """An observer gain with its quadratic Lyapunov certificate.

    Attributes
    ----------
    L : ndarray, shape (n_x, n_y)
        Observer gain.
    P : ndarray, shape (n_x, n_x)
        ``V(xi) = xi' P xi``, symmetric positive definite.
    Q : ndarray, shape (n_x, n_x)
        Decrease matrix: ``P A_cl,k + A_cl,k' P <= -Q`` at every vertex ``k``.
    vertices : tuple of ndarray
        The matrices ``A_k`` added to ``A`` at the vertices.
    residuals : ndarray, shape (K,)
        Largest eigenvalue of ``P A_cl,k + A_cl,k' P + Q`` at each vertex (must be <= 0).
    abscissa : ndarray, shape (K,)
        Largest real part of the eigenvalues of each vertex matrix ``A + A_k - L C``.
    solver_status : str
        What the SDP solver reported (``"given"`` when ``L`` was given and only ``P``
        found, ``"P given"`` when both were given and only re-checked).
    margin : float
        Margin used for the strict inequalities in the solve.
    origin : str
        How ``P`` was found, in words (shown by certificates that rest on it: the
        guarantees depend on ``P``, and ``L`` admits many).
    region : Region or None
        Where the slope bounds of the vertices hold (``None``: everywhere). The
        decrease, and every guarantee built on it, holds only while ``x`` and ``xhat``
        stay in it; certificates state it and :func:`~etobs.design.runs_leaving` finds
        the simulated runs that leave it.

    """

    L: np.ndarray
    P: np.ndarray
    Q: np.ndarray
    vertices: tuple[np.ndarray, ...]
    residuals: np.ndarray
    abscissa: np.ndarray
    solver_status: str
    margin: float
    notes: tuple[str, ...] = field(default=())
    origin: str = ""
    region: Region | None = None

    @property
    def ok(self) -> bool:
        """Whether the re-check holds: ``P > 0`` and ``P A_cl,k + A_cl,k' P + Q < 0`` at every vertex."""
        return bool(np.linalg.eigvalsh(self.P).min() > 0 and np.all(self.residuals < 0))

    @property
    def decay_rate(self) -> float:
        """``lambda_min(Q) / lambda_max(P)``: ``V' <= -rate V`` without network and disturbance."""
        return float(np.linalg.eigvalsh(self.Q).min() / np.linalg.eigvalsh(self.P).max())


def slope_vertices(G: Any, H: Any, slopes: Sequence[tuple[float, float]]) -> tuple[np.ndarray, ...]:
    """Vertices ``G diag(s) H`` for a nonlinearity ``phi(H x)`` with slope bounds per component.

    Parameters
    ----------
    G : array_like, shape (n_x, m)
    H : array_like, shape (m, n_x)
    slopes : sequence of (low, high), length m
        Bounds of ``d phi_j / d s`` for each component ``j``.

    Returns
    -------
    tuple of ndarray, shape (n_x, n_x)
        The ``2^m`` vertex matrices (low before high, first component slowest).

    Examples
    --------
    The robot arm's ``3.3 sin(x_3)`` (slope in [-3.3, 3.3]) gives the paper's ``G_1, G_2``:

    >>> import numpy as np
    >>> V = slope_vertices([[0], [0], [0], [-1]], [[0, 0, 1, 0]], [(-3.3, 3.3)])
    >>> [float(Vk[3, 2]) for Vk in V]
    [3.3, -3.3]

    """
    Gm = np.atleast_2d(np.asarray(G, dtype=float))
    Hm = np.atleast_2d(np.asarray(H, dtype=float))
    if Gm.shape[0] == 1 and Gm.shape[1] > 1 and Hm.shape[0] == 1:
        Gm = Gm.T
    m = Gm.shape[1]
    if Hm.shape[0] != m or Hm.shape[1] != Gm.shape[0]:
        raise InputError(f"`G` and `H` must have shapes (n_x, m) and (m, n_x); got {Gm.shape} and {Hm.shape}")
    if len(slopes) != m:
        raise InputError(f"`slopes` must give (low, high) for each of the {m} components; got {len(slopes)}")
    bounds = []
    for j, pair in enumerate(slopes):
        lo, hi = (float(s) for s in pair)
        if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
            raise InputError(f"`slopes[{j}]` must be finite with low <= high; got {pair!r}")
        bounds.append((lo, hi))
    return tuple(Gm @ np.diag(choice) @ Hm for choice in itertools.product(*bounds))


def observer_gain(
    A: Any,
    C: Any,
    vertices: Sequence[Any] = (),
    *,
    Q: Any = None,
    margin: float = 1e-6,
    objective: str = "min_gain",
    max_gain: float | None = None,
    solver: str | None = None,
    region: Region | None = None,
) -> ObserverGain:
    """Design ``L`` from the polytopic LMIs (a plain Luenberger design without vertices).

    Parameters
    ----------
    A : array_like, shape (n_x, n_x)
    C : array_like, shape (n_y, n_x)
    vertices : sequence of array_like, shape (n_x, n_x)
        Matrices ``A_k`` added to ``A`` (e.g. from :func:`slope_vertices`); none for a
        linear plant.
    Q : array_like, shape (n_x, n_x), optional
        Required decrease, symmetric positive definite (default: identity, as the paper).
    margin : float
        Strictness margin: ``P >= margin I`` and every vertex inequality ``<= -Q - margin I``.
    objective : {"min_gain", "max_decay"}
        The LMIs are homogeneous and let ``L`` grow without bound, so the design fixes
        ``P >= I`` (then ``||L|| <= ||W||``) and ``"min_gain"`` minimizes the spectral norm
        of ``W = P L`` (the smallest gain with the required decrease; a slow observer,
        and ``L = 0`` when ``A`` is Hurwitz and there are no vertices: the LMIs are
        homogeneous, so a large enough ``P`` meets any ``Q`` with the plant's own decay),
        ``"max_decay"`` minimizes ``lambda_max(P)``, maximizing the guaranteed rate
        ``lambda_min(Q) / lambda_max(P)``, under ``||W|| <= max_gain``.
    max_gain : float, optional
        Bound on ``||W||_2`` (and so on ``||L||_2``); required with ``"max_decay"``.
    solver : str, optional
        cvxpy solver name (default: Clarabel, else SCS).
    region : Region, optional
        Where the slope bounds of ``vertices`` hold, when not everywhere (``x_1^3``
        has slope in ``[0, 12]`` only on ``|x_1| <= 2``): recorded on the result, stated
        by certificates, checked on runs by :func:`~etobs.design.runs_leaving`.

    Returns
    -------
    ObserverGain
        Re-checked with eigenvalues; see :attr:`ObserverGain.ok`.

    Raises
    ------
    DesignError
        When the LMIs are infeasible, the solver fails, or the answer fails the re-check.

    """
    cp = _cvxpy()
    Am, Cm, verts, Qm = _system(A, C, vertices, Q)
    v.real("margin", margin, lower=0.0, lower_open=True)
    if objective not in OBJECTIVES:
        raise InputError(f"`objective` must be one of {OBJECTIVES}; got {objective!r}")
    if objective == "max_decay" and max_gain is None:
        raise InputError(
            "`max_gain` is required with objective='max_decay' (the rate is unbounded otherwise)"
        )
    if max_gain is not None:
        v.real("max_gain", max_gain, lower=0.0, lower_open=True)
    # The solver meets the inequalities up to its own accuracy, relative to the size of
    # P and W; a margin below that accuracy does not survive the eigenvalue re-check, so
    # the margin grows tenfold until the answer passes (or is a sizeable share of Q).
    cap = 1e-2 * float(np.linalg.eigvalsh(Qm).min())
    if margin > cap:
        raise InputError(f"`margin` must be <= 1 % of lambda_min(Q) = {cap:g}; got {margin:g}")
    mu = float(margin)
    while True:
        out = _design(cp, Am, Cm, verts, Qm, mu, objective, max_gain, solver)
        if out.ok:
            origin = f"designed together with L by observer_gain (objective {objective!r})"
            return replace(out, origin=origin, region=_region(region, Am.shape[0]))
        if mu * 10 > cap:
            break
        mu *= 10
    raise DesignError(
        f"the solver's answer fails the eigenvalue re-check (solver status {out.solver_status!r}) with "
        f"margins up to {mu:g}: largest vertex residual {out.residuals.max():.3g} (must be < 0); "
        "try another solver or a smaller `max_gain`"
    )


def _design(
    cp: Any,
    Am: np.ndarray,
    Cm: np.ndarray,
    verts: tuple[np.ndarray, ...],
    Qm: np.ndarray,
    margin: float,
    objective: str,
    max_gain: float | None,
    solver: str | None,
) -> ObserverGain:
    """One solve of the design LMIs with the given margin, re-checked."""
    n, p = Am.shape[0], Cm.shape[0]
    P = cp.Variable((n, n), symmetric=True)
    W = cp.Variable((n, p))
    eye = np.eye(n)
    cons = [P >> eye]  # normalization (the LMIs are homogeneous in P, W, Q): ||L|| <= ||W||
    for Ak in verts:
        M = P @ (Am + Ak) - W @ Cm
        cons.append(M + M.T << -Qm - margin * eye)
    if max_gain is not None:
        cons.append(cp.sigma_max(W) <= max_gain)
    if objective == "min_gain":
        goal = cp.Minimize(cp.sigma_max(W))
    else:
        t = cp.Variable()
        cons.append(P << t * eye)
        goal = cp.Minimize(t)
    status = _solve(cp.Problem(goal, cons), solver)
    if P.value is None or W.value is None:
        raise DesignError(f"the observer LMIs have no solution: the solver reported {status!r}")
    Pv = _sym(P.value)
    return _recheck(Am, Cm, verts, Qm, np.linalg.solve(Pv, W.value), Pv, status, margin)


def check_gain(
    A: Any,
    C: Any,
    L: Any,
    vertices: Sequence[Any] = (),
    *,
    P: Any = None,
    Q: Any = None,
    margin: float = 1e-6,
    solver: str | None = None,
    region: Region | None = None,
) -> ObserverGain:
    """Whether a given ``L`` satisfies the LMIs, for a given ``P`` or for some ``P``.

    With ``P`` (e.g. the :attr:`ObserverGain.P` of a design) the LMIs are only
    re-checked with eigenvalues at that ``P``; no solver runs. Without it, finds ``P``
    with ``trace(P) = 1`` maximizing ``s`` such that every vertex has
    ``P A_cl,k + A_cl,k' P <= -s I``; if ``s > 0``, ``P`` is scaled so that the
    inequalities hold with ``Q`` (they are homogeneous in ``P``) and re-checked. That
    ``P`` is one of many: the guarantees built on it (ISS gains, certificates) differ
    from those built on the ``P`` designed together with ``L``, and either may be the
    smaller, so pass the designed ``P`` to certify a design as designed.

    Parameters
    ----------
    A, C, L, vertices
        As in :func:`observer_gain`, with ``L`` of shape (n_x, n_y).
    P : array_like, shape (n_x, n_x), optional
        Lyapunov matrix to re-check, symmetric (up to 1e-9 relative; its symmetric part
        is used).
    Q, margin, solver
        As in :func:`observer_gain`. With ``P`` no solver runs (``solver`` is refused),
        and a re-check that holds by less than ``margin`` gets a note.
    region : Region, optional
        As in :func:`observer_gain`: where the slope bounds of ``vertices`` hold.

    Returns
    -------
    ObserverGain
        ``ok`` tells whether ``L`` satisfies the LMIs; ``notes`` say why not, and
        ``origin`` how ``P`` was found.

    """
    Am, Cm, verts, Qm = _system(A, C, vertices, Q)
    Lm = v.matrix("L", L, (Am.shape[0], Cm.shape[0]))
    v.real("margin", margin, lower=0.0, lower_open=True)
    return replace(_check(Am, Cm, verts, Qm, Lm, P, margin, solver), region=_region(region, Am.shape[0]))


def _check(
    Am: np.ndarray,
    Cm: np.ndarray,
    verts: tuple[np.ndarray, ...],
    Qm: np.ndarray,
    Lm: np.ndarray,
    P: Any,
    margin: float,
    solver: str | None,
) -> ObserverGain:
    """:func:`check_gain` on validated matrices."""
    n = Am.shape[0]
    if P is not None:
        if solver is not None:  # no solver runs for a given P: say so rather than ignore it
            raise InputError(
                f"`solver` = {solver!r} has no use with `P`: a given P is re-checked with eigenvalues"
            )
        Pm = v.matrix("P", P, (n, n))
        if np.max(np.abs(Pm - Pm.T)) > 1e-9 * max(1.0, float(np.max(np.abs(Pm)))):
            asym = float(np.max(np.abs(Pm - Pm.T)))
            raise InputError(f"`P` must be symmetric; got P - P' with largest entry {asym:.3g}")
        out = _recheck(Am, Cm, verts, Qm, Lm, _sym(Pm), "P given", margin)
        out = replace(out, origin="given with L (re-checked with eigenvalues)")
        worst = int(np.argmax(out.residuals))
        if out.residuals[worst] >= 0:
            out = _with_notes(
                out,
                f"the given P does not fit L and Q: P A_cl + A_cl' P + Q has the eigenvalue "
                f"{out.residuals[worst]:.3g} at vertex {worst} (must be < 0)",
            )
        elif out.residuals[worst] >= -margin:  # holds, but closer to 0 than the margin asked for
            out = _with_notes(
                out,
                f"the given P fits L and Q by less than margin = {margin:g}: P A_cl + A_cl' P + Q "
                f"has the eigenvalue {out.residuals[worst]:.3g} at vertex {worst}",
            )
        return out
    cp = _cvxpy()
    P_ = cp.Variable((n, n), symmetric=True)
    s = cp.Variable()
    cons = [P_ >> 0, cp.trace(P_) == 1]
    for Ak in verts:
        Acl = Am + Ak - Lm @ Cm
        cons.append(P_ @ Acl + Acl.T @ P_ << -s * np.eye(n))
    status = _solve(cp.Problem(cp.Maximize(s), cons), solver)
    if P_.value is None or s.value is None:
        raise DesignError(f"could not test the gain: the solver reported {status!r}")
    best = float(s.value)
    if best <= margin:
        Pv = _sym(P_.value)
        out = _recheck(Am, Cm, verts, Qm, Lm, Pv, status, margin)
        note = f"no common quadratic Lyapunov function: the best decrease is {best:.3g} (needs > 0)"
        return _with_notes(out, note)
    # The inequalities are homogeneous in P: with the decrease s_true measured by
    # eigenvalues at the solver's P, scaling P by (lambda_max(Q) + margin) / s_true makes
    # every vertex satisfy P A_cl + A_cl' P <= -(lambda_max(Q) + margin) I <= -Q - margin I.
    Pv = _sym(P_.value)
    s_true = -max(
        np.linalg.eigvalsh(_sym(Pv @ (Am + Ak - Lm @ Cm) + (Am + Ak - Lm @ Cm).T @ Pv)).max() for Ak in verts
    )
    if s_true <= 0:
        out = _recheck(Am, Cm, verts, Qm, Lm, Pv, status, margin)
        return _with_notes(out, f"the solver's P gives no decrease when re-checked (best {s_true:.3g})")
    Pv = Pv * (np.linalg.eigvalsh(Qm).max() + margin) / s_true
    out = _recheck(Am, Cm, verts, Qm, Lm, Pv, "given", margin)
    return replace(
        out,
        origin="found by check_gain for the given L (the trace-1 P with the largest common decrease, "
        "scaled to meet Q); another P, such as the one designed with L, gives other bounds",
    )


def _system(A: Any, C: Any, vertices: Sequence[Any], Q: Any) -> tuple[np.ndarray, ...]:
    Am = v.matrix("A", A, (None, None))
    n = Am.shape[0]
    if Am.shape[1] != n:
        raise InputError(f"`A` must be square; got shape {Am.shape}")
    Cm = v.matrix("C", C, (None, n))
    verts = tuple(v.matrix(f"vertices[{k}]", Ak, (n, n)) for k, Ak in enumerate(vertices)) or (
        np.zeros((n, n)),
    )
    Qm = np.eye(n) if Q is None else v.matrix("Q", Q, (n, n))
    if not np.allclose(Qm, Qm.T) or np.linalg.eigvalsh(_sym(Qm)).min() <= 0:
        raise InputError("`Q` must be symmetric positive definite")
    return Am, Cm, verts, _sym(Qm)


def _recheck(
    A: np.ndarray,
    C: np.ndarray,
    verts: tuple[np.ndarray, ...],
    Q: np.ndarray,
    L: np.ndarray,
    P: np.ndarray,
    status: str,
    margin: float,
) -> ObserverGain:
    """Eigenvalue re-check of the LMIs at the solution (never trust the solver's status alone)."""
    res, absc = [], []
    for Ak in verts:
        Acl = A + Ak - L @ C
        res.append(np.linalg.eigvalsh(_sym(P @ Acl + Acl.T @ P + Q)).max())
        absc.append(np.linalg.eigvals(Acl).real.max())
    notes = ()
    if np.linalg.eigvalsh(P).min() <= 0:
        notes = ("P is not positive definite",)
    return ObserverGain(
        L=L,
        P=P,
        Q=Q,
        vertices=verts,
        residuals=np.array(res),
        abscissa=np.array(absc),
        solver_status=status,
        margin=margin,
        notes=notes,
    )


def _region(region: Region | None, n_x: int) -> Region | None:
    """``region`` checked to be a :class:`Region` of ``n_x`` components (or ``None``)."""
    if region is None:
        return None
    if not isinstance(region, Region):
        raise InputError(f"`region` must be a Region (etobs.design.Region); got {type(region).__name__}")
    if region.low.size != n_x:
        raise InputError(f"`region` must bound the {n_x} plant states; got {region.low.size} components")
    return region


def _with_notes(gain: ObserverGain, note: str) -> ObserverGain:
    return replace(gain, notes=(*gain.notes, note))


def _solve(problem: Any, solver: str | None) -> str:
    """Solve with the named solver, or Clarabel then SCS; warn when a solver says *inaccurate*."""
    cp = _cvxpy()
    names = [solver] if solver else [s for s in ("CLARABEL", "SCS") if s in cp.installed_solvers()]
    failures = []
    for name in names:
        try:
            with warnings.catch_warnings():  # cvxpy's own warning; ours below says what follows
                warnings.filterwarnings("ignore", message="Solution may be inaccurate", category=UserWarning)
                problem.solve(solver=name)
        except cp.error.SolverError as exc:
            failures.append(f"{name}: {exc}")
            continue
        status = str(problem.status)
        if status.endswith("inaccurate"):
            warnings.warn(
                f"the SDP solver {name} reports {status!r}: the answer is re-checked with eigenvalues",
                RuntimeWarning,
                stacklevel=3,
            )
        return status
    raise DesignError("the SDP solver failed: " + "; ".join(failures))


def _sym(M: np.ndarray) -> np.ndarray:
    return (M + M.T) / 2


def _cvxpy() -> Any:
    try:
        import cvxpy
    except ImportError as exc:
        raise InputError(
            "LMI design needs the optional dependency cvxpy; install it with `pip install 'etobs[design]'`"
        ) from exc
    return cvxpy
