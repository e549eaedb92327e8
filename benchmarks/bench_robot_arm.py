"""Benchmark: robot-arm runs with the engine against the scipy backend.

The two backends of ``simulate`` run the paper's robot arm (section 8), written once
for one run (``etobs.examples.robot_arm``), from the same random initial states:
``backend="engine"`` (compiled, 16 runs side by side per thread) and ``"scipy"`` (``solve_ivp``, the
Python functions as written). The figures that matter are the per-run time ratio,
measured in one process on the same runs (these machines are shared and noisy, so
absolute times vary).

    python benchmarks/bench_robot_arm.py            # 100 engine runs, 3 scipy runs, 30 s
    python benchmarks/bench_robot_arm.py --quick    # CI smoke: 10 engine runs, 1 scipy, 5 s

Each backend's first solve in the process (compile, or load from the disk cache) is
timed apart from the measured runs; without ``--quick`` the engine's first solve is also
timed in fresh processes, with an empty and with a filled disk cache.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from _agree import expect, status
from _ready import ready
from etobs import SaveAt, SolverOptions, simulate
from etobs.estimation import transmission_counts
from etobs.examples import random_initial_states, robot_arm

BACKENDS = ("engine", "scipy")


def timed(fn):
    start = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - start


def agreement(a, b) -> tuple[bool, float]:
    """Whether two results send the same transmissions, and the largest event-time gap."""
    same = np.array_equal(transmission_counts(a), transmission_counts(b))
    return same, (float(np.max(np.abs(a.transmissions.t - b.transmissions.t))) if same else float("nan"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes for CI")
    parser.add_argument("--runs", type=int, default=None, help="engine runs (default 100)")
    parser.add_argument("--ref-runs", type=int, default=None, help="scipy-backend runs (default 3)")
    parser.add_argument("--t-end", type=float, default=None, help="horizon (default 30 s)")
    args = parser.parse_args()
    runs = args.runs or (10 if args.quick else 100)
    ref_runs = min(args.ref_runs or (1 if args.quick else 3), runs)
    t_end = args.t_end or (5.0 if args.quick else 30.0)

    pb = robot_arm()
    x0 = random_initial_states(runs, seed=1)
    opts = SolverOptions()  # rtol = atol = 1e-10, the defaults
    save = SaveAt(steps=False)

    def run(backend: str, x: np.ndarray, horizon: float = t_end):
        return simulate(pb, x, horizon, options=opts, save=save, backend=backend)

    print(f"robot arm, horizon {t_end:g} s, rtol = atol = {opts.rtol:g}, {_threads()} engine threads")
    first = {b: timed(lambda b=b: run(b, x0[:1], 0.01))[1] for b in ("engine",)}
    for b, t in first.items():
        print(
            f"{b:6} backend, first solve in this process: {t:8.2f} s (compile, or load from the disk cache)"
        )
    if not args.quick:
        for label, cold in (("compile with an empty disk cache", True), ("load from the disk cache", False)):
            print(f"engine backend, fresh process, {label}: {_first_solve(cold):8.2f} s")

    res, secs = {}, {}
    ready(pb)  # the lane form too (the first solve above does not wait for it)
    res["engine"], secs["engine"] = timed(lambda: run("engine", x0))
    res["scipy"], secs["scipy"] = timed(lambda: run("scipy", x0[:ref_runs]))
    per_run = {"engine": secs["engine"] / runs, "scipy": secs["scipy"] / ref_runs}
    for b, n in (("engine", runs), ("scipy", ref_runs)):
        label = f"{b} backend, {n} runs:"
        print(f"{label:28} {secs[b]:8.2f} s total, {secs[b] / n * 1e3:8.1f} ms/run")
    print(f"ratio per run: scipy/engine {per_run['scipy'] / per_run['engine']:.1f}x")
    sub_engine = run("engine", x0[:ref_runs])
    same_es, gap_es = agreement(sub_engine, res["scipy"])
    expect(same_es, f"robot arm: engine and scipy transmission counts on {ref_runs} runs")
    print(f"transmissions: mean {transmission_counts(res['engine']).sum(1).mean():.1f} per run")
    print(
        f"engine and scipy agree on the shared {ref_runs} runs: {same_es}, max event-time gap {gap_es:.2e} s"
    )
    statuses = {b: sorted(set(res[b].status_labels())) for b in BACKENDS}
    print(f"statuses: {statuses}; backends that ran: {[res[b].backend for b in BACKENDS]}")


def _first_solve(cold: bool) -> float:
    """Time of a first robot-arm solve on the engine in a new process, empty or filled disk cache."""
    import os
    import subprocess
    import sys
    import tempfile

    code = (
        "import time; from etobs import SaveAt, simulate; from etobs.examples import robot_arm; "
        "t = time.perf_counter(); "
        "simulate(robot_arm(), [3, 2, 3, -2], 0.01, save=SaveAt(steps=False), backend='engine'); "
        "print(time.perf_counter() - t)"
    )
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "ETOBS_CACHE_DIR": tmp}
        runs = [
            subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
        ]
        if not cold:
            runs.append(
                subprocess.run(
                    [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
                )
            )
        return float(runs[-1].stdout.split()[-1])


def _threads() -> int:
    import numba

    return numba.get_num_threads()


if __name__ == "__main__":
    main()
    raise SystemExit(status())
