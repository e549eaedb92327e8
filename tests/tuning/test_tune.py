"""A tuning end to end: certified front, pruning, screening, exported specs, resume after kill -9."""

import json
import math
import os
import re
import signal
import subprocess
import sys
import tomllib
from pathlib import Path

import pandas as pd
import pytest

from etobs.cli.main import main
from etobs.errors import InputError
from etobs.tuning import parse_tune_spec, tune
from etobs.tuning.evaluate import SimulatedFigures
from etobs.tuning.front import dominates
from etobs.tuning.tune import _clearly_out
from tests.tuning.conftest import BASE, raw_tune

pytestmark = [
    pytest.mark.usefixtures("cvxpy"),
    # a candidate with sigma*c >= 1 simulated (screen = false) warns in its chunk, as a sweep of it does
    pytest.mark.filterwarnings("ignore:.*Theorem 1 needs sigma_i c_i < 1:RuntimeWarning"),
]


def front_of(result):
    return [(r["transmissions_rate"], r["error"]) for r in result.front]


@pytest.fixture(scope="module")
def wide(tmp_path_factory):
    """sigma up to 2000 with c = 0.001: sigma*c >= 1 fails Theorem 1; simulated anyway (no screening)."""
    pytest.importorskip("cvxpy")
    raw = raw_tune(
        parameters={**BASE["parameters"], "sigma": {"low": 0.0, "high": 2000.0}},
        search={**BASE["search"], "trials": 16, "screen": False, "prune_share": 0.0},
        # a known design that fails Theorem 1 (sigma*c = 1.5), and a good one
        references=[
            {"name": "row 8", "params": {"a": [1.0, 1.0]}},
            {
                "name": "sigma*c > 1",
                "params": {"sigma": [1500.0, 1500.0], "eps": [1.0, 1.0], "a": [1.0, 1.0]},
            },
        ],
    )
    out = tmp_path_factory.mktemp("wide")
    return tune(parse_tune_spec(raw), out, executor="serial", progress=False)


def test_a_candidate_that_fails_a_condition_is_never_on_the_front(wide):
    failing = [r for r in wide.trials if r["evaluated"] == "full" and not r["certified"]]
    assert failing, "the box must hold candidates with sigma*c >= 1 for this test to mean anything"
    assert all("sigma*c < 1 (Theorem 1)" in r["cert_failures"] for r in failing)
    assert all(max(r["sigma1"], r["sigma2"]) >= 1000 for r in failing)
    assert wide.front
    for r in wide.front:
        assert r["certified"] and r["feasible"]
        assert all(r[k] <= 0 for k in r if k.startswith("constraint_"))
        assert r["error"] <= 12.0
        # certified under what the certificate did not check, said on the row
        assert r["cert_assumptions"].startswith("solutions are complete")
        assert "E = (30, 60) bounds |dh_i/dx f_p|" in r["cert_assumptions"]


def test_the_front_is_the_non_dominated_feasible_trials(wide):
    feasible = [(r["transmissions_rate"], r["error"]) for r in wide.trials if r["feasible"]]
    front = front_of(wide)
    assert all(not dominates(p, f) for f in front for p in feasible)
    for p in feasible:
        assert p in front or any(dominates(f, p) or f == p for f in front)
    assert front == sorted(front)


def test_the_trial_count_is_the_one_asked_for_and_the_start_and_references_are_trials(wide):
    assert len(wide.trials) == 16
    # the start design (a = (2, 3)) is not in the space (a shared): the references in it come first
    assert [r["design"] for r in wide.trials[:3]] == ["row 8", "sigma*c > 1", ""]
    row8 = wide.trials[0]
    assert (row8["sigma1"], row8["sigma2"], row8["eps1"], row8["a1"], row8["a2"]) == (
        600.0,
        800.0,
        10.0,
        1.0,
        1.0,
    )
    ref = {r["name"]: r for r in wide.references}
    assert list(ref) == ["start", "row 8", "sigma*c > 1"]
    # a reference and the trial of the same design: the same runs, the same figures
    assert ref["row 8"]["transmissions_rate"] == row8["transmissions_rate"]
    assert ref["row 8"]["error"] == row8["error"]
    assert not ref["sigma*c > 1"]["certified"] and ref["start"]["certified"]


