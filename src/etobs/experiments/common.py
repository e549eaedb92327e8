"""What every experiment spec shares, parsed once: the base class :class:`Experiment`.

A sweep (``etobs sweep``) and a rule comparison (``etobs compare``) are both a set of
*groups* (a parameter row under a scenario; a rule on a network), each simulated from
the same seeded initial states with the same horizon, metrics, solver settings and
execution settings. These common tables are parsed here, by one function
(:func:`parse_common`), so a key means the same and fails with the same message in
every spec format. Every key, its type, default and limits are listed in
``docs/specs.md`` ("Sweep and comparison: the shared tables").

The pipeline (:mod:`etobs.experiments.pipeline`) runs the groups of any
:class:`Experiment` through the same executors and chunk store.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass, field, fields
from typing import Any, Self

import numpy as np

from etobs._spec import FACTORY, TABLE, SpecError
from etobs._spec import keys as _keys
from etobs._spec import name as _name
from etobs._spec import number as _number
from etobs._validate import shown
from etobs.errors import EtobsError
from etobs.estimation.problem import EstimationProblem
from etobs.hybrid.checks import check_backend
from etobs.hybrid.options import SolverOptions, step_grid

#: Keys of ``[solver]``: every field of :class:`SolverOptions` (written once, there).
_SOLVER_KEYS = {f.name for f in fields(SolverOptions) if f.init}
#: Runs per chunk when ``execution.chunk_size`` is not given.
DEFAULT_CHUNK = 20
#: Most runs in one experiment (groups x initial states). Every run's record is held in
#: memory and written to the tables (about 1 kB each), and at 0.1 s a run this is twelve
#: days of one core: split a larger study into several experiments. (``--runs 10**12``
#: listed every run before failing with MemoryError.)
MAX_RUNS = 10_000_000
#: Most points of the error metric's grid (``error_window`` / ``error_grid_step``): 80 MB of
#: times. (A step of 1e-12 on [0, 0.5] s asked for a 3.6 TiB array in every chunk.)
MAX_GRID_POINTS = 10_000_000
#: Format of the stored records; part of every result key, so records written in an
#: earlier format are never mixed with new ones.
RECORD_FORMAT = 3


@dataclass(frozen=True)
class InitialStates:
    """Plant initial states drawn uniformly in the box ``[low, high]`` with ``seed``.

    ``z0`` is the observer's initial state of every run (``None``: zero, as in
    :func:`~etobs.estimation.simulate`).
    """

    low: tuple[float, ...]
    high: tuple[float, ...]
    runs: int
    seed: int
    z0: tuple[float, ...] | None = None

    def check_z0(self, n_z: int) -> None:
        """Fail, naming ``initial_states.z0``, unless it has one entry per observer state."""
        if self.z0 is not None and len(self.z0) != n_z:
            raise SpecError(
                f"`initial_states.z0` has {len(self.z0)} entries but the observer has n_z = {n_z}; "
                f"expected {n_z} numbers"
            )

    def draw(self, count: int | None = None) -> np.ndarray:
        """The first ``count`` (default ``runs``) initial states, shape ``(count, n_x)``.

        Row ``k`` is the same whatever ``count``, and for every group.
        """
        rng = np.random.default_rng(self.seed)
        lo, hi = np.array(self.low), np.array(self.high)
        n = self.runs if count is None else count
        return lo + rng.uniform(0.0, 1.0, size=(n, lo.size)) * (hi - lo)


@dataclass(frozen=True)
class Metrics:
    """Windows of the per-run metrics and the grid spacing of the error metric."""

    transmissions_window: tuple[float, float]
    error_window: tuple[float, float]
    error_grid_step: float

    def grid(self) -> np.ndarray:
        """The save grid on which ``max |x - xhat|`` is taken: steps from the window's start.

        Points past the window's end by rounding are left out (on [20, 30] with a 1 ms
        step the last ``lo + k step`` is 1.2e-11 above 30): they would lie past the
        horizon when the window ends at ``t_end``.
        """
        lo, hi = self.error_window
        return step_grid(lo, hi, self.error_grid_step)


@dataclass(frozen=True, kw_only=True)
class Experiment(abc.ABC):
    """The parts every experiment spec shares; subclasses say what their groups are.

    A group is one problem simulated from the spec's initial states (a sweep's parameter
    row under a scenario, a comparison's rule on a network). Groups are numbered
    ``0 .. n_groups - 1``.
    """

    name: str
    factory: str
    initial_states: InitialStates
    t_end: float
    metrics: Metrics
    solver: dict[str, Any]
    backend: str
    chunk_size: int
    raw: dict[str, Any] = field(repr=False, compare=False)

    @classmethod
    @abc.abstractmethod
    def from_raw(cls, raw: dict[str, Any]) -> Self:
        """Validate a spec given as a dictionary (the parsed TOML)."""

    @property
    @abc.abstractmethod
    def n_groups(self) -> int:
        """Number of groups."""

    @abc.abstractmethod
    def group_identity(self, group: int) -> Any:
        """What, besides :meth:`identity`, determines the numbers of ``group`` (JSON-ready)."""

    @abc.abstractmethod
    def where(self, group: int) -> str:
        """``group`` in words, for reports and errors."""

    @abc.abstractmethod
    def problem(self, group: int) -> EstimationProblem:
        """The estimation problem of ``group``."""

    def check(self) -> None:  # noqa: B027 (a default, not an abstract method)
        """Fail early, naming the key, on what can be checked before any run (default: nothing)."""

    @property
    def options(self) -> SolverOptions:
        """The solver settings as :class:`SolverOptions`."""
        return SolverOptions(**self.solver)

    @property
    def n_runs(self) -> int:
        """Total number of runs: groups x initial states."""
        return self.n_groups * self.initial_states.runs

    def with_runs(self, runs: int | None = None, seed: int | None = None) -> Self:
        """The same experiment with another number of initial states and/or seed."""
        raw = {**self.raw, "initial_states": dict(self.raw["initial_states"])}
        if runs is not None:
            raw["initial_states"]["runs"] = runs
        if seed is not None:
            raw["initial_states"]["seed"] = seed
        return type(self).from_raw(raw)

    def with_backend(self, backend: str) -> Self:
        """The same experiment solved with another backend (``execution.backend``)."""
        raw = {**self.raw, "execution": {**self.raw.get("execution", {}), "backend": backend}}
        return type(self).from_raw(raw)

    def identity(self) -> dict[str, Any]:
        """What determines the numbers of every run, for result keys.

        Resolved values are used, so ``1`` and ``1.0`` or an omitted default and the
        same value written out give the same key. The number of runs is left out: run
        ``k``'s initial state is the ``k``-th row of the seeded draw whatever the total,
        so more runs reuse the ones already stored. The etobs version and the record
        format are included, so an upgrade never mixes old and new numbers. (A change to
        a user factory's code is not seen: use a new output folder.)
        """
        from etobs._version import __version__

        st, m = self.initial_states, self.metrics
        return normalize(
            {
                "etobs": __version__,
                "records": RECORD_FORMAT,
                "factory": self.factory,
                # z0 only when given: the keys of specs without it are those of earlier versions
                "initial_states": {"low": st.low, "high": st.high, "seed": st.seed}
                | ({} if st.z0 is None else {"z0": st.z0}),
                "t_end": self.t_end,
                "metrics": [m.transmissions_window, m.error_window, m.error_grid_step],
                "solver": self.options.__dict__,
                "backend": self.backend,
            }
        )

    def resolved(self) -> dict[str, Any]:
        """The common settings with every default filled in (written to ``spec.json``)."""
        return {
            "name": self.name,
            "factory": self.factory,
            "initial_states": self.initial_states.__dict__,
            "t_end": self.t_end,
            "metrics": self.metrics.__dict__,
            "solver": self.options.__dict__,
            "backend": self.backend,
            "chunk_size": self.chunk_size,
        }


def parse_common(top: dict[str, Any], *, default_name: str, kwargs_key: str) -> dict[str, Any]:
    """The shared tables of a spec whose top-level keys were checked, as keyword arguments.

    ``kwargs_key`` names the ``[system]`` table of factory arguments (``fixed`` in a
    sweep, ``params`` in a comparison); it is returned under ``"kwargs"``.
    """
    system = _keys("system", top["system"], {"factory": FACTORY}, {kwargs_key})
    if not isinstance(system["factory"], str):
        raise SpecError(f"`system.factory` must be a string; got {shown(system['factory'])}")
    kwargs = system.get(kwargs_key, {})
    if not isinstance(kwargs, dict):
        raise SpecError(f"`system.{kwargs_key}` must be a table of keyword arguments; got {shown(kwargs)}")
    hor = _keys("horizon", top["horizon"], {"t_end": "a number > 0"}, set())
    t_end = float(_number("horizon.t_end", hor["t_end"], lower=0.0, strict=True))
    execution = _keys("execution", top.get("execution", {}), set(), {"chunk_size", "backend"})
    chunk = execution.get("chunk_size", DEFAULT_CHUNK)
    return {
        "name": _name("name", top.get("name", default_name)),
        "factory": system["factory"],
        "kwargs": dict(kwargs),
        "initial_states": parse_initial_states(top["initial_states"]),
        "t_end": t_end,
        "metrics": parse_metrics(top.get("metrics", {}), t_end),
        "solver": parse_solver(top.get("solver", {})),
        "backend": parse_backend(execution.get("backend", "auto")),
        "chunk_size": int(_number("execution.chunk_size", chunk, lower=1, integer=True)),
    }


#: Top-level keys :func:`parse_common` reads (required, optional).
COMMON_KEYS = (
    {"system": TABLE, "initial_states": TABLE, "horizon": TABLE},
    {"name", "metrics", "solver", "execution"},
)


def normalize(obj: Any, *, ints_as_floats: bool = True) -> Any:
    """JSON-ready copy: numpy scalars to Python, tuples to lists, inf and NaN to strings.

    With ``ints_as_floats`` (for result keys) ``1`` and ``1.0`` become the same value.
    """
    if isinstance(obj, dict):
        return {str(k): normalize(v, ints_as_floats=ints_as_floats) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [normalize(v, ints_as_floats=ints_as_floats) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return str(obj)
    if ints_as_floats and isinstance(obj, int) and not isinstance(obj, bool):
        return float(obj)
    return obj


def _pair(key: str, value: Any) -> tuple[float, float]:
    if not isinstance(value, list) or len(value) != 2:
        raise SpecError(f"`{key}` must be a pair [start, stop]; got {shown(value)}")
    lo, hi = (_number(f"{key}[{i}]", v) for i, v in enumerate(value))
    if hi < lo:
        raise SpecError(f"`{key}` must satisfy start <= stop; got {shown(value)}")
    return float(lo), float(hi)


def _window(key: str, value: Any, t_end: float) -> tuple[float, float]:
    lo, hi = _pair(key, value)
    if lo < 0 or hi > t_end:
        raise SpecError(f"`{key}` must lie within [0, horizon.t_end = {t_end:g}]; got {shown(value)}")
    return lo, hi


def parse_backend(value: Any) -> str:
    """Validate ``execution.backend`` (:func:`~etobs.hybrid.checks.check_backend`)."""
    try:
        return check_backend(value, "execution.backend")
    except EtobsError as exc:
        raise SpecError(str(exc)) from None


def parse_initial_states(table: Any) -> InitialStates:
    """Validate ``[initial_states]``: ``low``, ``high``, ``runs``, ``seed``."""
    box = "a non-empty list of numbers (one per plant state)"
    ini = _keys(
        "initial_states",
        table,
        {"low": box, "high": box, "runs": "an integer >= 1", "seed": "an integer >= 0"},
        {"z0"},
    )
    for k in ("low", "high"):
        if not isinstance(ini[k], list) or not ini[k]:
            raise SpecError(f"`initial_states.{k}` must be a non-empty list of numbers; got {shown(ini[k])}")
    low = tuple(float(_number(f"initial_states.low[{i}]", v)) for i, v in enumerate(ini["low"]))
    high = tuple(float(_number(f"initial_states.high[{i}]", v)) for i, v in enumerate(ini["high"]))
    if len(low) != len(high):
        raise SpecError(
            f"`initial_states.low` has {len(low)} entries but `initial_states.high` has {len(high)}"
        )
    if any(h < lo for lo, h in zip(low, high, strict=True)):
        raise SpecError("`initial_states.high` must be >= `initial_states.low` entrywise")
    z0 = ini.get("z0")
    if z0 is not None:
        if not isinstance(z0, list) or not z0:
            raise SpecError(
                "`initial_states.z0` must be a non-empty list of numbers (one per observer state); "
                f"got {shown(z0)}"
            )
        z0 = tuple(float(_number(f"initial_states.z0[{i}]", v)) for i, v in enumerate(z0))
    return InitialStates(
        low,
        high,
        int(_number("initial_states.runs", ini["runs"], lower=1, integer=True)),
        int(_number("initial_states.seed", ini["seed"], lower=0, integer=True)),
        z0,
    )


def parse_metrics(table: Any, t_end: float) -> Metrics:
    """Validate ``[metrics]`` (every key optional) for a horizon ``t_end``."""
    met = _keys("metrics", table, set(), {"transmissions_window", "error_window", "error_grid_step"})
    error_window = _window("metrics.error_window", met.get("error_window", [0.0, t_end]), t_end)
    step = float(_number("metrics.error_grid_step", met.get("error_grid_step", 1e-3), lower=0.0, strict=True))
    width = error_window[1] - error_window[0]
    if width / step > MAX_GRID_POINTS:
        raise SpecError(
            f"`metrics.error_grid_step` = {step:g} gives {width / step:.3g} grid points on "
            f"`metrics.error_window`; at most {MAX_GRID_POINTS:g}: use a step >= {width / MAX_GRID_POINTS:g}"
        )
    return Metrics(
        _window("metrics.transmissions_window", met.get("transmissions_window", [0.0, t_end]), t_end),
        error_window,
        step,
    )


def check_size(groups: int, runs: int, what: str) -> None:
    """Refuse more than :data:`MAX_RUNS` runs (``groups`` of ``what`` x ``runs`` initial states)."""
    if groups * runs > MAX_RUNS:
        raise SpecError(
            f"{what} ({groups:.3g} groups) x `initial_states.runs` = {runs} (or --runs) make "
            f"{groups * runs:.3g} runs; "
            f"at most {MAX_RUNS:g} in one experiment: split it"
        )


def parse_solver(table: Any) -> dict[str, Any]:
    """Validate ``[solver]``: any :class:`SolverOptions` field."""
    solver = _keys("solver", table, set(), _SOLVER_KEYS)
    try:
        SolverOptions(**solver)
    except EtobsError as exc:
        raise SpecError(f"`solver`: {exc}") from exc
    return dict(solver)
