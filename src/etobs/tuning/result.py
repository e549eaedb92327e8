"""What a tuning gives: every trial, the front validated on held-out runs, and the files written.

``OUT/trials.{csv,parquet}`` holds every trial (parameters, objectives, certificate
figures, constraints, how it was evaluated); ``OUT/front.{csv,parquet}`` the feasible
non-dominated trials with their held-out figures; ``OUT/references.{csv,parquet}`` the
start design and the spec's references on the same runs; ``OUT/specs/front-K-check.toml``
and ``front-K-sweep.toml`` a check spec that ``etobs check`` certifies and a sweep spec
that ``etobs sweep`` reproduces for each front point; ``OUT/tuning.json`` the summary.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from etobs.experiments.store import atomic_write
from etobs.experiments.tables import flatten_params, write_table
from etobs.tuning.front import pareto
from etobs.tuning.space import factory_kwargs, start_values
from etobs.tuning.spec import TuneSpec

#: Constraint names, in the tables' order (``constraint_NAME``: ``<= 0`` is met).
CONSTRAINTS = ("certificate", "tau_min", "budget", "completed")


@dataclass(frozen=True)
class TrialRow:
    """One trial as a flat table row (parameters flattened as in the sweep tables)."""

    row: dict[str, Any]

    @classmethod
    def of(cls, trial: Any) -> TrialRow:
        """The row of an Optuna trial told by :func:`~etobs.tuning.tune.tune`."""
        a = {
            **trial.user_attrs.get("etobs", {}),
            **{k: v for k, v in trial.user_attrs.items() if k != "etobs"},
        }
        cons = {k.split(":", 1)[1]: v for k, v in trial.system_attrs.items() if k.startswith("constraints:")}
        sim = a.get("simulated", "running")
        row: dict[str, Any] = {
            "trial": trial.number,
            "state": trial.state.name.lower(),
            "evaluated": sim,
            "design": a.get("design", ""),
        }
        row.update(flatten_params(a.get("kwargs", {})))
        if a.get("observer"):
            row["observer"] = a["observer"]
        full = sim == "full"
        row.update(
            transmissions_rate=a.get("transmissions_rate") if sim in ("full", "pruned") else None,
            error=a.get("error") if sim in ("full", "pruned") else None,
            transmissions_mean=a.get("transmissions_mean") if sim in ("full", "pruned") else None,
            error_mean=a.get("error_mean") if sim in ("full", "pruned") else None,
            transmissions_se=a.get("transmissions_se") if sim in ("full", "pruned") else None,
            error_se=a.get("error_se") if sim in ("full", "pruned") else None,
            **{
                f"transmissions_rate_node{i}": x
                for i, x in enumerate(a.get("node_rates", []) if sim in ("full", "pruned") else [])
            },
            runs=a.get("runs", 0),
            completed=a.get("completed", 0),
            certified=bool(a.get("cert_ok", False)),
            cert_failures=a.get("cert_failures", ""),
            cert_assumptions=a.get("cert_assumptions", ""),
            nu=a.get("nu"),
            mu=a.get("mu"),
            error_bound=a.get("error_bound"),
        )
        for i, t in enumerate(a.get("tau", [])):
            row[f"tau_node{i}"] = t
        for k in CONSTRAINTS:  # one not evaluated (a screened trial's budget) is blank
            if k in cons:
                row[f"constraint_{k}"] = None if k in a.get("unevaluated", ()) else cons[k]
        row["feasible"] = full and trial.state.name == "COMPLETE" and all(v <= 0 for v in cons.values())
        return cls(row)


@dataclass(frozen=True)
class TuningResult:
    """The outcome of :func:`~etobs.tuning.tune.tune`.

    Attributes
    ----------
    trials : list of dict
        One row per trial (``trials.csv``).
    front : list of dict
        The feasible, non-dominated trials by increasing transmissions, each with its
        held-out figures (``holdout_*``) and ``holdout_over_budget``; ``check_spec`` and
        ``sweep_spec`` name its exported specs.
    references : list of dict
        The start design and the spec's references on the same runs and on the held-out runs.
    out : Path
    saved_runs : int
        Runs not simulated: screened candidates (the certificate rules them out) and the
        rest of pruned ones.

    """

    trials: list[dict[str, Any]]
    front: list[dict[str, Any]]
    references: list[dict[str, Any]]
    out: Path
    budget_kind: str
    budget: float
    saved_runs: int = 0
    summary: dict[str, Any] = field(default_factory=dict)

    def to_pandas(self, table: str = "front") -> Any:
        """``front``, ``trials`` or ``references`` as a pandas DataFrame."""
        import pandas as pd

        tables = {"front": self.front, "trials": self.trials, "references": self.references}
        if table not in tables:
            from etobs.errors import InputError

            raise InputError(f"`table` must be one of {', '.join(tables)}; got {table!r}")
        return pd.DataFrame(tables[table])


def finish(spec: TuneSpec, ev: Any, study: Any, out: Path) -> TuningResult:
    """Collect the trials, validate the front on held-out runs, write the tables and specs."""
    rows = [TrialRow.of(t).row for t in study.get_trials(deepcopy=False)]
    feasible = [r for r in rows if r["feasible"]]
    idx = pareto([(r["transmissions_rate"], r["error"]) for r in feasible])
    front = sorted(
        (dict(feasible[i]) for i in idx), key=lambda r: (r["transmissions_rate"], r["error"], r["trial"])
    )
    trials = {t.number: t for t in study.get_trials(deepcopy=False)}
    cands = [
        (trials[r["trial"]].user_attrs["etobs"]["kwargs"], trials[r["trial"]].user_attrs["etobs"]["observer"])
        for r in front
    ]
    first_obs = next(iter(spec.observers), None)
    refs = [("start", {}, first_obs)] + [(r.name, r.params, first_obs) for r in spec.references]
    ref_rows = _references(spec, ev, [(name, _resolved(spec, ev, p), o) for name, p, o in refs])
    held = ev.simulate(cands, spec.validation_runs, seed=spec.validation_seed) if cands else []
    specs = out / "specs"
    specs.mkdir(exist_ok=True)
    for old in specs.glob("front-*.toml"):  # an earlier front's: its numbers name other designs now
        old.unlink()
    for k, (r, recs, (kw, obs)) in enumerate(zip(front, held, cands, strict=True)):
        fig = ev.figures(recs) if recs is not None else None
        r["holdout_runs"] = spec.validation_runs
        r["holdout_transmissions_rate"] = None if fig is None else fig.transmissions_rate
        r["holdout_error"] = None if fig is None else fig.error
        r["holdout_transmissions_mean"] = None if fig is None else fig.transmissions_mean
        r["holdout_over_budget"] = fig is None or not fig.error <= spec.budget.error
        r["check_spec"], r["sweep_spec"] = _export(spec, ev, specs, f"front-{k:02d}", kw, obs)
    write_table(out, "trials", rows)
    write_table(out, "front", front)
    write_table(out, "references", ref_rows)
    saved = sum(int(t.user_attrs.get("etobs", {}).get("saved_runs", 0)) for t in trials.values())
    summary = {
        "name": spec.name,
        "trials": len(rows),
        "feasible": len(feasible),
        "front": len(front),
        "budget": {"kind": spec.budget.kind, "error": spec.budget.error},
        "saved_runs": saved,
        "runs_per_trial": spec.runs,
        "best": front[0] if front else None,
        "references": ref_rows,
    }
    atomic_write(out / "tuning.json", json.dumps(summary, indent=2, default=_json) + "\n")
    return TuningResult(rows, front, ref_rows, out, spec.budget.kind, spec.budget.error, saved, summary)


def _resolved(spec: TuneSpec, ev: Any, params: dict[str, Any]) -> dict[str, Any]:
    """A known design's arguments as a trial of it has them (the same runs' key: not simulated twice).

    The start design (``{}``) and a reference inside the search space are written as the
    searched parameters; any other keeps its arguments as given.
    """
    values = start_values(spec, ev.n_nodes, params)
    return params if values is None else factory_kwargs(spec, values, ev.n_nodes)


def _references(
    spec: TuneSpec, ev: Any, refs: list[tuple[str, dict[str, Any], str | None]]
) -> list[dict[str, Any]]:
    """The start design and the references: certificate, figures on the tuning's runs and held out."""
    same = ev.simulate([(p, o) for _, p, o in refs], spec.runs)
    held = ev.simulate([(p, o) for _, p, o in refs], spec.validation_runs, seed=spec.validation_seed)
    out = []
    for (name, params, obs), a, b in zip(refs, same, held, strict=True):
        cert = ev.certify(params, obs)
        row: dict[str, Any] = {"name": name, **flatten_params(params)}
        for prefix, recs in (("", a), ("holdout_", b)):
            fig = ev.figures(recs) if recs is not None else None
            row[f"{prefix}transmissions_rate"] = None if fig is None else fig.transmissions_rate
            row[f"{prefix}error"] = None if fig is None else fig.error
            row[f"{prefix}transmissions_mean"] = None if fig is None else fig.transmissions_mean
        row.update(
            certified=cert.ok,
            cert_failures=cert.failures,
            cert_assumptions=cert.assumptions,
            error_bound=_finite(cert.error_bound),
        )
        out.append(row)
    return out


def _export(
    spec: TuneSpec, ev: Any, folder: Path, stem: str, kwargs: dict[str, Any], obs: str | None
) -> tuple[str, str]:
    """Write the check spec and the sweep spec of one design; return their paths."""
    import tomli_w

    check: dict[str, Any] = {
        "name": stem,
        "system": {"factory": spec.factory, "params": {**spec.fixed, **kwargs}},
    }
    if obs is not None:
        check["observer"] = spec.observers[obs]
    if spec.guarantees:
        check["guarantees"] = spec.guarantees
    sweep = spec.sweep_raw([ev.sim_kwargs(kwargs, obs)])
    sweep["name"] = stem
    paths = []
    for kind, data in (("check", check), ("sweep", sweep)):
        path = folder / f"{stem}-{kind}.toml"
        atomic_write(path, tomli_w.dumps(data))
        paths.append(str(path))
    return paths[0], paths[1]


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None


def _json(x: Any) -> Any:
    return str(x)
