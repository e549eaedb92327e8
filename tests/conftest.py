"""Shared test settings: a deterministic hypothesis profile for CI, a fresh compile cache."""

import os

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile(
    "ci", derandomize=True, max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.register_profile("dev", max_examples=60, deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else os.environ.get("HYPOTHESIS_PROFILE", "dev"))


@pytest.fixture(scope="session", autouse=True)
def _compile_cache(tmp_path_factory):
    """A fresh compile cache for the session (hermetic), unless ETOBS_CACHE_DIR is set."""
    if "ETOBS_CACHE_DIR" in os.environ:
        yield
        return
    os.environ["ETOBS_CACHE_DIR"] = str(tmp_path_factory.mktemp("etobs-cache"))
    try:
        yield
    finally:
        os.environ.pop("ETOBS_CACHE_DIR", None)


def local_cluster(threads_per_worker: int):
    """A Dask scheduler and one worker in this process, listening on 127.0.0.1 only."""
    distributed = pytest.importorskip("distributed", reason="the dask extra is not installed")
    return distributed.LocalCluster(
        n_workers=1,
        threads_per_worker=threads_per_worker,
        processes=False,
        protocol="tcp://",
        host="127.0.0.1",
        dashboard_address=None,
    )


@pytest.fixture
def dask_cluster():
    """A Dask scheduler and one worker of two threads (:func:`local_cluster`)."""
    with local_cluster(2) as cluster:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        yield cluster
