"""Hypotheses of the theorems that :func:`~etobs.design.certify` checks or states.

The theorems (sections 5-6) rest on more than their inequalities: the ISS gains of
Assumption 2 must be those of the problem's own observer and plant, the rules must be the
paper's rule (eq. (16)-(17)) with class-K∞ functions, ``tau_i`` of Theorem 4 needs a bound
``E`` on the output rate, and an LMI design on slope bounds holds only where the slopes
do. This module holds the checks a certificate runs and :func:`runs_leaving`, which finds
the simulated runs that leave a design's :class:`Region`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from etobs.errors import InputError
from etobs.model.functions import KFunction, Linear, Power, Quadratic

#: Points of the probe of a K-function on ``[0, s]`` (zero at zero, strictly increasing).
K_PROBE = 4097
#: Log-spaced points of the probe beyond ``s``, up to ``K_TAIL_END``.
K_TAIL = 1024
K_TAIL_END = 1e6
#: Sampled pairs ``(x, xhat)`` at which the ISS gains are tied to the problem's plant and observer.
TIE_SAMPLES = 256
#: Half-width of the sampling box on state components the design's region leaves unbounded.
TIE_BOX = 20.0


@dataclass(frozen=True)
class Region:
    """A box ``low <= x <= high`` of plant states (``-inf``/``inf`` where unbounded).

    The slope bounds of an LMI design (:func:`~etobs.design.slope_vertices`) often hold
    only in such a region (``x_1^3`` has slope ``3 x_1^2 <= 12`` on ``|x_1| <= 2``); the
    Lyapunov decrease, hence the ISS gains and every certificate built on them, then
    holds only while ``x`` and ``xhat`` stay in it (:func:`runs_leaving` finds the runs
    that do not).

    Examples
    --------
    >>> str(Region([-2.0, -np.inf], [2.0, np.inf]))
    '-2 <= x[0] <= 2'

    """

    low: Any
    high: Any

    def __post_init__(self) -> None:
        low = np.array(self.low, dtype=float, ndmin=1)
        high = np.array(self.high, dtype=float, ndmin=1)
        if low.ndim != 1 or high.shape != low.shape:
            raise InputError(
                f"`low` and `high` of a Region must be vectors of one length; got shapes {low.shape} "
                f"and {high.shape}"
            )
        if np.any(np.isnan(low)) or np.any(np.isnan(high)) or np.any(low > high):
            raise InputError(
                f"a Region needs low <= high (no NaN); got low = {low.tolist()}, high = {high.tolist()}"
            )
        for name, arr in (("low", low), ("high", high)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    def contains(self, x: np.ndarray) -> np.ndarray:
        """Whether each state (last axis) lies in the box."""
        x = np.asarray(x, dtype=float)
        return np.all((x >= self.low) & (x <= self.high), axis=-1)

    def __str__(self) -> str:
        parts = []
        for k, (lo, hi) in enumerate(zip(self.low, self.high, strict=True)):
            if math.isfinite(lo) and math.isfinite(hi):
                parts.append(f"{lo:g} <= x[{k}] <= {hi:g}")
            elif math.isfinite(lo):
                parts.append(f"x[{k}] >= {lo:g}")
            elif math.isfinite(hi):
                parts.append(f"x[{k}] <= {hi:g}")
        return ", ".join(parts) or "all x"


def runs_leaving(result: Any, region: Region) -> dict[int, float]:
    """The runs whose plant state ``x`` or estimate ``xhat`` leaves ``region``, with the first time.

    Parameters
    ----------
    result : EstimationResult
        Simulated with saved steps (``SaveAt(steps=True)``, the default) or a grid; the
        check is on the saved points only.
    region : Region
        Typically :attr:`~etobs.design.ObserverGain.region`, where a design's slope bounds hold.

    Returns
    -------
    dict of int to float
        Run index to the first saved time at which ``x`` or ``xhat`` is outside; runs
        that stay inside are absent. A certificate whose ISS gains rest on ``region``
        says nothing about those runs from that time on.

    """
    if not isinstance(region, Region):
        raise InputError(f"`region` must be a Region; got {type(region).__name__}")
    out: dict[int, float] = {}
    for run in range(result.n_runs):
        arc = result.arc(run) if result.solution.arcs is not None else _grid_run(result, run)
        if arc.x.shape[-1] != region.low.size:
            raise InputError(
                f"`region` has {region.low.size} components; the result's plant state has {arc.x.shape[-1]}"
            )
        outside = ~(region.contains(arc.x) & region.contains(arc.xhat))
        if outside.any():
            out[run] = float(np.asarray(arc.t)[np.argmax(outside)])
    return out


def _grid_run(result: Any, run: int) -> Any:
    traj = result.on_grid()
    return type(traj)(**{k: getattr(traj, k)[run] for k in ("t", "j", "x", "z", "xhat", "ybar", "e", "eta")})


def known_class_kinf(fn: KFunction) -> bool:
    """Whether ``fn`` is exactly one of etobs's K∞ functions (class K∞ by its formula)."""
    return type(fn) in (Linear, Quadratic, Power)


