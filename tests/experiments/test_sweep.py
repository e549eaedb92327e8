import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from etobs import simulate
from etobs.errors import InputError
from etobs.experiments import parse_spec, run_sweep
from etobs.experiments.spec import SpecError
from etobs.experiments.systems import resolve_factory

from .conftest import FACTORY, raw_spec


def read_runs(out):
    return (out / "runs.csv").read_text()


def test_same_numbers_whatever_the_executor_workers_and_chunking(tiny, tmp_path):
    serial = run_sweep(tiny, tmp_path / "serial", executor="serial", chunk=5, progress=False)
    pooled = run_sweep(tiny, tmp_path / "pool", executor="process", workers=2, chunk=1, progress=False)
    assert serial.complete and pooled.complete
    assert len(serial.runs) == tiny.n_runs == 20
    assert read_runs(tmp_path / "serial") == read_runs(tmp_path / "pool")
    assert (tmp_path / "serial" / "aggregate.csv").read_text() == (
        tmp_path / "pool" / "aggregate.csv"
    ).read_text()


def test_outputs_and_resume(tiny, tmp_path):
    first = run_sweep(tiny, tmp_path, executor="serial", progress=False)
    assert (first.computed, first.reused) == (20, 0)
    again = run_sweep(tiny, tmp_path, executor="serial", progress=False)
    assert (again.computed, again.reused) == (0, 20)
    meta = json.loads((tmp_path / "meta.json").read_text())
    assert meta["seed"] == 7 and meta["runs_present"] == 20 and "numpy" in meta["versions"]
    written = json.loads((tmp_path / "spec.json").read_text())
    assert written["as_given"]["name"] == "tiny"
    assert written["resolved"]["solver"]["rtol"] == 1e-10  # defaults filled in
    assert written["resolved"]["metrics"]["error_window"] == [2.0, 3.0]
    header = read_runs(tmp_path).splitlines()[0].split(",")
    assert header[:4] == ["row", "scenario", "run", "k"]
    assert "transmissions_node0" in header and "error" in header
    agg = first.aggregate
    assert [(a["row"], a["scenario"], a["runs"]) for a in agg] == [
        (0, "coarse", 5),
        (0, "fine", 5),
        (1, "coarse", 5),
        (1, "fine", 5),
    ]
    # a finer threshold never transmits less on average
    assert agg[1]["transmissions_mean"] > agg[0]["transmissions_mean"]
    assert "| row | scenario |" in (tmp_path / "report.md").read_text()
    # a changed spec gets new keys: nothing is reused from the old one
    other = run_sweep(
        parse_spec(raw_spec(solver={"rtol": 1e-8})), tmp_path, executor="serial", progress=False
    )
    assert other.reused == 0


def test_more_runs_reuse_the_first_ones(tiny, tmp_path):
    run_sweep(tiny, tmp_path, executor="serial", progress=False)
    more = run_sweep(tiny.with_runs(8), tmp_path, executor="serial", progress=False)
    assert (more.computed, more.reused) == (12, 20)
    run_sweep(tiny.with_runs(8), tmp_path / "fresh", executor="serial", progress=False)
    assert read_runs(tmp_path) == read_runs(tmp_path / "fresh")


def test_a_failing_chunk_is_recorded_and_the_sweep_goes_on(tmp_path):
    spec = parse_spec(raw_spec(rows=[{"k": 1.0}, {"k": 2.0, "fail": True}]))
    res = run_sweep(spec, tmp_path, executor="serial", progress=False)
    assert not res.complete
    assert len(res.runs) == 10 and {r["row"] for r in res.runs} == {0}
    assert len(res.failures) == 6  # row 1: 2 scenarios x 3 chunks of at most 2 runs
    assert "this row fails on purpose" in res.failures[0]["error"]
    assert "failed chunk" in (tmp_path / "report.md").read_text()


