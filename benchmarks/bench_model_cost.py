"""Benchmark: what a model's way of writing costs on the engine, and what the cost report names.

Run: ``python benchmarks/bench_model_cost.py [--quick]``. One model, a 2-degree-of-freedom
mass-spring-damper ``M q'' = -K q - D q' + v`` (4 states, the two positions sent by two
nodes), written four ways:

* ``solve``: ``q''`` by ``np.linalg.solve(M, rhs)`` in every flow call;
* ``written out``: the same 2x2 solve written out (Cramer's rule);
* ``python-control``: the written-out model as a ``control.NonlinearIOSystem`` whose
  ``updfcn`` reads its numbers from ``params`` (converted by
  :func:`etobs.model.python_control_plant`);
* ``Plant``: the written-out model as an etobs ``Plant`` reading them from ``p``.

It prints the per-run engine time of each (the same runs, in one process: ratios are what
matter on a shared machine) and :func:`etobs.estimation.model_cost`'s report of each, with
the functions it names as slow.

    python benchmarks/bench_model_cost.py            # 200 runs over 20 s each
    python benchmarks/bench_model_cost.py --quick    # CI smoke: 20 runs over 5 s
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from _ready import ready
from etobs import DynamicRule, EstimationProblem, Linear, Node, Plant, Quadratic, SaveAt, simulate
from etobs.estimation.cost import model_cost
from etobs.model import luenberger

M = np.array([[2.0, 0.5], [0.5, 1.0]])
KS = (4.0, 2.0)  # spring constants
DAMP = 0.4


def _rhs(x, u):
    q1, q2, w1, w2 = x
    return (
        -KS[0] * q1 + KS[1] * (q2 - q1) - DAMP * w1 + u[0],
        -KS[1] * (q2 - q1) - DAMP * w2,
    )


def flow_solve(t, x, u):
    r1, r2 = _rhs(x, u)
    acc = np.linalg.solve(M, np.array([r1, r2]))
    return np.array([x[2], x[3], acc[0], acc[1]])


def flow_written(t, x, u):
    r1, r2 = _rhs(x, u)
    det = M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]
    return np.array([x[2], x[3], (M[1, 1] * r1 - M[0, 1] * r2) / det, (M[0, 0] * r2 - M[1, 0] * r1) / det])


def flow_params(x, u, k1, k2, d):
    q1, q2, w1, w2 = x
    r1 = -k1 * q1 + k2 * (q2 - q1) - d * w1 + u[0]
    r2 = -k2 * (q2 - q1) - d * w2
    det = M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]
    return np.array([w1, w2, (M[1, 1] * r1 - M[0, 1] * r2) / det, (M[0, 0] * r2 - M[1, 0] * r1) / det])


def updfcn(t, x, u, params):
    return flow_params(x, u, params["k1"], params["k2"], params["d"])


def outfcn(t, x, u, params):
    return x[:2]


def plant_of(kind: str) -> Plant:
    if kind == "python-control":
        import control as ct

        from etobs.model import python_control_plant

        sys = ct.nlsys(
            updfcn, outfcn, states=4, inputs=["v"], outputs=["q1", "q2"], name="msd",
            params={"k1": KS[0], "k2": KS[1], "d": DAMP},
        )  # fmt: skip
        return python_control_plant(sys, disturbances=["v"])
    if kind == "Plant":
        return Plant(
            lambda t, x, u, v, p: flow_params(x, v, p[0], p[1], p[2]),
            lambda x, p: x[:2],
            n_x=4, n_y=2, n_v=1, params=[KS[0], KS[1], DAMP], name="msd",
        )  # fmt: skip
    flow = flow_solve if kind == "solve" else flow_written
    return Plant(lambda t, x, u, v: flow(t, x, v), lambda x: x[:2], n_x=4, n_y=2, n_v=1, name="msd")


def problem(kind: str) -> EstimationProblem:
    L = np.array([[3.0, 0.0], [0.0, 3.0], [2.0, 0.0], [0.0, 2.0]])
    observer = luenberger(lambda t, x, u: flow_written(t, x, np.zeros(1)), L)
    rule = DynamicRule(gamma=Quadratic(2.0), alpha=Linear(1.0), sigma=5.0, c=0.05, eps=1e-3, eta0=0.1)
    nodes = [Node((0,), rule, name="q1"), Node((1,), rule, name="q2")]
    return EstimationProblem(plant_of(kind), observer, nodes=nodes)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes for CI")
    args = parser.parse_args()
    runs, t_end = (20, 5.0) if args.quick else (200, 20.0)
    x0 = np.random.default_rng(3).uniform(-1.0, 1.0, (runs, 4))
    kinds = ("solve", "written out", "python-control", "Plant")
    problems = {k: problem(k) for k in kinds}
    secs = {}
    for k, pb in problems.items():
        simulate(pb, x0[:1], 0.01)  # compile (or load) outside the clock
        ready(pb)
        start = time.perf_counter()
        res = simulate(pb, x0, t_end, save=SaveAt(steps=False))
        secs[k] = (time.perf_counter() - start) / runs
        assert res.ok, res.status_labels()
    print(f"2-DOF mass-spring-damper, {runs} engine runs over {t_end:g} s each (one process)")
    for k in kinds:
        print(f"  {k:15} {secs[k] * 1e3:8.2f} ms/run")
    print(f"  solve / written out:     {secs['solve'] / secs['written out']:5.1f}x")
    print(f"  python-control / Plant:  {secs['python-control'] / secs['Plant']:5.1f}x")
    for k in kinds:
        cost = model_cost(problems[k], x0[0], horizon=min(t_end, 5.0), repeats=1 if args.quick else 3)
        print(f"\n[{k}] slow: {', '.join(cost.slow) or 'none'}")
        print(cost)
    named = {
        k: model_cost(problems[k], x0[0], horizon=1.0, repeats=1).slow for k in ("solve", "python-control")
    }
    for k, slow in named.items():
        if "f_p" not in slow:
            print(f"note: the cost report did not name f_p of the {k!r} model as slow (a busy machine?)")


if __name__ == "__main__":
    main()