def probe_class_k(fn: KFunction, dense_upto: float) -> tuple[bool, str]:
    """Whether ``fn`` is zero at zero and strictly increasing on a probe: a check, not a proof.

    The probe is :data:`K_PROBE` equally spaced points of ``[0, dense_upto]`` (where the
    theorem uses ``fn``: up to ``gamma_i^{-1}(eps_i)`` for Theorem 4) and
    :data:`K_TAIL` log-spaced points from there to :data:`K_TAIL_END` (class K∞ is a
    property of all ``s >= 0``); what lies between the points is not seen, and the message
    says so. etobs's own functions are class K∞ by their formula and are not probed.
    """
    if known_class_kinf(fn):
        return True, f"{fn} is class K-infinity by its formula"
    s = np.linspace(0.0, dense_upto, K_PROBE)
    if dense_upto < K_TAIL_END:
        s = np.concatenate([s, np.geomspace(dense_upto, K_TAIL_END, K_TAIL)[1:]])
    vals = np.asarray(fn(s), dtype=float)
    where = (
        f"probed at {K_PROBE} equally spaced points of [0, {dense_upto:.6g}] and {K_TAIL} log-spaced points "
        f"up to {K_TAIL_END:g}, not between them"
    )
    if not np.all(np.isfinite(vals)):
        k = int(np.argmax(~np.isfinite(vals)))
        return False, f"{fn}({s[k]:.6g}) = {vals[k]} is not finite ({where})"
    if vals[0] != 0.0:
        return False, f"{fn}(0) = {vals[0]:.6g}, not 0 ({where})"
    drops = np.flatnonzero(np.diff(vals) <= 0)
    if drops.size:
        k = int(drops[0])
        return False, (
            f"not strictly increasing: {fn}({s[k]:.6g}) = {vals[k]:.6g} >= {fn}({s[k + 1]:.6g}) = "
            f"{vals[k + 1]:.6g} ({where})"
        )
    return True, f"zero at 0 and strictly increasing ({where})"


def first_crossing(fn: KFunction, level: float) -> float:
    """The least ``s >= 0`` with ``fn(s) = level``: Theorem 4 needs ``gamma_i^{-1}`` at its first crossing.

    ``fn.inverse`` may return a later root of a function that is not monotone (``s + 2
    sin^2(pi s)`` at 1 gives 1.0, where the first crossing is 0.215); the first one is
    found on a :data:`K_PROBE`-point grid of ``[0, fn.inverse(level)]`` and refined.
    """
    upper = float(fn.inverse(np.array(level)))
    if known_class_kinf(fn) or level <= 0 or upper <= 0:
        return max(upper, 0.0)
    s = np.linspace(0.0, upper, K_PROBE)
    above = np.flatnonzero(np.asarray(fn(s), dtype=float) >= level)
    if not above.size:  # fn(upper) is below level by rounding: upper is the first crossing seen
        return upper
    k = int(above[0])
    if k == 0:
        return 0.0
    from scipy.optimize import brentq

    lo, hi = float(s[k - 1]), float(s[k])
    return float(brentq(lambda r: float(fn(np.array(r))) - level, lo, hi, xtol=1e-14))


