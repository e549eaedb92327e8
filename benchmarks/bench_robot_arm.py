"""Benchmark: robot-arm runs with the fast and compiled solvers against the scipy backend.

The solvers simulate the paper's robot arm (section 7) from the same random initial
states; the figure that matters is the per-run time ratio, measured in one process on
the same runs (these machines are shared and noisy, so absolute times vary).

    python benchmarks/bench_robot_arm.py            # 100 fast/numba runs, 3 scipy runs, 30 s
    python benchmarks/bench_robot_arm.py --quick    # CI smoke: 10 fast, 1 scipy, 5 s

The compiled (numba) backend is measured when numba is installed: its compile time (in
a fresh process with an empty disk cache, and the load from a filled one), then the
same runs as the fast solver.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from etobs import SaveAt, SolverOptions, simulate
from etobs.estimation import transmission_counts
from etobs.examples import random_initial_states, robot_arm


def timed(fn):
    start = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes for CI")
    parser.add_argument("--runs", type=int, default=None, help="fast-solver runs (default 100)")
    parser.add_argument("--ref-runs", type=int, default=None, help="scipy-backend runs (default 3)")
    parser.add_argument("--t-end", type=float, default=None, help="horizon (default 30 s)")
    args = parser.parse_args()
    runs = args.runs or (10 if args.quick else 100)
    ref_runs = args.ref_runs or (1 if args.quick else 3)
    t_end = args.t_end or (5.0 if args.quick else 30.0)

    pb = robot_arm()
    x0 = random_initial_states(runs, seed=1)
    opts = SolverOptions()  # rtol = atol = 1e-10, the defaults
    save = SaveAt(steps=False)
    fast, t_fast = timed(lambda: simulate(pb, x0, t_end, options=opts, save=save))
    sub, t_fast_sub = timed(lambda: simulate(pb, x0[:ref_runs], t_end, options=opts, save=save))
    ref, t_ref = timed(lambda: simulate(pb, x0[:ref_runs], t_end, options=opts, save=save, backend="scipy"))

    same = np.array_equal(transmission_counts(sub), transmission_counts(ref))
    worst = np.max(np.abs(sub.transmissions.t - ref.transmissions.t)) if same else float("nan")
    print(f"robot arm, horizon {t_end:g} s, rtol = atol = {opts.rtol:g}")
    print(f"fast solver, {runs} runs in one batch: {t_fast:8.2f} s total, {t_fast / runs * 1e3:8.1f} ms/run")
    print(
        f"fast solver, {ref_runs} runs in one batch:  {t_fast_sub:8.2f} s total, "
        f"{t_fast_sub / ref_runs * 1e3:8.1f} ms/run"
    )
    print(
        f"scipy backend, {ref_runs} runs:              {t_ref:8.2f} s total, {t_ref / ref_runs * 1e3:8.1f} ms/run"
    )
    print(
        f"ratio scipy/fast per run: {t_ref / ref_runs / (t_fast / runs):.1f}x "
        f"(batch of {runs}), {t_ref / t_fast_sub:.1f}x (same {ref_runs} runs)"
    )
    print(
        f"transmissions: mean {transmission_counts(fast).sum(1).mean():.1f} per run; "
        f"scipy and fast agree on the shared runs: {same}, max event-time gap {worst:.2e} s"
    )
    print(f"statuses: {sorted(set(fast.status_labels()))}")
    from etobs.hybrid.compiled import numba_available

    if not numba_available():
        print("numba backend: not installed (pip install 'etobs[numba]')")
        return
    _, t_compile = timed(lambda: simulate(pb, x0[:1], 0.01, options=opts, save=save, backend="numba"))
    nb, t_nb = timed(lambda: simulate(pb, x0, t_end, options=opts, save=save, backend="numba"))
    same_nb = np.array_equal(transmission_counts(nb), transmission_counts(fast))
    gap = np.max(np.abs(nb.transmissions.t - fast.transmissions.t)) if same_nb else float("nan")
    print(
        f"numba backend, first solve in this process: {t_compile:8.2f} s (compile, or load from the disk cache)"
    )
    if not args.quick:
        for label, cold in (("compile with an empty disk cache", True), ("load from the disk cache", False)):
            print(f"numba backend, fresh process, {label}: {_first_solve(cold):8.2f} s")
    print(
        f"numba backend, {runs} runs ({_threads()} threads): {t_nb:8.2f} s total, {t_nb / runs * 1e3:8.1f} ms/run"
    )
    print(
        f"ratio fast/numba per run: {t_fast / t_nb:.1f}x; scipy/numba per run: "
        f"{t_ref / ref_runs / (t_nb / runs):.1f}x"
    )
    print(f"numba and fast agree on all {runs} runs: {same_nb}, max event-time gap {gap:.2e} s")


def _first_solve(cold: bool) -> float:
    """Time of a first robot-arm solve in a new process, with an empty or a filled disk cache."""
    import os
    import subprocess
    import sys
    import tempfile

    code = (
        "import time; from etobs import SaveAt, simulate; from etobs.examples import robot_arm; "
        "t = time.perf_counter(); "
        "simulate(robot_arm(), [3, 2, 3, -2], 0.01, save=SaveAt(steps=False), backend='numba'); "
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
