"""Sweep specifications: a validated, frozen description of a Monte-Carlo sweep.

A spec is data, usually a TOML file (see ``examples/table1.toml``)::

    name = "table1"
    [system]
    factory = "robot_arm"          # a registered example or "package.module:function"
    fixed = { c = [0.001, 0.001] } # keyword arguments given to every row
    [[rows]]                       # one table per parameter row (or a [grid])
    sigma = [600, 800]
    [[scenarios]]                  # each row runs under every scenario
    name = "with_v_m"
    noise = true
    [initial_states]               # uniform in a box, seeded
    low = [0, 0, 0, 0]
    high = [20, 10, 20, 10]
    runs = 100
    seed = 2023
    [horizon]
    t_end = 30.0
    [metrics]
    transmissions_window = [0.0, 30.0]
    error_window = [20.0, 30.0]
    error_grid_step = 0.001
    [solver]                       # any SolverOptions field
    rtol = 1e-10
    [execution]
    chunk_size = 100               # runs solved together
    backend = "auto"               # or "engine", "scipy" (see etobs.simulate)

Every key is checked: unknown keys are rejected and a wrong value names its key.
"""

from __future__ import annotations

import itertools
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from etobs._spec import SpecError
from etobs._spec import keys as _keys
from etobs._spec import number as _number
from etobs.errors import InputError
from etobs.hybrid.options import SolverOptions
from etobs.hybrid.solver import check_backend

_SOLVER_KEYS = {
    "method",
    "rtol",
    "atol",
    "max_step",
    "first_step",
    "max_jumps",
    "max_steps",
    "event_samples",
    "event_xtol",
}


def _pair(key: str, value: Any) -> tuple[float, float]:
    if not isinstance(value, list) or len(value) != 2:
        raise SpecError(f"`{key}` must be a pair [start, stop]; got {value!r}")
    lo, hi = (_number(f"{key}[{i}]", v) for i, v in enumerate(value))
    if hi < lo:
        raise SpecError(f"`{key}` must satisfy start <= stop; got {value!r}")
    return float(lo), float(hi)


def _window(key: str, value: Any, t_end: float) -> tuple[float, float]:
    lo, hi = _pair(key, value)
    if lo < 0 or hi > t_end:
        raise SpecError(f"`{key}` must lie within [0, horizon.t_end = {t_end:g}]; got {value!r}")
    return lo, hi


#: Columns of the result tables; a parameter may not take one of these names.
RESERVED = ("row", "scenario", "run", "status", "transmissions", "error", "steps", "runs", "completed")
_RESERVED_PREFIXES = ("transmissions_", "min_inter_event_time_", "x0_", "error_", "paper_")


def _check_names(rows: tuple[dict[str, Any], ...], scenarios: tuple[Any, ...], fixed: dict[str, Any]) -> None:
    tables = [("system.fixed", fixed)] + [(f"rows[{i}]", r) for i, r in enumerate(rows)]
    tables += [(f"scenarios[{i}]", s.params) for i, s in enumerate(scenarios)]
    for where, table in tables:
        for key in table:
            if key in RESERVED or key.startswith(_RESERVED_PREFIXES):
                raise SpecError(f"parameter `{where}.{key}` clashes with a result column; rename it")


def _name(key: str, value: Any) -> str:
    if not isinstance(value, str) or not value or not all(c.isalnum() or c in "_-" for c in value):
        raise SpecError(f"`{key}` must be a non-empty name of letters, digits, '_' or '-'; got {value!r}")
    return value


