"""``etobs compare``: the spec, the table, persistence and resume, the plot."""

import json
import re

import numpy as np
import pytest

from etobs.cli.main import main
from etobs.errors import InputError
from etobs.experiments.compare import compare
from etobs.experiments.compare_spec import parse_compare_spec
from etobs.experiments.spec import SpecError

SPEC = {
    "name": "oscillator",
    "system": {"factory": "tests.estimation.linear:factory", "params": {"eps": 0.01}},
    "initial_states": {"low": [-1.0, -1.0], "high": [1.0, 1.0], "runs": 3, "seed": 4},
    "horizon": {"t_end": 8.0},
    "metrics": {"error_window": [6.0, 8.0], "error_grid_step": 0.01},
    "execution": {"backend": "engine"},
    "rules": [
        {"name": "dynamic", "kind": "base"},
        {"name": "static", "kind": "static", "eps": 0.01},
        {"name": "periodic", "kind": "periodic", "period": 0.05},
        {"name": "relative", "kind": "relative", "rho": 0.05, "eps": 0.01},
        {"name": "send-on-delta", "kind": "send_on_delta", "delta": 0.05},
        {"name": "copy", "kind": "base", "observer_copy": True},
        {"name": "dynamic sigma 0", "kind": "dynamic", "sigma": 0.0},
    ],
    "networks": [{"name": "ideal"}, {"name": "lossy", "loss": 0.2, "delay": 0.01, "seed": 3}],
}

TOML = """
name = "oscillator"
[system]
factory = "tests.estimation.linear:factory"
[initial_states]
low = [-1.0, -1.0]
high = [1.0, 1.0]
runs = 2
seed = 4
[horizon]
t_end = 4.0
[metrics]
error_window = [3.0, 4.0]
error_grid_step = 0.01
[execution]
backend = "engine"
[[rules]]
name = "dynamic"
kind = "base"
[[rules]]
name = "periodic"
kind = "periodic"
period = 0.1
[[networks]]
name = "ideal"
[[networks]]
name = "lossy"
loss = 0.5
delay = 0.02
"""


@pytest.fixture(scope="module")
def comparison(tmp_path_factory):
    return compare(parse_compare_spec(SPEC), tmp_path_factory.mktemp("cmp"), executor="serial")


def test_every_rule_runs_on_every_network_from_the_same_states(comparison):
    rows = comparison.table()
    assert [(r["rule"], r["network"]) for r in rows[:2]] == [("dynamic", "ideal"), ("static", "ideal")]
    assert len(rows) == 13 and all(r["completed"] == "3/3" for r in rows)
    assert [s[:2] for s in comparison.skipped] == [
        ("copy", "lossy")
    ]  # Remark 3's copy needs the ideal network
    by = {(r["rule"], r["network"]): r for r in rows}
    # periodic: 0.05 s over 8 s, whatever the network (it counts packets sent)
    # (the 160th falls on t_end, where the clock's rounding decides)
    assert by[("periodic", "ideal")]["transmissions y"] in (159.0, 160.0)
    assert by[("periodic", "lossy")]["transmissions y"] == by[("periodic", "ideal")]["transmissions y"]
    # static with the same gamma and eps as sigma = 0 dynamic: the same transmissions
    e = {(x.rule, x.network): x for x in comparison.entries}
    np.testing.assert_array_equal(
        e[("static", "ideal")].transmissions, e[("dynamic sigma 0", "ideal")].transmissions
    )
    # the dynamic rule sends less than the static one (sigma alpha(eta) raises the bar)
    assert by[("dynamic", "ideal")]["transmissions total"] < by[("static", "ideal")]["transmissions total"]
    # the ideal network loses nothing; the lossy one about 20 %
    assert np.isnan(by[("dynamic", "ideal")]["not applied"])
    assert 0.05 < by[("periodic", "lossy")]["not applied"] < 0.35
    for r in rows:  # every min inter-event time is positive
        assert not r["min inter-event y"] <= 0


def test_markdown_table_has_a_row_per_entry_and_states_the_windows(comparison):
    md = comparison.markdown()
    lines = md.splitlines()
    assert lines[0].startswith("| rule | network | completed | transmissions y |")
    assert sum(1 for ln in lines if ln.startswith("| ")) == 14
    assert "Not run: copy / lossy: the observer copy of Remark 3 is simulated as a perfect copy" in md
    assert "error = max |x - xhat| on [6, 8] s on a 0.01 s grid" in md