def test_factory_errors_name_the_problem(tmp_path):
    with pytest.raises(
        SpecError,
        match=r"parameter `q` \(`rows\[0\].q`, row 0, scenario 'coarse'\) is not an argument of the factory",
    ):
        parse_spec(raw_spec(rows=[{"q": 1}])).check()
    # found by the spec fuzz test: a key of system.fixed is named as one (not as the row's)
    with pytest.raises(SpecError, match=r"parameter `A` \(`system.fixed.A`, row 0, scenario 'coarse'\)"):
        parse_spec(raw_spec(system={"factory": FACTORY, "fixed": {"A": False}})).check()
    with pytest.raises(SpecError, match=r"`system.factory` = 'pendulum' is neither a registered example"):
        resolve_factory("pendulum")
    with pytest.raises(SpecError, match=r"`system.factory`: cannot import 'no_such_module'"):
        resolve_factory("no_such_module:f")
    with pytest.raises(SpecError, match=r"has no callable 'nothing'"):
        resolve_factory(FACTORY.replace(":scalar", ":nothing"))
    bad = parse_spec(raw_spec(system={"factory": FACTORY.replace(":scalar", ":not_a_problem")}))
    with pytest.raises(SpecError, match=r"returned dict, not an EstimationProblem"):
        bad.problem(0)


def test_a_value_the_model_refuses_is_refused_before_any_run_naming_its_key(tmp_path):
    # before: each chunk of row 1 failed in the workers, and row 0 ran (compare refused it up front)
    bad = parse_spec(raw_spec(rows=[{"sigma": 0.0}, {"sigma": -0.1}]))
    with pytest.raises(
        SpecError, match=r"^`rows\[1\].sigma` \(row 1, scenario 'coarse'\): `sigma` must be >= 0; got -0.1$"
    ):
        run_sweep(bad, tmp_path / "out", executor="serial", progress=False)
    assert not (tmp_path / "out").exists()  # nothing run, nothing written
    parse_spec(raw_spec(rows=[{"sigma": 0.0}])).check()  # sigma = 0 (the static rule) is accepted
    refused = parse_spec(raw_spec(rows=[{"k": 1.0}, {"k": 2.0, "refuse": True}]))
    with pytest.raises(SpecError, match=r"failed on the arguments of row 1, scenario 'coarse': ValueError"):
        refused.check()


def test_a_killed_worker_is_replaced_and_nothing_is_lost(tmp_path):
    marker = tmp_path / "died"
    spec = parse_spec(raw_spec(system={"factory": FACTORY, "fixed": {"die_marker": str(marker)}}))
    res = run_sweep(spec, tmp_path / "out", executor="process", workers=2, chunk=2, progress=False)
    assert marker.exists()  # one worker really died
    assert res.complete
    keys = [(r["row"], r["scenario"], r["run"]) for r in res.runs]
    assert len(keys) == len(set(keys)) == spec.n_runs


