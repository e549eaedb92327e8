"""The engine: the solver's algorithm compiled with numba, many runs per thread in lanes.

It solves a :class:`CompiledSystem`: a hybrid system whose flow, guard and jump are C
functions called by address (see :mod:`etobs.hybrid._kernel` for their contract), so
the kernel is compiled once per machine and method and cached on disk, and a new
system only compiles its own small functions (:mod:`etobs.compile`).
:func:`compile_system` makes one from one-run Python functions; the estimation layer
makes its own (:mod:`etobs.estimation.compiled`).

The algorithm, options and results are those of :func:`etobs.hybrid.solve` (see the
contract in :mod:`etobs.hybrid.solver`); tests compare the two and the scipy reference.
"""

from __future__ import annotations

import itertools
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import partial
from typing import Any, SupportsInt, cast

import numpy as np

from etobs import _validate as v
from etobs.errors import InputError, InputTypeError
from etobs.hybrid.checks import check_log_columns, check_progress, check_sizes, span, warn_unreached_grid
from etobs.hybrid.options import SaveAt, SolverOptions
from etobs.hybrid.solution import (
    GridMax,
    HybridArc,
    HybridSolution,
    JumpLog,
    LaneStats,
    SavedGrid,
    log_names,
)
from etobs.hybrid.status import Status

#: Jump-log rows and arc points kept per run on the first pass (runs with more are
#: solved again with room for all of them); bounded so that a big batch stays small.
LOG_CAPACITY = 4096
ARC_CAPACITY = 8192
#: 8-byte words in all runs' jump-log buffers together on the first pass, and as many
#: in their arc buffers (32 MiB each): a log row holds rule, t, j and the logged
#: columns, an arc point t, j and the state.
_BUFFER_BUDGET = 2**22
_NEVER = 2**62  # a count no run reaches (SolverOptions(zeno_jumps=None))
RUNNING = int(Status.RUNNING)
#: Seconds between two readings of the runs' simulated time for a progress callback: the
#: kernel writes each run's time after every accepted step (one store, no call), and the
#: caller's thread reads them while the batch is solved in one pass on another thread.
POLL = 0.2
#: Runs a thread advances side by side in lanes (``solve_compiled(lanes=...)``): 16
#: doubles fill two AVX-512 registers or four AVX2 ones.
LANES = 16