def test_the_tables_and_specs_are_written(wide):

    for name in ("trials", "front", "references"):
        csv = pd.read_csv(wide.out / f"{name}.csv")
        parquet = pd.read_parquet(wide.out / f"{name}.parquet")
        assert len(csv) == len(parquet) == len(getattr(wide, name))
    assert list(wide.to_pandas("front")["trial"]) == [r["trial"] for r in wide.front]
    with pytest.raises(InputError, match=r"`table` must be one of front, trials, references; got 'runs'"):
        wide.to_pandas("runs")
    summary = json.loads((wide.out / "tuning.json").read_text())
    assert summary["trials"] == 16 and summary["front"] == len(wide.front)


def test_every_front_point_has_held_out_figures(wide):
    for r in wide.front:
        assert r["holdout_runs"] == 3
        assert math.isfinite(r["holdout_error"]) and math.isfinite(r["holdout_transmissions_rate"])
        assert r["holdout_over_budget"] == (r["holdout_error"] > 12.0)


def test_the_exported_specs_certify_and_reproduce_the_figures(wide, tmp_path, capsys):
    r = wide.front[0]
    assert main(["check", r["check_spec"]]) == 0
    assert "certificate: all conditions hold" in capsys.readouterr().out
    assert main(["sweep", r["sweep_spec"], "--out", str(tmp_path / "s"), "--executor", "serial"]) == 0
    agg = pd.read_csv(tmp_path / "s" / "aggregate.csv").iloc[0]
    assert agg["transmissions_mean"] == r["transmissions_mean"]
    assert agg["error_mean"] == r["error_mean"]
    spec = tomllib.loads(Path(r["sweep_spec"]).read_text())
    assert spec["rows"][0]["sigma"] == [r["sigma1"], r["sigma2"]]


def test_screened_candidates_are_not_simulated(tmp_path):
    raw = raw_tune(
        parameters={**BASE["parameters"], "sigma": {"low": 1100.0, "high": 2000.0}},
        search={**BASE["search"], "trials": 4},
        references=[],
    )
    res = tune(parse_tune_spec(raw), tmp_path, executor="serial", progress=False)
    assert [r["evaluated"] for r in res.trials] == ["screened"] * 4  # no start: 600 is outside the box
    assert all(r["runs"] == 0 and r["transmissions_rate"] is None for r in res.trials)
    assert res.front == [] and res.saved_runs == 16


def test_pruned_candidates_broke_the_budget_by_the_margin_on_their_first_runs(tmp_path):
    raw = raw_tune(
        budget={"kind": "simulated", "error": 6.0},
        search={**BASE["search"], "trials": 12, "prune_share": 0.5, "prune_z": 1.0},
        initial_states={**BASE["initial_states"], "runs": 10},
    )
    res = tune(parse_tune_spec(raw), tmp_path, executor="serial", progress=False)
    pruned = [r for r in res.trials if r["evaluated"] == "pruned"]
    assert pruned, "the budget must prune some candidates for this test to mean anything"
    assert res.saved_runs == 5 * len(pruned)
    for r in pruned:
        assert r["runs"] == 5  # half of 10
        # over the budget by one standard error of its two runs' mean, or then beaten by the front:
        # the feasible trials of the batches before its own (batches of 4), less one standard error
        before = [
            (f["transmissions_rate"], f["error"])
            for f in res.trials
            if f["feasible"] and f["trial"] < r["trial"] // 4 * 4
        ]
        tx, err = r["transmissions_rate"] - r["transmissions_se"], r["error"] - r["error_se"]
        assert err > 6.0 or any(p[0] <= tx and p[1] <= err for p in before)
    for r in res.trials:
        if r["evaluated"] == "full":
            assert r["runs"] == 10


def test_no_candidate_is_pruned_on_fewer_than_five_runs(tmp_path):
    # the same tuning on 9 runs: a first share of 4.5 -> 5 runs may prune, of 8 -> 4 runs may not
    raw = raw_tune(
        budget={"kind": "simulated", "error": 6.0},
        search={**BASE["search"], "trials": 8, "prune_share": 0.5, "prune_z": 1.0},
        initial_states={**BASE["initial_states"], "runs": 9},
    )
    five = tune(parse_tune_spec(raw), tmp_path / "five", executor="serial", progress=False)
    assert any(r["evaluated"] == "pruned" and r["runs"] == 5 for r in five.trials)
    raw["initial_states"]["runs"] = 8
    four = tune(parse_tune_spec(raw), tmp_path / "four", executor="serial", progress=False)
    assert all(r["evaluated"] == "full" and r["runs"] == 8 for r in four.trials)
    assert four.saved_runs == 0


