"""Where chunks run: in this process, in a local process pool, or on a Dask cluster.

Every executor calls ``on_done(task, records)`` or ``on_error(task, message)`` in the
driver for each task, so results are persisted by the driver as they arrive, whatever
the executor.
"""

from __future__ import annotations

import multiprocessing
import os
import threading
import time
import traceback
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from etobs.errors import EtobsError, InputError
from etobs.experiments.common import Experiment
from etobs.experiments.runner import Task, run_task

EXECUTORS = ("serial", "process", "dask")
#: After a worker dies, each chunk it may have taken down is rerun alone this many
#: times before it is recorded as failed.
MAX_POOL_RESTARTS = 3

#: Seconds a Dask sweep waits while the scheduler has no worker (all were killed, say)
#: before it ends with :class:`WorkersLost`: long enough for a nanny to restart one.
WORKERLESS_WAIT = 60.0
#: Seconds between two looks at the Dask futures and workers when nothing finished.
_POLL = 0.1

#: What every task of one experiment shares: the spec class and the raw spec.
Job = tuple[type[Experiment], dict[str, Any]]
Done = Callable[[Task, list[dict[str, Any]]], None]
Failed = Callable[[Task, str], None]


class WorkersLost(EtobsError):
    """Every Dask worker was lost for :data:`WORKERLESS_WAIT` seconds: the remaining chunks were cancelled."""


def execute(
    tasks: Sequence[Task],
    kind: type[Experiment],
    raw_spec: dict[str, Any],
    on_done: Done,
    on_error: Failed,
    *,
    executor: str = "process",
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
    pool: ProcessPoolExecutor | None = None,
    while_running: Callable[[], None] | None = None,
) -> None:
    """Run ``tasks`` of the experiment ``kind.from_raw(raw_spec)``, reporting each as it finishes.

    ``pool`` (from :func:`process_pool`) serves the process executor across calls, so that
    many small experiments (the trials of a tuning) do not each start workers that load
    the compiled model again; without it each call starts its own pool.
    ``while_running`` is called once in this thread once the chunks are handed to
    workers (a process pool or Dask), so that the driver's own set-up for afterwards
    (importing the table writers, say) overlaps them; the serial executor never calls it.
    An exception it raises is raised again once every chunk is reported (none is lost).
    """
    check_execution(executor, workers)
    if not tasks:
        return
    job = (kind, raw_spec)
    raised: list[Exception] = []

    def started() -> None:
        if while_running is None or raised:
            return
        try:
            while_running()
        except Exception as exc:  # raised below, once the chunks are in
            raised.append(exc)

    if executor == "serial":
        _serial(tasks, job, on_done, on_error)
    elif executor == "process":
        _process(tasks, job, on_done, on_error, workers, pool, started)
    else:
        _dask(tasks, job, on_done, on_error, scheduler, client, started)
    if raised:
        raise raised[0]


def _nothing() -> None:
    return None


#: Local worker processes per core at most: the runs are CPU-bound, so more only costs
#: memory (``--workers 1000``, a typo, started a process per chunk up to 1000).
MAX_WORKERS_PER_CORE = 4


def check_execution(executor: str, workers: int | None) -> None:
    """Fail, naming the argument, on an unknown executor or a bad number of workers."""
    if executor not in EXECUTORS:
        raise InputError(f"`executor` must be one of {EXECUTORS}; got {executor!r}")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise InputError(f"`workers` must be a positive integer; got {workers!r}")
    cores = os.cpu_count() or 1
    if workers is not None and executor == "process" and workers > MAX_WORKERS_PER_CORE * cores:
        raise InputError(
            f"`workers` = {workers} is more than {MAX_WORKERS_PER_CORE} per core of this machine's {cores} "
            f"(each is a process of about 140 MB, and runs use one core each): at most "
            f"{MAX_WORKERS_PER_CORE * cores}"
        )


def _serial(tasks: Sequence[Task], job: Job, on_done: Done, on_error: Failed) -> None:
    for task in tasks:
        try:
            records = run_task(*job, task)
        except Exception:  # a failing chunk is recorded; the sweep goes on
            on_error(task, traceback.format_exc())
        else:
            on_done(task, records)


def process_pool(workers: int | None) -> ProcessPoolExecutor:
    """A pool of worker processes to pass to :func:`execute` for many calls (close it after)."""
    check_execution("process", workers)
    return ProcessPoolExecutor(
        max_workers=workers, mp_context=_SPAWN, initializer=_worker_init, initargs=(os.getpid(),)
    )


def usable_pool(pool: ProcessPoolExecutor, workers: int | None) -> ProcessPoolExecutor:
    """``pool``, or a new one in its place when a worker's death broke it (the old one is shut down)."""
    try:
        pool.submit(int).result()
    except BrokenProcessPool:
        pool.shutdown(wait=False, cancel_futures=True)
        return process_pool(workers)
    return pool


#: "spawn" starts clean workers: safe with threads, the same on every platform.
_SPAWN = multiprocessing.get_context("spawn")