def test_tidy_tables_in_python_are_the_files(comparison):
    import pandas as pd

    for name in ("runs", "aggregate"):
        frame = comparison.to_pandas(name)
        pd.testing.assert_frame_equal(frame, pd.read_parquet(comparison.out / f"{name}.parquet"))
    agg = comparison.to_pandas("aggregate").set_index(["rule", "network"])
    assert len(agg) == len(comparison.entries)  # one line per entry run (skipped pairs have none)
    periodic = agg.loc[("periodic", "ideal")]  # period 0.05 on [0, 8] s: 160 sends at most
    assert 150 <= periodic.transmissions_node0_mean <= 161 and periodic.transmissions_node0_std == 0
    with pytest.raises(InputError, match=r"`table` must be one of 'runs', 'aggregate'; got 3"):
        comparison.to_pandas(3)


def test_trade_off_plot(comparison):
    pytest.importorskip("matplotlib")
    from etobs.plot import plot_tradeoff

    _, ax = plot_tradeoff(comparison)
    assert len(ax.get_legend().get_texts()) == 7 + 2
    assert ax.get_yscale() == "log"
    # coinciding points stay visible: hollow markers, each rule's smaller than the one before
    points = [
        ln for ln in ax.get_lines() if ln.get_marker() not in ("None", None, "") and len(ln.get_xdata()) == 1
    ]
    assert points and all(ln.get_markerfacecolor() == "none" for ln in points)
    sizes = {ln.get_color(): ln.get_markersize() for ln in points}  # rule k is drawn in colour C<k>
    assert sizes == {f"C{k}": max(12.0 - 2.0 * k, 4.0) for k in range(len(sizes))} and len(sizes) >= 5


def test_cli_writes_table_json_plot_and_resumes(tmp_path, capsys):
    spec = tmp_path / "cmp.toml"
    spec.write_text(TOML)
    out = tmp_path / "out"
    serial = ["--executor", "serial", "--no-progress"]
    assert main(["compare", str(spec), "--out", str(out), *serial]) == 0
    printed = capsys.readouterr()
    assert "| dynamic | ideal | 2/2 |" in printed.out
    assert "[4/4] periodic / lossy: 2/2 runs completed" in printed.err
    for name in ("comparison.md", "comparison.json", "tradeoff.png", "spec.json"):
        assert (out / name).is_file()
    import pandas as pd

    for name in ("runs", "aggregate"):  # tidy tables, each CSV with its typed Parquet twin
        csv, parquet = pd.read_csv(out / f"{name}.csv"), pd.read_parquet(out / f"{name}.parquet")
        pd.testing.assert_frame_equal(parquet, csv, check_dtype=True)
    runs, agg = pd.read_parquet(out / "runs.parquet"), pd.read_parquet(out / "aggregate.parquet")
    assert list(runs.columns[:4]) == ["rule", "network", "run", "status"]
    assert len(runs) == 8 and runs.transmissions_node0.dtype == "int64"
    lossy = runs[runs.network == "lossy"]
    assert (lossy.packets_node0 >= lossy.not_applied_node0).all() and lossy.not_applied_node0.sum() > 0
    assert runs[runs.network == "ideal"].packets_node0.isna().all()
    assert list(zip(agg.rule, agg.network, agg.completed, strict=True)) == [
        ("dynamic", "ideal", 2),
        ("periodic", "ideal", 2),
        ("dynamic", "lossy", 2),
        ("periodic", "lossy", 2),
    ]
    table = {
        (r["rule"], r["network"]): r for r in json.loads((out / "comparison.json").read_text())["entries"]
    }
    for a in agg.itertuples():  # the same numbers as the JSON's entries
        assert a.transmissions_node0_mean == np.mean(
            np.array(table[(a.rule, a.network)]["transmissions"])[:, 0]
        )
    data = json.loads((out / "comparison.json").read_text())
    assert [e["rule"] for e in data["entries"]] == ["dynamic", "periodic", "dynamic", "periodic"]
    assert [e["runs"] for e in data["entries"]] == [[0, 1]] * 4
    chunks = sorted((out / "chunks").glob("*.json"))
    assert len(chunks) == 4  # one chunk of 2 runs per entry (chunk_size 20)
    # a rerun reuses every stored run and gives the same table
    before = (out / "comparison.md").read_text()
    assert main(["compare", str(spec), "--out", str(out), "--no-plot", *serial]) == 0
    err = capsys.readouterr().err
    assert "reused 8 of 8 runs finished earlier" in err and "[1/4]" not in err
    assert (out / "comparison.md").read_text() == before
    # an interrupted comparison (chunks missing) computes only what is missing
    chunks[0].unlink()
    chunks[3].unlink()
    assert main(["compare", str(spec), "--out", str(out), "--no-plot", "--chunk-size", "1", *serial]) == 0
    err = capsys.readouterr().err
    assert "reused 4 of 8 runs" in err and err.count("runs completed") == 2
    assert (out / "comparison.md").read_text() == before
    # more runs reuse the first ones
    assert main(["compare", str(spec), "--out", str(out), "--runs", "3", "--no-plot", *serial]) == 0
    assert "reused 8 of 12 runs" in capsys.readouterr().err