@dataclass(frozen=True)
class CompiledSystem:
    """A hybrid system given by compiled C functions (module docstring).

    Parameters
    ----------
    n : int
        State dimension.
    n_rules : int
        Number of jump rules.
    addresses : tuple of int
        Addresses of the flow, guard and jump C functions.
    lane_form : callable, optional
        ``lane_form(shared)`` returns the address of the lane form of flow and guard
        (``0``: none; the kernel then calls the one-run functions lane by lane); called
        (and so compiled) when a batch first fills :attr:`lane_width` lanes, with
        ``shared`` true when all runs the kernel call solves have the same parameters
        (the form may then read them from the first lane's row). It is called as the one-run functions are
        (:mod:`etobs.hybrid._kernel`), with ``a0`` the lanes' states (``n x W``, the lane
        axis last), ``a1`` their times, ``a2`` their scratch (``n_work + 1 x W``), ``a3``
        the shared floats, ``ia = [lo, hi, W, st_0, .., st_(W-1)]`` (it computes lanes
        ``lo .. hi-1`` and writes each lane's status at ``st_l``), ``p`` the parameters
        (``W x n_params``: one row per lane) and ``out`` the results (``rows x W``).
    lane_width : int
        The ``W`` the lane form computes (a constant of its code): the kernel calls it only
        when it advances that many lanes.
    ia : ndarray of int64
        Integer data passed to every call.
    cf : ndarray of float64
        Float data passed to every call.
    n_params : int
        Length of each run's parameter vector ``p``.
    n_work : int
        Length of each run's scratch array.
    n_flow : int, optional
        When given, only the entries ``0 .. n_flow-1`` change along flows: the others are
        left out of the integration and its error control, and the flow need not write
        them (as :class:`~etobs.hybrid.HybridSystem`'s ``n_flow``).
    rule_names : tuple of str, optional
    function_names : tuple of str
        Names of the functions by failure slot (slot ``s`` is ``function_names[s - 1]``),
        for messages.
    keep : object
        What must stay alive for the addresses to stay valid (the compiled functions).
    log_columns : tuple of int, optional
        State entries whose values just after every jump are kept in the jump log
        (``solution.jumps.x``), as :class:`~etobs.hybrid.HybridSystem`'s ``log_columns``.

    """

    n: int
    n_rules: int
    addresses: tuple[int, int, int]
    lane_form: Callable[[bool], int] | None = None
    lane_width: int = 0
    ia: np.ndarray = field(default_factory=lambda: np.zeros(1, dtype=np.int64))
    cf: np.ndarray = field(default_factory=lambda: np.zeros(1))
    n_params: int = 0
    n_work: int = 0
    n_flow: int | None = None
    rule_names: tuple[str, ...] = ()
    function_names: tuple[str, ...] = ("flow", "guard", "jump")
    keep: Any = None
    log_columns: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        check_sizes(self.n, self.n_rules, self.n_flow)
        object.__setattr__(self, "log_columns", check_log_columns(self.log_columns, self.n))
        v.integer("n_params", self.n_params, lower=0)
        v.integer("n_work", self.n_work, lower=0)
        object.__setattr__(self, "ia", np.ascontiguousarray(np.r_[self.ia, 0], dtype=np.int64))
        object.__setattr__(self, "cf", np.ascontiguousarray(np.r_[self.cf, 0.0], dtype=np.float64))
        if not self.rule_names:
            object.__setattr__(self, "rule_names", tuple(f"rule{k}" for k in range(self.n_rules)))
        elif len(self.rule_names) != self.n_rules:
            raise InputError(
                f"`rule_names` has {len(self.rule_names)} names; expected n_rules={self.n_rules}"
            )

    def failure(self, code: SupportsInt) -> str:
        """The failing function and how it failed, from a run's ``error_code``."""
        from etobs.compile.functions import describe_failure

        slot, how = divmod(int(code), 16)
        names = self.function_names
        return describe_failure(names[slot - 1] if 0 < slot <= len(names) else f"function {slot}", how)


def compile_system(
    flow: Callable[..., Any],
    guard: Callable[..., Any],
    jump: Callable[..., Any],
    n: int,
    n_rules: int,
    *,
    n_params: int = 0,
    rule_names: tuple[str, ...] = (),
    n_flow: int | None = None,
    log_columns: tuple[int, ...] = (),
) -> CompiledSystem:
    """A :class:`CompiledSystem` from one-run Python functions.

    ``flow(t, x) -> x'``, ``guard(t, x) -> g`` (shape ``(n_rules,)``) and
    ``jump(k, t, x) -> x+``, on 1-D arrays; with ``n_params > 0`` each also takes the
    run's parameter vector ``p`` last. ``n_flow`` and ``log_columns`` as in
    :class:`CompiledSystem`.

    Examples
    --------
    The bouncing ball; ``p[0]`` is the restitution coefficient:

    >>> import numpy as np
    >>> ball = compile_system(
    ...     lambda t, x, p: np.array([x[1], -9.81]),
    ...     lambda t, x, p: np.array([-x[0] if x[1] < 0 else -1.0]),
    ...     lambda k, t, x, p: np.array([0.0, -p[0] * x[1]]),
    ...     n=2, n_rules=1, n_params=1)
    >>> sol = solve_compiled(ball, [1.0, 0.0], (0.0, 1.0), params=[0.5])
    >>> round(float(sol.jumps.t[0]), 6)  # sqrt(2 / 9.81)
    0.451524

    """
    from etobs.compile.functions import FunctionSpec, compile_function

    n = v.integer("n", n, lower=1)
    n_rules = v.integer("n_rules", n_rules, lower=0)
    n_params = v.integer("n_params", n_params, lower=0)
    fns = (
        compile_function(flow, FunctionSpec("t, A0", (n,), n, n_params), "flow"),
        compile_function(guard, FunctionSpec("t, A0", (n,), max(n_rules, 1), n_params), "guard")
        if n_rules
        else compile_function(_no_rules, FunctionSpec("t, A0", (n,), 1, 0), "guard"),
        compile_function(jump, FunctionSpec("k, t, A0", (n,), n, n_params), "jump"),
    )
    return CompiledSystem(
        n=n,
        n_rules=n_rules,
        addresses=tuple(f.address for f in fns),  # type: ignore[arg-type]
        n_params=n_params,
        rule_names=rule_names,
        n_flow=n_flow,
        keep=fns,
        log_columns=log_columns,
    )


