"""Benchmark: how the engine's cost grows with runs, horizon and number of nodes.

Robot arm (section 8) with the paper's first parameter row, noise and disturbance;
the N-node case uses `robot_arm_network` (N/2 independent arms, N sensor nodes).
Times are measured in one process and reported with their ratio to the first entry
of each series (these machines are shared: compare ratios, not seconds).

    python benchmarks/bench_scaling.py            # runs 1..2600 (30 s), horizon 3..30 s, N 2..100
    python benchmarks/bench_scaling.py --quick    # small sizes, for CI

Each problem structure is compiled (or loaded from the disk cache) once before it is
timed; that time is printed on its own line.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from _ready import ready
from etobs import SaveAt, simulate
from etobs.examples import random_initial_states, robot_arm, robot_arm_network


def timed(problem, x0, t_end, backends):
    """``{backend: (seconds, transmissions)}`` for the runs ``x0``, compile excluded."""
    out = {}
    for backend in backends:
        start = time.perf_counter()
        simulate(problem, x0[:1], 1e-3, save=SaveAt(steps=False), backend=backend)
        if backend == "engine":
            ready(problem)
        print(f"  ({backend}: compile or reuse for n = {x0.shape[1]}: {time.perf_counter() - start:.2f} s)")
        start = time.perf_counter()
        res = simulate(problem, x0, t_end, save=SaveAt(steps=False), backend=backend)
        elapsed = time.perf_counter() - start
        if not res.ok:
            raise RuntimeError(f"a {backend} run failed: {set(res.status_labels())}")
        out[backend] = (elapsed, len(res.transmissions))
    return out


def series(title, label, points, backends):
    print(f"\n{title}")
    head = f"{label:>10}"
    for b in backends:
        head += f" {b + ' [s]':>11} {'per run [ms]':>13} {'ratio':>6}"
    head += f" {'transmissions':>14}"
    print(head)
    first: dict[str, float] = {}
    for key, runs, times in points:
        line = f"{key:>10}"
        for b in backends:
            elapsed = times[b][0]
            first.setdefault(b, elapsed)
            line += f" {elapsed:>11.2f} {elapsed / runs * 1e3:>13.1f} {elapsed / first[b]:>6.2f}"
        sent = {times[b][1] for b in backends}
        line += f" {'/'.join(str(s) for s in sorted(sent)):>14}"
        print(line)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes for CI")
    args = parser.parse_args()
    backends = ("engine",)
    q = args.quick
    arm = robot_arm()
    x_all = random_initial_states(2600, seed=1)

    t_runs = 1.0 if q else 30.0
    counts = (1, 4, 16) if q else (1, 10, 100, 1000, 2600)
    series(
        f"runs (horizon {t_runs:g} s, one batch)",
        "runs",
        [(b, b, timed(arm, x_all[:b], t_runs, backends)) for b in counts],
        backends,
    )

    horizons = (0.5, 1.0, 2.0) if q else (3.0, 10.0, 30.0)
    series(
        "horizon (10 runs)",
        "t_end [s]",
        [(f"{h:g}", 10, timed(arm, x_all[:10], h, backends)) for h in horizons],
        backends,
    )

    nodes = (2, 10) if q else (2, 10, 50, 100)
    t_nodes = 0.5 if q else 3.0
    points = []
    for n in nodes:
        arms = n // 2
        x0 = np.concatenate([np.roll(x_all[:10], k, axis=0) for k in range(arms)], axis=1)
        points.append((n, 10, timed(robot_arm_network(arms), x0, t_nodes, backends)))
    series(f"nodes N (10 runs, horizon {t_nodes:g} s)", "N", points, backends)


if __name__ == "__main__":
    main()