def test_cli_progress_bar_counts_runs_and_keeps_the_entry_lines_whole(tmp_path, capsys):
    spec = tmp_path / "cmp.toml"
    spec.write_text(TOML)
    assert (
        main(["compare", str(spec), "--out", str(tmp_path / "out"), "--executor", "serial", "--progress"])
        == 0
    )
    err = capsys.readouterr().err
    assert "oscillator: 100%" in err and "8/8" in err and "0 failed" in err
    # each entry's line is written through tqdm: the bar is cleared (\r), the line written whole
    assert re.search(r"\r\[4/4\] periodic / lossy: 2/2 runs completed in [0-9.]+ s \(engine\)\n", err)


def test_process_pool_and_dask_give_the_same_table(tmp_path, dask_cluster):
    spec = parse_compare_spec({**SPEC, "rules": SPEC["rules"][:2]})
    serial = compare(spec, tmp_path / "serial", executor="serial", chunk=2)
    pooled = compare(spec, tmp_path / "pool", executor="process", workers=2, chunk=1)
    dask = compare(spec, tmp_path / "dask", executor="dask", scheduler=dask_cluster.scheduler_address)
    assert serial.complete and pooled.complete and dask.complete
    assert serial.markdown() == pooled.markdown() == dask.markdown()
    assert (pooled.computed, dask.computed) == (spec.n_runs, spec.n_runs) == (12, 12)


def test_entries_that_differ_only_by_name_are_computed_once(tmp_path):
    rules = [{"name": "dynamic", "kind": "base"}, {"name": "the same", "kind": "base"}]
    spec = parse_compare_spec({**SPEC, "rules": rules, "networks": SPEC["networks"][:1]})
    res = compare(spec, tmp_path, executor="serial")
    assert res.complete and res.computed == 3
    np.testing.assert_array_equal(res.entries[0].transmissions, res.entries[1].transmissions)


def test_a_failing_chunk_is_reported_and_the_rest_runs(tmp_path, monkeypatch, capsys):
    import etobs.experiments.runner as runner
    from etobs import StaticRule

    spec = parse_compare_spec({**SPEC, "rules": SPEC["rules"][:2], "networks": SPEC["networks"][:1]})
    real = runner.simulate

    def flaky(problem, x0, *a, run_ids, **kw):
        if isinstance(problem.nodes[0].rule, StaticRule):
            raise RuntimeError("the static entry fails on purpose")
        return real(problem, x0, *a, run_ids=run_ids, **kw)

    monkeypatch.setattr(runner, "simulate", flaky)
    res = compare(spec, tmp_path, executor="serial", on_entry=lambda e: print(e.rule, len(e.runs)))
    assert not res.complete
    assert [len(e.runs) for e in res.entries] == [3, 0]
    assert capsys.readouterr().out.splitlines() == ["dynamic 3", "static 0"]
    assert len(res.failures) == 1 and res.failures[0]["where"] == "rule 'static' on network 'ideal'"
    md = res.markdown()
    assert "| static | ideal | 0/3 |" in md
    assert "Failed: rule 'static' on network 'ideal', runs 0..2: RuntimeError: the static entry fails" in md
    monkeypatch.setattr(runner, "simulate", real)
    again = compare(spec, tmp_path, executor="serial")
    assert again.complete and (again.computed, again.reused) == (3, 3)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"rules": []}, r"`rules` must be a non-empty array of tables"),
        ({"rules": [{"name": "x", "kind": "magic"}]}, r"`rules\[0\].kind` must be one of base, dynamic"),
        ({"rules": [{"name": "x", "kind": "periodic"}]}, r"missing key `rules\[0\].period`"),
        ({"rules": [{"name": "x", "kind": "static", "rho": 1}]}, r"unknown key `rules\[0\].rho`"),
        (
            {"rules": [{"name": "x", "kind": "base"}] * 2},
            r"`rules` names must be distinct; 'x' is used twice",
        ),
        (
            {"rules": [{"name": "x", "kind": "base", "observer_copy": 1}]},
            r"observer_copy` must be true or false",
        ),
        ({"rules": [{"name": "x", "kind": "static", "eps": "big"}]}, r"`rules\[0\].eps` must be a number"),
        ({"networks": [{"name": "n", "loss": 2.0}]}, r"`networks\[0\]\.loss` must be <= 1; got 2"),
        (
            {"networks": [{"name": "n", "delay": {"gamma": [1, 2]}}]},
            r"unknown key `networks\[0\].delay.gamma`",
        ),
        ({"networks": [{"name": "n", "delay": {"uniform": [1]}}]}, r"uniform` must be a list of 2 numbers"),
        ({"execution": {"backend": "gpu"}}, r"`execution.backend` must be one of"),
        ({"horizon": {"t_end": -1}}, r"`horizon.t_end` must be > 0"),
        # the tables shared with a sweep spec: the same parser, the same messages
        ({"name": "my rules"}, r"`name` must be a non-empty name of letters, digits, '_' or '-'"),
        ({"execution": {"chunk_size": 0}}, r"`execution.chunk_size` must be >= 1; got 0"),
        ({"system": {"factory": "robot_arm", "fixed": {}}}, r"unknown key `system.fixed`; allowed keys"),
        ({"metrics": {"error_window": [6.0, 9.0]}}, r"`metrics.error_window` must lie within \[0, horizon"),
        (
            {"initial_states": {"low": [0, 0], "high": [1, 1], "runs": 10**7, "seed": 1}},
            r"`rules` x `networks` \(14 groups\) x `initial_states.runs` = 10000000 \(or --runs\) make 1.4e\+08",
        ),
    ],
)
def test_spec_errors_name_the_key(change, message):
    with pytest.raises(SpecError, match=message):
        parse_compare_spec({**SPEC, **change})


