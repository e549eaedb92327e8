"""The sweep front door: :func:`run_sweep` computes what is missing and writes the tables."""

from __future__ import annotations

import json
import platform
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from etobs.errors import InputError
from etobs.experiments.executors import execute
from etobs.experiments.progress import Progress
from etobs.experiments.runner import Task
from etobs.experiments.spec import SweepSpec, chunk_size, normalize
from etobs.experiments.store import ResultStore, atomic_write, task_key
from etobs.experiments.systems import check_factory, factory_kwargs
from etobs.experiments.tables import aggregate, flatten_params, run_rows, to_csv, to_markdown


@dataclass(frozen=True)
class SweepResult:
    """What a sweep produced.

    Attributes
    ----------
    spec : SweepSpec
    out : Path
        Output folder (``runs.csv``, ``aggregate.csv``, ``report.md``, ``chunks/``).
    runs : list of dict
        One record per finished run.
    aggregate : list of dict
        Statistics per (row, scenario).
    computed, reused : int
        Runs computed by this call, and runs found already stored.
    failures : list of dict
        Chunks that failed (with their error); their runs are missing from ``runs``.
    params : tuple of str
        Flattened parameter columns (``sigma1``, ``sigma2``, ``noise``...).

    """

    spec: SweepSpec
    out: Path
    runs: list[dict[str, Any]]
    aggregate: list[dict[str, Any]]
    computed: int
    reused: int
    failures: list[dict[str, Any]]
    params: tuple[str, ...] = ()

    @property
    def complete(self) -> bool:
        """Whether every run of the spec is present."""
        return len(self.runs) == self.spec.n_runs and not self.failures


def plan(spec: SweepSpec, store: ResultStore, size: int) -> tuple[list[Task], int]:
    """Tasks for the runs not stored yet, and the number of runs already stored."""
    tasks, reused = [], 0
    for r in range(len(spec.rows)):
        for s in range(len(spec.scenarios)):
            key = task_key(spec, r, s)
            done = store.records(key, spec.initial_states.runs)
            reused += len(done)
            missing = [k for k in range(spec.initial_states.runs) if k not in done]
            for start in range(0, len(missing), size):
                tasks.append(Task(key=key, row=r, scenario=s, runs=tuple(missing[start : start + size])))
    return tasks, reused


def run_sweep(
    spec: SweepSpec,
    out: str | Path,
    *,
    executor: str = "process",
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
    chunk: int | None = None,
    progress: bool = True,
) -> SweepResult:
    """Run (or resume) a sweep into ``out`` and write its tables.

    Parameters
    ----------
    spec : SweepSpec
    out : path
        Output folder; runs already stored there for the same spec are not recomputed.
    executor : {"process", "serial", "dask"}
        Local process pool (default), this process, or a Dask cluster.
    workers : int, optional
        Processes of the local pool (default: one per core).
    scheduler : str, optional
        Dask scheduler address (with ``executor="dask"``), or pass ``client``.
    chunk : int, optional
        Runs per chunk (default: the spec's ``execution.chunk_size``, else 20).
    progress : bool
        Show a progress line on stderr.

    """
    if chunk is not None and (isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1):
        raise InputError(f"`chunk` must be a positive integer (runs per chunk); got {chunk!r}")
    check_factory(spec)
    store = ResultStore(out)
    store.clean_temporary()
    started = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    resolved = {
        "name": spec.name,
        "factory": spec.factory,
        "fixed": spec.fixed,
        "rows": list(spec.rows),
        "scenarios": [{"name": sc.name, **sc.params} for sc in spec.scenarios],
        "initial_states": spec.initial_states.__dict__,
        "t_end": spec.t_end,
        "metrics": spec.metrics.__dict__,
        "solver": spec.options.__dict__,
        "backend": spec.backend,
    }
    written = normalize({"as_given": spec.raw, "resolved": resolved}, ints_as_floats=False)
    atomic_write(store.out / "spec.json", json.dumps(written, indent=2, sort_keys=True) + "\n")
    tasks, reused = plan(spec, store, chunk or chunk_size(spec))
    bar = Progress(spec.n_runs, spec.name, enabled=progress)
    bar.update(done=reused)
    computed = 0

    def done(task: Task, records: list[dict[str, Any]]) -> None:
        nonlocal computed
        store.write(task.key, task.runs, records)
        computed += len(records)
        bar.update(done=len(records))

    def failed(task: Task, message: str) -> None:
        where = f"row {task.row}, scenario {spec.scenarios[task.scenario].name!r}"
        store.write_error(task.key, task.runs, message, where)
        bar.update(failed=len(task.runs))

    try:
        execute(
            tasks,
            spec.raw,
            done,
            failed,
            executor=executor,
            workers=workers,
            scheduler=scheduler,
            client=client,
        )
    finally:
        bar.close()
    result = collect(spec, store, computed=computed, reused=reused)
    _write_outputs(result, started)
    return result


def collect(spec: SweepSpec, store: ResultStore, *, computed: int = 0, reused: int = 0) -> SweepResult:
    """Gather the stored records of ``spec`` into tables."""
    groups, param_names, failures = [], [], []
    n = spec.initial_states.runs
    for r in range(len(spec.rows)):
        for s, scen in enumerate(spec.scenarios):
            params = {**spec.rows[r], **scen.params}
            for k in flatten_params(params):
                if k not in param_names:
                    param_names.append(k)
            key = task_key(spec, r, s)
            stored = store.records(key, n)
            groups.append((r, scen.name, params, list(stored.values())))
            failures += store.errors(key, set(stored), n)
    runs = run_rows(groups)
    keys = [(r, name, flatten_params(params)) for r, name, params, _ in groups]
    return SweepResult(
        spec=spec,
        out=store.out,
        runs=runs,
        aggregate=aggregate(runs, param_names, keys),
        computed=computed,
        reused=reused,
        failures=failures,
        params=tuple(param_names),
    )


def _write_outputs(result: SweepResult, started: str) -> None:
    out = result.out
    atomic_write(out / "runs.csv", to_csv(result.runs))
    atomic_write(out / "aggregate.csv", to_csv(result.aggregate))
    meta = {
        "name": result.spec.name,
        "seed": result.spec.initial_states.seed,
        "runs_expected": result.spec.n_runs,
        "runs_present": len(result.runs),
        "computed": result.computed,
        "reused": result.reused,
        "failed_chunks": len(result.failures),
        "started": started,
        "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "versions": _versions(),
    }
    atomic_write(out / "meta.json", json.dumps(meta, indent=2) + "\n")
    cols = [
        "row",
        "scenario",
        *result.params,
        "runs",
        "completed",
        "transmissions_mean",
        "transmissions_std",
        "error_mean",
        "error_std",
    ]
    text = [
        f"# Sweep `{result.spec.name}`",
        "",
        f"{len(result.runs)} of {result.spec.n_runs} runs present; seed {result.spec.initial_states.seed}; "
        f"{len(result.failures)} failed chunks.",
        "",
        to_markdown(result.aggregate, cols),
    ]
    for f in result.failures:
        last = f["error"].strip().splitlines()[-1] if f["error"].strip() else ""
        text.append(f"- failed: {f.get('where', '')} runs {f['runs'][0]}..{f['runs'][-1]}: {last}")
    atomic_write(out / "report.md", "\n".join(text) + "\n")


def _versions() -> dict[str, str]:
    import scipy

    from etobs import __version__

    return {
        "etobs": __version__,
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "python": platform.python_version(),
    }


__all__ = ["SweepResult", "collect", "factory_kwargs", "plan", "run_sweep"]