def _no_rules(t: float, x: np.ndarray) -> np.ndarray:
    return np.full(1, -1.0)


def solve_compiled(
    system: CompiledSystem,
    x0: Any,
    t_span: Any,
    *,
    params: Any = None,
    options: SolverOptions | None = None,
    save: SaveAt | None = None,
    parallel: bool = True,
    progress: Callable[[float], object] | None = None,
    lanes: int | None = None,
) -> HybridSolution:
    """Solve a batch of runs of a :class:`CompiledSystem`.

    Parameters
    ----------
    system : CompiledSystem
    x0 : array_like, shape (n,) or (B, n)
        Initial state of each run.
    t_span : (float, float)
        Start and end time, common to all runs.
    params : array_like, shape (n_params,) or (B, n_params), optional
        Parameter vector of each run (one row for all runs, or one per run).
    options : SolverOptions, optional
    save : SaveAt, optional
        What to keep (default: the full hybrid arcs).
    parallel : bool
        Spread the runs over numba's threads (``numba.set_num_threads`` sets how many).
    progress : callable, optional
        ``progress(k)`` is called every :data:`POLL` seconds with the runs done since
        the last call, a run that has simulated to ``t`` counting ``(t - t0) / (t_end -
        t0)`` (a float; the calls sum to ``B``), e.g. a tqdm bar's ``update``. It is
        called on the caller's thread while the batch is solved in one pass on another;
        the numbers are the same as without it.
    lanes : int, optional
        Runs each thread advances side by side (default :data:`LANES`, at most the
        thread's runs). A run's numbers do not depend on it.

    Returns
    -------
    HybridSolution
        With ``backend == "engine"``.

    """
    if not isinstance(system, CompiledSystem):
        raise InputTypeError(f"`system` must be a CompiledSystem; got {type(system).__name__}")
    t0, t_end = span(t_span)
    progress = check_progress(progress)
    if lanes is not None:
        lanes = v.integer("lanes", lanes, lower=1)
    x = np.array(v.batch("x0", x0, system.n), dtype=float, order="C")
    B = x.shape[0]
    P = _params(params, system.n_params, B)
    opts = options or SolverOptions()
    save = save or SaveAt()
    warn_unreached_grid(save.grid, t0, t_end)
    grid = np.empty(0) if save.grid is None else np.array(save.grid, dtype=float, order="C")
    dist = save.distance_pairs(system.n)
    out = _Buffers(B, system.n, grid.shape[0], reduce=dist.shape[0] > 0)
    solve = partial(_solve_runs, system, x, P, t0, t_end, opts, save.steps, grid, dist, out, parallel, lanes)
    logs: dict[int, tuple[np.ndarray, ...]] = {}
    arcs: dict[int, tuple[np.ndarray, ...]] = {}
    if progress is None:
        solve(np.arange(B), logs, arcs)
    else:
        _watched(partial(solve, np.arange(B), logs, arcs), out, t0, t_end, progress)
    return HybridSolution(
        t_span=(t0, t_end),
        status=out.status,
        t_final=out.t_final,
        j_final=out.j_final,
        x_final=out.x_final,
        jumps=_jump_log(logs, B, system.log_columns),
        arcs=tuple(HybridArc(*arcs[r]) for r in range(B)) if save.steps else None,
        grid=SavedGrid(grid, out.grid_j, out.grid_x) if save.grid is not None and not dist.size else None,
        n_steps=out.n_steps,
        n_rejected=out.n_rejected,
        rule_names=system.rule_names,
        backend="engine",
        failures=tuple(system.failure(c) if c else "" for c in out.error_code),
        grid_max=GridMax(grid, out.grid_max) if dist.size else None,
        lanes=out.lanes,
    )


