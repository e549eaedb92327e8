"""The tuning spec (``etobs tune SPEC``): what is searched, under which constraints, on which runs.

The keys are listed in ``docs/specs.md`` (format ``tune``); each error names the key.
A tuning spec is a sweep's shared tables (``system``, ``initial_states``, ``horizon``,
``metrics``, ``solver``, ``execution``: the Monte-Carlo runs every candidate is
simulated on), a check spec's ``[observer]`` and ``[guarantees]`` (how each candidate is
certified), and its own tables: ``[parameters]`` (the search space), ``[budget]``,
``[constraints]``, ``[objective]``, ``[search]``, ``[validation]`` and
``[[references]]``.
"""

from __future__ import annotations

import inspect
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from etobs._spec import TOP, SpecError, check_tree, in_file, read_toml
from etobs._spec import keys as _keys
from etobs._spec import name as _name
from etobs._spec import number as _number
from etobs._validate import shown
from etobs.examples.registry import check_arguments, located, resolve_factory
from etobs.experiments.check_spec import guarantees_table, observer_table
from etobs.experiments.common import COMMON_KEYS, parse_common

#: How a parameter is given to the factory: a list with one searched value per node, a
#: list with one searched value repeated for every node, or a plain number.
PER = ("node", "shared", "scalar")
#: What the budget bounds: the simulated error statistic, or the certificate's error bound.
BUDGET_KINDS = ("simulated", "certified")
#: The variable that picks one of ``[[observers]]``.
OBSERVER_VARIABLE = "observer"
#: At most this many trials in one tuning (each is a small sweep).
MAX_TRIALS = 100_000


@dataclass(frozen=True)
class Parameter:
    """One searched factory argument: a box (``low``, ``high``, ``log``) or ``choices``."""

    name: str
    low: float = math.nan
    high: float = math.nan
    log: bool = False
    per: str = "node"
    choices: tuple[Any, ...] = ()

    @property
    def categorical(self) -> bool:
        """Whether the parameter takes one of ``choices`` rather than a number in a box."""
        return bool(self.choices)


@dataclass(frozen=True)
class Budget:
    """The accuracy asked for: ``error`` bounds the simulated statistic or the certified bound."""

    kind: str
    error: float


@dataclass(frozen=True)
class Search:
    """How the search runs (``[search]``)."""

    trials: int = 100
    seed: int = 0
    batch: int = 4
    startup: int = 16
    prune_share: float = 0.25
    prune_z: float = 2.0
    screen: bool = True
    error_floor: float = 0.5


@dataclass(frozen=True)
class Reference:
    """A named design evaluated on the same runs as the candidates and marked on the plot."""

    name: str
    params: dict[str, Any]


@dataclass(frozen=True)
class TuneSpec:
    """A validated tuning spec; ``raw`` is the spec as given (its factory located).

    ``sweep`` holds the shared tables as a sweep reads them (``fixed``, the runs, the
    horizon, the metrics, the solver); ``observers`` maps an observer's name to its
    ``[observer]`` table (one entry named ``""`` for a single ``[observer]``, none
    without).
    """

    name: str
    factory: str
    fixed: dict[str, Any]
    parameters: tuple[Parameter, ...]
    budget: Budget
    search: Search
    observers: dict[str, dict[str, Any]]
    guarantees: dict[str, Any]
    tau_min: tuple[float, ...] | float | None
    quantile: float | None
    validation_runs: int
    validation_seed: int
    references: tuple[Reference, ...]
    common: dict[str, Any] = field(repr=False)
    raw: dict[str, Any] = field(repr=False, compare=False)

    def sweep_raw(
        self, rows: list[dict[str, Any]], *, runs: int | None = None, seed: int | None = None
    ) -> dict[str, Any]:
        """A sweep spec (as a dictionary) simulating ``rows`` on this spec's runs (or others)."""
        raw = {
            k: self.raw[k]
            for k in ("system", "initial_states", "horizon", "metrics", "solver", "execution")
            if k in self.raw
        }
        raw["name"] = self.name
        raw["system"] = {"factory": self.factory, "fixed": dict(self.fixed)}
        raw["initial_states"] = dict(raw["initial_states"])
        if runs is not None:
            raw["initial_states"]["runs"] = runs
        if seed is not None:
            raw["initial_states"]["seed"] = seed
        raw["rows"] = rows
        return raw

    @property
    def runs(self) -> int:
        """Monte-Carlo runs per candidate."""
        return int(self.common["initial_states"].runs)

    @property
    def window(self) -> float:
        """Length of the transmissions window (s)."""
        lo, hi = self.common["metrics"].transmissions_window
        return float(hi - lo)


_OWN = {
    "parameters",
    "budget",
    "search",
    "validation",
    "references",
    "constraints",
    "objective",
    "observer",
    "observers",
    "guarantees",
}


def load_tune_spec(path: str | Path) -> TuneSpec:
    """Read and validate a TOML tuning spec (a relative factory file from the spec's folder)."""
    with in_file(path):
        return parse_tune_spec(read_toml(path), folder=Path(path).resolve().parent)


