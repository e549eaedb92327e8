"""Solve one chunk of a sweep: a few runs of one row under one scenario.

A chunk's numbers do not depend on how the sweep was chunked or where it ran: the
initial states of all runs are drawn once from the spec's seed, and the solver gives
each run bit-for-bit the same result whatever it is batched with.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from etobs.estimation import (
    max_estimation_error,
    min_inter_event_time,
    simulate,
    transmission_counts,
)
from etobs.experiments.spec import SweepSpec, parse_spec
from etobs.experiments.systems import build_problem
from etobs.hybrid.options import SaveAt


@dataclass(frozen=True)
class Task:
    """One chunk: runs ``runs`` of row ``row`` under scenario ``scenario``."""

    key: str
    row: int
    scenario: int
    runs: tuple[int, ...]


def run_task(raw_spec: dict[str, Any], task: Task) -> list[dict[str, Any]]:
    """Simulate a chunk and return one record per run (plain, JSON-ready values).

    Takes the raw spec (a plain dictionary) so that it travels to any worker.
    """
    spec: SweepSpec = parse_spec(raw_spec)
    problem = build_problem(spec, task.row, task.scenario)
    x0 = spec.initial_states.draw(max(task.runs) + 1)[list(task.runs)]
    lo, hi = spec.metrics.error_window
    hi = min(hi, spec.t_end)
    step = spec.metrics.error_grid_step
    grid = np.arange(lo, hi + step / 2, step) if hi >= lo else np.array([spec.t_end])
    res = simulate(
        problem,
        x0,
        spec.t_end,
        options=spec.options,
        save=SaveAt(steps=False, grid=grid),
        backend=spec.backend,
        run_ids=np.array(task.runs),
    )
    counts = transmission_counts(res, spec.metrics.transmissions_window)
    errors = max_estimation_error(res, (lo, hi)) if hi >= lo else np.full(len(task.runs), np.nan)
    mins = min_inter_event_time(res)
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
        }
        for k, run in enumerate(task.runs)
    ]


def _num(value: float) -> float | None:
    return None if not np.isfinite(value) else float(value)
