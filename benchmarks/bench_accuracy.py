"""Benchmark: event-time accuracy and cost of the Table 1 runs against a tight-tolerance run.

Every (row, scenario) of the paper's Table 1 is run from the same initial states at a
tight tolerance (the reference) and at the tolerances under test; for each tolerance
it prints the share of runs whose transmission counts equal the reference's, the
distribution of the event-time gaps over the events of those runs, and the cost per
run measured in this process (``backend="engine"`` unless ``--backend`` says otherwise).

    python benchmarks/bench_accuracy.py                 # 20 runs per cell, rtol 1e-10 and 1e-9
    python benchmarks/bench_accuracy.py --runs 100 --rtol 1e-10 1e-9 1e-8
    python benchmarks/bench_accuracy.py --backend scipy # the solve_ivp reference (slow)
    python benchmarks/bench_accuracy.py --quick         # CI smoke: 2 rows, 3 runs, 5 s
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from _ready import ready
from etobs import SaveAt, SolverOptions, simulate
from etobs.estimation import transmission_counts
from etobs.experiments.table1 import table1_spec


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20, help="initial states per cell (default 20)")
    parser.add_argument("--rtol", type=float, nargs="+", default=[1e-10, 1e-9], help="tolerances under test")
    parser.add_argument("--reference", type=float, default=1e-12, help="reference tolerance (default 1e-12)")
    parser.add_argument(
        "--rows", type=int, nargs="+", default=None, help="Table 1 rows (0-based; default all)"
    )
    parser.add_argument(
        "--backend",
        choices=("auto", "engine", "scipy"),
        default="engine",
        help="solver (default engine)",
    )
    parser.add_argument("--quick", action="store_true", help="small sizes for CI")
    args = parser.parse_args()
    spec = table1_spec()
    runs = 3 if args.quick else args.runs
    t_end = 5.0 if args.quick else spec.t_end
    rows = range(2) if args.quick else (args.rows or range(len(spec.rows)))
    backend = args.backend
    x0 = spec.initial_states.draw(runs)
    save = SaveAt(steps=False)
    stats = {rt: {"equal": 0, "runs": 0, "gaps": [], "time": 0.0, "worst": (0.0, None)} for rt in args.rtol}
    simulate(spec.problem(0), x0[:1], 0.01, save=save, backend=backend)  # compile outside the timing
    if backend == "engine":
        ready(spec.problem(0))  # every row's problem has this structure: one compiled model
    for row in rows:
        for sc in range(len(spec.scenarios)):
            problem = spec.problem(row * len(spec.scenarios) + sc)
            tight = SolverOptions(rtol=args.reference, atol=args.reference)
            ref = simulate(problem, x0, t_end, options=tight, save=save, backend=backend)
            ref_counts = transmission_counts(ref)
            for rt in args.rtol:
                start = time.perf_counter()
                res = simulate(
                    problem, x0, t_end, options=SolverOptions(rtol=rt, atol=rt), save=save, backend=backend
                )
                st = stats[rt]
                st["time"] += time.perf_counter() - start
                same = np.all(transmission_counts(res) == ref_counts, axis=1)
                st["equal"] += int(same.sum())
                st["runs"] += runs
                for r in np.flatnonzero(same):
                    for k in range(problem.n_nodes):
                        gap = np.abs(res.transmission_times(r, k) - ref.transmission_times(r, k))
                        st["gaps"].append(gap)
                        if gap.size and gap.max() > st["worst"][0]:
                            st["worst"] = (float(gap.max()), (row, spec.scenarios[sc].name, int(r), k))
    print(
        f"Table 1 runs ({len(rows)} rows x {len(spec.scenarios)} scenarios x {runs} runs, {t_end:g} s), ",
        end="",
    )
    print(f"backend {backend}, reference rtol = atol = {args.reference:g}")
    print(
        "  rtol   counts equal   events   within 1e-9 s   median gap   p99.9 gap   max gap   ms/run (1 process)"
    )
    for rt, st in stats.items():
        gaps = np.concatenate(st["gaps"]) if st["gaps"] else np.zeros(1)
        print(
            f"{rt:6.0e}   {100 * st['equal'] / st['runs']:10.2f} %   {gaps.size:6d}   "
            f"{100 * np.mean(gaps <= 1e-9):11.2f} %   {np.median(gaps):10.1e}   "
            f"{np.percentile(gaps, 99.9):9.1e}   {gaps.max():7.1e}   {1e3 * st['time'] / st['runs']:8.2f}"
        )
        print(f"        largest gap at (row, scenario, run, node) = {st['worst'][1]}")


if __name__ == "__main__":
    main()
