"""A Dask sweep whose workers are all lost ends with one line saying what is kept (issue 23).

Before, it waited on the scheduler until killed. The wait is bounded by
``executors.WORKERLESS_WAIT`` seconds without a worker (shortened here: the test asserts
what ends the sweep, never how long it took).
"""

import threading
import time

import pytest

from etobs.errors import EtobsError
from etobs.experiments import executors, parse_spec, run_sweep
from etobs.experiments.store import ResultStore

from ..conftest import local_cluster
from .conftest import FACTORY, raw_spec


def test_a_sweep_whose_dask_workers_are_all_lost_ends_with_what_is_kept(tmp_path, monkeypatch):
    distributed = pytest.importorskip("distributed", reason="the dask extra is not installed")
    monkeypatch.setattr(executors, "WORKERLESS_WAIT", 0.5)
    spec = parse_spec(
        raw_spec(
            system={"factory": FACTORY, "fixed": {"delay": 0.5}},
            rows=[{"k": 1.0}],
            scenarios=[{"name": "only"}],
            initial_states={"low": [-1.0], "high": [1.0], "runs": 20, "seed": 7},
        )
    )
    out = tmp_path / "out"
    with local_cluster(1) as cluster:

        def kill_every_worker_after_the_first_chunk():
            for _ in range(1200):  # at most 120 s: the first chunk is stored, then no worker is left
                if list((out / "chunks").glob("*__*.json")):
                    break
                time.sleep(0.1)
            cluster.scale(0)

        killer = threading.Thread(target=kill_every_worker_after_the_first_chunk, daemon=True)
        killer.start()
        with distributed.Client(cluster) as client:
            with pytest.raises(EtobsError) as info:
                run_sweep(spec, out, executor="dask", client=client, chunk=2, progress=False)
        killer.join(timeout=120)
    message = str(info.value)
    assert "\n" not in message
    stored = len(ResultStore(out).records(next(iter(_keys(out))), 20))
    assert 2 <= stored < 20
    assert message.startswith("every Dask worker was lost (none for 0.5 s)")
    assert f"{stored} of 20 runs are stored in {str(out)!r} and kept" in message
    assert f"rerun the same command to compute the other {20 - stored}" in message


def _keys(out):
    return {p.name.partition("__")[0] for p in (out / "chunks").glob("*__*.json")}
