"""One pipeline for every experiment: plan the missing chunks, run them, store each one.

:func:`experiment_folder` holds the output folder, and :func:`run_groups` serves the
sweep (:func:`~etobs.experiments.sweep.run_sweep`) and the rule comparison
(:func:`~etobs.experiments.compare.compare`) alike: the chunks of every group of an
:class:`~etobs.experiments.common.Experiment` run on the chosen executor (this process,
a local process pool or a Dask cluster) and are written to the chunk store as they
arrive, so an interrupted experiment resumes with what it finished.
:func:`stored` reads them back.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from etobs._progress import progress_bar
from etobs.errors import InputError
from etobs.experiments.common import Experiment, normalize
from etobs.experiments.executors import WorkersLost, check_execution, execute
from etobs.experiments.runner import Task
from etobs.experiments.store import ResultStore, atomic_write, task_key


@dataclass(frozen=True)
class Stored:
    """What the store holds for one group: its records by run and its standing failures."""

    group: int
    records: dict[int, dict[str, Any]]
    failures: list[dict[str, Any]]


def plan(spec: Experiment, store: ResultStore, size: int) -> tuple[list[Task], int]:
    """Tasks for the runs not stored yet, and the number of runs already stored.

    Groups whose numbers are those of an earlier group (the same key: e.g. two entries
    that differ only by name) are planned once; both read the same records.
    """
    tasks, reused, planned = [], 0, set()
    n = spec.initial_states.runs
    for g in range(spec.n_groups):
        key = task_key(spec, g)
        if key in planned:  # a group with the same numbers as an earlier one (other names)
            continue
        planned.add(key)
        done = store.records(key, n)
        reused += len(done)
        missing = [k for k in range(n) if k not in done]
        for start in range(0, len(missing), size):
            tasks.append(Task(key=key, group=g, runs=tuple(missing[start : start + size])))
    return tasks, reused


@contextmanager
def experiment_folder(
    spec: Experiment, out: str | Path, *, executor: str, workers: int | None, chunk: int | None
) -> Iterator[ResultStore]:
    """The output folder of ``spec``, held for this process (:meth:`ResultStore.lock`).

    The executor settings and the spec are checked first, so nothing is written for bad
    input. Held, the temporary files of dead writers are removed and ``spec.json``
    records the spec as given and resolved. Run :func:`run_groups`, read the results back
    and write the outputs inside, so no other writer can interleave.
    """
    if chunk is not None and (isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1):
        raise InputError(f"`chunk` must be a positive integer (runs per chunk); got {chunk!r}")
    check_execution(executor, workers)  # before anything is written
    spec.check()
    store = ResultStore(out)
    with store.lock():
        store.clean_temporary()  # the folder is held: only dead writers leave temporary files
        written = normalize({"as_given": spec.raw, "resolved": spec.resolved()}, ints_as_floats=False)
        atomic_write(store.out / "spec.json", json.dumps(written, indent=2, sort_keys=True) + "\n")
        yield store


def run_groups(
    spec: Experiment,
    store: ResultStore,
    *,
    executor: str = "process",
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
    chunk: int | None = None,
    progress: bool | None = None,
    on_group: Callable[[int, dict[int, dict[str, Any]]], None] | None = None,
    pool: Any = None,
    while_running: Callable[[], None] | None = None,
) -> tuple[int, int]:
    """Compute the runs of ``spec`` missing from ``store``; return how many were computed and reused.

    Call it inside :func:`experiment_folder` (which checks the arguments).
    ``on_group(g, records)`` is called once every chunk of group ``g`` computed by this
    call has been stored or has failed, with the group's stored records by run. ``pool``
    is a process pool kept across calls (:func:`~etobs.experiments.executors.process_pool`);
    ``while_running`` is called once while workers compute (see
    :func:`~etobs.experiments.executors.execute`).
    Other parameters as in :func:`~etobs.experiments.sweep.run_sweep`.
    """
    tasks, reused = plan(spec, store, chunk or spec.chunk_size)
    pending: dict[int, int] = {}
    for t in tasks:
        pending[t.group] = pending.get(t.group, 0) + 1
    # one bar over every run of the spec: those stored earlier count from the start
    # (not in the rate); a failed chunk's runs count as done and in the postfix
    total = reused + sum(len(t.runs) for t in tasks)
    bar = progress_bar(total, spec.name, enabled=progress, initial=reused)
    bar.set_postfix_str("0 failed", refresh=False)
    computed = failures = 0

    def finished(task: Task) -> None:
        pending[task.group] -= 1
        if pending[task.group] == 0 and on_group is not None:
            on_group(task.group, store.records(task.key, spec.initial_states.runs))

    def done(task: Task, records: list[dict[str, Any]]) -> None:
        nonlocal computed
        store.write(task.key, task.runs, records)
        computed += len(records)
        bar.update(len(records))
        finished(task)

    def failed(task: Task, message: str) -> None:
        nonlocal failures
        store.write_error(task.key, task.runs, message, spec.where(task.group))
        failures += len(task.runs)
        bar.set_postfix_str(f"{failures} failed", refresh=False)
        bar.update(len(task.runs))
        finished(task)

    try:
        execute(
            tasks,
            type(spec),
            spec.raw,
            done,
            failed,
            executor=executor,
            workers=workers,
            scheduler=scheduler,
            client=client,
            pool=pool,
            while_running=while_running,
        )
    except WorkersLost as exc:  # one line: what ended it, and what is kept
        kept = reused + computed
        raise WorkersLost(
            f"{exc}: {kept} of {total} runs are stored in {str(store.out)!r} and kept; rerun the same "
            f"command to compute the other {total - kept}"
        ) from None
    finally:
        bar.close()
    return computed, reused


def other_chunks(spec: Experiment, store: ResultStore) -> int:
    """Chunk files in ``store`` that belong to no group of ``spec`` (:meth:`ResultStore.other_chunks`)."""
    return store.other_chunks({task_key(spec, g) for g in range(spec.n_groups)})


def stored(spec: Experiment, store: ResultStore) -> list[Stored]:
    """The records and standing failures of every group of ``spec`` in ``store``."""
    n = spec.initial_states.runs
    out = []
    for g in range(spec.n_groups):
        key = task_key(spec, g)
        records = store.records(key, n)
        out.append(Stored(group=g, records=records, failures=store.errors(key, set(records), n)))
    return out