def _watched(
    solve: Callable[[], None], out: _Buffers, t0: float, t_end: float, progress: Callable[[float], object]
) -> None:
    """``solve()`` on a thread; meanwhile ``progress`` gets the runs done, by simulated time.

    A run counts ``(t - t0) / (t_end - t0)`` while it goes on (its ``t_final``, which the
    kernel writes after every accepted step) and 1 once its status is written, however it
    ended. The sum never goes down (a run solved again for room in its buffers restarts
    at ``t0`` but is already counted). The wait ends when the thread does, which the
    solver's limits bound.
    """
    raised: list[BaseException] = []

    def target() -> None:
        try:
            solve()
        except BaseException as exc:  # handed to the caller's thread below
            raised.append(exc)

    worker = threading.Thread(target=target, name="etobs-engine", daemon=True)
    span = t_end - t0
    reported = 0.0
    out.t_final[:] = t0  # runs not yet started have simulated nothing
    worker.start()
    while worker.is_alive():
        worker.join(POLL)
        ended = out.status != RUNNING
        running = np.clip((out.t_final - t0) / span, 0.0, 1.0) if span > 0 else 0.0
        done = float(np.sum(np.where(ended, 1.0, running)))
        if done > reported:
            progress(done - reported)
            reported = done
    if raised:
        raise raised[0]
    if out.status.size > reported:
        progress(out.status.size - reported)


def _solve_runs(
    system: CompiledSystem,
    x: np.ndarray,
    P: np.ndarray,
    t0: float,
    t_end: float,
    opts: SolverOptions,
    keep_steps: bool,
    grid: np.ndarray,
    dist: np.ndarray,
    out: _Buffers,
    parallel: bool,
    lanes: int | None,
    runs: np.ndarray,
    logs: dict[int, tuple[np.ndarray, ...]],
    arcs: dict[int, tuple[np.ndarray, ...]],
) -> None:
    """Solve ``runs`` into ``out``, and their jump logs and arcs into ``logs`` and ``arcs``."""
    log_cap, arc_cap = capacities(runs.size, system.n, len(system.log_columns), keep_steps)
    while runs.size:
        part = _call(
            system,
            x,
            P,
            t0,
            t_end,
            opts,
            keep_steps,
            grid,
            dist,
            runs,
            log_cap,
            arc_cap,
            out,
            parallel,
            lanes,
        )
        full = (out.log_n[runs] > log_cap) | (out.arc_n[runs] > arc_cap)
        for slot in np.flatnonzero(~full):
            r = int(runs[slot])
            logs[r] = tuple(a[slot, : out.log_n[r]].copy() for a in part[:4])
            if keep_steps:
                arcs[r] = tuple(a[slot, : out.arc_n[r]].copy() for a in part[4:])
        # Runs whose buffers overflowed are solved again with room for everything (same
        # numbers: the computation does not depend on the buffers).
        runs = runs[full]
        if runs.size:
            log_cap = max(log_cap, int(out.log_n[runs].max()))
            arc_cap = max(arc_cap, int(out.arc_n[runs].max())) if keep_steps else 0