def test_auto_backend_is_decided_per_entry_by_simulate(tmp_path):
    # the engine runs every entry, networks too; the entry records what ran
    spec = parse_compare_spec(
        {
            **SPEC,
            "initial_states": {"low": [-1.0, -1.0], "high": [1.0, 1.0], "runs": 2, "seed": 4},
            "horizon": {"t_end": 2.0},
            "metrics": {"error_window": [1.0, 2.0], "error_grid_step": 0.01},
            "execution": {"backend": "auto"},
            "rules": [{"name": "dynamic", "kind": "base"}],
        }
    )
    assert spec.backend == "auto"
    backends = {e.network: e.backend for e in compare(spec, tmp_path, executor="serial").entries}
    assert backends == {"ideal": "engine", "lossy": "engine"}
    engine_spec = parse_compare_spec({**SPEC, "execution": {"backend": "numba"}})
    assert engine_spec.backend == "engine"  # the earlier name


def test_rule_errors_at_run_time_name_the_entry_and_node(tmp_path):
    spec = parse_compare_spec({**SPEC, "rules": [{"name": "bad", "kind": "periodic", "period": [0.1, 0.2]}]})
    with pytest.raises(SpecError, match=r"`rules\[0\].period` has 2 values but the problem has 1 nodes"):
        compare(spec, tmp_path, executor="serial")
    rules = [{"name": "fine", "kind": "base"}, {"name": "neg", "kind": "relative", "rho": -1, "eps": 1}]
    spec = parse_compare_spec({**SPEC, "rules": rules})
    ran = []
    with pytest.raises(SpecError, match=r"`rules\[1\]`, node 0: `rho` must be > 0; got -1"):
        compare(spec, tmp_path, executor="serial", on_entry=ran.append)
    assert ran == []  # every entry is checked before the first one runs
    assert not list((tmp_path / "chunks").glob("*.json"))


def test_an_observer_initial_state_of_the_wrong_size_is_refused_before_any_run(tmp_path):
    # it was refused only when a worker began a chunk (runner.py), after the entries before it ran
    states = {**SPEC["initial_states"], "z0": [0.0, 0.0, 0.0]}
    spec = parse_compare_spec({**SPEC, "initial_states": states, "rules": SPEC["rules"][:2]})
    ran = []
    with pytest.raises(SpecError, match=r"^`initial_states.z0` has 3 entries but the observer has n_z = 2"):
        compare(spec, tmp_path, executor="serial", on_entry=ran.append)
    assert ran == [] and not list((tmp_path / "chunks").glob("*.json"))
    parse_compare_spec({**SPEC, "initial_states": {**states, "z0": [0.5, 0.0]}}).check()


def test_cli_bad_spec_exits_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["compare", str(tmp_path / "missing.toml")])
    assert exc.value.code == 2
    assert (
        "does not exist (SPEC is a TOML file or one of robot_arm, robot_arm_sampled)"
        in capsys.readouterr().err
    )


def test_packaged_robot_arm_spec_parses():
    from etobs.cli.compare import load

    spec = load("robot_arm")
    assert [r.kind for r in spec.rules][:2] == ["base", "static"]
    assert spec.networks[1].network.links[0].loss.p == 0.2