def test_another_tuning_in_the_same_folder_is_refused(tmp_path):
    spec = parse_tune_spec(raw_tune(search={**BASE["search"], "trials": 1}))
    tune(spec, tmp_path, executor="serial", progress=False)
    other = parse_tune_spec(raw_tune(search={**BASE["search"], "trials": 1, "seed": 4}))
    with pytest.raises(InputError, match=r"the study 'arm' in .* holds the trials of another tuning"):
        tune(other, tmp_path, executor="serial", progress=False)


@pytest.mark.parametrize(
    ("over", "says"),
    [
        (
            {"budget": {"kind": "simulated", "error": 1e-6}},
            r"trial (\d+): its error [\d.]+ is over the budget 1e-06",
        ),
        (
            {"budget": {"kind": "certified", "error": 1e-9}},
            r"trial (\d+): its certified bound [\d.e+]+ is over the budget 1e-09",
        ),
        (
            {"constraints": {"tau_min": 100.0}},
            r"trial (\d+): its tau_i \([\d., ]+ s\) fall short of constraints.tau_min",
        ),
    ],
    ids=["simulated budget", "certified budget", "tau_min"],
)
def test_a_budget_no_candidate_meets_is_one_line(over, says, tmp_path, capsys):
    import tomli_w

    path = tmp_path / "tune.toml"
    path.write_text(tomli_w.dumps(raw_tune(**over, search={**BASE["search"], "trials": 4})))
    code = main(["tune", str(path), "--out", str(tmp_path / "o"), "--executor", "serial", "--no-plot"])
    out = capsys.readouterr()
    assert code == 1
    assert out.err.count("\n") == 1
    assert out.err.startswith(
        "etobs: no candidate of 4 met every constraint: the certified candidate nearest, "
    )
    found = re.search(says, out.err)
    assert found, out.err
    # the nearest: the certified trial that misses its constraints by the least
    rows = pd.read_csv(tmp_path / "o" / "trials.csv")
    rows = rows[rows.certified]
    missed = rows.filter(like="constraint_").clip(lower=0).fillna(0).sum(axis=1)
    assert int(found[1]) == int(rows.trial[missed.idxmin()])


KILLER = """
import os, signal, sys, json
from etobs.tuning import parse_tune_spec, tune

def main():
    raw = json.loads(sys.argv[1])
    def kill(row):
        if row.row["trial"] == int(sys.argv[3]):
            os.kill(os.getpid(), signal.SIGKILL)  # kill -9 in the middle of a batch
    tune(parse_tune_spec(raw), sys.argv[2], executor="serial", progress=False, on_trial=kill)

if __name__ == "__main__":
    main()
"""


def test_a_tuning_killed_with_sigkill_resumes_to_the_same_front(tmp_path):
    raw = raw_tune(search={**BASE["search"], "trials": 12})
    whole = tune(parse_tune_spec(raw), tmp_path / "whole", executor="serial", progress=False)
    script = tmp_path / "killer.py"
    script.write_text(KILLER)
    out = tmp_path / "killed"
    proc = subprocess.run(
        [sys.executable, str(script), json.dumps(raw), str(out), "5"],
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ},
    )
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    import optuna

    study = optuna.load_study(study_name="arm", storage=f"sqlite:///{out / 'study.db'}")
    states = [t.state.name for t in study.trials]
    assert len(states) == 8 and states[6:] == ["RUNNING", "RUNNING"]  # 6, 7: simulated, never told
    assert all(s in ("COMPLETE", "PRUNED") for s in states[:6])
    chunks = {p: p.stat().st_mtime_ns for p in (out / "runs").rglob("*") if p.is_file() and p.name != ".lock"}
    resumed = tune(parse_tune_spec(raw), out, executor="serial", progress=False)
    key = lambda rows: [(r["trial"], r["state"], r["transmissions_rate"], r["error"]) for r in rows]  # noqa: E731
    assert key(resumed.trials) == key(whole.trials)
    assert front_of(resumed) == front_of(whole)
    assert len(optuna.load_study(study_name="arm", storage=f"sqlite:///{out / 'study.db'}").trials) == 12
    # no run computed twice: every chunk stored before the kill is read back, none written again
    assert all(p.stat().st_mtime_ns == t for p, t in chunks.items())


def test_a_candidate_is_clearly_out_at_z_standard_errors_on_both_sides():
    spec = parse_tune_spec(raw_tune(search={**BASE["search"], "prune_z": 2.0}))  # budget 12

    def fig(tx, err, se_tx=0.1, se_err=0.5):
        return SimulatedFigures(4, 4, tx, err, tx * 60, err, se_tx, se_err)

    assert _clearly_out(fig(1.0, 13.0 + 1e-9), [], spec)  # 13 - 2 x 0.5 > 12
    assert not _clearly_out(fig(1.0, 13.0), [], spec)
    front = [(1.0, 5.0)]
    assert _clearly_out(fig(1.2 + 1e-9, 6.0 + 1e-9), front, spec)  # 1.2 - 0.2 >= 1, 6 - 1 >= 5
    assert not _clearly_out(fig(1.2 - 1e-9, 8.0), front, spec)
    assert not _clearly_out(fig(3.0, 6.0 - 1e-9), front, spec)