def parse_tune_spec(raw: dict[str, Any], *, folder: str | Path | None = None) -> TuneSpec:
    """Validate a tuning spec given as a dictionary (the parsed TOML); errors name the key."""
    check_tree(raw)
    raw = located(raw, folder)
    required, optional = COMMON_KEYS
    top = _keys(
        TOP,
        raw,
        {**required, "parameters": "a table of factory arguments to search", "budget": "a table"},
        optional | _OWN,
    )
    common = parse_common(top, default_name="tune", kwargs_key="fixed")
    factory, fixed = common["factory"], common.pop("kwargs")
    parameters = _parameters(top["parameters"], fixed)
    observers = _observers(top)
    if observers and any(p.name == OBSERVER_VARIABLE for p in parameters):
        raise SpecError(
            f"`parameters.{OBSERVER_VARIABLE}` is the name of the observer choice of `[[observers]]`"
        )
    guarantees = guarantees_table(top.get("guarantees", {}), bool(observers))
    budget = _budget(top["budget"], bool(observers))
    search = _search(top.get("search", {}))
    val = _keys("validation", top.get("validation", {}), set(), {"runs", "seed"})
    runs = int(
        _number("validation.runs", val.get("runs", common["initial_states"].runs), lower=1, integer=True)
    )
    seed = int(
        _number("validation.seed", val.get("seed", common["initial_states"].seed + 1), lower=0, integer=True)
    )
    if seed == common["initial_states"].seed:
        raise SpecError(
            f"`validation.seed` must differ from `initial_states.seed` ({seed}): held-out runs are other runs"
        )
    cons = _keys("constraints", top.get("constraints", {}), set(), {"tau_min"})
    tau_min = None if "tau_min" not in cons else _per_node("constraints.tau_min", cons["tau_min"])
    if tau_min is not None and "E" not in guarantees and "E_estimate" not in guarantees:
        raise SpecError(
            "`constraints.tau_min` needs `guarantees.E` or `guarantees.E_estimate`: Theorem 4's tau_i is "
            "gamma_i^-1(eps_i) / E"
        )
    obj = _keys("objective", top.get("objective", {}), set(), {"error_quantile"})
    quantile = None
    if "error_quantile" in obj:
        quantile = float(_number("objective.error_quantile", obj["error_quantile"], lower=0.0, strict=True))
        if quantile > 1:
            raise SpecError(f"`objective.error_quantile` must be in (0, 1]; got {quantile!r}")
    refs = _references(top.get("references", []))
    names = {p.name for p in parameters}
    # with every searched argument (a value stands for each): a factory that needs one is
    # told apart by the start design, which is the factory with `system.fixed` alone
    searched = {n: None for n in names if n != OBSERVER_VARIABLE}
    calls = [("parameters", {**fixed, **searched})]
    calls += [(f"references[{i}].params", {**fixed, **searched, **r.params}) for i, r in enumerate(refs)]
    check_arguments(factory, calls)
    if len(observers) > 1 and "L" in fixed:  # with one observer, the certificate compares the two
        raise SpecError(
            "`system.fixed.L` fixes the observer gain that `[[observers]]` chooses: remove `system.fixed.L` "
            "(each candidate is simulated with its observer's L)"
        )
    return TuneSpec(
        name=common["name"],
        factory=factory,
        fixed=dict(fixed),
        parameters=parameters,
        budget=budget,
        search=search,
        observers=observers,
        guarantees=guarantees,
        tau_min=tau_min,
        quantile=quantile,
        validation_runs=runs,
        validation_seed=seed,
        references=refs,
        common=common,
        raw=raw,
    )


def _parameters(table: Any, fixed: dict[str, Any]) -> tuple[Parameter, ...]:
    if not isinstance(table, dict) or not table:
        raise SpecError(
            f"`parameters` must be a non-empty table of factory arguments to search; got {shown(table)}"
        )
    out = []
    for name, item in table.items():
        where = f"parameters.{name}"
        if name in fixed:
            raise SpecError(f"`{where}` is also in `system.fixed`: a parameter is either searched or fixed")
        t = _keys(where, item, set(), {"low", "high", "log", "per", "choices"})
        per = t.get("per", "node")
        if per not in PER:
            raise SpecError(f"`{where}.per` must be one of {', '.join(PER)}; got {shown(per)}")
        if "choices" in t:
            extra = sorted(set(t) & {"low", "high", "log"})
            if extra:
                raise SpecError(f"`{where}.{extra[0]}` goes with a box, not with `{where}.choices`")
            ch = t["choices"]
            if not isinstance(ch, list) or not ch:
                raise SpecError(f"`{where}.choices` must be a non-empty list; got {shown(ch)}")
            out.append(Parameter(name, per=per, choices=tuple(ch)))
            continue
        missing = [k for k in ("low", "high") if k not in t]
        if missing:
            raise SpecError(
                f"missing key `{where}.{missing[0]}`: expected a number (or give `{where}.choices`)"
            )
        low, high = (float(_number(f"{where}.{k}", t[k])) for k in ("low", "high"))
        log = t.get("log", False)
        if not isinstance(log, bool):
            raise SpecError(f"`{where}.log` must be true or false; got {shown(log)}")
        if low > high:
            raise SpecError(f"`{where}` is an empty box: `low` = {low:g} > `high` = {high:g}")
        if log and low <= 0:
            raise SpecError(f"`{where}.low` must be > 0 with `log = true`; got {low:g}")
        out.append(Parameter(name, low, high, log, per))
    return tuple(out)


