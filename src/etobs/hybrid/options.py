"""Solver settings and save options, as frozen validated objects."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.errors import InputError, InputTypeError

METHODS = ("dop853", "dopri5")
_INT_LIMIT = 2**62
#: Default step limit per run. An engine step of the robot arm (section 8, two nodes)
#: costs 3-9 us on one core of a shared machine (measured, benchmarks/bench_robot_arm.py),
#: so a run that never reaches its horizon stops within about 20 s, and a model ten times
#: as costly within minutes, with status ``max_steps``; the longest run of Table 1 (30 s)
#: takes 11,100 steps. The earlier 10,000,000 let a runaway run go on for 6 minutes.
MAX_STEPS = 2_000_000

# Step-size controller constants, as in Hairer, Nørsett & Wanner (1993), II.4; the
# engine's kernel template reads them.
SAFETY = 0.9  # keep the next error estimate below the tolerance with margin
MIN_FACTOR = 0.2  # never shrink a step by more than 5x at once
MAX_FACTOR = 10.0  # never grow a step by more than 10x at once


@dataclass(frozen=True)
class SolverOptions:
    """Settings of the hybrid solvers (fast and reference).

    Parameters
    ----------
    method : {"dop853", "dopri5"}
        Embedded Runge--Kutta pair of the engine: Dormand--Prince 8(5,3) with
        7th-order dense output (default) or Dormand--Prince 5(4) with 4th-order dense
        output.
    rtol, atol : float
        Relative and absolute local error tolerances.
    max_step : float
        Upper bound on the step size (``inf`` for none).
    first_step : float or None
        Initial step size; ``None`` selects it automatically per run.
    max_jumps : int
        Jump limit per run; a run reaching it stops with status ``max_jumps``.
    max_steps : int
        Step limit per run (accepted and rejected steps on the engine; accepted steps
        on the scipy reference, which counts them inside every flow segment); a run
        reaching it stops with status ``max_steps``. The default
        (``etobs.hybrid.options.MAX_STEPS``, 2,000,000) ends a runaway run
        (``t_end=1e300``, ``max_step=1e-12``) of the robot arm in about 20 s on the
        engine, and is 180 times the steps of the longest run of Table 1.
    zeno_jumps : int or None
        The Zeno rule (:mod:`etobs.hybrid.zeno`): a run whose jumps number more than
        ``zeno_jumps`` within a time window of ``zeno_span * max(1, |t|)`` stops with
        status ``zeno``. ``None`` turns the rule off (``max_jumps`` still bounds the run).
    zeno_span : float
        Width of the Zeno rule's window, relative to ``max(1, |t|)``. The default
        (1000 jumps within ``1e-7`` s at ``|t| <= 1``) stops a run whose jumps come less
        than ``1e-10`` s (a hundred times the default ``event_xtol``) apart on average.
    event_samples : int
        Number of sub-intervals of every step on which the event functions are sampled
        before root finding. A sign test at step ends alone (``event_samples=1``) misses
        an event function that rises above zero and falls back inside one step; sampling
        catches any excursion longer than ``step / event_samples``.
    event_xtol : float
        Width in time of the final bracket around each crossing of the dense output. The
        event time is further off by the dense output's state error divided by the
        crossing speed: on a stiff flow at DOP853's stability boundary that can reach
        1e-6 s at the default tolerances (docs/solver.md, "Event-time accuracy").

    Examples
    --------
    Table 1's tolerances, and a bound on the jumps of a run:

    >>> from etobs import SolverOptions
    >>> opts = SolverOptions(rtol=1e-10, atol=1e-10, max_jumps=100_000)
    >>> opts.rtol, opts.max_jumps
    (1e-10, 100000)

    """

    method: str = "dop853"
    rtol: float = 1e-10
    atol: float = 1e-10
    max_step: float = np.inf
    first_step: float | None = None
    max_jumps: int = 1_000_000
    max_steps: int = MAX_STEPS
    zeno_jumps: int | None = 1000
    zeno_span: float = 1e-7
    event_samples: int = 8
    event_xtol: float = 1e-12

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise InputError(f"`method` must be one of {METHODS}; got {self.method!r}")
        v.real("rtol", self.rtol, lower=1e-14, upper=1.0)
        v.real("atol", self.atol, lower=0.0, lower_open=True)
        v.real("max_step", self.max_step, lower=0.0, lower_open=True, allow_inf=True)
        if self.first_step is not None:
            v.real("first_step", self.first_step, lower=0.0, lower_open=True)
        # the limits travel to the engine as int64
        v.integer("max_jumps", self.max_jumps, lower=0, upper=_INT_LIMIT)
        v.integer("max_steps", self.max_steps, lower=1, upper=_INT_LIMIT)
        if self.zeno_jumps is not None:
            v.integer("zeno_jumps", self.zeno_jumps, lower=1, upper=_INT_LIMIT)
        v.real("zeno_span", self.zeno_span, lower=0.0)
        v.integer("event_samples", self.event_samples, lower=1)
        v.real("event_xtol", self.event_xtol, lower=0.0, lower_open=True)


def step_grid(start: float, end: float, step: float) -> np.ndarray:
    """The times ``start + k step`` up to ``end``, for a ``SaveAt`` grid.

    A last point past ``end`` by rounding is left out: ``np.arange(20, 30 + 0.0005,
    0.001)`` ends 1.2e-11 above 30, a point a run ending at 30 never reaches (its value
    NaN, said with a warning by the solvers).
    """
    g = np.arange(start, end + step / 2, step)
    return g[g <= end]


@dataclass(frozen=True)
class SaveAt:
    """What a solve keeps of each run.

    Parameters
    ----------
    steps : bool
        Keep the state at every step end and on both sides of every jump (the full
        hybrid arc). Memory grows with the number of steps; turn off for big batches.
    grid : array_like or None
        Increasing times at which to keep the state (from the dense output). At a jump
        time the value before the jump (smallest ``j``) is kept. Points outside the
        horizon, or after a run stopped early, hold NaN with ``j = -1``.
    max_distance : (sequence of int, sequence of int) or "estimation_error", optional
        Keep, instead of the states on ``grid``, only each run's largest distance
        ``sqrt(sum_i (x[a_i] - x[b_i])**2)`` over the grid points, computed while the
        run is solved (``HybridSolution.grid_max``; NaN when a value is not finite or a
        point was never reached). Memory no longer grows with the grid.
        ``"estimation_error"`` is for :func:`etobs.simulate`: ``max |x - xhat|``.

    Examples
    --------
    The states on a 1 ms grid over 30 s, without every step of the arc:

    >>> import numpy as np
    >>> from etobs import SaveAt
    >>> save = SaveAt(steps=False, grid=np.linspace(0.0, 30.0, 30_001))
    >>> save.steps, save.grid.shape
    (False, (30001,))

    """

    steps: bool = True
    grid: Any = field(default=None)
    max_distance: Any = field(default=None)

    def __post_init__(self) -> None:
        if self.grid is not None:
            g = v.vector("grid", self.grid)
            if g.size and np.any(np.diff(g) <= 0):
                raise InputError("`grid` must be strictly increasing")
            object.__setattr__(self, "grid", g)
        d = self.max_distance
        if d is None:
            return
        if self.grid is None:
            raise InputError("`max_distance` needs a `grid`: the distance is taken on its points")
        if isinstance(d, str):
            if d != "estimation_error":
                raise InputError(
                    f"`max_distance` must be a pair of index lists or 'estimation_error'; got {d!r}"
                )
            return
        pair = None
        if isinstance(d, (tuple, list)) and len(d) == 2:
            a, b = (np.asarray(side) for side in d)
            if a.ndim == b.ndim == 1 and a.size == b.size > 0 and all(_ints(s) for s in (a, b)):
                pair = (tuple(int(i) for i in a), tuple(int(i) for i in b))
        if pair is None:
            raise InputError(
                f"`max_distance` must be two equal-length, non-empty lists of state indices (a, b); got {d!r}"
            )
        object.__setattr__(self, "max_distance", pair)

    def distance_pairs(self, n: int) -> np.ndarray:
        """``max_distance`` as rows ``(a_i, b_i)``, checked against the state size ``n``.

        Shape ``(0, 2)`` when the grid's states are kept.
        """
        d = self.max_distance
        if d is None:
            return np.zeros((0, 2), dtype=np.int64)
        if isinstance(d, str):
            raise InputError(
                "`max_distance='estimation_error'` needs an estimation problem: pass it to "
                "etobs.simulate, or give the state indices (a, b) to a hybrid solve"
            )
        pairs = np.array(d, dtype=np.int64).T.copy()
        if pairs.min() < 0 or pairs.max() >= n:
            raise InputError(f"`max_distance` indices must lie in 0 .. {n - 1} (the state size); got {d!r}")
        return pairs


def beyond_step_limit(span: float, options: SolverOptions, *, t_end: str = "t_end", solver: str = "") -> str:
    """Why a run over a horizon of length ``span`` cannot end before ``max_steps``; ``""`` if it may.

    A run takes at least ``span / max_step`` steps, so when that is more than
    ``max_steps`` every run would stop with status ``max_steps`` after its whole step
    budget: the work is refused before it is spent. ``t_end`` and ``solver`` (a prefix
    of ``max_step``, ``max_steps``) spell the settings as the caller's input does, e.g.
    ``"horizon.t_end"`` and ``"solver."`` for a spec.
    """
    fewest = span / options.max_step
    if fewest <= options.max_steps:
        return ""
    step, steps = f"{solver}max_step", f"{solver}max_steps"
    count = f"{math.ceil(fewest)}" if fewest < 1e12 else f"{fewest:.3g}"
    return (
        f"`{t_end}` = {span:g} needs at least {count} steps at `{step}` = {options.max_step:g}, "
        f"more than `{steps}` = {options.max_steps} (every run would stop with status max_steps); "
        f"raise `{steps}` or `{step}`, or shorten the horizon"
    )


def checked_options(options: Any) -> SolverOptions:
    """``options`` of a solve: a :class:`SolverOptions`, or ``None`` for the defaults.

    Raises
    ------
    InputTypeError
        Anything else (a dict of settings, say), naming ``options`` and the way to write it.

    """
    if options is None:
        return SolverOptions()
    if not isinstance(options, SolverOptions):
        hint = " (a dict of settings is SolverOptions(**settings))" if isinstance(options, dict) else ""
        raise InputTypeError(
            "`options` must be a SolverOptions, e.g. options=SolverOptions(rtol=1e-8), or None; "
            f"got {type(options).__name__} {v.shown(options)}{hint}"
        )
    return options


def checked_save(save: Any) -> SaveAt | None:
    """``save`` of a solve: a :class:`SaveAt`, or ``None`` for the full arcs.

    Raises
    ------
    InputTypeError
        Anything else (an array of times, say), naming ``save`` and the way to write it.

    """
    if save is not None and not isinstance(save, SaveAt):
        raise InputTypeError(
            "`save` must be a SaveAt or None; the states on a time grid are save=SaveAt(grid=times); "
            f"got {type(save).__name__} {v.shown(save)}"
        )
    return save


def _ints(a: np.ndarray) -> bool:
    return a.dtype.kind in "iu"