def capacities(R: int, n: int, n_log: int, keep_steps: bool) -> tuple[int, int]:
    """First-pass jump-log rows and arc points per run for ``R`` runs (:data:`_BUFFER_BUDGET`).

    A log row takes ``3 + n_log`` words (rule, t, j, the logged columns), an arc point
    ``2 + n`` (t, j, the state); each kind gets the budget, split over the runs, within
    ``64 .. LOG_CAPACITY`` (``ARC_CAPACITY``) per run. Returns ``(log_cap, arc_cap)``,
    ``arc_cap = 0`` without ``keep_steps``.
    """
    log_cap = int(np.clip(_BUFFER_BUDGET // max(R * (3 + n_log), 1), 64, LOG_CAPACITY))
    arc_cap = int(np.clip(_BUFFER_BUDGET // max(R * (2 + n), 1), 64, ARC_CAPACITY)) if keep_steps else 0
    return log_cap, arc_cap


def _params(params: Any, n_params: int, B: int) -> np.ndarray:
    if params is None:
        if n_params:
            raise InputError(f"`params` is required: the system has n_params={n_params}")
        return np.zeros((B, 0))
    P = np.asarray(params, dtype=float)
    if P.ndim == 1:
        P = P[None, :]
    if P.ndim != 2 or P.shape[1] != n_params or P.shape[0] not in (1, B):
        raise InputError(
            f"`params` must have shape ({n_params},) or ({B}, {n_params}); got {np.shape(params)}"
        )
    if not np.all(np.isfinite(P)):
        raise InputError("`params` must be finite")
    return np.array(np.broadcast_to(P, (B, n_params)), order="C")


class _Buffers:
    """Per-run outputs of the kernel."""

    def __init__(self, B: int, n: int, n_grid: int, *, reduce: bool) -> None:
        # the kernel writes both at the end of each run, and t_final after every step too
        self.status = np.full(B, RUNNING, dtype=np.int64)
        self.t_final = np.zeros(B)
        self.j_final = np.zeros(B, dtype=np.int64)
        self.x_final = np.zeros((B, n))
        self.n_steps = np.zeros(B, dtype=np.int64)
        self.n_rejected = np.zeros(B, dtype=np.int64)
        self.log_n = np.zeros(B, dtype=np.int64)
        self.arc_n = np.zeros(B, dtype=np.int64)
        # with a distance to reduce, the grid's states are never written: no room for them
        kept = 0 if reduce else n_grid
        self.grid_x = np.full((B, kept, n), np.nan)
        self.grid_j = np.full((B, kept), -1, dtype=np.int64)
        self.grid_max = np.full(B, -np.inf if n_grid else np.nan)
        self.error_code = np.zeros(B, dtype=np.int64)
        self.lanes: LaneStats | None = None

    def count_lanes(self, counts: np.ndarray, width: int, vector: bool) -> None:
        """Add one kernel call's lane-steps ``(all, idle, rejected, events)``."""
        old = self.lanes or LaneStats(width, vector, 0, 0, 0, 0)
        slots, idle, rejected, events = (int(c) for c in counts)
        self.lanes = LaneStats(
            max(old.width, width),
            old.vector or vector,
            old.slots + slots,
            old.idle + idle,
            old.rejected + rejected,
            old.events + events,
        )

    def outputs(self) -> Any:
        """The kernel's view of them (:class:`etobs.hybrid._kernel.Outputs`)."""
        from etobs.hybrid._kernel import Outputs

        return Outputs(
            self.status,
            self.t_final,
            self.j_final,
            self.x_final,
            self.n_steps,
            self.n_rejected,
            self.log_n,
            self.arc_n,
            self.grid_x,
            self.grid_j,
            self.grid_max,
            self.error_code,
        )


def _call(
    system: CompiledSystem,
    x: np.ndarray,
    P: np.ndarray,
    t0: float,
    t_end: float,
    opts: SolverOptions,
    keep_steps: bool,
    grid: np.ndarray,
    dist: np.ndarray,
    runs: np.ndarray,
    log_cap: int,
    arc_cap: int,
    out: _Buffers,
    parallel: bool,
    lanes: int | None = None,
) -> tuple[np.ndarray, ...]:

    from etobs.hybrid._kernel import Logs, Options, Problem, System

    n = x.shape[1]
    fopt = np.array(
        [opts.rtol, opts.atol, opts.max_step, opts.first_step or 0.0, opts.event_xtol, opts.zeno_span],
        dtype=float,
    )
    iopt = np.array(
        [
            opts.max_jumps,
            opts.max_steps,
            opts.event_samples,
            int(keep_steps),
            system.n_work + 1,
            system.n if system.n_flow is None else system.n_flow,
            _NEVER if opts.zeno_jumps is None else opts.zeno_jumps,
            system.n_rules,
        ],
        dtype=np.int64,
    )
    R = runs.shape[0]  # buffer row r belongs to run runs[r]
    logs = Logs(
        np.zeros((R, log_cap), dtype=np.int64),
        np.zeros((R, log_cap)),
        np.zeros((R, log_cap), dtype=np.int64),
        np.zeros((R, log_cap, len(system.log_columns))),
        np.zeros((R, arc_cap)),
        np.zeros((R, arc_cap), dtype=np.int64),
        np.zeros((R, arc_cap, n)),
    )
    kernel = _built(opts.method)
    problem = Problem(
        x, P, np.array([t0, t_end], dtype=float), grid, dist, np.array(system.log_columns, dtype=np.int64)
    )
    options = Options(fopt, iopt)
    outputs = out.outputs()
    threads = _threads() if parallel else 1
    # Each thread solves a contiguous slice of ``runs``, W of them at a time; the kernel
    # releases the GIL. Log rows are per slice, so every slice gets its own views.
    cuts = np.linspace(0, R, min(threads, R) + 1).astype(int) if R else np.zeros(1, int)
    jobs = []
    for a, b in itertools.pairwise(cuts):
        part = Logs(*(cast(Any, buf)[a:b] for buf in logs))  # each buffer's rows of this slice
        W = lanes_for(b - a, lanes)
        # the system's lane form computes lane_width lanes: with fewer, the one-run form lane by lane
        wide = system.lane_form is not None and W == system.lane_width
        lane_fn = system.lane_form(_shared(P, runs[a:b])) if wide else 0  # type: ignore[misc]
        functions = [*system.addresses, lane_fn]
        job_system = System(np.array(functions, dtype=np.int64), system.ia, system.cf)
        jobs.append((job_system, np.ascontiguousarray(runs[a:b], dtype=np.int64), part, W))
    counts = np.zeros((len(jobs), 4), dtype=np.int64)

    def call(k: int) -> None:
        job_system, job_runs, part, W = jobs[k]
        kernel(job_system, problem, options, outputs, part, job_runs, W, counts[k])

    if len(jobs) == 1:
        call(0)
    else:
        with ThreadPoolExecutor(len(jobs)) as pool:
            list(pool.map(call, range(len(jobs))))
    widths = [job[3] for job in jobs]
    out.count_lanes(counts.sum(axis=0), max(widths, default=1), any(job[0].addresses[3] for job in jobs))
    return tuple(logs)


def _shared(P: np.ndarray, runs: np.ndarray) -> bool:
    """Whether the runs ``runs`` all have the parameters (rows of ``P``) of the first, bit for bit.

    Bits, not values: ``-0.0 == 0.0``, yet a model may tell them apart (``copysign``, ``1/p``).
    """
    rows = np.ascontiguousarray(P[runs]).view(np.uint64)
    return bool((rows == rows[:1]).all()) if rows.size else True


def lanes_for(runs: int, lanes: int | None) -> int:
    """Lanes of a thread that solves ``runs`` runs: ``lanes``, or :data:`LANES`, at most ``runs``."""
    return max(1, min(LANES if lanes is None else lanes, runs))


_BUILT: dict[str, Any] = {}
_BUILD_LOCK = threading.Lock()


def _built(method: str) -> Any:
    """The kernel of ``method`` (compiled, or loaded from the disk cache, once per process)."""
    from etobs.hybrid import _kernel

    with _BUILD_LOCK:
        if method not in _BUILT:
            _BUILT[method] = _kernel.build(method)
        return _BUILT[method]


def _threads() -> int:
    """Threads used for a parallel solve: numba's thread count (``NUMBA_NUM_THREADS``)."""
    import numba

    return int(numba.get_num_threads())


def _jump_log(logs: dict[int, tuple[np.ndarray, ...]], B: int, columns: tuple[int, ...]) -> JumpLog:
    empty = np.empty(0, dtype=np.int64)
    counts = [len(logs[r][0]) for r in range(B)]
    return JumpLog(
        run=np.repeat(np.arange(B, dtype=np.int64), counts),
        rule=np.concatenate([logs[r][0] for r in range(B)] or [empty]).astype(np.int64),
        t=np.concatenate([logs[r][1] for r in range(B)] or [np.empty(0)]),
        j=np.concatenate([logs[r][2] for r in range(B)] or [empty]).astype(np.int64),
        x=np.concatenate([logs[r][3] for r in range(B)] or [np.empty((0, len(columns)))]),
        names=log_names(columns),
    )
