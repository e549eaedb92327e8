"""Reference backend: one run at a time with :func:`scipy.integrate.solve_ivp`.

Slow and simple, it exists to cross-check the engine with an independent
integrator and event locator. Each flow segment is a ``solve_ivp`` call (method
``DOP853``) with one terminal event per rule, restarted after every jump.

``solve_ivp`` tests the sign of an event function only at step ends, so it misses an
excursion above zero that starts and ends inside one step. As a guard, every step of
every segment is also sampled at ``event_samples`` points on ``solve_ivp``'s dense
output, plus the peak probes of :mod:`etobs.hybrid.peaks` where a parabola through three
samples predicts a peak above zero; the earliest crossing found either way is refined
with :func:`scipy.optimize.brentq`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.errors import InputTypeError, ModelError
from etobs.hybrid.checks import check_progress, span, warn_unreached_grid
from etobs.hybrid.options import SaveAt, SolverOptions
from etobs.hybrid.peaks import peak_probes
from etobs.hybrid.recorder import Recorder
from etobs.hybrid.solution import GridMax, HybridSolution, SavedGrid, max_over_grid
from etobs.hybrid.status import Status
from etobs.hybrid.system import BatchedSystem, HybridSystem, raised, read_only
from etobs.hybrid.zeno import zeno_window


def solve_ivp(*args: Any, **kwargs: Any) -> Any:
    """:func:`scipy.integrate.solve_ivp`, imported when the reference first runs.

    ``scipy.integrate`` takes about half a second to import; the engine does not need it.
    """
    from scipy.integrate import solve_ivp as scipy_solve_ivp

    return scipy_solve_ivp(*args, **kwargs)


def _budgeted_dop853(budget: int) -> Any:
    """The ``DOP853`` of scipy, taking at most ``budget`` steps (``solve_ivp`` has no step limit).

    A step beyond the budget fails, so ``solve_ivp`` returns with status -1 at the last
    step taken, and the class's ``ran_out`` says why; the run then ends with
    ``max_steps`` there. Without it a flow segment without events ran to its end however
    many steps it took (``x' = -1e6 x``: 0.5 ms per step, 156,000 steps per second).
    """
    from scipy.integrate import DOP853

    class Budgeted(DOP853):  # type: ignore[misc]  # scipy has no type information: DOP853 is Any
        ran_out = False

        def _step_impl(self) -> tuple[bool, str | None]:
            nonlocal budget
            if budget <= 0:
                type(self).ran_out = True
                return False, "max_steps"
            budget -= 1
            return super()._step_impl()  # type: ignore[no-any-return]

    return Budgeted


def brentq(*args: Any, **kwargs: Any) -> Any:
    """:func:`scipy.optimize.brentq`, imported on first use (see :func:`solve_ivp`)."""
    from scipy.optimize import brentq as scipy_brentq

    return scipy_brentq(*args, **kwargs)


# After brentq (or solve_ivp's own location), the event time is moved right by at most
# this many xtol/4 until an event function is >= 0 there, so the state is in the jump
# set, as in the engine.
_NUDGES = 64

# brentq's bound on iterations: bisection alone halves [a, b] to xtol in under 1100 steps
# from any float interval (brentq's default, 100, failed on a zero-slope root)
_ROOT_ITERATIONS = 1100


def solve_reference(
    system: HybridSystem | BatchedSystem,
    x0: Any,
    t_span: Any,
    *,
    options: SolverOptions | None = None,
    save: SaveAt | None = None,
    progress: Callable[[int], object] | None = None,
) -> HybridSolution:
    """Solve each run with ``solve_ivp``; same arguments and result as :func:`~etobs.hybrid.solve`.

    ``options.method`` is ignored (``solve_ivp``'s ``DOP853`` is always used) and
    ``max_steps`` counts accepted steps. A :class:`HybridSystem`'s Python functions are
    called as they are, uncompiled, on read-only arrays. A function that raises, returns
    the wrong shape or an event function that is NaN ends its run with ``model_error``,
    and ``failures`` names it (as on the engine); other runs go on.
    """
    if isinstance(system, HybridSystem):
        system = system.batched()
    if not isinstance(system, BatchedSystem):
        raise InputTypeError(f"`system` must be a HybridSystem; got {type(system).__name__}")
    t0, t_end = span(t_span)
    X = v.batch("x0", x0, system.n)
    progress = check_progress(progress)
    opts = options or SolverOptions()
    save = save or SaveAt()
    warn_unreached_grid(save.grid, t0, t_end)
    dist = save.distance_pairs(system.n)
    B = X.shape[0]
    rec = Recorder(B, system.n, save, t0, system.log_columns)
    status = np.full(B, Status.RUNNING, dtype=np.int64)
    t_final, j_final = np.full(B, t0), np.zeros(B, dtype=np.int64)
    x_final = X.copy()
    n_steps = np.zeros(B, dtype=np.int64)
    failures = [""] * B
    for b in range(B):
        run = _Run(system, b, X[b], t0, t_end, opts, rec)
        # as in the engine, floating-point trouble inside the solve ends the run with a
        # status (nonfinite, step_underflow), not a warning from solve_ivp's internals
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            try:
                status[b] = run.solve()
            except _Overflowed:
                status[b] = Status.NONFINITE
            except ModelError as exc:  # a model function failed: this run ends, the others go on
                status[b], failures[b] = Status.MODEL_ERROR, str(exc)
        t_final[b], j_final[b], x_final[b], n_steps[b] = run.t, run.j, run.x, run.n_steps
        if progress is not None:
            progress(1)
    return HybridSolution(
        t_span=(t0, t_end),
        status=status,
        t_final=t_final,
        j_final=j_final,
        x_final=x_final,
        jumps=rec.jump_log(),
        arcs=rec.arcs(),
        grid=None if dist.size else rec.saved_grid(),
        n_steps=n_steps,
        n_rejected=np.zeros(B, dtype=np.int64),
        rule_names=system.rule_names,
        backend="scipy",
        failures=tuple(failures),
        grid_max=_grid_max(rec.saved_grid(), dist),
    )


def _grid_max(grid: SavedGrid | None, dist: np.ndarray) -> GridMax | None:
    """``SaveAt(max_distance=...)`` from the grid's states (the engine folds it as it goes)."""
    if grid is None or not dist.size:
        return None
    d = grid.x[..., dist[:, 0]] - grid.x[..., dist[:, 1]]
    return GridMax(grid.t, max_over_grid(np.sqrt(np.sum(d * d, axis=-1))))


class _Run:
    """One run of the reference backend.

    The system is batched; ``solve_ivp`` works on one state of shape ``(n,)``. The
    batch-of-one wrappers around ``flow`` and ``guard`` and the ``m`` event functions
    are built here once per run, not once per segment or per call.
    """

    def __init__(
        self,
        system: BatchedSystem,
        b: int,
        x0: np.ndarray,
        t0: float,
        t_end: float,
        opts: SolverOptions,
        rec: Recorder,
    ) -> None:
        self.sys, self.b, self.opts, self.rec = system, np.array([b]), opts, rec
        self.t, self.x, self.j, self.t_end = t0, x0.copy(), 0, t_end
        self.n_steps = 0
        self.zeno = (-np.inf, 0)  # the Zeno rule's window (etobs.hybrid.zeno)
        self.g_start = np.empty(0)
        self.theta = np.arange(1, opts.event_samples + 1) / opts.event_samples
        # The last point the guard was evaluated at, as (t, x, g): solve_ivp calls its
        # m event functions one by one at the same (t, y), and once more at the start
        # of a segment where jumps() has just evaluated the guard. The key is the
        # identity of x (held here, so it cannot be recycled) and the value of t.
        self.last: tuple[float, np.ndarray, np.ndarray] | None = None
        # Guard values along the dense output of the current segment, by time:
        # locate() and brentq evaluate the bracket ends more than once.
        self.on_dense: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        flow, n = system.flow, system.n

        def fun(t: float, x: np.ndarray) -> np.ndarray:
            dx: np.ndarray = _checked("flow", _call("flow", flow, np.array((t,)), x[None]), (1, n))[0]
            return dx

        self.fun = fun
        self.events = [self._event(k) for k in range(system.n_rules)] or None

    def _event(self, k: int) -> Any:
        def ev(t: float, x: np.ndarray) -> float:
            value: float = self.g1(t, x)[k]
            return value

        ev.terminal = True  # type: ignore[attr-defined]
        ev.direction = 1.0  # type: ignore[attr-defined]
        return ev

    def g1(self, t: float, x: np.ndarray) -> np.ndarray:
        """Event functions at one point, x (n,) -> (m,)."""
        if self.last is not None:
            last_t, last_x, last_g = self.last
            if x is last_x and t == last_t:
                return last_g
        # a copy: the values are remembered, whatever the guard does with its output
        g: np.ndarray = _event_values(
            _call("guard", self.sys.guard, np.array((t,)), x[None]), x[None], self.sys.n_rules
        )[0]
        self.last = (t, x, g)
        return g

    def gk(self, t: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Event functions at many points, t (K,), x (K, n) -> (K, m)."""
        return _event_values(_call("guard", self.sys.guard, t, x), x, self.sys.n_rules)

    def at(self, dense: Any, t: float) -> tuple[np.ndarray, np.ndarray]:
        """State and event functions at ``t`` on the dense output of this segment."""
        hit = self.on_dense.get(t)
        if hit is None:
            x = dense(t)
            hit = self.on_dense[t] = (x, self.g1(t, x))
        return hit

    def keep(self, t: float, x: np.ndarray) -> None:
        self.rec.steps(self.b, np.array([t]), np.array([self.j]), x[None])

    def solve(self) -> Status:
        self.keep(self.t, self.x)
        row, gi = self.rec.grid_due(self.b, np.array([self.t]))
        self.rec.grid_fill(
            self.b[row], gi, np.array([self.j] * row.size), np.repeat(self.x[None], row.size, 0)
        )
        st = self.jumps()
        while st is Status.RUNNING and self.t < self.t_end:
            st = self.segment()
        return Status.COMPLETED if st is Status.RUNNING else st

    def jumps(self) -> Status:
        """Apply jumps until every event function is negative."""
        while True:
            g = self.g1(self.t, self.x)
            fire = np.flatnonzero(g >= 0)
            if fire.size == 0:
                self.g_start = g
                return Status.RUNNING
            for k in fire:
                if self.j >= self.opts.max_jumps:
                    return Status.MAX_JUMPS
                out = _call("jump", self.sys.jump, int(k), np.array([self.t]), self.x[None])
                xn = _checked("jump", out, (1, self.sys.n))[0].copy()
                self.rec.jumps(self.b, int(k), np.array([self.t]), np.array([self.j]), xn[None])
                self.j += 1
                self.x = xn
                self.keep(self.t, xn)
                if not np.all(np.isfinite(xn)):
                    return Status.NONFINITE
                start, count = zeno_window(self.t, *self.zeno, self.opts.zeno_span)
                self.zeno = (start, count)
                if self.opts.zeno_jumps is not None and count > self.opts.zeno_jumps:
                    return Status.ZENO

    def segment(self) -> Status:
        """Flow from the current state to the next event (or the end), then jump."""
        o = self.opts
        # a jump due at the final time (within event_xtol of it) is not applied: the run
        # ends on its flow at t_end (docs/solver.md, "Jumps at the final time")
        cutoff = self.t_end - o.event_xtol
        events = self.events if self.t <= cutoff else None
        try:
            sol, method = self.integrate(events)
        except RuntimeError as exc:
            # solve_ivp's own event location (brentq, 100 iterations to 4 eps) fails on an
            # event function with zero slope at its root ((tau - 1)^3): integrate without
            # its events; the scan below finds the crossing on the dense output
            if "converge" not in str(exc):
                raise
            sol, method = self.integrate(None)
        self.n_steps += sol.t.size - 1
        if sol.status == -1:
            # Report where the integration actually stopped, like the engine.
            self.t, self.x = float(sol.t[-1]), np.asarray(sol.y[:, -1], dtype=float)
            self.keep(self.t, self.x)
            if method.ran_out:
                return Status.MAX_STEPS
            dx = np.asarray(self.fun(self.t, self.x), dtype=float)
            finite = np.all(np.isfinite(self.x)) and np.all(np.isfinite(dx))
            return Status.STEP_UNDERFLOW if finite else Status.NONFINITE
        dense = sol.sol
        self.on_dense = {}
        t_stop, bracket = float(sol.t[-1]), None
        if sol.status == 1:
            t_hit = min(float(te[0]) for te in sol.t_events if te.size)
            bracket = (float(sol.t[-2]) if sol.t.size > 1 else self.t, t_hit)
        # Guard: sample every step (and probe predicted peaks); an earlier crossing
        # overrides solve_ivp's event.
        if events:
            early = self.scan(dense, float(self.t), self.g_start)
            if early is not None and (bracket is None or early[1] < bracket[1]):
                bracket = early
        if bracket is not None:
            t_stop = self.locate(dense, *bracket)
            x_stop = np.asarray(self.at(dense, t_stop)[0], dtype=float)
        else:
            x_stop = np.asarray(sol.y[:, -1], dtype=float)
        if self.rec.keep_steps:
            # every step end before t_stop, then t_stop itself, in one chunk
            t_keep = np.append(sol.t[1:][sol.t[1:] < t_stop], t_stop)
            n_keep = t_keep.size
            x_keep = np.concatenate([sol.y[:, 1:n_keep].T, x_stop[None]])
            self.rec.steps(np.repeat(self.b, n_keep), t_keep, np.full(n_keep, self.j), x_keep)
        row, gi = self.rec.grid_due(self.b, np.array([t_stop]))
        if row.size:
            xs = dense(self.rec.grid_t[gi]).T
            self.rec.grid_fill(self.b[row], gi, np.full(row.size, self.j), xs)
        self.t, self.x = t_stop, x_stop
        if bracket is None:
            self.t = self.t_end
            return Status.RUNNING
        if t_stop > cutoff:  # flow on to t_end, without events
            return Status.RUNNING
        status = self.jumps()
        if status is Status.RUNNING and self.n_steps >= o.max_steps and self.t < self.t_end:
            return Status.MAX_STEPS
        return status

    def integrate(self, events: Any) -> tuple[Any, Any]:
        """``solve_ivp`` from the current state to ``t_end``, stopping at ``events``; and its method."""
        o = self.opts
        first = {"first_step": min(o.first_step, self.t_end - self.t)} if o.first_step else {}
        method = _budgeted_dop853(o.max_steps - self.n_steps)
        sol = solve_ivp(
            self.fun,
            (self.t, self.t_end),
            self.x,
            method=method,
            rtol=o.rtol,
            atol=o.atol,
            max_step=o.max_step,
            events=events,
            dense_output=True,
            **first,
        )
        return sol, method

    def scan(self, dense: Any, t_start: float, g0: np.ndarray) -> tuple[float, float] | None:
        """First sampled crossing on the steps of ``dense``, as a bracket, or None.

        ``g0`` (m,) holds the event functions at the start of the segment, where
        ``jumps()`` has just evaluated them.
        """
        ts = np.asarray(dense.ts)
        S, m = self.opts.event_samples, self.sys.n_rules
        h = np.diff(ts)
        times = ts[:-1, None] + h[:, None] * self.theta[None, :]
        t_all = times.ravel()
        gs = self.gk(t_all, dense(t_all).T).reshape(times.shape[0], S, m)
        g_start = np.concatenate([g0[None], gs[:-1, -1]], axis=0)
        g_all = gs.reshape(-1, m)
        tp = self.probes(ts, np.concatenate([g_start[:, None], gs], axis=1))
        if tp.size:
            t_all = np.concatenate([t_all, tp])
            g_all = np.concatenate([g_all, self.gk(tp, dense(tp).T)])
        order = np.argsort(t_all, kind="stable")
        t_all, g_all = t_all[order], g_all[order]
        hit = np.flatnonzero((g_all >= 0).any(axis=1))
        if hit.size == 0:
            return None
        i = hit[0]
        return (float(t_all[i - 1]) if i > 0 else t_start, float(t_all[i]))

    def probes(self, ts: np.ndarray, seq: np.ndarray) -> np.ndarray:
        """Times of the peak probes (:mod:`etobs.hybrid.peaks`) on the steps ``ts``.

        ``seq`` (M, S + 1, m) holds the event functions at ``θ = 0, 1/S, ..., 1`` of each
        step; of each kind (start, inside, end) the earliest over the rules is probed.
        """
        S = self.opts.event_samples
        found = []
        # rows as lists: the scalar function indexes them much faster than arrays
        for r, rules in enumerate(np.swapaxes(seq, 1, 2).tolist()):
            first = [np.inf, np.inf, np.inf]
            for g in rules:
                for kind, theta in enumerate(peak_probes(g, S)):
                    if theta < first[kind]:  # NaN (no probe) compares false
                        first[kind] = theta
            found += [ts[r] + theta * (ts[r + 1] - ts[r]) for theta in first if theta < np.inf]
        return np.array(found)

    def locate(self, dense: Any, a: float, b: float) -> float:
        """Earliest crossing in ``[a, b]`` (some g(b) >= 0), returned where ``g >= 0``."""
        ga, gb = self.at(dense, a)[1], self.at(dense, b)[1]
        best = b
        for k in np.flatnonzero((ga < 0) & (gb >= 0)):
            r = brentq(
                lambda s, k=k: _entered(float(self.at(dense, s)[1][k])),
                a,
                b,
                xtol=self.opts.event_xtol / 4,
                rtol=4 * np.finfo(float).eps,
                maxiter=_ROOT_ITERATIONS,
            )
            best = min(best, r)
        for _ in range(_NUDGES):
            if np.any(self.at(dense, best)[1] >= 0) or best >= self.t_end:
                break
            best = min(best + self.opts.event_xtol / 4, self.t_end)
        return best


def _entered(g: float) -> float:
    """An event function's value for the root finder: 0 (in the jump set) counts as positive.

    The jump set is ``g >= 0``, so the event is the entry into it, not a zero of ``g``. A
    guard that is exactly 0 on an interval (clipped, ``min(tau - 1, 0)``) has every point
    of it as a root, and ``brentq`` stopped at whichever it met first: the jumps of a
    clock of period 1 came at 1.0106, 2.1242, 3.1396. With 0 moved to the smallest
    positive float there is one sign change, at the entry, and ``brentq`` brackets it to
    ``xtol`` as the engine's regula falsi does (it too keeps ``g >= 0`` on the right end).
    """
    return g if g != 0.0 else _TINY


_TINY = float(np.nextafter(0.0, 1.0))


def _call(name: str, fn: Any, *args: Any) -> Any:
    """``fn(*args)`` with read-only arrays; an exception becomes a ``ModelError`` naming ``name``.

    The run then ends with ``model_error`` (:func:`solve_reference`), as on the engine.
    """
    try:
        return fn(*[read_only(a) for a in args])
    except ModelError:
        raise
    except Exception as exc:  # the user's function: any exception ends its run the same way
        raise ModelError(raised(name, exc)) from exc


def _checked(name: str, out: Any, shape: tuple[int, ...]) -> np.ndarray:
    """``out`` as a float array of the ``shape`` a batched function must return."""
    try:
        arr = np.asarray(out, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ModelError(
            f"`{name}` returned {type(out).__name__}, not an array of floats of shape {shape}"
        ) from exc
    if arr.shape != shape:
        raise ModelError(f"`{name}` returned an array of shape {arr.shape}; expected {shape}")
    return arr


class _Overflowed(Exception):
    """The guard was NaN at a state that is no longer finite: the run ends ``nonfinite``."""


def _event_values(out: Any, x: np.ndarray, m: int) -> np.ndarray:
    """The ``m`` guard values at the states ``x`` (K, n), as (K, m) (a copy: they are remembered).

    NaN ends the run: a NaN event function never fires, and the run went on as if it
    were negative (a ball fell through its floor and "completed"). At a state with a
    non-finite entry (a state that overflowed, on the dense output inside a step) the
    NaN is the state's, and the run ends ``nonfinite``; at a finite state it is the
    guard's, ``model_error``. The engine draws the same line; before, which of the two
    a blow-up gave depended on the machine's floating-point path for huge arguments.
    """
    g = _checked("guard", out, (x.shape[0], m)).copy()
    if np.isnan(g).any():
        if not np.all(np.isfinite(x[np.isnan(g).any(axis=1)])):
            raise _Overflowed
        raise ModelError("`guard` " + describe_failure_nan())
    return g


def describe_failure_nan() -> str:
    """How the engine words a NaN event function (:data:`etobs.compile.functions.FAILURES`)."""
    from etobs.compile.functions import FAILURES, NAN_RESULT

    return FAILURES[NAN_RESULT]