def tie_gains(problem: Any, iss: Any, seed: int = 0) -> tuple[bool, str]:
    """Whether the ISS gains are those of the problem's observer and plant, on sampled states.

    Gains from :func:`~etobs.design.quadratic_iss_gains` rest on ``L``, ``P`` and ``Q``
    (:attr:`QuadraticISS.L`, ``.P``, ``.Q``) and on the plant and observer the LMIs were
    written for. At :data:`TIE_SAMPLES` seeded pairs ``(x, xhat)`` (in the design's
    :class:`Region`, or a box of half-width :data:`TIE_BOX` where it is unbounded) and
    times in ``[0, 10]`` with the problem's ``u(t)``, this checks

    1. the observer's response to the held outputs is ``L``:
       ``d f_o / d ybar = L`` (central difference; eq. (57) for the Luenberger observer);
    2. the decrease behind Assumption 2 with ``e = 0, v = 0``:
       ``2 xi' P (f_p(x, u, 0) - f_o(xhat, u, h(x), h(xhat))) <= -xi' Q xi``, ``xi = x - xhat``,

    which ties the plant's matrices, its nonlinearity and ``C`` to the LMIs. Observers
    whose state is not ``xhat`` (``n_z != n_x`` or a ``psi``) cannot be tied this way.
    """
    plant, obs = problem.plant, problem.observer
    if iss.P is None or iss.L is None or iss.Q is None:
        return (
            False,
            "the ISS gains carry no P, L and Q (given by hand): they cannot be tied to this observer",
        )
    n_x, n_y = plant.n_x, plant.n_y
    if obs.n_z != n_x or obs.psi is not None:
        return False, (
            f"the observer's state is not xhat (n_z = {obs.n_z}, n_x = {n_x}"
            + (", psi given" if obs.psi is not None else "")
            + "): the quadratic ISS gains of V = xi' P xi cannot be tied to it"
        )
    if iss.L.shape != (n_x, n_y):
        return (
            False,
            f"the ISS gains were computed for L of shape {iss.L.shape}; the problem has ({n_x}, {n_y})",
        )
    rng = np.random.default_rng(seed)
    region = iss.region if iss.region is not None else Region(np.full(n_x, -np.inf), np.full(n_x, np.inf))
    lo = np.where(np.isfinite(region.low), region.low, -TIE_BOX)
    hi = np.where(np.isfinite(region.high), region.high, TIE_BOX)
    lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
    P, Q, L = (np.asarray(m, dtype=float) for m in (iss.P, iss.Q, iss.L))
    box = ", ".join(f"{a:g}..{b:g}" for a, b in zip(lo, hi, strict=True))
    where = f"at {TIE_SAMPLES} sampled (x, xhat) in [{box}]"
    zero_v = np.zeros(plant.n_v)
    worst_gain = worst_decrease = 0.0
    for _ in range(TIE_SAMPLES):
        t = float(rng.uniform(0.0, 10.0))
        u = np.asarray(problem.u(np.array([t])), dtype=float).reshape(-1)
        x, xhat = rng.uniform(lo, hi), rng.uniform(lo, hi)
        y, yhat = _h(plant, x), _h(plant, xhat)
        step = 1e-6 * max(1.0, float(np.abs(y).max()))
        resp = np.column_stack(
            [
                (_f_o(obs, t, xhat, u, y + step * e_j, yhat) - _f_o(obs, t, xhat, u, y - step * e_j, yhat))
                / (2 * step)
                for e_j in np.eye(n_y)
            ]
        )
        worst_gain = max(worst_gain, float(np.abs(resp - L).max()) / max(1.0, float(np.abs(L).max())))
        xi = x - xhat
        dxi = np.asarray(plant.call_f_p(t, x, u, zero_v), dtype=float) - _f_o(obs, t, xhat, u, y, yhat)
        lhs, rhs = 2 * xi @ P @ dxi, -(xi @ Q @ xi)
        worst_decrease = max(worst_decrease, (lhs - rhs) / max(1e-300, xi @ P @ xi))
    if worst_gain > 1e-4:
        return False, (
            f"the observer's response to ybar is not the L of the ISS gains ({where}: largest "
            f"|d f_o/d ybar - L| / max|L| = {worst_gain:.3g}): compute the gains with the observer's own L"
        )
    if worst_decrease > 1e-6:
        return False, (
            f"2 xi' P xi' <= -xi' Q xi fails for this plant and observer ({where}, e = 0, v = 0: excess "
            f"{worst_decrease:.3g} V): the LMIs were written for other matrices or another nonlinearity"
        )
    return True, f"d f_o/d ybar = L and 2 xi' P xi' <= -xi' Q xi hold {where} (e = 0, v = 0)"


def _h(plant: Any, x: np.ndarray) -> np.ndarray:
    return np.asarray(plant.call_h(x), dtype=float).reshape(-1)


def _f_o(obs: Any, t: float, z: np.ndarray, u: np.ndarray, ybar: np.ndarray, yhat: np.ndarray) -> np.ndarray:
    return np.asarray(obs.call_f_o(t, z, u, ybar, yhat), dtype=float).reshape(-1)