def test_a_killed_driver_resumes_and_every_run_is_present_once(tmp_path):
    spec_file = tmp_path / "slow.toml"
    fixed = "{ delay = 0.15 }"
    spec_file.write_text(
        f'name = "slow"\n[system]\nfactory = "{FACTORY}"\nfixed = {fixed}\n'
        "[[rows]]\nk = 1.0\n[[rows]]\nk = 2.0\n"
        "[initial_states]\nlow = [-1.0]\nhigh = [1.0]\nruns = 12\nseed = 5\n[horizon]\nt_end = 2.0\n"
    )
    out = tmp_path / "out"
    cmd = [
        sys.executable,
        "-m",
        "etobs.cli.main",
        "sweep",
        str(spec_file),
        "--out",
        str(out),
        "--executor",
        "serial",
        "--chunk-size",
        "1",
        "--no-progress",
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while len(list((out / "chunks").glob("*.json"))) < 5 and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)
    stored = len(list((out / "chunks").glob("*__*.json")))
    assert 5 <= stored < 24  # killed mid-way
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    lines = (out / "runs.csv").read_text().splitlines()[1:]
    keys = [tuple(line.split(",")[:3]) for line in lines]
    assert len(keys) == len(set(keys)) == 24
    assert f"({24 - stored} computed now, {stored} reused)" in done.stdout
    clean = subprocess.run(
        [*cmd[:6], str(tmp_path / "clean"), "--executor", "serial", "--no-progress"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert clean.returncode == 0
    assert (tmp_path / "clean" / "runs.csv").read_text() == (out / "runs.csv").read_text()
    assert not list((out / "chunks").glob(".*tmp"))  # no half-written files left visible
    import pyarrow.parquet as pq

    assert pq.read_table(tmp_path / "clean" / "runs.parquet").equals(pq.read_table(out / "runs.parquet"))


def test_a_dead_writers_temporary_table_is_removed_and_the_tables_are_whole(tiny, tmp_path):
    import pyarrow.parquet as pq

    tmp_path.joinpath(".runs.parquet.x1y2.tmp").write_bytes(b"PAR1 half")  # killed mid-write
    run_sweep(tiny, tmp_path, executor="serial", progress=False)
    assert not list(tmp_path.glob(".*.tmp"))
    assert pq.read_table(tmp_path / "runs.parquet").num_rows == tiny.n_runs


def test_dask_executor_gives_the_same_numbers(tiny, tmp_path, dask_cluster):
    import distributed

    by_address = run_sweep(
        tiny,
        tmp_path / "addr",
        executor="dask",
        scheduler=dask_cluster.scheduler_address,
        chunk=3,
        progress=False,
    )
    with distributed.Client(dask_cluster) as client:
        by_client = run_sweep(tiny, tmp_path / "client", executor="dask", client=client, progress=False)
    assert by_address.complete and by_client.complete
    run_sweep(tiny, tmp_path / "serial", executor="serial", progress=False)
    assert read_runs(tmp_path / "addr") == read_runs(tmp_path / "serial") == read_runs(tmp_path / "client")


def test_executor_errors(tiny, tmp_path):
    from etobs import InputError

    with pytest.raises(
        InputError, match=r"`executor` must be one of \('serial', 'process', 'dask'\); got 'gpu'"
    ):
        run_sweep(tiny, tmp_path / "gpu", executor="gpu", progress=False)
    assert not (tmp_path / "gpu").exists()  # checked before anything is written
    with pytest.raises(InputError, match=r"`workers` must be a positive integer; got 0"):
        run_sweep(tiny, tmp_path, workers=0, progress=False)
    with pytest.raises(InputError, match=r"needs `scheduler`"):
        run_sweep(tiny, tmp_path / "d", executor="dask", progress=False)


def test_stale_errors_are_cleared_when_the_runs_succeed_in_another_chunking(tmp_path):
    failing = parse_spec(raw_spec(rows=[{"k": 1.0, "fail": True}]))
    first = run_sweep(failing, tmp_path, executor="serial", chunk=2, progress=False)
    assert len(first.failures) == 6
    # Same key space is not shared (fail=True is a parameter); simulate a fixed factory by
    # storing the runs under the failing key through a successful spec with that key.
    from etobs.experiments.store import ResultStore, task_key

    store = ResultStore(tmp_path)
    key = task_key(failing, 0)
    ok = parse_spec(raw_spec(rows=[{"k": 1.0}]))
    run_sweep(ok, tmp_path / "ok", executor="serial", progress=False)
    coarse = ResultStore(tmp_path / "ok").records(task_key(ok, 0), 5)  # whole records, as run_task writes
    recs = [coarse[r] for r in range(5)]
    store.write(key, tuple(range(5)), recs)  # one chunk of 5 covering the 3 failed chunks of 2
    again = run_sweep(failing, tmp_path, executor="serial", chunk=5, progress=False)
    # 'fine' still fails: one standing failure (the chunk of 5 supersedes the three older
    # chunks of 2); the 'coarse' errors are gone since its runs are now stored
    assert [(f["where"], f["runs"]) for f in again.failures] == [("row 0, scenario 'fine'", [0, 1, 2, 3, 4])]
    assert not list((tmp_path / "chunks").glob(f"{key}__*.error.json"))


def test_fewer_runs_use_only_the_first_ones(tiny, tmp_path):
    run_sweep(tiny, tmp_path, executor="serial", progress=False)
    fewer = run_sweep(tiny.with_runs(3), tmp_path, executor="serial", progress=False)
    assert fewer.complete and (fewer.computed, fewer.reused) == (0, 12)
    assert sorted({r["run"] for r in fewer.runs}) == [0, 1, 2]


def test_a_group_without_runs_keeps_its_line(tmp_path):
    spec = parse_spec(raw_spec(rows=[{"k": 1.0}, {"k": 2.0, "fail": True}]))
    res = run_sweep(spec, tmp_path, executor="serial", progress=False)
    assert [(a["row"], a["runs"]) for a in res.aggregate] == [(0, 5), (0, 5), (1, 0), (1, 0)]
    assert res.aggregate[2]["transmissions_mean"] is None
    assert "| 0 | 0 | n/a | n/a | n/a | n/a |" in (tmp_path / "report.md").read_text()


def test_only_the_chunk_that_kills_its_worker_is_blamed(tmp_path):
    spec = parse_spec(
        raw_spec(rows=[{"k": 1.0}, {"k": 2.0, "die_always": True}], scenarios=[{"name": "only"}])
    )
    res = run_sweep(spec, tmp_path / "out", executor="process", workers=2, chunk=5, progress=False)
    assert [(f["where"], f["runs"]) for f in res.failures] == [("row 1, scenario 'only'", [0, 1, 2, 3, 4])]
    assert "died 3 times in a row" in res.failures[0]["error"]
    assert sorted(r["row"] for r in res.runs) == [0] * 5


def test_bad_chunk_and_numpy_parameters(tmp_path):
    import numpy as np

    from etobs import InputError

    spec = parse_spec(
        raw_spec(
            rows=[{"k": np.float64(1.0)}],
            initial_states={"low": [-1.0], "high": [1.0], "runs": np.int64(2), "seed": 7},
        )
    )
    with pytest.raises(InputError, match=r"`chunk` must be a positive integer \(runs per chunk\); got -1"):
        run_sweep(spec, tmp_path, chunk=-1, progress=False)
    res = run_sweep(spec, tmp_path, executor="serial", progress=False)
    assert res.complete and '"k": 1.0' in (tmp_path / "spec.json").read_text()


def test_dimension_mismatch_is_named(tmp_path):
    spec = parse_spec(raw_spec(initial_states={"low": [0.0, 0.0], "high": [1.0, 1.0], "runs": 2, "seed": 1}))
    # refused before any run (it failed every chunk in the workers)
    with pytest.raises(
        SpecError, match=r"`initial_states.low` and `.high` have 2 entries but the plant has n_x = 1"
    ):
        run_sweep(spec, tmp_path / "out", executor="serial", progress=False)
    assert not (tmp_path / "out").exists()


def test_keys_ignore_how_numbers_are_written(tmp_path):
    from etobs.experiments.store import task_key

    a = parse_spec(raw_spec(rows=[{"k": 1}], initial_states={"low": [-1], "high": [1], "runs": 5, "seed": 7}))
    b = parse_spec(
        raw_spec(
            rows=[{"k": 1.0}], metrics={}, initial_states={"low": [-1.0], "high": [1.0], "runs": 9, "seed": 7}
        )
    )
    c = parse_spec(raw_spec(rows=[{}], system={"factory": FACTORY, "fixed": {"k": 1.0}}))
    assert task_key(a, 0) != task_key(b, 0)  # the metrics differ (defaults vs tiny's)
    b2 = parse_spec(
        raw_spec(rows=[{"k": 1.0}], initial_states={"low": [-1.0], "high": [1.0], "runs": 9, "seed": 7})
    )
    assert task_key(a, 0) == task_key(b2, 0) == task_key(c, 0)


def test_unreachable_dask_scheduler_is_an_input_error(tiny, tmp_path):
    pytest.importorskip("distributed", reason="the dask extra is not installed")
    from etobs import InputError

    # Nothing listens on port 1 of the loopback address; the client gives up after 10 s.
    with pytest.raises(InputError, match=r"cannot reach the Dask scheduler at 'tcp://127.0.0.1:1'"):
        run_sweep(tiny, tmp_path, executor="dask", scheduler="tcp://127.0.0.1:1", progress=False)


def test_auto_is_passed_to_simulate_and_earlier_backend_names_are_accepted(tiny):
    # "auto" is decided by simulate for each problem, not by the sweep
    assert tiny.backend == "auto"
    assert tiny.with_backend("scipy").backend == "scipy"
    assert tiny.with_backend("scipy").identity() != tiny.identity()
    assert tiny.with_backend("numba").backend == "engine"
    for retired in ("numpy", "fast"):
        with pytest.raises(
            SpecError, match=rf"^`execution.backend` '{retired}' \(the batched numpy solver\) was retired"
        ):
            tiny.with_backend(retired)
    assert tiny.with_backend("numba").identity() == tiny.with_backend("engine").identity()


def test_engine_backend_sweep_gives_the_scipy_backend_counts(tmp_path):
    def spec(backend):
        return parse_spec(
            {
                "name": "arm",
                "system": {"factory": "robot_arm", "fixed": {}},
                "rows": [{"eps": [10.0, 10.0]}, {"eps": [100.0, 100.0]}],
                "initial_states": {"low": [0, 0, 0, 0], "high": [20, 10, 20, 10], "runs": 3, "seed": 1},
                "horizon": {"t_end": 3.0},
                "metrics": {
                    "transmissions_window": [0.0, 3.0],
                    "error_window": [2.0, 3.0],
                    "error_grid_step": 0.01,
                },
                "execution": {"chunk_size": 2, "backend": backend},
            }
        )

    assert spec("auto").backend == "auto"
    batched = run_sweep(spec("scipy"), tmp_path / "scipy", executor="serial", progress=False)
    ours = run_sweep(spec("engine"), tmp_path / "engine", executor="serial", progress=False)
    auto = run_sweep(spec("auto"), tmp_path / "auto", executor="serial", progress=False)
    assert [r["transmissions"] for r in ours.runs] == [r["transmissions"] for r in batched.runs]
    errors = np.array([[a["error"], b["error"]] for a, b in zip(ours.runs, batched.runs, strict=True)])
    np.testing.assert_allclose(errors[:, 0], errors[:, 1], rtol=1e-6)
    # "auto" runs the robot arm on the engine: the same numbers, bit for bit
    assert [(r["transmissions"], r["error"]) for r in auto.runs] == [
        (r["transmissions"], r["error"]) for r in ours.runs
    ]


def test_network_problems_sweep_with_the_same_numbers_whatever_the_chunking(tmp_path):
    """A factory may return any problem: here a lossy, delayed network and the relative
    rule. Packets are drawn per global run index, so chunking does not change them."""
    spec = parse_spec(
        raw_spec(
            system={
                "factory": FACTORY.replace(":scalar", ":scalar_network"),
                "fixed": {"loss": 0.3, "delay": 0.05},
            },
            rows=[{"relative": False}, {"relative": True}],
            scenarios=[{"name": "default"}],
        )
    )
    one = run_sweep(spec, tmp_path / "one", executor="serial", chunk=5, progress=False)
    assert run_sweep(spec, tmp_path / "many", executor="serial", chunk=2, progress=False).complete
    assert one.complete and len(one.runs) == 10
    assert read_runs(tmp_path / "one") == read_runs(tmp_path / "many")
    with pytest.raises(InputError, match=r"`run_ids` must be 2 non-negative integers"):
        simulate(spec.problem(0), [[0.5], [0.2]], 1.0, run_ids=[0])


def test_a_string_for_a_switch_is_refused_before_any_run_naming_the_key(tmp_path):
    raw = {
        "name": "switch",
        "system": {"factory": "robot_arm"},
        "scenarios": [{"name": "quoted", "noise": "false"}],
        "initial_states": {"low": [0.0] * 4, "high": [1.0] * 4, "runs": 1, "seed": 1},
        "horizon": {"t_end": 0.1},
    }
    # refused before any run, naming the spec key (it failed the chunk in the workers)
    with pytest.raises(
        SpecError, match=r"^`scenarios\[0\].noise` .*: `noise` must be true or false; got 'false' \(str\)"
    ):
        run_sweep(parse_spec(raw), tmp_path / "out", executor="serial", progress=False)


def _chunk_files(out):
    return sorted(p for p in (out / "chunks").glob("*__*.json") if not p.name.endswith(".error.json"))


def test_a_tampered_chunk_is_set_aside_and_recomputed(tiny, tmp_path):
    run_sweep(tiny, tmp_path, executor="serial", progress=False)
    before = read_runs(tmp_path)
    target = _chunk_files(tmp_path)[0]
    data = json.loads(target.read_text())
    data["records"][0]["error"] = 123.0  # one number changed by hand
    target.write_text(json.dumps(data))
    with pytest.warns(
        RuntimeWarning, match=r"was changed since it was written \(its checksum does not match\)"
    ):
        again = run_sweep(tiny, tmp_path, executor="serial", progress=False)
    assert (again.computed, again.reused) == (len(data["records"]), 20 - len(data["records"]))
    assert read_runs(tmp_path) == before  # the tampered value is not used
    assert (tmp_path / "set-aside" / target.name).is_file()


@pytest.mark.parametrize(
    ("text", "why"),
    [
        ("[]", r"not a chunk of this version \(wrong structure\)"),
        ('{"key": "x", "records": [], "sha256": "0"}', r"stored under key 'x', not its file's"),
        ("{not json", r"unreadable"),
    ],
)
def test_a_foreign_or_broken_chunk_is_set_aside_with_a_warning_not_a_traceback(tiny, tmp_path, text, why):
    run_sweep(tiny, tmp_path, executor="serial", progress=False)
    target = _chunk_files(tmp_path)[-1]
    target.write_text(text)
    with pytest.warns(RuntimeWarning, match=why):
        again = run_sweep(tiny, tmp_path, executor="serial", progress=False)
    assert again.complete and again.computed > 0


def test_a_second_writer_on_the_same_folder_is_refused(tiny, tmp_path):
    from etobs.experiments.store import ResultStore

    with ResultStore(tmp_path).lock():
        with pytest.raises(
            InputError, match=r"another sweep or comparison is writing to .* \(process \d+ holds"
        ):
            run_sweep(tiny, tmp_path, executor="serial", progress=False)
    assert run_sweep(tiny, tmp_path, executor="serial", progress=False).complete  # released


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads child processes from /proc (Linux)")
def test_pool_workers_end_when_their_driver_is_killed(tmp_path):
    spec_file = tmp_path / "slow.toml"
    spec_file.write_text(
        f'name = "slow"\n[system]\nfactory = "{FACTORY}"\nfixed = {{ delay = 2.0 }}\n'
        "[initial_states]\nlow = [-1.0]\nhigh = [1.0]\nruns = 40\nseed = 5\n[horizon]\nt_end = 1.0\n"
    )
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "etobs.cli.main", "sweep", str(spec_file), "--out", str(out)]
    cmd += ["--workers", "2", "--chunk-size", "1", "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    children: set[int] = set()
    deadline = time.monotonic() + 60
    while len(children) < 2 and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.2)
        children = _workers_of(proc.pid)
    assert len(children) >= 2, "the pool did not start"
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)
    deadline = time.monotonic() + 30
    while children and time.monotonic() < deadline:
        time.sleep(0.2)
        children = {pid for pid in children if _alive(pid)}
    assert not children, f"workers {sorted(children)} outlived their driver"


