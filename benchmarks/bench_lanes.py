"""The engine's lanes: per-run speed, Table 1's wall time, lane statistics, vector code, compile times.

Run: ``python benchmarks/bench_lanes.py [--quick] [--base REV]``.

* **Per run, one thread** (robot arm, 30 s, Table 1's tolerances): the engine with its
  :data:`~etobs.hybrid.compiled.LANES` lanes against one lane (the same code), in one
  process, alternating; with ``--base REV`` also against the engine of the commit ``REV``
  (a git worktree, default :data:`BASE`: the engine before lanes), alternating fresh
  processes, with each run's transmissions per node and largest error compared.
* **Lane statistics**: idle, rejected and event lane-steps, nanoseconds per lane-step.
* **Vector code**: the robot arm's lane form compiled afresh (no cache), its vector
  instructions counted in the LLVM IR; without ``--quick`` the kernel's too.
* **A model of one's own** (benchmarks/user_model.py: a ``Custom`` K-function, a
  ``FunctionSignal``): as written (it returns arrays: etobs says why it is not vector
  code), and the same model returning tuples; lanes against one lane.
* Without ``--quick``: ``etobs reproduce table1`` on two cores (wall time, and the share
  of it outside the solver), and compile times in fresh processes (the kernel once per
  machine; a new model; a model from the cache).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import textwrap
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
from _ready import ready  # noqa: E402 (a sibling module of this script)

#: The engine before lanes (one run per thread): what --base compares with by default.
BASE = "752f71e"

_ARM = """
import json, os, sys, time
if os.environ.get("ETOBS_BASE_SRC"):  # the engine of another commit
    sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in repr(f).lower()]
    sys.path.insert(0, os.environ["ETOBS_BASE_SRC"])
import numpy as np
from etobs import SaveAt, SolverOptions, simulate
from etobs.examples import robot_arm
from etobs.examples.robot_arm import random_initial_states
pb = robot_arm()
x0 = random_initial_states({runs}, seed=2023)
opts = SolverOptions(rtol=1e-10, atol=1e-10)
save = SaveAt(steps=False, grid=np.linspace(20.0, 30.0, 10001), max_distance="estimation_error")
simulate(pb, x0[:2], 1.0, options=opts)  # compile or load
from etobs.estimation.compiled import compile_problem
system = compile_problem(pb).system
if getattr(system, "lane_form", None):  # the lane form too (a warm-up of two runs does not fill lanes)
    system.lane_form(True)
best = 1e9
for _ in range({reps}):
    t = time.perf_counter()
    res = simulate(pb, x0, 30.0, options=opts, save=save, progress=False)
    best = min(best, time.perf_counter() - t)
