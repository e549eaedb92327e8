"""Rule comparison: every rule of a :class:`CompareSpec` on every network, same initial states.

:func:`compare` is the front door. It returns a :class:`Comparison` whose
:meth:`~Comparison.table` has one row per (rule, network) with, side by side:
transmissions per node in the window, the maximum estimation error on the error window,
the minimum inter-event time per node and, with a network, the share of packets the
observer never applied.

A comparison is an experiment like a sweep (its groups are the entries), so it runs
through the same pipeline (:mod:`etobs.experiments.pipeline`): chunks on this process, a
process pool or a Dask cluster, each stored in ``out/chunks`` as it finishes; a rerun on
the same folder computes only what is missing.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from etobs.errors import InputError
from etobs.experiments.compare_spec import CompareSpec
from etobs.experiments.pipeline import experiment_folder, other_chunks, run_groups, stored
from etobs.experiments.store import last_line
from etobs.experiments.tables import aggregate, not_completed, run_rows, status_notes, to_frame, write_table


@dataclass(frozen=True)
class EntryResult:
    """Per-run metrics of one (rule, network) entry; arrays have one row per stored run.

    Attributes
    ----------
    runs : tuple of int
        The runs present (all of ``0 .. runs-1`` unless a chunk failed).
    transmissions : ndarray of int, shape (B, C)
        Transmissions of each node (output nodes, then input nodes) in the window.
    error : ndarray, shape (B,)
        ``max |x - xhat|`` on the error window (NaN for runs that failed).
    min_inter_event_time : ndarray, shape (B, C)
        NaN where a node sent fewer than twice.
    not_applied, packets : ndarray of int, shape (B, C) or None
        Packets sent but never applied by the observer (lost, dropped, stale or still in
        flight), and all packets sent, over the whole run; ``None`` on the ideal network.
    seconds : float
        Wall time of the entry's runs (the solver's, summed over chunks).

    """

    rule: str
    network: str
    backend: str
    runs: tuple[int, ...]
    status: tuple[str, ...]
    transmissions: np.ndarray
    error: np.ndarray
    min_inter_event_time: np.ndarray
    not_applied: np.ndarray | None
    packets: np.ndarray | None
    seconds: float

    @classmethod
    def from_records(
        cls, rule: str, network: str, records: Sequence[dict[str, Any]], n_channels: int
    ) -> EntryResult:
        """The entry from its stored run records (:func:`~etobs.experiments.runner.run_task`)."""
        recs = sorted(records, key=lambda r: r["run"])

        def table(name: str, dtype: Any) -> np.ndarray:
            rows = [[np.nan if v is None else v for v in r[name]] for r in recs]
            return np.array(rows, dtype=dtype).reshape(len(recs), n_channels)

        networked = bool(recs) and recs[0]["packets"] is not None
        return cls(
            rule=rule,
            network=network,
            backend=", ".join(sorted({r["backend"] for r in recs})) or "none",
            runs=tuple(int(r["run"]) for r in recs),
            status=tuple(r["status"] for r in recs),
            transmissions=table("transmissions", np.int64),
            error=np.array([np.nan if r["error"] is None else r["error"] for r in recs], dtype=float),
            min_inter_event_time=table("min_inter_event_time", float),
            not_applied=table("not_applied", np.int64) if networked else None,
            packets=table("packets", np.int64) if networked else None,
            seconds=float(sum(r["seconds"] for r in recs)),
        )

    def to_json(self) -> dict[str, Any]:
        """Plain values (NaN as ``None``)."""

        def plain(a: np.ndarray | None) -> Any:
            if a is None:
                return None
            return [[None if not np.isfinite(v) else float(v) for v in np.atleast_1d(row)] for row in a]

        return {
            "rule": self.rule,
            "network": self.network,
            "backend": self.backend,
            "runs": list(self.runs),
            "status": list(self.status),
            "transmissions": self.transmissions.tolist(),
            "error": [None if not np.isfinite(v) else float(v) for v in self.error],
            "min_inter_event_time": plain(self.min_inter_event_time),
            "not_applied": None if self.not_applied is None else self.not_applied.tolist(),
            "packets": None if self.packets is None else self.packets.tolist(),
            "seconds": self.seconds,
        }


@dataclass(frozen=True)
class Comparison:
    """Result of :func:`~etobs.experiments.compare.compare`: one ``EntryResult`` per (rule, network).

    Attributes
    ----------
    spec : CompareSpec
    out : Path
        The output folder (``chunks/`` holds every run's record).
    node_names : tuple of str
        Output nodes, then input nodes.
    entries : tuple of EntryResult
        In the order of :attr:`CompareSpec.entries`.
    skipped : tuple of (rule, network, why)
        Pairs not run.
    failures : list of dict
        Chunks that failed (their error and ``where``); their runs are missing.
    computed, reused : int
        Runs computed by this call, and runs found already stored.
    runs : tuple of dict
        One line per stored run, as in ``runs.csv``: ``rule``, ``network``, ``run``,
        ``status``, transmissions (total and per node), ``error``, per node the minimum
        inter-event time (and with a network ``packets`` and ``not_applied``), ``x0_1``...,
        ``steps`` (:func:`~etobs.experiments.tables.run_rows`).
    aggregate : tuple of dict
        One line per entry, as in ``aggregate.csv``: mean, std, min and max of each
        metric over the completed runs (:func:`~etobs.experiments.tables.aggregate`).
    other_chunks : int
        Chunk files in ``out/chunks`` written for another spec or etobs version: not used.

    """

    spec: CompareSpec
    out: Path
    node_names: tuple[str, ...]
    entries: tuple[EntryResult, ...]
    skipped: tuple[tuple[str, str, str], ...] = ()
    failures: tuple[dict[str, Any], ...] = ()
    computed: int = 0
    reused: int = 0
    runs: tuple[dict[str, Any], ...] = ()
    aggregate: tuple[dict[str, Any], ...] = ()
    other_chunks: int = 0

    @property
    def complete(self) -> bool:
        """Whether every run of every entry is present."""
        return not self.failures and all(len(e.runs) == self.spec.initial_states.runs for e in self.entries)

    def to_pandas(self, table: str = "runs") -> Any:
        """``"runs"`` or ``"aggregate"`` (:attr:`runs`, :attr:`aggregate`) as a ``pandas.DataFrame``."""
        return to_frame(table, {"runs": list(self.runs), "aggregate": list(self.aggregate)})

    def table(self) -> list[dict[str, Any]]:
        """One row per entry, read from :attr:`aggregate` (one computation of the statistics).

        Means over the runs that completed, minima of the inter-event times, and the share
        of packets not applied (over the whole runs, like ``not_applied``).
        """

        def value(line: dict[str, Any], key: str) -> float:
            got = line.get(key)
            return np.nan if got is None else float(got)

        rows = []
        runs = self.spec.initial_states.runs
        for line in self.aggregate:
            row: dict[str, Any] = {
                "rule": line["rule"],
                "network": line["network"],
                "completed": f"{line['completed']}/{runs}",
            }
            for c, n in enumerate(self.node_names):
                row[f"transmissions {n}"] = value(line, f"transmissions_node{c}_mean")
            row["transmissions total"] = value(line, "transmissions_mean")
            row["error mean"] = value(line, "error_mean")
            row["error max"] = value(line, "error_max")
            for c, n in enumerate(self.node_names):
                row[f"min inter-event {n}"] = value(line, f"min_inter_event_time_node{c}_min")
            C = range(len(self.node_names))
            sent = sum(value(line, f"packets_node{c}_mean") for c in C)
            lost = sum(value(line, f"not_applied_node{c}_mean") for c in C)
            row["not applied"] = lost / sent if sent > 0 else (0.0 if sent == 0 else np.nan)
            rows.append(row)
        return rows

    def markdown(self) -> str:
        """The table in Markdown, with the spec's windows and runs stated under it."""
        rows = self.table()
        cols = list(rows[0])
        fmt = {c: _fmt_count if c.startswith("transmissions") else _fmt for c in cols}
        fmt["not applied"] = _fmt_share
        lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
        for r in rows:
            lines.append("| " + " | ".join(fmt[c](r[c]) if c in fmt else str(r[c]) for c in cols) + " |")
        s, m = self.spec, self.spec.metrics
        lines += [
            "",
            f"{s.initial_states.runs} runs per entry from the same initial states (seed "
            f"{s.initial_states.seed}); transmissions counted on [{m.transmissions_window[0]:g}, "
            f"{m.transmissions_window[1]:g}] s and averaged over the runs that completed; error = max "
            f"|x - xhat| on [{m.error_window[0]:g}, {m.error_window[1]:g}] s on a {m.error_grid_step:g} s "
            "grid (mean and max over runs); min inter-event time over all runs; not applied = share of "
            "the packets sent that the observer never used (lost, dropped, stale or in flight).",
        ]
        for rule, network, why in self.skipped:
            lines += ["", f"Not run: {rule} / {network}: {why}."]
        for f in self.failures:
            last = last_line(f)
            lines += ["", f"Failed: {f['where']}, runs {f['runs'][0]}..{f['runs'][-1]}: {last}"]
        statuses = [st for e in self.entries for st in e.status]
        for e in self.entries:
            if not_completed(e.status):
                lines += ["", f"Not completed: {e.rule} / {e.network}: {not_completed(e.status)}."]
        notes = status_notes(statuses)
        lines += [""] + [f"- {note}" for note in notes] if notes else []
        return "\n".join(lines) + "\n"

    def to_json(self) -> dict[str, Any]:
        """The entries and the node names, JSON-ready."""
        return {
            "name": self.spec.name,
            "nodes": list(self.node_names),
            "entries": [e.to_json() for e in self.entries],
            "skipped": [{"rule": r, "network": n, "why": w} for r, n, w in self.skipped],
            "failures": list(self.failures),
        }


def _fmt(v: Any) -> str:
    if isinstance(v, str):
        return v
    return "–" if not np.isfinite(v) else f"{v:.4g}"


def _fmt_count(v: Any) -> str:
    return "–" if not np.isfinite(v) else f"{v:.1f}"


def _fmt_share(v: Any) -> str:
    return "–" if not np.isfinite(v) else f"{100 * v:.1f} %"


def compare(
    spec: CompareSpec,
    out: str | Path,
    *,
    executor: str = "process",
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
    chunk: int | None = None,
    progress: bool | None = None,
    on_entry: Callable[[EntryResult], None] | None = None,
) -> Comparison:
    """Run (or resume) every rule of ``spec`` on every network, from the same initial states.

    Parameters
    ----------
    spec : CompareSpec
    out : path
        Output folder; runs already stored there for the same spec are not recomputed.
        ``runs.csv`` and ``aggregate.csv`` (:attr:`Comparison.runs` and
        :attr:`Comparison.aggregate`), each with a typed ``.parquet`` twin, are written there.
    executor, workers, scheduler, client, chunk, progress
        As in :func:`~etobs.experiments.sweep.run_sweep`.
    on_entry : callable, optional
        Called as ``on_entry(result)`` when the last chunk this call computes for an entry
        has finished (stored or failed), e.g. to report it.

    Returns
    -------
    Comparison

    Raises
    ------
    SpecError
        Before any run, when a rule does not fit the problem (every entry is built first).

    """
    if not isinstance(spec, CompareSpec):
        raise InputError(f"`spec` must be a CompareSpec (see parse_compare_spec); got {type(spec).__name__}")
    names = tuple(ch.name for ch in spec.base().layout.channels)

    def entry(g: int, records: Any) -> EntryResult:
        rule, network = spec.entries[g]
        return EntryResult.from_records(rule.name, network.name, records, len(names))

    def report(g: int, records: dict[int, dict[str, Any]]) -> None:
        if on_entry is not None:
            on_entry(entry(g, records.values()))

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
            on_group=report,
        )
        got = stored(spec, store)
        labels = [
            {"rule": spec.entries[s.group][0].name, "network": spec.entries[s.group][1].name} for s in got
        ]
        runs = run_rows((lab, {}, list(s.records.values())) for lab, s in zip(labels, got, strict=True))
        summary = aggregate(runs, (), [(lab, {}) for lab in labels])
        write_table(store.out, "runs", runs)
        write_table(store.out, "aggregate", summary)
        return Comparison(
            spec=spec,
            out=store.out,
            node_names=names,
            entries=tuple(entry(s.group, s.records.values()) for s in got),
            skipped=spec.skipped,
            failures=tuple(f for s in got for f in s.failures),
            computed=computed,
            reused=reused,
            runs=tuple(runs),
            aggregate=tuple(summary),
            other_chunks=other_chunks(spec, store),
        )
