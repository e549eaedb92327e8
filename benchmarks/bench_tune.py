"""Benchmark: certified tuning of the robot arm (``etobs tune robot_arm``), timed, and a kill -9 resume.

The packaged spec (``src/etobs/tuning/data/robot_arm_tune.toml``): the robot arm with v and
m, Table 1's parameters and eta(0) per node in a box, the budget of Table 1 row 1 on the
simulated error (8.15, as ``etobs reproduce table1`` simulates row 1 on these 100 runs),
Theorems 1 and 4 and section 7.2 as hard constraints. Printed, from one run:

- the wall time of the search (trials x runs) and of the validation (front and
  references on held-out runs), and the runs pruning and screening did not simulate;
- the best certified design's transmissions against Table 1 row 1's on the same runs
  (a ratio), and both on the held-out runs, with the budget check there.

``--kill SECONDS`` also runs the same tuning (``--trials``) as ``etobs tune`` in a child
process, kills it with SIGKILL after that many seconds, reruns the command in the same
folder, and compares the front and every trial with an uninterrupted tuning.

    python benchmarks/bench_tune.py                   # 200 trials x 100 runs (minutes)
    python benchmarks/bench_tune.py --quick           # CI smoke: 8 trials x 4 runs of 5 s
    python benchmarks/bench_tune.py --trials 40 --kill 20
"""

from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import tempfile
import time
import tomllib
from importlib import resources
from pathlib import Path

import tomli_w

from etobs.tuning import parse_tune_spec, tune


def packaged() -> dict:
    data = resources.files("etobs.tuning").joinpath("data", "robot_arm_tune.toml").read_bytes()
    return tomllib.loads(data.decode())


def quick(raw: dict) -> dict:
    raw["search"].update(trials=8, startup=4)
    raw["initial_states"]["runs"] = 4
    raw["validation"]["runs"] = 4
    raw["horizon"]["t_end"] = 5.0
    raw["metrics"] = {"error_window": [4.0, 5.0], "transmissions_window": [0.0, 5.0], "error_grid_step": 0.01}
    raw["guarantees"] = {"E": [30.0, 60.0], "noise": [0.0, 0.01], "disturbance": 0.0283}
    raw["budget"]["error"] = 20.0
    return raw


def search(raw: dict, out: Path, trials: int) -> None:
    spec = parse_tune_spec(raw)
    t0 = time.perf_counter()
    timing = {}

    def told(row):  # the last call ends the search; validation follows
        timing["search"] = time.perf_counter() - t0

    res = tune(spec, out, trials=trials, progress=False, on_trial=told)
    wall = time.perf_counter() - t0
    runs = spec.runs
    print(
        f"search: {trials} trials x {runs} runs in {timing['search']:.1f} s wall "
        f"({trials * runs / timing['search']:.0f} runs/s asked); validation and outputs "
        f"{wall - timing['search']:.1f} s; total {wall:.1f} s"
    )
    print(
        f"runs not simulated: {res.saved_runs} of {trials * runs} "
        f"({100 * res.saved_runs / (trials * runs):.1f} %: screened by the certificate or pruned after "
        f"{spec.search.prune_share:g} of the runs)"
    )
    counts = {}
    for r in res.trials:
        counts[r["evaluated"]] = counts.get(r["evaluated"], 0) + 1
    print(f"trials: {counts}; feasible {sum(r['feasible'] for r in res.trials)}; front {len(res.front)}")
    refs = {r["name"]: r for r in res.references}
    row1 = refs.get("Table 1 row 1")
    if not res.front:
        print("no certified design within the budget")
        return
    best = res.front[0]
    print(
        f"best certified design (trial {best['trial']}): {best['transmissions_mean']:.1f} transmissions per run, "
        f"error {best['error']:.4g} (budget {spec.budget.error:g}); held out: "
        f"{best['holdout_transmissions_mean']:.1f}, error {best['holdout_error']:.4g}"
        f"{'  OVER BUDGET' if best['holdout_over_budget'] else ''}"
    )
    params = {
        k: round(v, 4) if isinstance(v, float) else v
        for k, v in best.items()
        if k[:-1] in ("sigma", "eps", "a", "ell", "eta0")
    }
    print(f"  parameters: {params}")
    if row1 is not None:
        ratio = row1["transmissions_mean"] / best["transmissions_mean"]
        held = row1["holdout_transmissions_mean"] / best["holdout_transmissions_mean"]
        print(
            f"Table 1 row 1 on the same runs: {row1['transmissions_mean']:.1f} transmissions, error "
            f"{row1['error']:.4g}; held out {row1['holdout_transmissions_mean']:.1f}, {row1['holdout_error']:.4g}"
        )
        print(f"ratio row 1 / best: {ratio:.2f}x on the tuning's runs, {held:.2f}x on the held-out runs")


def kill_and_resume(raw: dict, trials: int, after: float, folder: Path) -> None:
    spec_file = folder / "tune.toml"
    spec_file.write_text(tomli_w.dumps(raw))
    cmd = [
        sys.executable,
        "-m",
        "etobs",
        "tune",
        str(spec_file),
        "--trials",
        str(trials),
        "--no-plot",
        "--no-progress",
    ]
    whole, killed = folder / "whole", folder / "killed"
    subprocess.run([*cmd, "--out", str(whole)], check=True, capture_output=True)
    proc = subprocess.Popen(
        [*cmd, "--out", str(killed)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    time.sleep(after)
    import os

    os.killpg(proc.pid, signal.SIGKILL)  # the command and its worker processes
    proc.wait()
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.load_study(study_name=raw["name"], storage=f"sqlite:///{killed / 'study.db'}")
    states = [t.state.name for t in study.trials]
    print(
        f"killed after {after:g} s: {len(states)} trials on disk, {states.count('RUNNING')} running, "
        f"{sum(s != 'RUNNING' for s in states)} told"
    )
    subprocess.run([*cmd, "--out", str(killed)], check=True, capture_output=True)
    study = optuna.load_study(study_name=raw["name"], storage=f"sqlite:///{killed / 'study.db'}")
    a = json.loads((whole / "tuning.json").read_text())
    b = json.loads((killed / "tuning.json").read_text())
    fa = (whole / "front.csv").read_text()
    fb = (killed / "front.csv").read_text().replace(str(killed), str(whole))
    ta = (whole / "trials.csv").read_text()
    tb = (killed / "trials.csv").read_text()
    print(
        f"after the rerun: {len(study.trials)} trials on disk (asked {trials}); front {b['front']} points "
        f"against {a['front']}; front table identical: {fa == fb}; trials table identical: {ta == tb}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes for CI")
    parser.add_argument("--trials", type=int, default=None, help="trials (default: the spec's 200)")
    parser.add_argument("--kill", type=float, default=None, help="kill -9 the tuning after this many seconds")
    args = parser.parse_args()
    raw = packaged()
    if args.quick:
        raw = quick(raw)
    trials = args.trials or raw["search"]["trials"]
    with tempfile.TemporaryDirectory() as tmp:
        search(raw, Path(tmp) / "tune", trials)
        if args.kill is not None:
            kill_and_resume(raw, trials, args.kill, Path(tmp))


if __name__ == "__main__":
    main()