def _process(
    tasks: Sequence[Task],
    job: Job,
    on_done: Done,
    on_error: Failed,
    workers: int | None,
    pool: ProcessPoolExecutor | None = None,
    started: Callable[[], None] = _nothing,
) -> None:
    ctx = _SPAWN
    if pool is None:
        lost = _pool_round(list(tasks), job, on_done, on_error, workers, ctx, started)
    else:
        futures: dict[Any, Task] = {}
        try:
            for t in tasks:
                futures[pool.submit(run_task, *job, t)] = t
        except BrokenProcessPool:  # a worker died: every chunk goes the lost chunks' way below
            lost = list(tasks)
            started()
        else:
            started()
            lost = _collect(futures, on_done, on_error)
    # A dead worker breaks the whole pool and every pending chunk with it. Rerun those
    # chunks one at a time, so only a chunk that itself kills its worker is blamed.
    for task in lost:
        for attempt in range(1, MAX_POOL_RESTARTS + 1):
            if not _pool_round([task], job, on_done, on_error, 1, ctx):
                break
            if attempt == MAX_POOL_RESTARTS:
                on_error(task, f"the worker process running this chunk died {attempt} times in a row")


def _worker_init(driver: int) -> None:
    """Pool workers are the parallelism: the compiled backend runs one thread in each.

    A worker also ends when its driver (process ``driver``) dies, killed say: it checks
    once a second that its parent is still the driver, from the start (a driver killed
    while the worker was starting up leaves it another parent already).
    """
    os.environ["NUMBA_NUM_THREADS"] = "1"
    if os.getppid() != driver:
        os._exit(3)

    def watch() -> None:
        while True:
            time.sleep(1.0)
            if os.getppid() != driver:
                os._exit(3)

    threading.Thread(target=watch, name="etobs-driver-watch", daemon=True).start()


def _pool_round(
    tasks: list[Task],
    job: Job,
    on_done: Done,
    on_error: Failed,
    workers: int | None,
    ctx: Any,
    started: Callable[[], None] = _nothing,
) -> list[Task]:
    """Run ``tasks`` on a fresh pool; return those lost because a worker died.

    Once every chunk is reported the workers exit on their own while the driver goes on
    (writing the tables: a third of a second saved on Table 1); Python joins them at exit.
    """
    pool = ProcessPoolExecutor(
        max_workers=workers, mp_context=ctx, initializer=_worker_init, initargs=(os.getpid(),)
    )
    try:
        futures = {pool.submit(run_task, *job, t): t for t in tasks}
        started()
        return _collect(futures, on_done, on_error)
    finally:
        pool.shutdown(wait=False, cancel_futures=True)


def _collect(futures: dict[Any, Task], on_done: Done, on_error: Failed) -> list[Task]:
    """Report each finished future; return the tasks lost because a worker died (the pool is broken)."""
    lost: list[Task] = []
    for fut in as_completed(futures):
        task = futures[fut]
        try:
            records = fut.result()
        except BrokenProcessPool:
            lost.append(task)
        except Exception:
            on_error(task, traceback.format_exc())
        else:
            on_done(task, records)
    return lost


def _dask(
    tasks: Sequence[Task],
    job: Job,
    on_done: Done,
    on_error: Failed,
    scheduler: str | None,
    client: Any,
    started: Callable[[], None] = _nothing,
) -> None:
    try:
        from dask.distributed import Client
        from dask.distributed import as_completed as dask_completed
    except ImportError as exc:
        raise InputError("the dask executor needs the `dask` extra: pip install 'etobs[dask]'") from exc
    own = client is None
    if own:
        if not scheduler:
            raise InputError(
                "the dask executor needs `scheduler` (an address such as tcp://host:8786) or a client"
            )
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError) as exc:
            raise InputError(f"cannot reach the Dask scheduler at {scheduler!r}: {exc}") from exc
        except ValueError as exc:  # e.g. no port: "missing port number in address 'foo'"
            raise InputError(
                f"`scheduler` (--scheduler) must be an address such as tcp://host:8786; "
                f"got {scheduler!r}: {exc}"
            ) from exc
    try:
        futures = [client.submit(run_task, *job, t, pure=False) for t in tasks]
        index = {f.key: t for f, t in zip(futures, tasks, strict=True)}
        started()
        pending = dask_completed(futures)
        lost_since: float | None = None
        while not pending.is_empty():
            batch = pending.next_batch(block=False)
            for fut in batch:
                task = index[fut.key]
                if fut.status == "error":
                    on_error(task, "".join(traceback.format_exception(fut.exception())))
                elif fut.status == "cancelled":
                    on_error(task, "the Dask future of this chunk was cancelled")
                else:
                    on_done(task, fut.result())
            if batch or client.nthreads():
                lost_since = None
            elif lost_since is None:
                lost_since = time.monotonic()
            elif time.monotonic() - lost_since > WORKERLESS_WAIT:
                # the scheduler keeps the chunks until a worker joins: without one, forever
                client.cancel(futures)
                raise WorkersLost(f"every Dask worker was lost (none for {WORKERLESS_WAIT:g} s)")
            if not batch:
                time.sleep(_POLL)
    finally:
        if own:
            client.close()