counts = [[int((res.transmissions.select(run=r).rule == k).sum()) for k in range(2)] for r in range({runs})]
print(json.dumps({{"ms": 1e3 * best / {runs}, "counts": counts, "error": res.solution.grid_max.value.tolist()}}))
"""


def _python(code: str, env: dict[str, str] | None = None, timeout: int = 1800) -> dict:
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env={**os.environ, **(env or {})},
        timeout=timeout,
    )
    if out.returncode:
        raise RuntimeError(out.stderr[-3000:])
    return json.loads(out.stdout.strip().splitlines()[-1])


def _one_thread() -> dict[str, str]:
    return {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}


def in_process(quick: bool) -> None:
    """Lanes against one lane, in this process (one thread), and the lane statistics."""
    import numba

    from etobs import SaveAt, SolverOptions, simulate
    from etobs.examples import robot_arm
    from etobs.examples.robot_arm import random_initial_states
    from etobs.hybrid import compiled as comp

    numba.set_num_threads(1)
    runs = 32 if quick else 128
    pb = robot_arm()
    x0 = random_initial_states(runs, seed=2023)
    opts = SolverOptions(rtol=1e-10, atol=1e-10)
    save = SaveAt(steps=False, grid=np.linspace(20.0, 30.0, 10001), max_distance="estimation_error")
    simulate(pb, x0[:2], 1.0, options=opts)
    ready(pb)
    lanes = comp.LANES
    best = {lanes: 1e9, 1: 1e9}
    sols = {}
    for _ in range(2 if quick else 3):
        for width in (lanes, 1):  # alternating
            comp.LANES = width
            t = time.perf_counter()
            sols[width] = simulate(pb, x0, 30.0, options=opts, save=save, progress=False).solution
            best[width] = min(best[width], time.perf_counter() - t)
    comp.LANES = lanes
    same = all(np.array_equal(getattr(sols[lanes], k), getattr(sols[1], k)) for k in ("x_final", "n_steps"))
    print(f"robot arm, {runs} runs x 30 s, one thread (rtol = atol = 1e-10):")
    print(
        f"  {lanes} lanes: {1e3 * best[lanes] / runs:.2f} ms per run; one lane: {1e3 * best[1] / runs:.2f} ms"
    )
    print(f"  lanes / one lane: {best[1] / best[lanes]:.2f}x; same numbers in both: {same}")
    st = sols[lanes].lanes
    print(f"  {st}")
    print(f"  {1e9 * best[lanes] / st.slots:.0f} ns per lane-step, {st.slots / runs:.0f} lane-steps per run")
    target("idle lane-slots under 2 %", st.share("idle") < 0.02)


def against_base(rev: str, quick: bool) -> None:
    """The engine of commit ``rev`` against this one: alternating fresh processes, one thread each."""
    runs = 32 if quick else 100
    folder = Path(tempfile.mkdtemp(prefix="etobs-base-"))
    subprocess.run(
        ["git", "-C", str(ROOT), "worktree", "add", "--detach", str(folder), rev],
        check=True,
        capture_output=True,
    )
    try:
        code = _ARM.format(runs=runs, reps=2)
        base_env = {**_one_thread(), "ETOBS_BASE_SRC": str(folder / "src")}
        _python(code, base_env)  # compile the old kernel once (its own cache entry)
        times: dict[str, list[float]] = {"base": [], "lanes": []}
        last: dict[str, dict] = {}
        for _ in range(2):
            for name, env in (("base", base_env), ("lanes", _one_thread())):
                last[name] = _python(code, env)
                times[name].append(last[name]["ms"])
        b, n = min(times["base"]), min(times["lanes"])
        print(f"against the engine of {rev} (one run per thread), {runs} runs, one thread, fresh processes:")
        print(f"  {rev}: {b:.2f} ms per run; lanes: {n:.2f} ms per run; ratio {b / n:.2f}x")
        target("at least 4x per run on one thread", b / n >= 4.0)
        same = last["base"]["counts"] == last["lanes"]["counts"]
        e0, e1 = np.array(last["base"]["error"], dtype=float), np.array(last["lanes"]["error"], dtype=float)
        same_nan = bool(np.array_equal(np.isnan(e0), np.isnan(e1)))
        ok = ~np.isnan(e0)
        rel = float(np.max(np.abs(e1[ok] - e0[ok]) / np.abs(e0[ok]))) if same_nan and ok.any() else np.inf
        print(
            f"  transmissions per node identical in {runs} of {runs} runs: {same}; errors equal to {rel:.1e}"
        )
        target("identical counts and errors equal to 1e-6", same and rel <= 1e-6)
    finally:
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(folder)], capture_output=True
        )


def vector_code(kernel: bool) -> None:
    """Vector instructions in the robot arm's lane form (and the kernel's), compiled afresh."""
    code = textwrap.dedent(
        f"""
        import json, re
        from etobs.examples import robot_arm
        from etobs.estimation.compiled import compile_problem
        from etobs.estimation.compiled import _LANE_FORMS
        cp = compile_problem(robot_arm())
        cp.system.lane_form(True)
        ir = _LANE_FORMS[(int(cp.system.keep[0].address), True)][1].cfunc.inspect_llvm()
        out = {{"model": re.findall(r"<(\\d+) x double>", ir)}}
        if {kernel}:
            import numpy as np
            from etobs import simulate
            from etobs.hybrid.compiled import _built
            simulate(robot_arm(), np.ones((40, 4)), 0.1)  # the kernel compiles at its first call
            k = _built("dop853")
            kir = "".join(k.inspect_llvm().values())
            out["kernel"] = re.findall(r"<(\\d+) x double>", kir)
        print(json.dumps(out))
        """
    )
    out = _python(code, {"ETOBS_CACHE_DIR": "off"})
    for part, found in out.items():
        widths = {w: found.count(w) for w in sorted(set(found), key=int)}
        print(f"  {part}: vector values in the LLVM IR by lanes per instruction: {widths}")
        target(f"{part} has vector code", bool(found))


def user_model(quick: bool) -> None:
    """benchmarks/user_model.py as written, and returning tuples: lanes against one lane."""
    import numba

    from etobs import SaveAt, simulate
    from etobs.hybrid import compiled as comp

    numba.set_num_threads(1)
    import user_model as um

    runs = 32 if quick else 128
    x0 = np.random.default_rng(1).uniform(-1.0, 1.0, size=(runs, 4))
    for name, pb in (("as written (arrays)", um.problem()), ("returning tuples", um.tuple_problem())):
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            simulate(pb, x0[:1], 1.0, progress=False)  # the one-run form
            ready(pb)  # and the lane form (compiled when a batch first fills the lanes)
        said = [str(w.message) for w in seen if "lane form" in str(w.message)]
        best = {}
        for width in (comp.LANES, 1):
            comp.LANES, keep = width, comp.LANES
            t = time.perf_counter()
            simulate(pb, x0, 20.0, save=SaveAt(steps=False), progress=False)
            best[width] = time.perf_counter() - t
            comp.LANES = keep
        ratio = best[1] / best[comp.LANES]
        print(
            f"user model {name}: {1e3 * best[comp.LANES] / runs:.2f} ms per run, lanes / one lane {ratio:.2f}x"
        )
        for text in said:
            print("  etobs said: " + re.sub(r"\s+", " ", text)[:400])


def table1(rev: str | None) -> None:
    """``etobs reproduce table1`` on two cores: wall time and the share outside the solver."""

    def once(env: dict[str, str]) -> tuple[float, float]:
        out = Path(tempfile.mkdtemp(prefix="etobs-t1-"))
        start = time.perf_counter()
        cmd = [sys.executable, "-m", "etobs", "reproduce", "table1", "--out", str(out)]
        subprocess.run(cmd, check=True, capture_output=True, env={**os.environ, **env}, timeout=3600)
        wall = time.perf_counter() - start
        solver = _solver_seconds(out)
        return wall, solver

    runs = {"lanes": once({})}
    print("etobs reproduce table1 (2,600 runs), two cores:")
    for name, (wall, solver) in runs.items():
        share = max(0.0, 1.0 - solver / (2 * wall))
        print(
            f"  {name}: {wall:.1f} s wall; outside the solver (workers, loading, metrics, storage): {share:.0%}"
        )
        target("at most 8 s (target 5 s)", wall <= 8.0)
        target("pipeline under 10 % of the wall time", share < 0.10)


def _solver_seconds(out: Path) -> float:
    """The solver's seconds over all runs of a sweep folder (each record: its share of its chunk's solve)."""
    total = 0.0
    for f in (out / "chunks").glob("*.json"):
        total += sum(float(r.get("seconds", 0.0)) for r in json.loads(f.read_text())["records"])
    return total


def compile_times() -> None:
    """The kernel once per machine, a new model, and a model from the cache, in fresh processes."""
    folder = tempfile.mkdtemp(prefix="etobs-cache-")
    code = textwrap.dedent(
        """
        import json, time
        import numpy as np
        from etobs import simulate
        from etobs.examples import robot_arm
        from etobs.estimation.compiled import compile_problem
        t = time.perf_counter()
        system = compile_problem(robot_arm()).system  # its one-run form
        first = time.perf_counter() - t
        t = time.perf_counter()
        system.lane_form(True)  # then its lane form (compiled when a batch first fills the lanes)
        lanes = time.perf_counter() - t
        t = time.perf_counter()
        simulate(robot_arm(), np.ones((1, 4)), 0.01)  # the kernel: compiled at its first call
        print(json.dumps({"kernel": time.perf_counter() - t, "model": first, "lanes": lanes}))
        """
    )
    env = {"ETOBS_CACHE_DIR": folder}
    cold = _python(code, env)
    warm = _python(code, env)
    print("compile times (fresh processes, one fresh cache folder):")
    print(f"  the kernel, once per machine: {cold['kernel']:.1f} s (then {warm['kernel']:.2f} s)")
    new, cached = cold["model"] + cold["lanes"], warm["model"] + warm["lanes"]
    print(
        f"  a new model: {new:.1f} s (its one-run form {cold['model']:.1f} s, its lane form "
        f"{cold['lanes']:.1f} s); from the cache: {cached:.2f} s"
    )
    target("a new model at most 5 s cold, 1 s cached", new <= 5.0 and cached <= 1.0)


def target(what: str, ok: bool) -> None:
    print(f"  target {what}: {'met' if ok else 'NOT MET'}")


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="fewer runs; no Table 1, no compile times")
    parser.add_argument("--base", default=None, help=f"compare with the engine of this commit (e.g. {BASE})")
    args = parser.parse_args()
    in_process(args.quick)
    user_model(args.quick)
    print("vector code:")
    vector_code(kernel=not args.quick)
    if args.base:
        against_base(args.base, args.quick)
    if not args.quick:
        table1(args.base)
        compile_times()


if __name__ == "__main__":
    main()