@dataclass(frozen=True)
class InitialStates:
    """Plant initial states drawn uniformly in the box ``[low, high]`` with ``seed``."""

    low: tuple[float, ...]
    high: tuple[float, ...]
    runs: int
    seed: int

    def draw(self, count: int | None = None) -> np.ndarray:
        """The first ``count`` (default ``runs``) initial states, shape ``(count, n_x)``.

        Row ``k`` is the same whatever ``count``, and for every row and scenario.
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


@dataclass(frozen=True)
class Scenario:
    """A named set of keyword arguments added to every row (e.g. with or without noise)."""

    name: str
    params: dict[str, Any]


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep; build it with :func:`load_spec` or :func:`parse_spec`."""

    name: str
    factory: str
    fixed: dict[str, Any]
    rows: tuple[dict[str, Any], ...]
    scenarios: tuple[Scenario, ...]
    initial_states: InitialStates
    t_end: float
    metrics: Metrics
    solver: dict[str, Any]
    raw: dict[str, Any] = field(repr=False, compare=False)

    @property
    def backend(self) -> str:
        """The solver backend asked for: ``execution.backend`` (default ``"auto"``).

        ``"numba"`` is given as ``"engine"``. ``"auto"`` is passed to
        :func:`~etobs.estimation.simulate.simulate`, which picks the engine (or the scipy
        reference for a rule of your own).
        """
        return parse_backend(self.raw.get("execution", {}).get("backend", "auto"))

    @property
    def options(self) -> SolverOptions:
        """The solver settings as :class:`SolverOptions`."""
        return SolverOptions(**self.solver)

    @property
    def n_runs(self) -> int:
        """Total number of runs: rows x scenarios x initial states."""
        return len(self.rows) * len(self.scenarios) * self.initial_states.runs

    def with_runs(self, runs: int | None = None, seed: int | None = None) -> SweepSpec:
        """The same sweep with another number of initial states and/or seed."""
        raw = {**self.raw, "initial_states": dict(self.raw["initial_states"])}
        if runs is not None:
            raw["initial_states"]["runs"] = runs
        if seed is not None:
            raw["initial_states"]["seed"] = seed
        return parse_spec(raw)

    def with_backend(self, backend: str) -> SweepSpec:
        """The same sweep solved with another backend (``execution.backend``)."""
        raw = {**self.raw, "execution": {**self.raw.get("execution", {}), "backend": backend}}
        return parse_spec(raw)

    def identity(self) -> dict[str, Any]:
        """What determines the numbers of a run, for result keys.

        Resolved values are used, so ``1`` and ``1.0`` or an omitted default and the
        same value written out give the same key. The number of runs is left out: run
        ``k``'s initial state is the ``k``-th row of the seeded draw whatever the total,
        so more runs reuse the ones already stored. The etobs version is included, so
        an upgrade never mixes old and new numbers. (A change to a user factory's code is
        not seen: use a new output folder.)
        """
        from etobs import __version__

        st, m = self.initial_states, self.metrics
        return normalize(
            {
                "etobs": __version__,
                "factory": self.factory,
                "initial_states": {"low": st.low, "high": st.high, "seed": st.seed},
                "t_end": self.t_end,
                "metrics": [m.transmissions_window, m.error_window, m.error_grid_step],
                "solver": self.options.__dict__,
                "backend": self.backend,
            }
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


def load_spec(path: str | Path) -> SweepSpec:
    """Read and validate a TOML sweep spec."""
    p = Path(path)
    try:
        raw = tomllib.loads(p.read_text())
    except FileNotFoundError as exc:
        raise SpecError(f"spec file {str(p)!r} does not exist") from exc
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"spec file {str(p)!r} is not valid TOML: {exc}") from exc
    return parse_spec(raw)


def parse_spec(raw: dict[str, Any]) -> SweepSpec:
    """Validate a spec given as a dictionary (the parsed TOML)."""
    top = _keys(
        "spec",
        raw,
        {"system", "initial_states", "horizon"},
        {"name", "rows", "grid", "scenarios", "metrics", "solver", "execution"},
    )
    name = _name("name", top.get("name", "sweep"))
    system = _keys("system", top["system"], {"factory"}, {"fixed"})
    if not isinstance(system["factory"], str):
        raise SpecError(f"`system.factory` must be a string; got {system['factory']!r}")
    fixed = system.get("fixed", {})
    if not isinstance(fixed, dict):
        raise SpecError("`system.fixed` must be a table of keyword arguments")
    if "rows" in top and "grid" in top:
        raise SpecError("give either `rows` or `grid`, not both")
    rows = _rows(top)
    scenarios = _scenarios(top.get("scenarios", [{"name": "default"}]))
    states = parse_initial_states(top["initial_states"])
    hor = _keys("horizon", top["horizon"], {"t_end"}, set())
    t_end = float(_number("horizon.t_end", hor["t_end"], lower=0.0, strict=True))
    metrics = parse_metrics(top.get("metrics", {}), t_end)
    solver = parse_solver(top.get("solver", {}))
    execution = _keys("execution", top.get("execution", {}), set(), {"chunk_size", "backend"})
    if "chunk_size" in execution:
        _number("execution.chunk_size", execution["chunk_size"], lower=1, integer=True)
    parse_backend(execution.get("backend", "auto"))
    _check_names(rows, scenarios, fixed)
    return SweepSpec(
        name=name,
        factory=system["factory"],
        fixed=dict(fixed),
        rows=rows,
        scenarios=scenarios,
        initial_states=states,
        t_end=t_end,
        metrics=metrics,
        solver=dict(solver),
        raw=raw,
    )


