"""Sweep specifications: a validated, frozen description of a Monte-Carlo sweep.

A spec is data, usually a TOML file (see ``examples/table1.toml``): every key, its type,
default and limits, and a minimal and a full example are in ``docs/specs.md`` ("Sweep"),
which a test keeps in step with this parser. Every key is checked: unknown keys are
rejected and a wrong value names its key. The tables a sweep shares with a comparison
are parsed by :func:`etobs.experiments.common.parse_common`.
"""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from etobs._spec import TOP, SpecError, argument_named, check_tree, in_file, read_toml
from etobs._spec import keys as _keys
from etobs._spec import name as _name
from etobs._validate import shown
from etobs.errors import EtobsError
from etobs.estimation.problem import EstimationProblem
from etobs.examples.registry import located
from etobs.experiments.common import COMMON_KEYS, Experiment, check_size, normalize, parse_common
from etobs.experiments.systems import build, check_arguments
from etobs.hybrid.options import SolverOptions, beyond_step_limit

#: Columns of the result tables; a parameter may not take one of these names.
RESERVED = ("row", "scenario", "run", "status", "transmissions", "error", "steps", "runs", "completed")
_RESERVED_PREFIXES = (
    "transmissions_",
    "min_inter_event_time_",
    "x0_",
    "error_",
    "paper_",
    "packets_",
    "not_applied_",
)


def _check_names(rows: tuple[dict[str, Any], ...], scenarios: tuple[Any, ...], fixed: dict[str, Any]) -> None:
    tables = [("system.fixed", fixed)] + [(f"rows[{i}]", r) for i, r in enumerate(rows)]
    tables += [(f"scenarios[{i}]", s.params) for i, s in enumerate(scenarios)]
    for where, table in tables:
        for key in table:
            if key in RESERVED or key.startswith(_RESERVED_PREFIXES):
                raise SpecError(f"parameter `{where}.{key}` clashes with a result column; rename it")


@dataclass(frozen=True)
class Scenario:
    """A named set of keyword arguments added to every row (e.g. with or without noise)."""

    name: str
    params: dict[str, Any]


@dataclass(frozen=True, kw_only=True)
class SweepSpec(Experiment):
    """A validated sweep; build it with :func:`load_spec` or :func:`parse_spec`.

    Its groups are the rows under each scenario: group ``g`` is row ``g // S`` under
    scenario ``g % S`` (``S`` scenarios).
    """

    fixed: dict[str, Any]
    rows: tuple[dict[str, Any], ...]
    scenarios: tuple[Scenario, ...]

    @classmethod
    def from_raw(cls, raw: dict[str, Any]) -> SweepSpec:
        """Validate a spec given as a dictionary (:func:`parse_spec`)."""
        return parse_spec(raw)

    @property
    def n_groups(self) -> int:
        """Rows x scenarios."""
        return len(self.rows) * len(self.scenarios)

    def row_scenario(self, group: int) -> tuple[int, int]:
        """The row and scenario of ``group``."""
        return divmod(group, len(self.scenarios))

    def kwargs(self, group: int) -> dict[str, Any]:
        """Keyword arguments of the factory for ``group``: fixed, then row, then scenario."""
        r, s = self.row_scenario(group)
        return {**self.fixed, **self.rows[r], **self.scenarios[s].params}

    def group_identity(self, group: int) -> Any:
        """The factory's keyword arguments (resolved)."""
        return normalize(self.kwargs(group))

    def where(self, group: int) -> str:
        """``row R, scenario 'NAME'``."""
        r, s = self.row_scenario(group)
        return f"row {r}, scenario {self.scenarios[s].name!r}"

    def problem(self, group: int) -> EstimationProblem:
        """The factory called with :meth:`kwargs`.

        An error the factory raises about one of its arguments (a message that starts
        with the argument's name in backquotes, as etobs's checks write it) names the
        spec key that gave it, e.g. ``rows[2].sigma``.
        """
        kwargs = self.kwargs(group)
        try:
            problem = build(self.factory, kwargs, len(self.initial_states.low), self.where(group))
        except SpecError as exc:
            cause = exc.__cause__
            if cause is None or isinstance(cause, SpecError):
                raise
            named = argument_named(str(cause)) if isinstance(cause, EtobsError) else None
            if named is None or named not in kwargs:  # the factory's own name for it: list the keys it got
                given = ", ".join(f"`{self.origin(group, k)}`" for k in kwargs) or "none"
                raise SpecError(f"{exc} (the spec keys given to the factory: {given})") from cause
            raise SpecError(f"`{self.origin(group, named)}` ({self.where(group)}): {cause}") from cause
        self.initial_states.check_z0(problem.observer.n_z)
        return problem

    def origin(self, group: int, key: str) -> str:
        """The spec key that gives the factory's argument ``key`` in ``group``.

        A scenario's value wins over a row's, and a row's over ``system.fixed``'s.
        """
        r, s = self.row_scenario(group)
        if key in self.scenarios[s].params:
            return f"scenarios[{s}].{key}"
        if key in self.rows[r]:
            return f"grid.{key}" if "grid" in self.raw else f"rows[{r}].{key}"
        return f"system.fixed.{key}"

    def resolved(self) -> dict[str, Any]:
        """The common settings, the fixed arguments, the rows and the scenarios."""
        scenarios = [{"name": sc.name, **sc.params} for sc in self.scenarios]
        return {**super().resolved(), "fixed": self.fixed, "rows": list(self.rows), "scenarios": scenarios}

    def check(self) -> None:
        """Build every group's problem, so a value the model refuses fails before any run.

        As in a comparison (:meth:`CompareSpec.check`), the values are checked by the
        classes that take them (a negative ``sigma`` by the rule), reached through the
        factory; the error names the spec key (``rows[2].sigma``). Groups with the same
        arguments are built once.
        """
        calls = [(self.where(g), self.kwargs(g)) for g in range(self.n_groups)]
        check_arguments(self.factory, calls, origin=self.origin)
        built = set()
        for g in range(self.n_groups):
            ident = json.dumps(self.group_identity(g), sort_keys=True, default=repr)
            if ident not in built:
                built.add(ident)
                self.problem(g)


