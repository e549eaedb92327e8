"""Benchmark: the lane engine's ``sin``/``cos`` (etobs.compile.vecmath) against libm, in a loop over lanes.

Run: ``python benchmarks/bench_vecmath.py [--quick]``. A numba loop over ``W`` lanes
evaluates ``sin`` of each lane's argument, ``rounds`` times, once with
:func:`etobs.compile.vecmath.sin` and once with ``math.sin`` (libm); the two alternate
in one process (the machine is shared: the ratio is the figure). It prints the time per
value of each and their ratio for W = 1, 8, 16, 32, whether the loop of 16 lanes is vector
code (the LLVM IR's vector types) and the largest error against libm in ulp on random
arguments below the exact-reduction limit.

    python benchmarks/bench_vecmath.py            # 2e5 rounds, 1e6 points for the error
    python benchmarks/bench_vecmath.py --quick    # CI smoke: 2e4 rounds, 1e5 points
"""

from __future__ import annotations

import argparse
import math
import re
import time

import numba
import numpy as np

from etobs.compile import vecmath as vm

SIN = vm.jitted()["sin"]


@numba.njit
def _ours(x, out, rounds):
    for r in range(rounds):
        for i in range(x.size):
            out[i] = SIN(x[i] + r * 1e-9)


@numba.njit
def _libm(x, out, rounds):
    for r in range(rounds):
        for i in range(x.size):
            out[i] = math.sin(x[i] + r * 1e-9)


@numba.njit
def _many(x):
    out = np.empty_like(x)
    for i in range(x.size):
        out[i] = SIN(x[i])
    return out


def _time(fn, x, rounds: int) -> float:
    out = np.empty_like(x)
    fn(x, out, 1)  # compiled for this type
    t = time.perf_counter()
    fn(x, out, rounds)
    return (time.perf_counter() - t) / (rounds * x.size) * 1e9


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="CI smoke size")
    args = ap.parse_args()
    rounds, points = (20_000, 100_000) if args.quick else (200_000, 1_000_000)
    rng = np.random.default_rng(0)
    print(f"{'lanes':>5} {'vecmath ns':>11} {'libm ns':>9} {'libm / vecmath':>15}")
    for width in (1, 8, 16, 32):
        x = rng.uniform(-50.0, 50.0, width)
        ours, libm = [], []
        for _ in range(3):  # alternating, best of three each
            ours.append(_time(_ours, x, rounds))
            libm.append(_time(_libm, x, rounds))
        print(f"{width:>5} {min(ours):>11.2f} {min(libm):>9.2f} {min(libm) / min(ours):>14.1f}x")
    ir = "\n".join(_ours.inspect_llvm().values())
    print(
        "vector types in the lane loop's LLVM IR:", sorted(set(re.findall(r"<\d+ x double>", ir))) or "none"
    )
    x = rng.uniform(-vm.EXACT_UP_TO, vm.EXACT_UP_TO, points)
    got, want = _many(x), np.sin(x)
    err = np.abs(got - want) / np.spacing(np.maximum(np.abs(want), np.finfo(float).tiny))
    print(
        f"largest error against libm on {points:,} points in |x| <= {vm.EXACT_UP_TO:.3g}: {err.max():.1f} ulp"
    )


if __name__ == "__main__":
    main()
