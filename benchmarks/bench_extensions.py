"""Benchmark: the paper's extensions and a network on the engine, against the scipy reference.

The robot arm (section 8) with, one at a time: an input node (section 7.3; send-on-delta
0.05 on the input ``u``), the observer-copy hold (Remark 3), a network (20 % Bernoulli
loss, 10 ms delay) and the generalized rule (section 7.1, eq. (44)--(45)). Each case
runs a batch of random initial states with ``backend="engine"`` (compiled, 16 runs side
by side per thread) and the first few of them with ``backend="scipy"`` (the ``solve_ivp`` reference
on the Python functions), in one process; the figures that matter are the per-run time
ratio and whether both send the same transmissions on the shared runs (and, with the
network, lose and apply the same packets).

    python benchmarks/bench_extensions.py            # engine: batch of 100, scipy: 2 runs, 5 s
    python benchmarks/bench_extensions.py --quick    # CI smoke: batch of 4, 1 scipy run, 0.5 s

Before the batched numpy solver was retired, it was measured against the engine in one
process of the last version that had both (batch of 100, 5-s runs, the solvers
alternating three times per case): with 2 engine threads the engine was 36.5–45.2x
faster per run with the copy hold, 29.1–35.9x with the generalized rule, 40.3–45.1x
with an input node and 61.2–82.7x with the network (17.8–19.7x, 16.9–20.7x,
19.8–24.1x and 32.5–44.0x on one thread each), with the same transmissions and packet
counts in every run.

The observer-copy hold sends about a thousand times a second on the robot arm (its
held innovation drives ``yhat`` fast with the paper's gain), so its runs are a tenth of
the horizon. Each backend's first solve of a case (compile, or load from the disk
cache) is timed apart.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numba
import numpy as np

from _agree import expect, status
from _ready import ready
from etobs import Link, Network, SaveAt, simulate
from etobs.estimation import transmission_counts
from etobs.examples import random_initial_states, robot_arm
from etobs.model import GeneralizedRule, InputNode, Quadratic, send_on_delta


def cases() -> dict[str, tuple[object, float]]:
    """The problems, with the fraction of the horizon each runs."""
    pb = robot_arm()
    generalized = tuple(
        replace(
            nd,
            rule=GeneralizedRule(
                gamma=nd.rule.gamma,
                gamma_check=Quadratic(0.005),
                alpha_check=nd.rule.alpha,
                d_prime=1.0,
                sigma=0.5,
                eps=nd.rule.eps,
                eta0=nd.rule.eta0,
            ),
        )
        for nd in pb.nodes
    )
    return {
        "input node": (replace(pb, input_nodes=(InputNode((0,), send_on_delta(0.05)),)), 1.0),
        "copy hold": (replace(pb, hold="innovation"), 0.1),
        "network": (replace(pb, network=Network(Link(delay=0.01, loss=0.2), seed=1)), 1.0),
        "generalized": (replace(pb, nodes=generalized), 1.0),
    }


def timed(fn):
    start = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - start


def same_outcome(a, b) -> bool:
    """Same transmissions per run and node, and with a network the same packet counts."""
    if not np.array_equal(transmission_counts(a), transmission_counts(b)):
        return False
    if a.problem.network is None:
        return True
    sa, sb = a.network_stats(), b.network_stats()
    return all(np.array_equal(sa[k], sb[k]) for k in sa)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes for CI")
    parser.add_argument("--runs", type=int, default=None, help="engine batch size (default 100)")
    parser.add_argument("--ref-runs", type=int, default=None, help="scipy runs (default 2)")
    parser.add_argument("--t-end", type=float, default=None, help="horizon (default 5 s)")
    args = parser.parse_args()
    runs = args.runs or (4 if args.quick else 100)
    ref_runs = min(args.ref_runs or (1 if args.quick else 2), runs)
    t_end = args.t_end or (0.5 if args.quick else 5.0)
    x0 = random_initial_states(runs, seed=1)
    save = SaveAt(steps=False)
    threads = numba.get_num_threads()
    print(f"robot arm, {runs} engine runs ({threads} threads), {ref_runs} scipy runs, horizon {t_end:g} s")
    print(
        f"{'case':12s} {'T (s)':>6s} {'engine ms/run':>14s} {'scipy ms/run':>13s} {'ratio':>7s}  same outcome"
    )
    for name, (pb, share) in cases().items():
        T = t_end * share
        timed(lambda pb=pb, T=T: simulate(pb, x0[:1], min(T, 0.01), backend="engine", save=save))
        ready(pb)
        eng, te = timed(lambda pb=pb, T=T: simulate(pb, x0, T, backend="engine", save=save))
        ref, ts = timed(lambda pb=pb, T=T: simulate(pb, x0[:ref_runs], T, backend="scipy", save=save))
        shared = simulate(pb, x0[:ref_runs], T, backend="engine", save=save)
        ok = eng.ok and ref.ok
        expect(ok, f"{name}: every run completed")
        expect(same_outcome(shared, ref), f"{name}: engine and scipy transmissions and packets")
        ratio = (ts / ref_runs) / (te / runs)
        n_tx = int(transmission_counts(eng).sum())
        print(
            f"{name:12s} {T:6.2f} {1e3 * te / runs:14.2f} {1e3 * ts / ref_runs:13.1f} {ratio:6.0f}x  "
            f"{same_outcome(shared, ref)} ({n_tx} transmissions{'' if ok else ', NOT ALL COMPLETED'})"
        )


if __name__ == "__main__":
    main()
    raise SystemExit(status())
