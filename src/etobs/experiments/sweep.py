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
from etobs.experiments.pipeline import experiment_folder, other_chunks, run_groups, stored
from etobs.experiments.spec import SweepSpec
from etobs.experiments.store import ResultStore, atomic_write, last_line
from etobs.experiments.tables import (
    aggregate,
    flatten_params,
    load_writers,
    not_completed,
    run_rows,
    status_notes,
    to_frame,
    to_markdown,
    write_table,
)


@dataclass(frozen=True)
class SweepResult:
    """What a sweep produced.

    Attributes
    ----------
    spec : SweepSpec
    out : Path
        Output folder (``runs.csv``, ``aggregate.csv``, each with a ``.parquet`` twin,
        ``report.md``, ``chunks/``).
    runs : list of dict
        One record per finished run.
    aggregate : list of dict
        Statistics per (row, scenario): of transmissions and error, and per node of
        transmissions and minimum inter-event time (:func:`~etobs.experiments.tables.aggregate`).
    computed, reused : int
        Runs computed by this call, and runs found already stored.
    failures : list of dict
        Chunks that failed (with their error); their runs are missing from ``runs``.
    params : tuple of str
        Flattened parameter columns (``sigma1``, ``sigma2``, ``noise``...).
    other_chunks : int
        Chunk files in ``out/chunks`` written for another spec or etobs version (or
        another format of records): not used, their runs computed anew for this one.

    """

    spec: SweepSpec
    out: Path
    runs: list[dict[str, Any]]
    aggregate: list[dict[str, Any]]
    computed: int
    reused: int
    failures: list[dict[str, Any]]
    params: tuple[str, ...] = ()
    other_chunks: int = 0

    @property
    def complete(self) -> bool:
        """Whether every run of the spec is present."""
        return len(self.runs) == self.spec.n_runs and not self.failures

    def to_pandas(self, table: str = "runs") -> Any:
        """``"runs"`` or ``"aggregate"`` as a ``pandas.DataFrame``, typed as its Parquet file.

        Examples
        --------
        >>> frame = result.to_pandas("aggregate")  # doctest: +SKIP
        >>> frame.filter(like="transmissions_node").filter(like="_mean")  # doctest: +SKIP

        """
        return to_frame(table, {"runs": self.runs, "aggregate": self.aggregate})


def run_sweep(
    spec: SweepSpec,
    out: str | Path,
    *,
    executor: str = "process",
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
    chunk: int | None = None,
    progress: bool | None = None,
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
    client : dask.distributed.Client, optional
        A client to run on (with ``executor="dask"``).
    chunk : int, optional
        Runs per chunk (default: the spec's ``execution.chunk_size``, else 20).
    progress : bool or None
        A progress bar on stderr counting runs (failed ones in its postfix): ``None``
        (default) when stderr is a terminal, ``True``/``False`` to force it
        (:func:`etobs._progress.progress_bar`).

    """
    if not isinstance(spec, SweepSpec):
        raise InputError(f"`spec` must be a SweepSpec (see load_spec); got {type(spec).__name__}")
    started = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    with experiment_folder(spec, out, executor=executor, workers=workers, chunk=chunk) as store:
        computed, reused = run_groups(
            spec,
            store,
            executor=executor,
            workers=workers,
            scheduler=scheduler,
            client=client,
            chunk=chunk,
            progress=progress,
            while_running=load_writers,
        )
        result = collect(spec, store, computed=computed, reused=reused)
        _write_outputs(result, started)
    return result


def collect(spec: SweepSpec, store: ResultStore, *, computed: int = 0, reused: int = 0) -> SweepResult:
    """Gather the stored records of ``spec`` into tables."""
    groups, param_names, failures = [], [], []
    for got in stored(spec, store):
        r, s = spec.row_scenario(got.group)
        params = {**spec.rows[r], **spec.scenarios[s].params}
        for k in flatten_params(params):
            if k not in param_names:
                param_names.append(k)
        groups.append(({"row": r, "scenario": spec.scenarios[s].name}, params, list(got.records.values())))
        failures += got.failures
    runs = run_rows(groups)
    keys = [(labels, flatten_params(params)) for labels, params, _ in groups]
    return SweepResult(
        spec=spec,
        out=store.out,
        runs=runs,
        aggregate=aggregate(runs, param_names, keys),
        computed=computed,
        reused=reused,
        failures=failures,
        params=tuple(param_names),
        other_chunks=other_chunks(spec, store),
    )


def _write_outputs(result: SweepResult, started: str) -> None:
    out = result.out
    write_table(out, "runs", result.runs)
    write_table(out, "aggregate", result.aggregate)
    meta = {
        "name": result.spec.name,
        "seed": result.spec.initial_states.seed,
        "runs_expected": result.spec.n_runs,
        "runs_present": len(result.runs),
        "computed": result.computed,
        "reused": result.reused,
        "failed_chunks": len(result.failures),
        "other_chunks": result.other_chunks,
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
        *_node_means(result.aggregate),
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
        last = last_line(f)
        text.append(f"- failed: {f.get('where', '')} runs {f['runs'][0]}..{f['runs'][-1]}: {last}")
    if result.other_chunks:  # e.g. written by another etobs version: say why runs were computed again
        text += [
            "",
            f"{result.other_chunks} chunk files in `chunks/` belong to another spec or etobs version "
            "and were not used (runs are recomputed for this one; delete them or use a new folder).",
        ]
    statuses = [r["status"] for r in result.runs]
    if not_completed(statuses):  # each run's status is in runs.csv; say here why runs stopped early
        text += ["", f"Runs not completed: {not_completed(statuses)} (see `status` in runs.csv)."]
        text += [f"- {note}" for note in status_notes(statuses)]
    atomic_write(out / "report.md", "\n".join(text) + "\n")


def _node_means(aggregate: list[dict[str, Any]]) -> list[str]:
    """``transmissions_node0_mean``, ... for the report, when there is more than one node."""
    names = [c for c in (aggregate[0] if aggregate else {}) if c.startswith("transmissions_node")]
    means = [c for c in names if c.endswith("_mean")]
    return means if len(means) > 1 else []


def _versions() -> dict[str, str]:
    import pyarrow
    import scipy

    from etobs._version import __version__

    return {
        "etobs": __version__,
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "pyarrow": pyarrow.__version__,
        "python": platform.python_version(),
    }


__all__ = ["SweepResult", "collect", "run_sweep"]