def load_spec(path: str | Path) -> SweepSpec:
    """Read (at most 1 MiB, :func:`etobs._spec.read_toml`) and validate a TOML sweep spec.

    An error names the file, the key and what it expects (the keys: ``docs/specs.md``).
    A relative ``path/file.py`` factory is taken from the spec file's folder.
    """
    with in_file(path):
        return parse_spec(read_toml(path), folder=Path(path).resolve().parent)


def parse_spec(raw: dict[str, Any], *, folder: str | Path | None = None) -> SweepSpec:
    """Validate a spec given as a dictionary (the parsed TOML).

    A relative ``path/file.py`` factory is taken from ``folder`` (the spec file's; made
    absolute in the spec's ``raw``, which its workers read), or from the current folder
    when it is called if ``folder`` is ``None``.
    """
    check_tree(raw)
    raw = located(raw, folder)
    required, optional = COMMON_KEYS
    top = _keys(TOP, raw, required, optional | {"rows", "grid", "scenarios"})
    common = parse_common(top, default_name="sweep", kwargs_key="fixed")
    fixed = common.pop("kwargs")
    # refused before any run is spent: each would stop at its step limit
    too_long = beyond_step_limit(
        common["t_end"], SolverOptions(**common["solver"]), t_end="horizon.t_end", solver="solver."
    )
    if too_long:
        raise SpecError(too_long)
    if "rows" in top and "grid" in top:
        raise SpecError("give either `rows` or `grid`, not both")
    scenarios = _scenarios(top.get("scenarios", [{"name": "default"}]))
    rows = _rows(top, len(scenarios), common["initial_states"].runs)
    _check_names(rows, scenarios, fixed)
    return SweepSpec(**common, fixed=fixed, rows=rows, scenarios=scenarios, raw=raw)


def _rows(top: dict[str, Any], scenarios: int, runs: int) -> tuple[dict[str, Any], ...]:
    """The parameter rows; their number is checked before a grid is expanded."""
    if "grid" in top:
        grid = top["grid"]
        if not isinstance(grid, dict) or not grid:
            raise SpecError(
                "`grid` must be a non-empty table mapping each parameter to a list of values; "
                f"got {shown(grid)}"
            )
        for k, vals in grid.items():
            if not isinstance(vals, list) or not vals:
                raise SpecError(f"`grid.{k}` must be a non-empty list of values; got {shown(vals)}")
        check_size(math.prod(len(v) for v in grid.values()) * scenarios, runs, "`grid` x `scenarios`")
        keys = list(grid)
        return tuple(dict(zip(keys, combo, strict=True)) for combo in itertools.product(*grid.values()))
    rows = top.get("rows", [{}])
    if not isinstance(rows, list) or not rows or not all(isinstance(r, dict) for r in rows):
        raise SpecError(f"`rows` must be a non-empty array of tables ([[rows]]); got {shown(rows)}")
    check_size(len(rows) * scenarios, runs, "`rows` x `scenarios`")
    return tuple(dict(r) for r in rows)


def _scenarios(items: Any) -> tuple[Scenario, ...]:
    if not isinstance(items, list) or not items or not all(isinstance(s, dict) for s in items):
        raise SpecError(
            f"`scenarios` must be a non-empty array of tables ([[scenarios]]); got {shown(items)}"
        )
    out, seen = [], set()
    for i, s in enumerate(items):
        if "name" not in s:  # the other keys are the factory's arguments
            raise SpecError(
                f"missing key `scenarios[{i}].name`: expected a name of letters, digits, '_' or '-'"
            )
        nm = _name(f"scenarios[{i}].name", s["name"])
        if nm in seen:
            raise SpecError(f"`scenarios[{i}].name` repeats {nm!r}")
        seen.add(nm)
        out.append(Scenario(nm, {k: v for k, v in s.items() if k != "name"}))
    return tuple(out)
