"""A process pool kept across calls (the trials of a tuning): the same records, and a broken one replaced."""

import os
import sys
from concurrent.futures.process import BrokenProcessPool

import pytest

from etobs.experiments.executors import execute, process_pool, usable_pool
from etobs.experiments.runner import Task


def tasks(spec):
    return [Task(key="k", group=g, runs=(0, 1)) for g in range(spec.n_groups)]


def collect(spec, got=None, **how):
    """Each group's records, reported into ``got`` (a new dict by default) as chunks finish."""
    got = {} if got is None else got
    failed = []
    execute(
        tasks(spec),
        type(spec),
        spec.raw,
        lambda t, r: got.setdefault(t.group, r),
        lambda t, m: failed.append(t),
        **how,
    )
    assert not failed
    return got


def test_a_kept_pool_gives_the_records_of_a_fresh_one_call_after_call(tiny):
    fresh = collect(tiny, executor="process", workers=1)
    pool = process_pool(1)
    try:
        for _ in range(2):  # the same pool serves two calls
            kept = collect(tiny, executor="process", workers=1, pool=pool)
            assert [[r["transmissions"] for r in kept[g]] for g in kept] == [
                [r["transmissions"] for r in fresh[g]] for g in kept
            ]
            assert {g: [r["error"] for r in recs] for g, recs in kept.items()} == {
                g: [r["error"] for r in recs] for g, recs in fresh.items()
            }
    finally:
        pool.shutdown()


def test_a_pool_a_dead_worker_broke_is_replaced_and_its_calls_still_finish(tiny):
    pool = process_pool(1)
    with pytest.raises(BrokenProcessPool):
        pool.submit(os._exit, 3).result()  # the worker dies: the pool is broken for good
    # a call given the broken pool reruns its chunks on fresh pools: every chunk is reported
    assert sorted(collect(tiny, executor="process", workers=1, pool=pool)) == list(range(tiny.n_groups))
    new = usable_pool(pool, 1)
    try:
        assert new is not pool and new.submit(int).result() == 0
        assert usable_pool(new, 1) is new  # a working pool is kept
    finally:
        new.shutdown()


@pytest.fixture(params=["serial", "fresh pool", "kept pool", "broken pool", "dask"])
def executor(request):
    """Each way ``execute`` runs chunks, with how many times it calls ``while_running``."""
    if request.param == "serial":
        yield {"executor": "serial"}, 0
    elif request.param == "fresh pool":
        yield {"executor": "process", "workers": 1}, 1
    elif request.param in ("kept pool", "broken pool"):
        pool = process_pool(1)
        if request.param == "broken pool":  # its worker died: the chunks rerun on fresh pools
            with pytest.raises(BrokenProcessPool):
                pool.submit(os._exit, 3).result()
        try:
            yield {"executor": "process", "workers": 1, "pool": pool}, 1
        finally:
            pool.shutdown()
    else:
        distributed = pytest.importorskip("distributed", reason="the dask extra is not installed")
        from tests.conftest import local_cluster

        with local_cluster(2) as cluster, distributed.Client(cluster) as client:
            yield {"executor": "dask", "client": client}, 1


@pytest.mark.parametrize("fails", [False, True])
def test_the_drivers_own_work_runs_once_while_workers_compute(tiny, executor, fails):
    """``while_running``: once with workers (after the chunks are handed over), never serially;
    if it raises, every chunk is still reported, then its exception is raised."""
    how, calls = executor
    said = []
    got = {}

    def own_work():
        said.append(len(got))
        if fails:
            raise OSError("disk full")

    def run():
        collect(tiny, got, while_running=own_work, **how)

    if fails and calls:
        with pytest.raises(OSError, match="disk full"):
            run()
    else:
        run()
    assert len(said) == calls
    assert sorted(got) == list(range(tiny.n_groups))  # every chunk reported all the same


def test_loading_the_table_writers_early_leaves_a_failure_to_the_writer(monkeypatch, tmp_path):
    from etobs.experiments.tables import load_writers, write_table

    monkeypatch.setitem(sys.modules, "pyarrow", None)  # not importable
    load_writers()  # says nothing: the sweep goes on
    with pytest.raises(ImportError, match="pyarrow"):
        write_table(tmp_path, "runs", [{"run": 0}])