def _workers_of(pid):
    """Child processes of ``pid`` running a multiprocessing spawn main (Linux /proc)."""
    out = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            cmdline = (stat.parent / "cmdline").read_bytes()
        except OSError:
            continue
        if int(fields[1]) == pid and b"spawn_main" in cmdline:
            out.add(int(stat.parent.name))
    return out


def _alive(pid):
    try:
        state = (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_a_malformed_dask_scheduler_address_is_an_input_error(tiny, tmp_path):
    pytest.importorskip("distributed", reason="the dask extra is not installed")
    from etobs import InputError

    # it was a ValueError traceback from distributed
    with pytest.raises(
        InputError, match=r"`scheduler` \(--scheduler\) must be an address such as tcp://host:8786"
    ):
        run_sweep(tiny, tmp_path, executor="dask", scheduler="foo", progress=False)


TWO_NODES = f"{Path(__file__).with_name('two_nodes.py')}:pair"


def two_node_spec(**over):
    raw = raw_spec(system={"factory": TWO_NODES}, rows=[{"eps1": 0.0005}, {"eps1": 0.01}], scenarios=[])
    raw.pop("scenarios")
    raw["initial_states"] = {"low": [-1.0, -1.0], "high": [1.0, 1.0], "runs": 4, "seed": 3}
    raw.update(over)
    return parse_spec(raw)


def test_which_node_transmits_is_in_every_table(tmp_path):
    import pandas as pd

    res = run_sweep(two_node_spec(), tmp_path, executor="serial", progress=False)
    assert res.complete
    runs = pd.read_csv(tmp_path / "runs.csv")
    agg = pd.read_csv(tmp_path / "aggregate.csv")
    assert (runs.transmissions == runs.transmissions_node0 + runs.transmissions_node1).all()
    for node in ("node0", "node1"):
        by_row = runs.groupby("row")
        assert list(agg[f"transmissions_{node}_mean"]) == list(by_row[f"transmissions_{node}"].mean())
        assert list(agg[f"transmissions_{node}_max"]) == list(by_row[f"transmissions_{node}"].max())
        assert list(agg[f"min_inter_event_time_{node}_min"]) == list(
            by_row[f"min_inter_event_time_{node}"].min()
        )
    # node 1 (the finer eps1) sends most: the aggregate says so, per node
    assert (agg.transmissions_node1_mean > 5 * agg.transmissions_node0_mean).all()
    assert "transmissions_node0_mean | transmissions_node1_mean" in (tmp_path / "report.md").read_text()


def test_parquet_twins_hold_the_csv_tables_with_their_types(tmp_path):
    import pandas as pd

    res = run_sweep(two_node_spec(), tmp_path, executor="serial", progress=False)
    for name in ("runs", "aggregate"):
        csv, parquet = pd.read_csv(tmp_path / f"{name}.csv"), pd.read_parquet(tmp_path / f"{name}.parquet")
        pd.testing.assert_frame_equal(parquet, csv, check_dtype=True)
        pd.testing.assert_frame_equal(res.to_pandas(name), parquet, check_dtype=True)  # the same from Python
    with pytest.raises(InputError, match=r"`table` must be one of 'runs', 'aggregate'; got 'summary'"):
        res.to_pandas("summary")
    runs = pd.read_parquet(tmp_path / "runs.parquet")
    kinds = runs.dtypes.map(lambda d: d.kind).to_dict()
    assert {c: kinds[c] for c in ("row", "run", "transmissions_node1", "steps")} == dict.fromkeys(
        ("row", "run", "transmissions_node1", "steps"), "i"
    )
    assert {c: kinds[c] for c in ("eps1", "error", "min_inter_event_time_node0", "x0_2")} == dict.fromkeys(
        ("eps1", "error", "min_inter_event_time_node0", "x0_2"), "f"
    )
    assert pd.api.types.is_string_dtype(runs.status) and set(runs.status) == {"completed"}
    assert pd.api.types.is_string_dtype(runs.scenario)
    assert len(runs) == res.spec.n_runs


def test_chunks_stored_earlier_give_the_per_node_columns_without_a_recomputation(tmp_path):
    run_sweep(two_node_spec(), tmp_path, executor="serial", progress=False)
    before = {n: (tmp_path / n).read_bytes() for n in ("runs.csv", "aggregate.csv", "runs.parquet")}
    for name in before:
        (tmp_path / name).unlink()
    again = run_sweep(two_node_spec(), tmp_path, executor="serial", progress=False)
    assert (again.computed, again.reused, again.other_chunks) == (0, 8, 0)
    assert {n: (tmp_path / n).read_bytes() for n in before} == before


def test_chunks_of_another_version_are_not_used_and_the_report_says_so(tmp_path, monkeypatch):
    import etobs.experiments.common as common

    run_sweep(two_node_spec(), tmp_path, executor="serial", progress=False)
    stored = len(list((tmp_path / "chunks").glob("*.json")))
    monkeypatch.setattr(common, "RECORD_FORMAT", common.RECORD_FORMAT + 1)  # records of a new layout
    res = run_sweep(two_node_spec(), tmp_path, executor="serial", progress=False)
    assert (res.computed, res.reused, res.other_chunks) == (8, 0, stored)
    assert (
        f"{stored} chunk files in `chunks/` belong to another spec or etobs version"
        in (tmp_path / "report.md").read_text()
    )
    assert json.loads((tmp_path / "meta.json").read_text())["other_chunks"] == stored


def test_the_progress_bar_counts_runs_reused_runs_and_failed_runs(tmp_path, capsys):
    spec = parse_spec(raw_spec(rows=[{"k": 1.0}, {"k": 2.0, "fail": True}]))
    run_sweep(spec, tmp_path, executor="serial", progress=True)
    err = capsys.readouterr().err
    assert "tiny: 100%" in err and "20/20" in err and "10 failed" in err
    assert "nan" not in err and "unknown" not in err
    # a rerun: the 10 stored runs count from the start, the failed chunks are tried again
    run_sweep(spec, tmp_path, executor="serial", progress=True)
    err = capsys.readouterr().err
    assert "tiny:  50%" in err and "10/20" in err and "20/20" in err and "10 failed" in err
    run_sweep(spec, tmp_path / "quiet", executor="serial", progress=False)
    run_sweep(spec, tmp_path / "default", executor="serial")  # stderr is not a terminal here
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("name", ["packets_node0", "not_applied_node1", "transmissions_node0_mean"])
def test_a_parameter_may_not_take_the_name_of_a_per_node_column(name):
    with pytest.raises(SpecError, match=rf"parameter `rows\[0\].{name}` clashes with a result column"):
        parse_spec(raw_spec(rows=[{name: 1.0}]))


def test_a_chunk_draws_no_bar_of_its_own_whatever_the_terminal(tiny, tmp_path, monkeypatch, capsys):
    import etobs.experiments.runner as runner

    asked = []
    real = runner.simulate

    def recorded(*args, progress=None, **kw):
        asked.append(progress)
        return real(*args, progress=progress, **kw)

    monkeypatch.setattr(runner, "simulate", recorded)
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)  # as on a terminal
    run_sweep(tiny, tmp_path, executor="serial", progress=False)
    assert asked == [False] * 12  # 4 groups x 3 chunks: no "simulate" bar inside the sweep's
    assert capsys.readouterr().err == ""