def _observers(top: dict[str, Any]) -> dict[str, dict[str, Any]]:
    if "observer" in top and "observers" in top:
        raise SpecError("give either `[observer]` (one) or `[[observers]]` (a choice), not both")
    if "observer" in top:
        return {"": dict(observer_table("observer", top["observer"]))}  # values: when the gains are computed
    if "observers" not in top:
        return {}
    items = top["observers"]
    if not isinstance(items, list) or not items or not all(isinstance(o, dict) for o in items):
        raise SpecError(
            f"`observers` must be a non-empty array of tables ([[observers]]); got {shown(items)}"
        )
    out: dict[str, dict[str, Any]] = {}
    for i, o in enumerate(items):
        observer_table(f"observers[{i}]", o, {"name": "a name of letters, digits, '_' or '-'"})
        nm = _name(f"observers[{i}].name", o["name"])
        if nm in out:
            raise SpecError(f"`observers[{i}].name` repeats {nm!r}")
        out[nm] = {k: x for k, x in o.items() if k != "name"}
    return out


def _budget(table: Any, with_iss: bool) -> Budget:
    t = _keys("budget", table, {"kind": f"one of {', '.join(BUDGET_KINDS)}", "error": "a number > 0"}, set())
    if t["kind"] not in BUDGET_KINDS:
        raise SpecError(f"`budget.kind` must be one of {', '.join(BUDGET_KINDS)}; got {shown(t['kind'])}")
    if t["kind"] == "certified" and not with_iss:
        raise SpecError(
            '`budget.kind = "certified"` needs `[observer]` or `[[observers]]`: the certified error bound '
            "rests on the observer's ISS gains (Theorem 2)"
        )
    return Budget(t["kind"], float(_number("budget.error", t["error"], lower=0.0, strict=True)))


def _search(table: Any) -> Search:
    names = ("trials", "seed", "batch", "startup", "prune_share", "prune_z", "screen", "error_floor")
    t = _keys("search", table, set(), set(names))
    d = Search()
    trials = int(_number("search.trials", t.get("trials", d.trials), lower=1, integer=True))
    if trials > MAX_TRIALS:
        raise SpecError(f"`search.trials` must be <= {MAX_TRIALS}; got {trials}")
    share = float(_number("search.prune_share", t.get("prune_share", d.prune_share), lower=0.0))
    if share >= 1:
        raise SpecError(f"`search.prune_share` must be < 1 (0: no pruning); got {share!r}")
    floor = float(_number("search.error_floor", t.get("error_floor", d.error_floor), lower=0.0))
    if floor > 1:
        raise SpecError(f"`search.error_floor` must be in [0, 1] (a share of the budget); got {floor!r}")
    screen = t.get("screen", d.screen)
    if not isinstance(screen, bool):
        raise SpecError(f"`search.screen` must be true or false; got {shown(screen)}")
    return Search(
        trials=trials,
        seed=int(_number("search.seed", t.get("seed", d.seed), lower=0, integer=True)),
        batch=int(_number("search.batch", t.get("batch", d.batch), lower=1, integer=True)),
        startup=int(_number("search.startup", t.get("startup", d.startup), lower=0, integer=True)),
        prune_share=share,
        prune_z=float(_number("search.prune_z", t.get("prune_z", d.prune_z), lower=0.0)),
        screen=screen,
        error_floor=floor,
    )


def _per_node(key: str, value: Any) -> tuple[float, ...] | float:
    if isinstance(value, list):
        return tuple(float(_number(f"{key}[{i}]", x, lower=0.0)) for i, x in enumerate(value))
    return float(_number(key, value, lower=0.0))


def _references(items: Any) -> tuple[Reference, ...]:
    if not isinstance(items, list) or not all(isinstance(r, dict) for r in items):
        raise SpecError(f"`references` must be an array of tables ([[references]]); got {shown(items)}")
    out, seen = [], set()
    for i, r in enumerate(items):
        t = _keys(f"references[{i}]", r, {"name": "a name", "params": "a table of factory arguments"}, set())
        nm = t["name"]
        if not isinstance(nm, str) or not nm or nm in seen:
            raise SpecError(f"`references[{i}].name` must be a distinct non-empty string; got {shown(nm)}")
        if not isinstance(t["params"], dict):
            raise SpecError(
                f"`references[{i}].params` must be a table of factory arguments; got {shown(t['params'])}"
            )
        seen.add(nm)
        out.append(Reference(nm, dict(t["params"])))
    return tuple(out)


def factory_defaults(factory: str) -> dict[str, Any]:
    """The default of every keyword argument of ``factory`` that has one (the start design's values)."""
    sig = inspect.signature(resolve_factory(factory))
    return {k: p.default for k, p in sig.parameters.items() if p.default is not inspect.Parameter.empty}
