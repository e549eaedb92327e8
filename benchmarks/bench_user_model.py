"""A model of a user's own on every backend, and what its compile costs.

Run: ``python benchmarks/bench_user_model.py [--quick]``. The model (benchmarks/user_model.py)
has a ``Custom`` K-function, a time-varying ``FunctionSignal`` input and a vector node.
Prints per-run times of backend="engine" (the default) and backend="scipy" on the same
runs and their ratio, the largest gap between their transmission times (at the default
tolerances and at tighter ones, with the engine's own gap to its tighter runs as the
yardstick of integration error), and the compile
times measured in fresh processes sharing a fresh cache folder:
cold (a new model), cached (a new process), after editing one function, after changing
only numbers (params), and with the factory named by file path.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from _agree import expect, status  # noqa: E402 (a sibling module of this script)
from _ready import ready  # noqa: E402


def per_run(quick: bool) -> None:
    from etobs import SolverOptions, simulate
    from user_model import problem

    pb = problem()
    rng = np.random.default_rng(1)
    n_engine, n_scipy = (20, 2) if quick else (200, 5)
    X = rng.uniform(-1, 1, size=(n_engine, 4))
    t_end = 10.0 if quick else 20.0
    simulate(pb, X[:1], 0.1)  # compile (or load) first
    ready(pb)
    t = time.perf_counter()
    eng = simulate(pb, X, t_end)
    t_eng = (time.perf_counter() - t) / n_engine
    t = time.perf_counter()
    ref = simulate(pb, X[:n_scipy], t_end, backend="scipy")
    t_ref = (time.perf_counter() - t) / n_scipy
    same, gap = agreement(eng, ref, n_scipy, pb.n_nodes)
    expect(same, f"user model: engine and scipy transmission counts on {n_scipy} runs")
    print(
        f"user model, {t_end:g} s horizon: engine {t_eng * 1e3:.2f} ms/run ({n_engine} runs, "
        f"{eng.backend}), scipy {t_ref * 1e3:.1f} ms/run ({n_scipy} runs)"
    )
    print(
        f"  ratio scipy/engine: {t_ref / t_eng:.0f}x; same transmission counts: {same}; "
        f"largest event-time gap: {gap:.2e} s"
    )
    # The gap is integration error: the engine against itself at a tighter tolerance is as
    # far, and both backends close in on each other as the tolerance shrinks.
    for tol in (1e-12, 1e-13):
        opts = SolverOptions(rtol=tol, atol=tol)
        e_t = simulate(pb, X[:n_scipy], t_end, options=opts)
        r_t = simulate(pb, X[:n_scipy], t_end, options=opts, backend="scipy")
        same_t, gap_t = agreement(e_t, r_t, n_scipy, pb.n_nodes)
        _, self_gap = agreement(eng, e_t, n_scipy, pb.n_nodes)
        print(
            f"  rtol = atol = {tol:g}: engine vs scipy {gap_t:.2e} s (same counts: {same_t}); "
            f"engine at the default against itself at {tol:g}: {self_gap:.2e} s"
        )


def agreement(a, b, runs: int, nodes: int) -> tuple[bool, float]:
    """Whether the first ``runs`` runs send the same transmissions, and the largest time gap."""
    gap, same = 0.0, True
    for r in range(runs):
        for node in range(nodes):
            ta, tb = a.transmissions.times(r, node), b.transmissions.times(r, node)
            same &= ta.shape == tb.shape
            if ta.shape == tb.shape and ta.size:
                gap = max(gap, float(np.max(np.abs(ta - tb))))
    return same, gap


SCRIPT = textwrap.dedent(
    """
    import sys, time
    t0 = time.perf_counter()
    sys.path.insert(0, {here!r})
    {setup}
    from etobs import simulate
    pb = {make}
    simulate(pb, [0.1, 0.0, -0.1, 0.0], 0.5)
    print(time.perf_counter() - t0)
    """
)


def run(cache: str, setup: str, make: str) -> float:
    env = {**os.environ, "ETOBS_CACHE_DIR": cache}
    code = SCRIPT.format(here=str(HERE), setup=setup, make=make)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def compile_times() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        cache = str(Path(tmp) / "cache")
        src = Path(tmp) / "mymodel.py"
        src.write_text((HERE / "user_model.py").read_text())
        setup = f"sys.path.insert(0, {tmp!r}); import mymodel"
        engine = run(cache, setup, "mymodel.problem()")  # also compiles the engine into this cache
        cold_src = src.read_text().replace("s * s * (1.0 + s)", "s * s * (1.0 + 0.5 * s)")
        src.write_text(cold_src.replace("K = 0.4", "K = 0.41"))
        cold = run(cache, setup, "mymodel.problem()")
        cached = run(cache, setup, "mymodel.problem()")
        src.write_text(src.read_text().replace("0.5 * math.sin(0.7 * t", "0.6 * math.sin(0.7 * t"))
        edited = run(cache, setup, "mymodel.problem()")
        numbers = run(cache, setup, "mymodel.problem(damping=0.5)")
        by_path = run(
            cache,
            "from etobs.examples.registry import resolve_factory",
            f"resolve_factory({str(src) + ':problem'!r})()",
        )
    print("first simulate in a fresh process, fresh cache folder [s]:")
    print(f"  engine not yet compiled on this machine: {engine:.1f}")
    print(f"  new model (engine cached): {cold:.2f}; same model, new process: {cached:.2f}")
    print(
        f"  one function edited: {edited:.2f}; only numbers changed: {numbers:.2f}; "
        f"factory named by path: {by_path:.2f}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    per_run(args.quick)
    if not args.quick:
        compile_times()


if __name__ == "__main__":
    main()
    raise SystemExit(status())
