"""Solve one chunk of an experiment: a few runs of one group.

A chunk's numbers do not depend on how the experiment was chunked or where it ran: the
initial states of all runs are drawn once from the spec's seed, and the solver gives
each run bit-for-bit the same result whatever it is batched with (a network's packet
fates are keyed by the run id).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from etobs.estimation import max_estimation_error, min_inter_event_time, simulate, transmission_counts
from etobs.experiments.common import Experiment
from etobs.hybrid.options import SaveAt
from etobs.hybrid.status import Status


@dataclass(frozen=True)
class Task:
    """One chunk: runs ``runs`` of group ``group``, stored under ``key``."""

    key: str
    group: int
    runs: tuple[int, ...]


def run_task(kind: type[Experiment], raw_spec: dict[str, Any], task: Task) -> list[dict[str, Any]]:
    """Simulate a chunk and return one record per run (plain, JSON-ready values).

    Takes the spec class and the raw spec (a plain dictionary) so that it travels to
    any worker. A record holds the run's ``status``, the ``transmissions`` of every
    node (output nodes, then input nodes) in the transmissions window, the ``error``
    ``max |x - xhat|`` on the error window's grid, each node's ``min_inter_event_time``,
    the plant's initial state ``x0`` (the observer's is
    ``initial_states.z0``), the solver's ``steps``, the ``backend`` that ran it, its
    share of the chunk's wall ``seconds``, and, with a network, the ``packets`` each
    node sent and those the observer never applied (``not_applied``), over the whole run.
    """
    spec = kind.from_raw(raw_spec)
    problem = spec.problem(task.group)
    x0 = spec.initial_states.draw(max(task.runs) + 1)[list(task.runs)]
    start = time.perf_counter()
    res = simulate(
        problem,
        x0,
        spec.t_end,
        z0=spec.initial_states.z0,
        options=spec.options,
        # only max |x - xhat| over the error window's grid is kept, folded during the solve
        save=SaveAt(steps=False, grid=spec.metrics.grid(), max_distance="estimation_error"),
        backend=spec.backend,
        run_ids=np.array(task.runs),
        progress=False,  # the experiment's one bar counts runs; a chunk (maybe in a worker) draws none
    )
    seconds = (time.perf_counter() - start) / len(task.runs)
    counts = transmission_counts(res, spec.metrics.transmissions_window, nodes="all")
    errors = max_estimation_error(res, spec.metrics.error_window)
    mins = min_inter_event_time(res, nodes="all")
    sent = not_applied = None
    if problem.network is not None:
        stats = res.network_stats()
        sent, not_applied = stats["sent"], stats["sent"] - stats["applied"]
    labels = res.status_labels()
    return [
        {
            "run": int(run),
            "status": labels[k],
            "transmissions": [int(c) for c in counts[k]],
            "error": _num(errors[k]),
            "min_inter_event_time": [_num(v) for v in mins[k]],
            "x0": [float(v) for v in x0[k]],
            "steps": int(res.solution.n_steps[k]),
            "backend": res.backend,
            "seconds": seconds,
            "packets": None if sent is None else [int(c) for c in sent[k]],
            "not_applied": None if not_applied is None else [int(c) for c in not_applied[k]],
        }
        for k, run in enumerate(task.runs)
    ]


def _num(value: float) -> float | None:
    return None if not np.isfinite(value) else float(value)


#: The keys of a record, as :func:`run_task` writes them.
RECORD_KEYS = frozenset(
    {
        "run",
        "status",
        "transmissions",
        "error",
        "min_inter_event_time",
        "x0",
        "steps",
        "backend",
        "seconds",
        "packets",
        "not_applied",
    }
)
#: The statuses a finished run can have (``running`` is never stored).
STORED_STATUSES = frozenset(s.label for s in Status if s is not Status.RUNNING)
_BACKENDS = ("engine", "scipy")


def record_problem(rec: Any, first: int, last: int) -> str:
    """What is wrong with a stored record of a chunk of runs ``first .. last``, or ``""``.

    Checked: the keys of :func:`run_task`, each value's type and range (counts are
    integers >= 0, times and errors numbers >= 0 or null, ``x0`` finite numbers), the
    status is one a run can end with, and the run index lies in the chunk's range.
    """
    if not isinstance(rec, dict) or set(rec) != RECORD_KEYS:
        return "a record without the keys of this version"
    run = rec["run"]
    if not _count(run) or not first <= run <= last:
        return f"a record of run {run!r}, outside the chunk's runs {first}..{last}"
    if rec["status"] not in STORED_STATUSES:
        return f"run {run}: unknown status {rec['status']!r}"
    if rec["backend"] not in _BACKENDS:
        return f"run {run}: unknown backend {rec['backend']!r}"
    nodes = rec["transmissions"]
    checks = {
        "transmissions": isinstance(nodes, list) and all(_count(c) for c in nodes),
        "min_inter_event_time": _list_of(rec["min_inter_event_time"], _time, len(nodes)),
        "error": _time(rec["error"]),
        "x0": _list_of(rec["x0"], _finite),
        "steps": _count(rec["steps"]),
        "seconds": _time(rec["seconds"]) and rec["seconds"] is not None,
        "packets": rec["packets"] is None or _list_of(rec["packets"], _count, len(nodes)),
        "not_applied": rec["not_applied"] is None or _list_of(rec["not_applied"], _count, len(nodes)),
    }
    wrong = [k for k, ok in checks.items() if not ok]
    return f"run {run}: `{wrong[0]}` is not of its type or out of its range" if wrong else ""


def _count(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and v >= 0


def _finite(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _time(v: Any) -> bool:
    """A duration or distance as :func:`_num` stores it: a finite number >= 0, or null."""
    return v is None or (_finite(v) and v >= 0)


def _list_of(v: Any, ok: Any, n: int | None = None) -> bool:
    return isinstance(v, list) and (n is None or len(v) == n) and all(ok(x) for x in v)
