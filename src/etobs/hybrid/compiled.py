"""The compiled backend: the fast solver's algorithm as a numba kernel, one run per thread.

Optional: it needs ``numba`` (``pip install 'etobs[numba]'``); nothing else in etobs
imports numba. It solves a :class:`CompiledSystem`, whose flow, event and jump
functions are numba-compiled functions of one run (not batched):

``flow(t, x, p, args, work, dx)``
    write ``x'`` into ``dx`` (shape ``(n,)``);
``guard(t, x, p, args, work, g)``
    write every rule's event function into ``g`` (shape ``(n_rules,)``); rule ``k``
    jumps where ``g[k] >= 0``;
``jump(k, t, x, p, args, work)``
    apply rule ``k``'s jump map to ``x`` in place.

``p`` is the run's own parameter vector (row of ``params``), so runs with different
parameters share one compiled kernel; ``args`` is one value shared by all runs (a
tuple of arrays, say; read it, do not write it); ``work`` is a scratch array of
``n_work`` floats owned by the run, so that the functions need not allocate.

The algorithm, options and results are those of :func:`etobs.hybrid.solve` (see the
contract in :mod:`etobs.hybrid.solver`); the two agree to the integration tolerance
(tests compare them and the scipy reference).

Compilation happens once per process and per set of functions (a few seconds); the
first call pays it.
"""

from __future__ import annotations

import itertools
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.errors import InputError, InputTypeError
from etobs.hybrid.options import SaveAt, SolverOptions
from etobs.hybrid.solution import HybridArc, HybridSolution, JumpLog, SavedGrid

#: Jump-log entries kept per run on the first pass (runs with more are solved again
#: with room for all of them); bounded so that a big batch stays small in memory.
LOG_CAPACITY = 4096
ARC_CAPACITY = 8192
_BUFFER_BUDGET = 2**22  # entries in all runs' buffers together, first pass


def numba_available() -> bool:
    """Whether the optional dependency numba can be imported."""
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


def require_numba(what: str = "the compiled backend") -> Any:
    """Import numba or raise an :class:`InputError` that says how to install it."""
    try:
        import numba
    except ImportError as exc:
        raise InputError(
            f"{what} needs the optional dependency numba, which is not installed; "
            "install it with `pip install 'etobs[numba]'` or use backend='fast'"
        ) from exc
    return numba


def is_compiled_function(fn: Any) -> bool:
    """Whether ``fn`` is a numba-compiled (``@numba.njit``) function."""
    numba = require_numba()
    return isinstance(fn, numba.core.registry.CPUDispatcher)


@dataclass(frozen=True)
class CompiledSystem:
    """A hybrid system given by numba-compiled functions of one run (module docstring).

    Parameters
    ----------
    n : int
        State dimension.
    n_rules : int
        Number of jump rules.
    flow, guard, jump : numba-compiled functions
    n_params : int
        Length of each run's parameter vector ``p``.
    n_work : int
        Length of the scratch array ``work``.
    args : object
        Shared data passed to every call (anything numba accepts, e.g. a tuple of arrays).
    rule_names : tuple of str, optional

    Examples
    --------
    The bouncing ball of :func:`etobs.hybrid.solve`, compiled; ``p[0]`` is the
    restitution coefficient:

    >>> import numba, numpy as np
    >>> from etobs.hybrid.compiled import CompiledSystem, solve_compiled
    >>> @numba.njit
    ... def flow(t, x, p, args, work, dx):
    ...     dx[0] = x[1]
    ...     dx[1] = -9.81
    >>> @numba.njit
    ... def guard(t, x, p, args, work, g):
    ...     g[0] = -x[0] if x[1] < 0 else -1.0
    >>> @numba.njit
    ... def jump(k, t, x, p, args, work):
    ...     x[0] = 0.0
    ...     x[1] = -p[0] * x[1]
    >>> ball = CompiledSystem(n=2, n_rules=1, flow=flow, guard=guard, jump=jump, n_params=1)
    >>> sol = solve_compiled(ball, [1.0, 0.0], (0.0, 1.0), params=[0.5])
    >>> round(float(sol.jumps.t[0]), 6)  # sqrt(2 / 9.81)
    0.451524

    """

    n: int
    n_rules: int
    flow: Any
    guard: Any
    jump: Any
    n_params: int = 0
    n_work: int = 0
    args: Any = ()
    rule_names: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        v.integer("n", self.n, lower=1)
        v.integer("n_rules", self.n_rules, lower=0)
        v.integer("n_params", self.n_params, lower=0)
        v.integer("n_work", self.n_work, lower=0)
        for name in ("flow", "guard", "jump"):
            fn = getattr(self, name)
            if not is_compiled_function(fn):
                raise InputTypeError(
                    f"`{name}` must be a numba-compiled function (decorated with @numba.njit); "
                    f"got {type(fn).__name__}"
                )
        if not self.rule_names:
            object.__setattr__(self, "rule_names", tuple(f"rule{k}" for k in range(self.n_rules)))
        elif len(self.rule_names) != self.n_rules:
            raise InputError(
                f"`rule_names` has {len(self.rule_names)} names; expected n_rules={self.n_rules}"
            )


