"""The fast hybrid solver: a batch of runs advanced together, one step size per run.

Solver contract (what :func:`solve` guarantees for every run of the batch):

1. Along flows the state follows ``flow`` with an embedded Runge--Kutta pair
   (``SolverOptions.method``) under local error control (``rtol``, ``atol``).
2. Every event function is evaluated at the start, at ``event_samples - 1`` interior
   points (on the method's own dense output) and at the end of every accepted step, so
   an excursion above zero longer than ``step / event_samples`` is never missed; at
   each negative interior local maximum of those samples a parabola predicts the peak,
   and a predicted peak ``>= 0`` is probed too (catching most shorter excursions).
3. The first crossing is located by bracketing root finding on the dense output to a
   bracket of width ``event_xtol`` in time; the event time reported is the right end,
   where the event function is ``>= 0``, and the state there comes from the dense output.
4. At an event every rule with ``g_k >= 0`` jumps once, in rule order, each with its own
   ``j``; the event functions are then evaluated again and the jumps repeat until all
   are negative (bounded by ``max_jumps``).
5. A run ends with status ``completed`` at ``t_end`` or with a failure status of its own
   (``max_jumps``, ``max_steps``, ``nonfinite``, ``step_underflow``); other runs go on.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.errors import InputError, InputTypeError, ModelError
from etobs.hybrid.options import SaveAt, SolverOptions
from etobs.hybrid.recorder import Recorder
from etobs.hybrid.rootfind import bracket_root
from etobs.hybrid.solution import HybridSolution
from etobs.hybrid.status import Status
from etobs.hybrid.system import BatchedSystem, HybridSystem

# Step-size controller constants, as in Hairer, Nørsett & Wanner (1993), II.4.
SAFETY = 0.9  # keep the next error estimate below the tolerance with margin
MIN_FACTOR = 0.2  # never shrink a step by more than 5x at once
MAX_FACTOR = 10.0  # never grow a step by more than 10x at once


#: The solvers of :func:`solve`.
BACKENDS = ("auto", "engine", "numpy", "scipy")


def check_inputs(system: Any, x0: Any, t_span: Any) -> tuple[np.ndarray, float, float]:
    """Validate the arguments shared by the batched solvers; return ``(x0 (B, n), t0, t_end)``."""
    if not isinstance(system, BatchedSystem):
        raise InputTypeError(f"`system` must be a HybridSystem; got {type(system).__name__}")
    t0, t_end = span(t_span)
    return v.batch("x0", x0, system.n), t0, t_end


def span(t_span: Any) -> tuple[float, float]:
    """Validate a time span ``(t0, t_end)`` with ``t0 <= t_end``."""
    try:
        t0, t_end = t_span
    except (TypeError, ValueError) as exc:
        raise InputError(f"`t_span` must be a pair (t0, t_end); got {t_span!r}") from exc
    t0 = v.real("t_span[0]", t0)
    t_end = v.real("t_span[1]", t_end)
    if t_end < t0:
        raise InputError(f"`t_span` must satisfy t0 <= t_end; got ({t0:g}, {t_end:g})")
    return t0, t_end


def solve(
    system: HybridSystem | BatchedSystem,
    x0: Any,
    t_span: Any,
    *,
    options: SolverOptions | None = None,
    save: SaveAt | None = None,
    backend: str = "auto",
) -> HybridSolution:
    """Solve a batch of runs of a hybrid system (the front door of :mod:`etobs.hybrid`).

    Parameters
    ----------
    system : HybridSystem
        Written for one run (see :class:`~etobs.hybrid.HybridSystem`).
    x0 : array_like, shape (n,) or (B, n)
        Initial state of each run.
    t_span : (float, float)
        Start and end time, common to all runs.
    options : SolverOptions, optional
    save : SaveAt, optional
        What to keep (default: the full hybrid arcs).
    backend : {"auto", "engine", "numpy", "scipy"}
        ``"auto"`` and ``"engine"``: the compiled engine (:mod:`etobs.hybrid.compiled`);
        ``"numpy"``: the batched numpy solver of this module; ``"scipy"``: the
        ``solve_ivp`` reference, which calls the Python functions as they are. All
        follow the contract in the module docstring.

    Returns
    -------
    HybridSolution

    Examples
    --------
    A bouncing ball, ``x = (height, velocity)``, restitution 0.5:

    >>> import numpy as np
    >>> from etobs.hybrid import HybridSystem, solve
    >>> ball = HybridSystem(
    ...     n=2, n_rules=1,
    ...     flow=lambda t, x: np.array([x[1], -9.81]),
    ...     guard=lambda t, x: np.array([-x[0] if x[1] < 0 else -1.0]),
    ...     jump=lambda k, t, x: np.array([0.0, -0.5 * x[1]]),
    ... )
    >>> [round(float(solve(ball, [1.0, 0.0], (0.0, 1.0), backend=b).jumps.t[0]), 6)
    ...  for b in ("engine", "numpy", "scipy")]  # sqrt(2 / 9.81)
    [0.451524, 0.451524, 0.451524]

    """
    if backend not in BACKENDS:
        raise InputError(f"`backend` must be one of {BACKENDS}; got {backend!r}")
    if isinstance(system, HybridSystem):
        if backend in ("auto", "engine"):
            from etobs.hybrid.compiled import solve_compiled

            params = system.params if system.params.size else None
            return solve_compiled(system.compiled(), x0, t_span, params=params, options=options, save=save)
        if backend == "scipy":
            from etobs.hybrid.reference import solve_reference

            return solve_reference(system, x0, t_span, options=options, save=save)
        system = system.batched(compiled=True)
    elif isinstance(system, BatchedSystem):
        if backend == "scipy":
            from etobs.hybrid.reference import solve_reference

            return solve_reference(system, x0, t_span, options=options, save=save)
        if backend == "engine":
            raise InputError("backend='engine' needs a HybridSystem written for one run; got a BatchedSystem")
    x, t0, t_end = check_inputs(system, x0, t_span)
    return _FastSolver(system, x, t0, t_end, options or SolverOptions(), save or SaveAt()).run()


def _checked(name: str, out: Any, shape: tuple[int, ...]) -> np.ndarray:
    arr = np.asarray(out, dtype=float)
    if arr.shape != shape:
        raise ModelError(f"`{name}` returned an array of shape {arr.shape}; expected {shape}")
    return arr


class _FastSolver:
    def __init__(
        self,
        system: BatchedSystem,
        x0: np.ndarray,
        t0: float,
        t_end: float,
        opts: SolverOptions,
        save: SaveAt,
    ) -> None:
        self.sys, self.opts, self.t0, self.t_end = system, opts, t0, t_end
        from etobs.hybrid.tableau import TABLEAUS  # imports scipy.integrate: only for this solver

        self.tab = TABLEAUS[opts.method]
        self.err_exp = -1.0 / (self.tab.error_order + 1)
        b, n = x0.shape
        self.B, self.n, self.m = b, n, system.n_rules
        self.n_flow = n if system.n_flow is None else system.n_flow
        self.t = np.full(b, t0)
        self.x = x0.copy()
        self.j = np.zeros(b, dtype=np.int64)
        self.status = np.full(b, Status.RUNNING, dtype=np.int64)
        self.n_steps = np.zeros(b, dtype=np.int64)
        self.n_rejected = np.zeros(b, dtype=np.int64)
        self.g = np.empty((b, self.m))
        self.f = np.zeros((b, n))
        self.h = np.zeros(b)
        self.rejected = np.zeros(b, dtype=bool)
        self.rec = Recorder(b, n, save, t0)

    # -- user functions with shape checks ---------------------------------------------
    def flow(self, t: np.ndarray, x: np.ndarray) -> np.ndarray:
        return _checked("flow", self.sys.flow(t, x), x.shape)

    def guard(self, t: np.ndarray, x: np.ndarray) -> np.ndarray:
        return _checked("guard", self.sys.guard(t, x), (x.shape[0], self.m))

    # -- driver -----------------------------------------------------------------------
    def run(self) -> HybridSolution:
        runs = np.arange(self.B)
        self.rec.steps(runs, self.t, self.j, self.x)
        row, g = self.rec.grid_due(runs, self.t)
        self.rec.grid_fill(runs[row], g, self.j[row], self.x[row])
        self._jump_until_flow(runs)
        live = runs[self.status == Status.RUNNING]
        self._refresh_flow(live)
        live = live[self.status[live] == Status.RUNNING]
        if live.size:
            if self.opts.first_step is not None:
                self.h[live] = self.opts.first_step
            else:
                self.h[live] = self._initial_step(live)
        # Overflow and invalid operations are expected here: a run whose state becomes
        # non-finite is stopped with status ``nonfinite``, so numpy need not warn.
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            while True:
                act = np.flatnonzero(self.status == Status.RUNNING)
                if act.size == 0:
                    break
                self._advance(act)
        return HybridSolution(
            t_span=(self.t0, self.t_end),
            status=self.status.copy(),
            t_final=self.t.copy(),
            j_final=self.j.copy(),
            x_final=self.x.copy(),
            jumps=self.rec.jump_log(),
            arcs=self.rec.arcs(),
            grid=self.rec.saved_grid(),
            n_steps=self.n_steps,
            n_rejected=self.n_rejected,
            rule_names=self.sys.rule_names,
            backend="numpy",
        )

    def _refresh_flow(self, runs: np.ndarray) -> None:
        """Recompute ``f`` after a jump; mark runs whose derivative is not finite."""
        if runs.size == 0:
            return
        f = self.flow(self.t[runs], self.x[runs])
        done = self.t[runs] >= self.t_end
        bad = ~np.all(np.isfinite(f), axis=1) & ~done
        self.status[runs[bad]] = Status.NONFINITE
        self.status[runs[done]] = Status.COMPLETED
        self.f[runs] = f

    def _initial_step(self, runs: np.ndarray) -> np.ndarray:
        """Hairer, Nørsett & Wanner (1993), II.4: a first step from two flow evaluations."""
        o = self.opts
        t, x_all, f_all = self.t[runs], self.x[runs], self.f[runs]
        nf = self.n_flow  # entries constant along flows are left out of the norms
        x, f = (np.ascontiguousarray(a[:, :nf]) for a in (x_all, f_all)) if nf < self.n else (x_all, f_all)
        remaining = self.t_end - t
        scale = o.atol + o.rtol * np.abs(x)
        d0 = np.sqrt(np.mean((x / scale) ** 2, axis=1))
        d1 = np.sqrt(np.mean((f / scale) ** 2, axis=1))
        with np.errstate(divide="ignore", invalid="ignore"):
            h0 = np.where((d0 < 1e-5) | (d1 < 1e-5), 1e-6, 0.01 * d0 / d1)
        h0 = np.minimum(h0, np.maximum(remaining, 1e-12))
        f1 = self.flow(t + h0, x_all + h0[:, None] * f_all)
        df = np.ascontiguousarray(f1[:, :nf]) - f if nf < self.n else f1 - f
        d2 = np.sqrt(np.mean((df / scale) ** 2, axis=1)) / h0
        big = np.maximum(d1, d2)
        with np.errstate(divide="ignore"):
            h1 = np.where(
                big <= 1e-15,
                np.maximum(1e-6, h0 * 1e-3),
                (0.01 / big) ** (1.0 / (self.tab.error_order + 1)),
            )
        h = np.minimum(np.minimum(100 * h0, h1), o.max_step)
        # A trial point where the flow is not finite gives a NaN or zero estimate:
        # fall back to the first guess, whose step control then takes over.
        return np.where(np.isfinite(h) & (h > 0), h, np.minimum(h0, o.max_step))

    # -- jumps ------------------------------------------------------------------------
    def _jump_until_flow(self, runs: np.ndarray) -> None:
        """Apply jumps to ``runs`` until every event function is negative."""
        runs = runs[self.status[runs] == Status.RUNNING]
        while runs.size:
            g = self.guard(self.t[runs], self.x[runs])
            self.g[runs] = g
            fire = g >= 0
            has = fire.any(axis=1)
            runs, fire = runs[has], fire[has]
            for k in range(self.m):
                rk = runs[fire[:, k]]
                rk = rk[self.status[rk] == Status.RUNNING]
                if rk.size == 0:
                    continue
                over = self.j[rk] >= self.opts.max_jumps
                self.status[rk[over]] = Status.MAX_JUMPS
                rk = rk[~over]
                if rk.size == 0:
                    continue
                xn = _checked("jump", self.sys.jump(k, self.t[rk], self.x[rk]), (rk.size, self.n))
                self.rec.jumps(rk, k, self.t[rk], self.j[rk])
                self.j[rk] += 1
                self.x[rk] = xn
                self.rec.steps(rk, self.t[rk], self.j[rk], xn)
                bad = ~np.all(np.isfinite(xn), axis=1)
                self.status[rk[bad]] = Status.NONFINITE
            runs = runs[self.status[runs] == Status.RUNNING]

    # -- one step of every active run -------------------------------------------------
    def _advance(self, act: np.ndarray) -> None:
        o, tab = self.opts, self.tab
        t, x, f = self.t[act], self.x[act], self.f[act]
        remaining = self.t_end - t
        h = np.minimum(np.minimum(self.h[act], o.max_step), remaining)
        last = h >= remaining
        K, x_new = tab.step(self.flow, t, x, f, h)
        if self.n_flow < self.n:  # entries constant along flows are left out of the norm
            # (contiguous copies: a run's rounding must not depend on its batch)
            nf = self.n_flow
            K_, x_, xn_ = (np.ascontiguousarray(a[..., :nf]) for a in (K, x, x_new))
            err = tab.error_norm(K_, h, x_, xn_, o.rtol, o.atol)
        else:
            err = tab.error_norm(K, h, x, x_new, o.rtol, o.atol)
        finite = np.isfinite(err) & np.all(np.isfinite(x_new), axis=1)
        finite &= np.all(np.isfinite(K[-1]), axis=1)
        accept = finite & (err <= 1.0)
        with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
            factor = np.clip(SAFETY * err**self.err_exp, MIN_FACTOR, MAX_FACTOR)
        factor = np.where(err == 0.0, MAX_FACTOR, factor)
        factor = np.where(finite, factor, MIN_FACTOR)
        # After a rejection, the next accepted step may not grow (Hairer et al., II.4).
        factor = np.where(~accept | self.rejected[act], np.minimum(factor, 1.0), factor)
        self.rejected[act] = ~accept
        h_next = h * factor
        self.n_steps[act[accept]] += 1
        self.n_rejected[act[~accept]] += 1
        # A rejected step that can no longer shrink ends its run.
        tiny = ~accept & ~(h_next > 4.0 * np.spacing(np.maximum(np.abs(t), 1.0)))
        self.status[act[tiny & finite]] = Status.STEP_UNDERFLOW
        self.status[act[tiny & ~finite]] = Status.NONFINITE
        self.h[act] = np.where(last & accept, np.maximum(self.h[act], h_next), h_next)
        too_many = (self.n_steps[act] + self.n_rejected[act]) >= o.max_steps
        ia = np.flatnonzero(accept)
        if ia.size:
            self._accept(act[ia], t[ia], x[ia], h[ia], last[ia], K[:, ia], x_new[ia])
        still = act[too_many]
        self.status[still[self.status[still] == Status.RUNNING]] = Status.MAX_STEPS

    def _accept(
        self,
        runs: np.ndarray,
        t0: np.ndarray,
        x0: np.ndarray,
        h: np.ndarray,
        last: np.ndarray,
        K: np.ndarray,
        x1: np.ndarray,
    ) -> None:
        tab, m = self.tab, self.m
        M = runs.size
        f1 = K[-1]
        t1 = np.where(last, self.t_end, t0 + h)
        g0 = self.g[runs]
        g1 = self.guard(t1, x1)
        # Every accepted step is screened on the method's dense output; a cheaper
        # interpolant (cubic Hermite) can hide a long excursion when the event
        # function is sensitive to the state, so it is not used here.
        Q = tab.dense(self.flow, t0, x0, x1, K, h) if (m or self.rec.grid_t is not None) else None

        def at(rows: np.ndarray, th: np.ndarray) -> np.ndarray:
            """Dense-output state of step rows ``rows`` at ``θ = th``."""
            if Q is None:  # pragma: no cover - only reached when Q was built
                raise RuntimeError("dense output requested but not built")
            return tab.evaluate(Q[:, rows], x0[rows], th)

        theta_ev = np.full(M, np.nan)
        if m:
            theta_ev[:] = self._locate(np.arange(M), at, t0, h, g0, g1)
        ev = np.flatnonzero(np.isfinite(theta_ev))
        t_stop = t1.copy()
        x_stop = x1.copy()
        if ev.size:
            inner = ev[theta_ev[ev] < 1.0]
            t_stop[inner] = t0[inner] + theta_ev[inner] * h[inner]
            x_stop[inner] = at(inner, theta_ev[inner])

        # Grid values up to the stop time, before any jump there.
        row, gidx = self.rec.grid_due(runs, t_stop)
        if row.size:
            th = np.clip((self.rec.grid_t[gidx] - t0[row]) / h[row], 0.0, 1.0)
            self.rec.grid_fill(runs[row], gidx, self.j[runs[row]], at(row, th))

        self.t[runs] = t_stop
        self.x[runs] = x_stop
        self.rec.steps(runs, t_stop, self.j[runs], x_stop)
        flowing = np.ones(M, dtype=bool)
        flowing[ev] = False
        fr = runs[flowing]
        self.f[fr] = f1[flowing]
        self.g[fr] = g1[flowing]
        self.status[fr[last[flowing]]] = Status.COMPLETED
        if ev.size:
            er = runs[ev]
            self._jump_until_flow(er)
            self._refresh_flow(er[self.status[er] == Status.RUNNING])

    def _locate(self, cand, at, t0, h, g0, g1) -> np.ndarray:
        """θ of the first event in each candidate step (NaN where there is none).

        The event functions are sampled on the dense output at ``event_samples - 1``
        uniform interior points, the step end and one peak probe (:func:`_peak_probe`);
        the first sign change is then bracketed and refined.
        """
        m, S = self.m, self.opts.event_samples
        C = cand.size
        thetas = np.ones((C, S + 1))
        gall = np.broadcast_to(g1[cand][:, None, :], (C, S + 1, m)).copy()
        if S > 1:
            thetas[:, : S - 1] = np.arange(1, S) / S
            rows = np.repeat(cand, S - 1)
            ths = thetas[:, : S - 1].ravel()
            gs = self.guard(t0[rows] + ths * h[rows], at(rows, ths)).reshape(C, S - 1, m)
            gall[:, : S - 1] = gs
            probe = peak_probe(np.concatenate([g0[cand][:, None], gs, g1[cand][:, None]], axis=1))
            pr = np.flatnonzero(np.isfinite(probe))
            if pr.size:
                r = cand[pr]
                thetas[pr, S] = probe[pr]
                gall[pr, S] = self.guard(t0[r] + probe[pr] * h[r], at(r, probe[pr]))
            order = np.argsort(thetas, axis=1, kind="stable")
            thetas = np.take_along_axis(thetas, order, axis=1)
            gall = np.take_along_axis(gall, order[:, :, None], axis=1)
        hit = (gall >= 0).any(axis=2)
        has = hit.any(axis=1)
        out = np.full(C, np.nan)
        if not has.any():
            return out
        c_idx = np.flatnonzero(has)
        k = hit[c_idx].argmax(axis=1)
        g_left = np.where((k == 0)[:, None], g0[cand[c_idx]], gall[c_idx, np.maximum(k - 1, 0)])
        g_right = gall[c_idx, k]
        lo_all = np.where(k == 0, 0.0, thetas[c_idx, np.maximum(k - 1, 0)])
        hi_all = thetas[c_idx, k]
        cross = (g_left < 0) & (g_right >= 0)
        pr, rule = np.nonzero(cross)
        rows = cand[c_idx[pr]]

        def fun(sel: np.ndarray, th: np.ndarray) -> np.ndarray:
            r = rows[sel]
            return self.guard(t0[r] + th * h[r], at(r, th))[np.arange(sel.size), rule[sel]]

        # θ-tolerance floored at the float resolution of θ (very long steps).
        xtol = np.maximum(self.opts.event_xtol / h[rows], 4 * np.finfo(float).eps)
        _, hi = bracket_root(fun, lo_all[pr], hi_all[pr], g_left[pr, rule], g_right[pr, rule], xtol)
        best = np.full(C, np.inf)
        np.minimum.at(best, c_idx[pr], hi)
        out[c_idx] = best[c_idx]
        return out


def _parabola_peaks(seq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Peaks of the parabolas through each negative interior local maximum of ``seq``.

    ``seq`` (M, S + 1, m) holds event-function values at ``θ = 0, 1/S, ..., 1``. Returns
    the predicted peak values and their θ, shape (M, S - 1, m); ``-inf`` and NaN where
    the sample is not such a maximum.
    """
    S = seq.shape[1] - 1
    left, mid, right = seq[:, :-2], seq[:, 1:-1], seq[:, 2:]
    curv = left - 2.0 * mid + right
    is_max = (mid > left) & (mid >= right) & (mid < 0) & (curv < 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        peak = mid - (right - left) ** 2 / (8.0 * curv)
        theta = (np.arange(1, S)[None, :, None] + (left - right) / (2.0 * curv)) / S
    return np.where(is_max, peak, -np.inf), np.where(is_max, theta, np.nan)


def peak_probe(seq: np.ndarray) -> np.ndarray:
    """Earliest θ per row where a parabola predicts the event function reaches zero.

    At every interior local maximum that is still negative, the parabola through it and
    its two neighbours predicts the peak; this catches a short excursion above zero
    between two samples near a smooth maximum, the typical way a sampled test misses.
    Returns NaN for rows with no such prediction.
    """
    peak, theta = _parabola_peaks(seq)
    theta = np.where(peak >= 0, theta, np.inf)
    best = theta.min(axis=(1, 2)) if theta.shape[1] else np.full(seq.shape[0], np.inf)
    return np.where(np.isfinite(best), best, np.nan)