def test_the_observer_is_a_variable_of_the_search_with_two_observers(tmp_path, capsys):
    paper = {"structure": "robot_arm", "L": "paper", "c_v": 0.1, "c": [0.1, 0.1]}
    lmi = {"structure": "robot_arm", "L": "design", "c_v": 0.1, "c": [0.1, 0.1]}
    raw = raw_tune(
        observer=None,
        observers=[{"name": "paper", **paper}, {"name": "lmi", **lmi}],
        search={**BASE["search"], "trials": 8, "prune_share": 0.0},
        budget={"kind": "simulated", "error": 100.0},
    )
    spec = parse_tune_spec(raw)
    res = tune(spec, tmp_path, executor="serial", progress=False)
    assert {r["observer"] for r in res.trials if r["evaluated"] == "full"} == {"paper", "lmi"}
    from etobs.examples.robot_arm import L_PAPER

    for r in res.front:
        check = tomllib.loads(Path(r["check_spec"]).read_text())
        sweep = tomllib.loads(Path(r["sweep_spec"]).read_text())
        assert check["observer"] == (paper if r["observer"] == "paper" else lmi)
        # simulated with the chosen observer's gain: the paper's, or the LMI design's (another)
        L = sweep["rows"][0]["L"]
        assert (L == L_PAPER.tolist()) == (r["observer"] == "paper")
        assert main(["check", r["check_spec"]]) == 0
    # every trial was simulated with its own observer's L: its runs are stored under that L's key
    from etobs.experiments.spec import parse_spec
    from etobs.experiments.store import ResultStore, task_key
    from etobs.tuning.evaluate import Evaluator

    ev, store = Evaluator(spec, None, {}), ResultStore(tmp_path / "runs")
    assert ev.gains["paper"][1] != ev.gains["lmi"][1]
    for r in res.trials:
        if r["evaluated"] != "full":
            continue
        kwargs = {k: [r[f"{k}1"], r[f"{k}2"]] for k in ("sigma", "eps", "a")}
        stored = {
            name: len(store.records(task_key(parse_spec(spec.sweep_raw([{**kwargs, "L": g[1]}])), 0), 4))
            for name, g in ev.gains.items()
        }
        assert stored == {name: 4 if name == r["observer"] else 0 for name in ev.gains}


def test_the_same_trials_on_a_dask_cluster_and_in_this_process(tmp_path, dask_cluster):
    from dask.distributed import Client

    raw = raw_tune(search={**BASE["search"], "trials": 6})
    serial = tune(parse_tune_spec(raw), tmp_path / "serial", executor="serial", progress=False)
    with Client(dask_cluster) as client:
        dask = tune(parse_tune_spec(raw), tmp_path / "dask", executor="dask", client=client, progress=False)
    key = lambda rows: [(r["trial"], r["state"], r["transmissions_rate"], r["error"]) for r in rows]  # noqa: E731
    assert key(dask.trials) == key(serial.trials)
    assert front_of(dask) == front_of(serial)


def test_two_output_folders_share_one_study_through_a_storage_url(tmp_path):
    import optuna

    url = f"sqlite:///{tmp_path / 'shared.db'}"
    raw = raw_tune(search={**BASE["search"], "trials": 4})
    first = tune(parse_tune_spec(raw), tmp_path / "a", executor="serial", progress=False, storage=url)
    assert len(first.trials) == 4 and not (tmp_path / "a" / "study.db").exists()
    # another machine's trial, asked and still running: not this one's to evaluate
    study = optuna.load_study(study_name="arm", storage=url)
    other = study.ask()
    other.set_user_attr("worker", "elsewhere:/out")
    second = tune(
        parse_tune_spec(raw), tmp_path / "b", trials=8, executor="serial", progress=False, storage=url
    )
    states = [r["state"] for r in second.trials]
    assert len(states) == 8 and states[4] == "running"  # counted, left to its machine
    assert [r["trial"] for r in second.trials[:4]] == [r["trial"] for r in first.trials]
    assert all(s in ("complete", "pruned") for i, s in enumerate(states) if i != 4)


