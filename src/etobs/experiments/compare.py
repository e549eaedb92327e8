"""Rule comparison: every rule of a :class:`CompareSpec` on every network, same initial states.

:func:`compare` is the front door. It returns a :class:`Comparison` whose
:meth:`~Comparison.table` has one row per (rule, network) with, side by side:
transmissions per node in the window, the maximum estimation error on the error window,
the minimum inter-event time per node and, with a network, the share of packets the
observer never applied. Entries finished earlier can be passed back in (``done``) so an
interrupted comparison resumes without recomputing them.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from etobs.errors import InputError
from etobs.estimation import max_estimation_error, min_inter_event_time, simulate, transmission_counts
from etobs.estimation.result import EstimationResult
from etobs.examples.registry import resolve_factory
from etobs.experiments.compare_spec import CompareSpec, NetworkEntry, RuleEntry
from etobs.experiments.spec import SpecError
from etobs.hybrid.options import SaveAt


@dataclass(frozen=True)
class EntryResult:
    """Per-run metrics of one (rule, network) entry; arrays have one row per run.

    Attributes
    ----------
    transmissions : ndarray of int, shape (B, C)
        Transmissions of each node (output nodes, then input nodes) in the window.
    error : ndarray, shape (B,)
        ``max |x - xhat|`` on the error window (NaN for runs that failed).
    min_inter_event_time : ndarray, shape (B, C)
        NaN where a node sent fewer than twice.
    not_applied, packets : ndarray of int, shape (B, C) or None
        Packets sent but never applied by the observer (lost, dropped, stale or still in
        flight), and all packets sent, over the whole run; ``None`` on the ideal network.

    """

    rule: str
    network: str
    backend: str
    status: tuple[str, ...]
    transmissions: np.ndarray
    error: np.ndarray
    min_inter_event_time: np.ndarray
    not_applied: np.ndarray | None
    packets: np.ndarray | None
    seconds: float

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
            "status": list(self.status),
            "transmissions": self.transmissions.tolist(),
            "error": [None if not np.isfinite(v) else float(v) for v in self.error],
            "min_inter_event_time": plain(self.min_inter_event_time),
            "not_applied": None if self.not_applied is None else self.not_applied.tolist(),
            "packets": None if self.packets is None else self.packets.tolist(),
            "seconds": self.seconds,
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> EntryResult:
        """Inverse of :meth:`to_json`."""

        def arr(x: Any, dtype: Any = float) -> np.ndarray:
            return np.array([[np.nan if v is None else v for v in row] for row in x], dtype=dtype)

        return cls(
            rule=d["rule"],
            network=d["network"],
            backend=d["backend"],
            status=tuple(d["status"]),
            transmissions=np.array(d["transmissions"], dtype=np.int64),
            error=np.array([np.nan if v is None else v for v in d["error"]], dtype=float),
            min_inter_event_time=arr(d["min_inter_event_time"]),
            not_applied=None if d["not_applied"] is None else np.array(d["not_applied"], dtype=np.int64),
            packets=None if d["packets"] is None else np.array(d["packets"], dtype=np.int64),
            seconds=float(d["seconds"]),
        )


@dataclass(frozen=True)
class Comparison:
    """Result of :func:`compare`: one :class:`EntryResult` per (rule, network)."""

    spec: CompareSpec
    node_names: tuple[str, ...]
    entries: tuple[EntryResult, ...]
    skipped: tuple[tuple[str, str, str], ...] = ()

    def table(self) -> list[dict[str, Any]]:
        """One row per entry: means over the runs that completed, minima of the inter-event times."""
        rows = []
        for e in self.entries:
            ok = np.array([s == "completed" for s in e.status])
            row: dict[str, Any] = {"rule": e.rule, "network": e.network, "completed": f"{ok.sum()}/{ok.size}"}
            tx = e.transmissions[ok]
            for c, n in enumerate(self.node_names):
                row[f"transmissions {n}"] = float(tx[:, c].mean()) if ok.any() else np.nan
            row["transmissions total"] = float(tx.sum(axis=1).mean()) if ok.any() else np.nan
            row["error mean"] = float(np.mean(e.error[ok])) if ok.any() else np.nan
            row["error max"] = float(np.max(e.error[ok])) if ok.any() else np.nan
            for c, n in enumerate(self.node_names):
                col = e.min_inter_event_time[ok, c]
                row[f"min inter-event {n}"] = float(np.nanmin(col)) if np.isfinite(col).any() else np.nan
            if e.not_applied is not None and e.packets is not None and ok.any():
                sent = e.packets[ok].sum()  # over the whole run, like not_applied
                row["not applied"] = float(e.not_applied[ok].sum() / sent) if sent else 0.0
            else:
                row["not applied"] = np.nan
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
        return "\n".join(lines) + "\n"

    def to_json(self) -> dict[str, Any]:
        """The entries and the node names, JSON-ready."""
        return {
            "name": self.spec.name,
            "nodes": list(self.node_names),
            "entries": [e.to_json() for e in self.entries],
            "skipped": [{"rule": r, "network": n, "why": w} for r, n, w in self.skipped],
        }


def _fmt(v: Any) -> str:
    if isinstance(v, str):
        return v
    return "–" if not np.isfinite(v) else f"{v:.4g}"


def _fmt_count(v: Any) -> str:
    return "–" if not np.isfinite(v) else f"{v:.1f}"


def _fmt_share(v: Any) -> str:
    return "–" if not np.isfinite(v) else f"{100 * v:.1f} %"


_COPY_NEEDS_IDEAL = (
    "the observer copy of Remark 3 is simulated as a perfect copy, which a lossy or delayed network "
    "would break (each node's copy would drift from the observer)"
)


def entry_key(spec: CompareSpec, rule: RuleEntry, network: NetworkEntry) -> str:
    """A key for one entry's results: it changes when anything that affects them does."""
    s = spec
    ident = {
        "factory": s.factory,
        "params": s.params,
        "initial_states": [s.initial_states.low, s.initial_states.high, s.initial_states.runs],
        "seed": s.initial_states.seed,
        "t_end": s.t_end,
        "metrics": [s.metrics.transmissions_window, s.metrics.error_window, s.metrics.error_grid_step],
        "solver": s.solver,
        "backend": s.backend,
        "rule": [rule.name, rule.kind, rule.params, rule.observer_copy],
        "network": [network.name, repr(network.network)],
    }
    text = json.dumps(ident, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def compare(
    spec: CompareSpec,
    *,
    done: Mapping[str, EntryResult] | None = None,
    on_entry: Callable[[str, EntryResult], None] | None = None,
) -> Comparison:
    """Run every rule of ``spec`` on every network from the same initial states.

    Parameters
    ----------
    spec : CompareSpec
    done : mapping from :func:`entry_key` to EntryResult, optional
        Entries already computed (e.g. read back from disk); they are not rerun.
    on_entry : callable, optional
        Called as ``on_entry(key, result)`` after each entry is computed, e.g. to
        persist it at once.

    Returns
    -------
    Comparison

    """
    if not isinstance(spec, CompareSpec):
        raise InputError(f"`spec` must be a CompareSpec; got {type(spec).__name__}")
    factory = resolve_factory(spec.factory)
    try:
        base = factory(**spec.params)
    except TypeError as exc:
        raise SpecError(f"`system.params` do not fit the factory {spec.factory!r}: {exc}") from exc
    x0 = spec.initial_states.draw()
    if x0.shape[1] != base.plant.n_x:
        raise SpecError(
            f"`initial_states.low` and `.high` have {x0.shape[1]} entries "
            f"but the plant has n_x = {base.plant.n_x}"
        )
    done = dict(done or {})
    # every problem is built (and so checked) before the first entry runs
    todo, skipped = [], []
    for network in spec.networks:
        for rule in spec.rules:
            if rule.observer_copy and network.network is not None:
                skipped.append((rule.name, network.name, _COPY_NEEDS_IDEAL))
            else:
                todo.append((rule, network, rule.apply(base, network.network)))
    entries = []
    for rule, network, problem in todo:
        key = entry_key(spec, rule, network)
        if key not in done:
            done[key] = _run_entry(spec, problem, rule, network, x0)
            if on_entry is not None:
                on_entry(key, done[key])
        entries.append(done[key])
    names = tuple(ch.name for ch in base.layout.channels)
    return Comparison(spec=spec, node_names=names, entries=tuple(entries), skipped=tuple(skipped))


def _run_entry(
    spec: CompareSpec, problem: Any, rule: RuleEntry, network: NetworkEntry, x0: np.ndarray
) -> EntryResult:
    lo, hi = spec.metrics.error_window
    step = spec.metrics.error_grid_step
    save = SaveAt(steps=False, grid=np.arange(lo, hi + step / 2, step))
    start = time.perf_counter()
    res, backend = _simulate(spec, problem, x0, save)
    seconds = time.perf_counter() - start
    tx = transmission_counts(res, spec.metrics.transmissions_window, nodes="all")
    mins = min_inter_event_time(res, nodes="all")
    not_applied = packets = None
    if problem.network is not None:
        st = res.network_stats()
        not_applied, packets = st["sent"] - st["applied"], st["sent"]
    return EntryResult(
        rule=rule.name,
        network=network.name,
        backend=backend,
        status=tuple(res.status_labels()),
        transmissions=tx,
        error=max_estimation_error(res, (lo, hi)),
        min_inter_event_time=mins,
        not_applied=not_applied,
        packets=packets,
        seconds=seconds,
    )


def _simulate(spec: CompareSpec, problem: Any, x0: np.ndarray, save: SaveAt) -> tuple[EstimationResult, str]:
    """Simulate one entry; ``"auto"`` is decided by :func:`~etobs.estimation.simulate.simulate`."""
    res = simulate(problem, x0, spec.t_end, options=spec.options, save=save, backend=spec.backend)
    return res, res.backend