def parse_backend(value: Any) -> str:
    """Validate ``execution.backend`` (:func:`~etobs.hybrid.solver.check_backend`)."""
    try:
        return check_backend(value, "execution.backend")
    except InputError as exc:
        raise SpecError(str(exc)) from None


def parse_initial_states(table: Any) -> InitialStates:
    """Validate ``[initial_states]``: ``low``, ``high``, ``runs``, ``seed``."""
    ini = _keys("initial_states", table, {"low", "high", "runs", "seed"}, set())
    for k in ("low", "high"):
        if not isinstance(ini[k], list) or not ini[k]:
            raise SpecError(f"`initial_states.{k}` must be a non-empty list of numbers; got {ini[k]!r}")
    low = tuple(float(_number(f"initial_states.low[{i}]", v)) for i, v in enumerate(ini["low"]))
    high = tuple(float(_number(f"initial_states.high[{i}]", v)) for i, v in enumerate(ini["high"]))
    if len(low) != len(high):
        raise SpecError(
            f"`initial_states.low` has {len(low)} entries but `initial_states.high` has {len(high)}"
        )
    if any(h < lo for lo, h in zip(low, high, strict=True)):
        raise SpecError("`initial_states.high` must be >= `initial_states.low` entrywise")
    return InitialStates(
        low,
        high,
        int(_number("initial_states.runs", ini["runs"], lower=1, integer=True)),
        int(_number("initial_states.seed", ini["seed"], lower=0, integer=True)),
    )


def parse_metrics(table: Any, t_end: float) -> Metrics:
    """Validate ``[metrics]`` (every key optional) for a horizon ``t_end``."""
    met = _keys("metrics", table, set(), {"transmissions_window", "error_window", "error_grid_step"})
    return Metrics(
        _window("metrics.transmissions_window", met.get("transmissions_window", [0.0, t_end]), t_end),
        _window("metrics.error_window", met.get("error_window", [0.0, t_end]), t_end),
        float(_number("metrics.error_grid_step", met.get("error_grid_step", 1e-3), lower=0.0, strict=True)),
    )


def parse_solver(table: Any) -> dict[str, Any]:
    """Validate ``[solver]``: any :class:`SolverOptions` field."""
    solver = _keys("solver", table, set(), _SOLVER_KEYS)
    try:
        SolverOptions(**solver)
    except InputError as exc:
        raise SpecError(f"`solver`: {exc}") from exc
    return dict(solver)


def _rows(top: dict[str, Any]) -> tuple[dict[str, Any], ...]:
    if "grid" in top:
        grid = top["grid"]
        if not isinstance(grid, dict) or not grid:
            raise SpecError("`grid` must be a table mapping each parameter to a list of values")
        for k, vals in grid.items():
            if not isinstance(vals, list) or not vals:
                raise SpecError(f"`grid.{k}` must be a non-empty list of values; got {vals!r}")
        keys = list(grid)
        return tuple(dict(zip(keys, combo, strict=True)) for combo in itertools.product(*grid.values()))
    rows = top.get("rows", [{}])
    if not isinstance(rows, list) or not rows or not all(isinstance(r, dict) for r in rows):
        raise SpecError("`rows` must be a non-empty array of tables ([[rows]])")
    return tuple(dict(r) for r in rows)


def _scenarios(items: Any) -> tuple[Scenario, ...]:
    if not isinstance(items, list) or not items or not all(isinstance(s, dict) for s in items):
        raise SpecError("`scenarios` must be a non-empty array of tables ([[scenarios]])")
    out, seen = [], set()
    for i, s in enumerate(items):
        if "name" not in s:
            raise SpecError(f"missing key `scenarios[{i}].name`")
        nm = _name(f"scenarios[{i}].name", s["name"])
        if nm in seen:
            raise SpecError(f"`scenarios[{i}].name` repeats {nm!r}")
        seen.add(nm)
        out.append(Scenario(nm, {k: v for k, v in s.items() if k != "name"}))
    return tuple(out)


def chunk_size(spec: SweepSpec, default: int = 20) -> int:
    """The ``execution.chunk_size`` of the spec (runs per chunk)."""
    value = spec.raw.get("execution", {}).get("chunk_size", default)
    return int(_number("execution.chunk_size", value, lower=1, integer=True))