def solve_compiled(
    system: CompiledSystem,
    x0: Any,
    t_span: Any,
    *,
    params: Any = None,
    options: SolverOptions | None = None,
    save: SaveAt | None = None,
    parallel: bool = True,
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

    Returns
    -------
    HybridSolution
        With ``backend == "numba"``.

    """
    if not isinstance(system, CompiledSystem):
        raise InputTypeError(f"`system` must be a CompiledSystem; got {type(system).__name__}")
    from etobs.hybrid.solver import span

    t0, t_end = span(t_span)
    x = np.array(v.batch("x0", x0, system.n), dtype=float, order="C")
    B = x.shape[0]
    P = _params(params, system.n_params, B)
    opts = options or SolverOptions()
    save = save or SaveAt()
    grid = np.empty(0) if save.grid is None else np.array(save.grid, dtype=float, order="C")
    out = _Buffers(B, system.n, grid.shape[0])
    runs = np.arange(B)
    log_cap = int(np.clip(_BUFFER_BUDGET // max(B, 1), 64, LOG_CAPACITY))
    arc_cap = int(np.clip(_BUFFER_BUDGET // max(B * system.n, 1), 64, ARC_CAPACITY)) if save.steps else 0
    logs: dict[int, tuple[np.ndarray, ...]] = {}
    arcs: dict[int, tuple[np.ndarray, ...]] = {}
    while runs.size:
        part = _call(system, x, P, t0, t_end, opts, save.steps, grid, runs, log_cap, arc_cap, out, parallel)
        full = (out.log_n[runs] > log_cap) | (out.arc_n[runs] > arc_cap)
        for slot in np.flatnonzero(~full):
            r = int(runs[slot])
            logs[r] = tuple(a[slot, : out.log_n[r]].copy() for a in part[:3])
            if save.steps:
                arcs[r] = tuple(a[slot, : out.arc_n[r]].copy() for a in part[3:])
        # Runs whose buffers overflowed are solved again with room for everything (same
        # numbers: the computation does not depend on the buffers).
        runs = runs[full]
        if runs.size:
            log_cap = max(log_cap, int(out.log_n[runs].max()))
            arc_cap = max(arc_cap, int(out.arc_n[runs].max())) if save.steps else 0
    return HybridSolution(
        t_span=(t0, t_end),
        status=out.status,
        t_final=out.t_final,
        j_final=out.j_final,
        x_final=out.x_final,
        jumps=_jump_log(logs, B),
        arcs=tuple(HybridArc(*arcs[r]) for r in range(B)) if save.steps else None,
        grid=SavedGrid(grid, out.grid_j, out.grid_x) if save.grid is not None else None,
        n_steps=out.n_steps,
        n_rejected=out.n_rejected,
        rule_names=system.rule_names,
        backend="numba",
    )


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

    def __init__(self, B: int, n: int, n_grid: int) -> None:
        self.status = np.zeros(B, dtype=np.int64)
        self.t_final = np.zeros(B)
        self.j_final = np.zeros(B, dtype=np.int64)
        self.x_final = np.zeros((B, n))
        self.n_steps = np.zeros(B, dtype=np.int64)
        self.n_rejected = np.zeros(B, dtype=np.int64)
        self.log_n = np.zeros(B, dtype=np.int64)
        self.arc_n = np.zeros(B, dtype=np.int64)
        self.grid_x = np.full((B, n_grid, n), np.nan)
        self.grid_j = np.full((B, n_grid), -1, dtype=np.int64)


def _call(
    system: CompiledSystem,
    x: np.ndarray,
    P: np.ndarray,
    t0: float,
    t_end: float,
    opts: SolverOptions,
    keep_steps: bool,
    grid: np.ndarray,
    runs: np.ndarray,
    log_cap: int,
    arc_cap: int,
    out: _Buffers,
    parallel: bool,
) -> tuple[np.ndarray, ...]:

    n = x.shape[1]
    fopt = np.array(
        [opts.rtol, opts.atol, opts.max_step, opts.first_step or 0.0, opts.event_xtol], dtype=float
    )
    iopt = np.array([opts.max_jumps, opts.max_steps, opts.event_samples, int(keep_steps)], dtype=np.int64)
    R = runs.shape[0]  # buffer row r belongs to run runs[r]
    log_rule = np.zeros((R, log_cap), dtype=np.int64)
    log_t = np.zeros((R, log_cap))
    log_j = np.zeros((R, log_cap), dtype=np.int64)
    arc_t = np.zeros((R, arc_cap))
    arc_j = np.zeros((R, arc_cap), dtype=np.int64)
    arc_x = np.zeros((R, arc_cap, n))
    kernel = _built(system, opts.method)
    call = partial(
        kernel,
        system.args,
        x,
        P,
        system.n_rules,
        float(t0),
        float(t_end),
        fopt,
        iopt,
        grid,
        log_cap,
        arc_cap,
    )
    rest = (
        out.status,
        out.t_final,
        out.j_final,
        out.x_final,
        out.n_steps,
        out.n_rejected,
        out.log_n,
        log_rule,
        log_t,
        log_j,
        out.grid_x,
        out.grid_j,
        out.arc_n,
        arc_t,
        arc_j,
        arc_x,
    )
    threads = _threads() if parallel else 1
    # Each thread solves a contiguous slice of ``runs``; the kernel releases the GIL.
    # Buffer rows are per slice, so every slice gets its own views.
    cuts = np.linspace(0, R, min(threads, R) + 1).astype(int) if R else np.zeros(1, int)
    jobs = []
    for a, b in itertools.pairwise(cuts):
        views = (
            rest[:7]
            + tuple(buf[a:b] for buf in rest[7:10])
            + rest[10:13]
            + tuple(buf[a:b] for buf in rest[13:])
        )
        jobs.append((np.ascontiguousarray(runs[a:b], dtype=np.int64), views))
    if len(jobs) == 1:
        call(jobs[0][0], *jobs[0][1])
    else:
        with ThreadPoolExecutor(len(jobs)) as pool:
            list(pool.map(lambda job: call(job[0], *job[1]), jobs))
    return log_rule, log_t, log_j, arc_t, arc_j, arc_x


_BUILT: dict[tuple[Any, ...], Any] = {}
_BUILD_LOCK = threading.Lock()


def _built(system: CompiledSystem, method: str) -> Any:
    """The kernel compiled for the system's functions (once per process, functions, method)."""
    from etobs.hybrid import _kernel

    fns = (system.flow, system.guard, system.jump)
    key = (*(id(fn) for fn in fns), method, system.n, system.n_work)
    with _BUILD_LOCK:
        if key not in _BUILT:
            # The functions are kept with their kernel so that their ids are not reused.
            _BUILT[key] = (_kernel.build(*fns, method, system.n, system.n_work), fns)
        return _BUILT[key][0]


def _threads() -> int:
    """Threads used for a parallel solve: numba's thread count (``NUMBA_NUM_THREADS``)."""
    numba = require_numba()
    return int(numba.get_num_threads())


def _jump_log(logs: dict[int, tuple[np.ndarray, ...]], B: int) -> JumpLog:
    empty = np.empty(0, dtype=np.int64)
    counts = [len(logs[r][0]) for r in range(B)]
    return JumpLog(
        run=np.repeat(np.arange(B, dtype=np.int64), counts),
        rule=np.concatenate([logs[r][0] for r in range(B)] or [empty]).astype(np.int64),
        t=np.concatenate([logs[r][1] for r in range(B)] or [np.empty(0)]),
        j=np.concatenate([logs[r][2] for r in range(B)] or [empty]).astype(np.int64),
    )