@pytest.mark.parametrize(
    ("over", "message"),
    [
        (
            {"guarantees": {"E": [30.0], "noise": [0.0, 0.01], "disturbance": 0.0283}},
            r"the start design \(the factory with `system.fixed`\) cannot be certified: `guarantees.E` must be one bound "
            r"or one per node \(2\); got 1",
        ),
        (
            {"constraints": {"tau_min": [0.01, 0.01, 0.01]}},
            r"`constraints.tau_min` must be one number or one per node \(2\); got 3",
        ),
    ],
    ids=["E of the wrong length", "tau_min of the wrong length"],
)
def test_a_mistake_seen_only_when_certifying_is_refused_before_any_trial(over, message, tmp_path):
    spec = parse_tune_spec(raw_tune(**over))
    with pytest.raises(InputError, match=message):
        tune(spec, tmp_path, executor="serial", progress=False)
    assert not (tmp_path / "study.db").exists()  # nothing asked: fixed, the spec runs in this folder


def test_a_factory_that_needs_a_searched_argument_is_told_to_give_it_a_default(tmp_path):
    factory = tmp_path / "needs.py"
    factory.write_text(
        "import etobs\nfrom etobs.examples import robot_arm\n\n\n@etobs.factory\n"
        "def arm(eps, noise=True):\n    return robot_arm(eps=eps, noise=noise)\n"
    )
    raw = raw_tune(
        system={"factory": f"{factory}:arm", "fixed": {}},
        parameters={"eps": BASE["parameters"]["eps"]},
        references=[],
    )
    spec = parse_tune_spec(raw)
    with pytest.raises(
        InputError, match=r"the factory .* needs `eps`, which `parameters` searches: .* default"
    ):
        tune(spec, tmp_path / "o", executor="serial", progress=False)


def test_a_storage_that_cannot_hold_the_study_is_one_error(tmp_path):
    spec = parse_tune_spec(raw_tune())
    with pytest.raises(InputError, match=r"`storage` \(--storage\) 'foo://bar' cannot hold the study"):
        tune(spec, tmp_path, executor="serial", progress=False, storage="foo://bar")


def test_a_shared_study_resumes_a_trial_killed_between_its_ask_and_its_mark(tmp_path):
    import socket

    import optuna

    url = f"sqlite:///{tmp_path / 'shared.db'}"
    raw = raw_tune(search={**BASE["search"], "trials": 4}, references=[])
    whole = tune(parse_tune_spec(raw), tmp_path / "whole", executor="serial", progress=False)
    # what a kill leaves between ask and the worker mark: the intent, then a running trial unmarked
    tune(parse_tune_spec(raw), tmp_path / "b", trials=1, executor="serial", progress=False, storage=url)
    study = optuna.load_study(study_name="arm", storage=url)
    study.set_user_attr(f"asking:{socket.gethostname()}:{(tmp_path / 'b').resolve()}", 1)
    from etobs.tuning.space import distributions
    from etobs.tuning.tune import _seed

    study.sampler = optuna.samplers.TPESampler(seed=_seed(3, 1), n_startup_trials=4, multivariate=True)
    study.ask(distributions(parse_tune_spec(raw), 2))
    resumed = tune(parse_tune_spec(raw), tmp_path / "b", executor="serial", progress=False, storage=url)
    assert [r["state"] for r in resumed.trials] == [r["state"] for r in whole.trials]
    assert [r["trial"] for r in resumed.trials] == [0, 1, 2, 3]
    assert all(r["state"] in ("complete", "pruned") for r in resumed.trials)


def test_the_front_plot_draws_what_it_says(wide):
    pytest.importorskip("matplotlib")
    from etobs.plot import plot_front

    fig, ax = plot_front(wide)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert f"front ({len(wide.front)})" in labels
    assert "budget 12" in labels
    full = [r for r in wide.trials if r["evaluated"] == "full" and not r["certified"]]
    assert f"not certified ({len(full)})" in labels
    assert "sigma*c > 1 (not certified)" in labels and "row 8" in labels
    assert f"{len(wide.trials)} trials, {len(wide.front)} on the front" in fig._suptitle.get_text()


@pytest.mark.parametrize("trials", [0, -1, 2.5, True])
def test_a_bad_trial_count_is_refused_naming_it(trials, tmp_path):
    with pytest.raises(InputError, match=rf"`trials` must be a positive integer; got {trials!r}"):
        tune(parse_tune_spec(raw_tune()), tmp_path / "o", trials=trials, executor="serial", progress=False)
    assert not (tmp_path / "o").exists()
