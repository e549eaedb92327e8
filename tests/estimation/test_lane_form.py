"""The estimation model's lane form: each lane's numbers are one run's, and etobs says when it is slow.

The engine calls a model's lane form (``est_lanes``) once per stage for 16 runs; it is
generated from the same body as the one-run form (:mod:`etobs.estimation._model_source`).
"""

import json
import os
import subprocess
import sys
import textwrap
import warnings

import numpy as np
import pytest

from etobs import (
    EstimationProblem,
    Node,
    Observer,
    PerformanceWarning,
    Plant,
    SaveAt,
    SolverOptions,
    simulate,
)
from etobs.estimation import _lane_probe as lp
from etobs.estimation._model_source import LANE_WIDTH
from etobs.estimation.compiled import _LANE_FORMS, _probe_states, compile_problem
from etobs.examples import robot_arm
from etobs.hybrid import Status
from etobs.model import DynamicRule, Linear, Quadratic

from .test_engine_agrees import STRUCTURES


def _forms(cp, shared=True):
    """The compiled one-run form of a compiled problem and its lane form ``shared`` (compiled here)."""
    one = cp.system.keep[0]
    assert cp.system.lane_form(shared) != 0
    return one, _LANE_FORMS[(int(one.address), shared)][1]


DRAW = {"eps": 0.01, "sigma": 1.0, "delta": 0.05, "period": 0.05, "delay": 0.01, "loss": 0.3, "seed": 7}


def _problems():
    yield "robot arm", robot_arm()
    for name, build in sorted(STRUCTURES.items()):
        yield name, build(DRAW)


@pytest.mark.parametrize(("name", "problem"), list(_problems()), ids=[n for n, _ in _problems()])
def test_every_lane_of_the_lane_form_computes_what_one_run_computes(name, problem, monkeypatch):
    from etobs.hybrid import compiled as comp

    cp = compile_problem(problem)
    assert cp.system.lane_width == LANE_WIDTH
    states = _probe_states(problem, LANE_WIDTH)
    for shared in (True, False):  # lanes of one problem, and lanes of a row each
        one, lanes = _forms(cp, shared)
        probe = lp.LaneProbe(one, lanes, states, cp.system.n_work + 1, cp.system.n_rules, cp.params)
        assert probe.agrees(), shared
    # and in a solve: 40 runs (20 a thread, in 16 lanes refilled) against one lane, bit for bit
    x0 = np.random.default_rng(5).uniform(-1.0, 1.0, (40, problem.plant.n_x))
    kw = {"save": SaveAt(steps=False), "progress": False}
    wide = simulate(problem, x0, 1.0, **kw).solution
    assert wide.lanes.vector and wide.lanes.width == LANE_WIDTH
    monkeypatch.setattr(comp, "LANES", 1)
    narrow = simulate(problem, x0, 1.0, **kw).solution
    assert not narrow.lanes.vector
    for key in ("status", "t_final", "x_final", "n_steps", "n_rejected", "j_final"):
        np.testing.assert_array_equal(getattr(wide, key), getattr(narrow, key), err_msg=key)
    np.testing.assert_array_equal(wide.jumps.t, narrow.jumps.t)


def _decay(sign):
    """x' = sign * x, y = x, one node: the same structure for either sign."""
    plant = Plant(f_p=lambda t, x, u, v: (sign * x[0],), h=lambda x: (x[0],), n_x=1, n_y=1)
    observer = Observer(f_o=lambda t, z, u, ybar, yhat: (ybar[0] - z[0],), n_z=1)
    rule = DynamicRule(gamma=Quadratic(1.0), alpha=Linear(1.0), sigma=0.5, c=0.1, eps=1e-3, eta0=0.1)
    return EstimationProblem(plant, observer, nodes=[Node((0,), rule)])


def test_two_models_of_one_structure_run_their_own_code():
    # guards against: the second model's one-run body linked to the first's (one symbol name)
    x0 = np.ones((40, 1))
    for sign in (-1.0, 1.0):
        res = simulate(_decay(sign), x0, 1.0, save=SaveAt(steps=False), progress=False)
        np.testing.assert_allclose(res.solution.x_final[:, 0], np.exp(sign), rtol=1e-8)


def _arrays_model():
    plant = Plant(
        f_p=lambda t, x, u, v: np.array([x[1], -np.exp(-x[0]) * x[0]]), h=lambda x: x[:1].copy(), n_x=2, n_y=1
    )
    observer = Observer(f_o=lambda t, z, u, ybar, yhat: np.array([z[1] + ybar[0] - yhat[0], -z[0]]), n_z=2)
    rule = DynamicRule(gamma=Quadratic(1.0), alpha=Linear(1.0), sigma=0.5, c=0.1, eps=1e-3, eta0=0.1)
    return EstimationProblem(plant, observer, nodes=[Node((0,), rule)])


def test_a_model_that_is_not_vector_code_is_named_once_with_its_cost():
    pb = _arrays_model()
    expected = (
        r"lane form is not vector code: `f_p` calls libm \(exp\), makes arrays per call \(array\); "
        r"`h` makes arrays per call \(copy\); `f_o` makes arrays per call \(array\)\. Its flow costs \d+ ns"
    )
    with pytest.warns(PerformanceWarning, match=expected):
        res = simulate(pb, np.ones((40, 2)), 1.0, save=SaveAt(steps=False), progress=False)
    assert np.all(res.solution.status == Status.COMPLETED)  # the numbers are still computed
    with warnings.catch_warnings():
        warnings.simplefilter("error", PerformanceWarning)
        simulate(pb, np.ones((40, 2)), 1.0, save=SaveAt(steps=False), progress=False)  # said once
        assert compile_problem(pb).system.lane_form(False) != 0  # the other form: once per model


def test_the_robot_arm_is_vector_code_with_no_note():
    with warnings.catch_warnings():
        warnings.simplefilter("error", PerformanceWarning)
        compile_problem(robot_arm()).system.lane_form()
    # the LLVM IR of a fresh compile (cached code cannot be inspected): vector instructions
    script = textwrap.dedent(
        """
        import json, re
        from etobs.examples import robot_arm
        from etobs.estimation.compiled import _LANE_FORMS, compile_problem
        cp = compile_problem(robot_arm())
        cp.system.lane_form(True)
        ir = _LANE_FORMS[(int(cp.system.keep[0].address), True)][1].cfunc.inspect_llvm()
        print(json.dumps(sorted(set(re.findall(r"<(\\d+) x double>", ir)))))
        """
    )
    env = {"ETOBS_CACHE_DIR": "off", "PATH": ""}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    widths = json.loads(out.stdout.strip().splitlines()[-1])
    assert widths and all(int(w) >= 2 for w in widths)


def test_runs_with_their_own_parameters_share_lanes_and_get_their_own_numbers():
    # two problems of one structure: one compiled model, the numbers in each run's row of p
    from dataclasses import replace

    from etobs.hybrid.compiled import solve_compiled

    low, high = robot_arm(sigma=(600.0, 800.0), eps=10.0), robot_arm(sigma=(300.0, 400.0), eps=1.0)
    cp, cp_high = compile_problem(low), compile_problem(high)
    assert cp.system.keep[0] is cp_high.system.keep[0] and not np.array_equal(cp.params, cp_high.params)
    asked = []

    def lane_form(shared):
        asked.append(shared)
        return cp.system.lane_form(shared)

    system = replace(cp.system, lane_form=lane_form)
    rng = np.random.default_rng(3)
    B = 40
    x0 = low.initial_state(rng.uniform(-1, 1, (B, 4)), np.zeros((B, 4)), np.zeros((B, 2)), 0.0)
    which = rng.permutation(np.arange(B) % 2)  # each run's problem, mixed in every thread's lanes
    P = np.where(which[:, None] == 1, cp_high.params, cp.params)
    opts = SolverOptions(rtol=1e-9, atol=1e-9)
    mixed = solve_compiled(system, x0, (0.0, 3.0), params=P, options=opts, parallel=False)
    assert asked == [False] and mixed.lanes.vector  # the form of a row per lane
    for k, params in ((0, cp.params), (1, cp_high.params)):
        runs = np.flatnonzero(which == k)
        asked.clear()
        alone = solve_compiled(system, x0[runs], (0.0, 3.0), params=params, options=opts, parallel=False)
        assert set(asked) == {True}  # one problem: the form that reads the first row
        for key in ("status", "t_final", "x_final", "n_steps", "n_rejected", "j_final"):
            np.testing.assert_array_equal(getattr(mixed, key)[runs], getattr(alone, key), err_msg=key)
    # the two problems send differently: the rows were not mixed up
    assert not np.array_equal(mixed.j_final[which == 0].mean(), mixed.j_final[which == 1].mean())


def test_the_lane_check_is_compiled_once_per_machine_not_per_process(tmp_path):
    """The loops that check a lane form come from numba's disk cache in the next process.

    Written inside a function they were closures, which numba's cache keys by their cells:
    every process compiled them again (0.44 s of each sweep worker's start) and wrote a new
    cache file (hundreds in a test run). Two fresh processes check the robot arm's lane
    form: the second compiles neither loop and writes no file.
    """
    code = textwrap.dedent(
        """
        import json
        from etobs.estimation import _lane_probe as lp
        from etobs.estimation.compiled import compile_problem
        from etobs.examples import robot_arm
        assert compile_problem(robot_arm()).system.lane_form(True) != 0
        print(json.dumps([[f.stats.cache_hits.total(), f.stats.cache_misses.total()]
                          for f in (lp._call_lanes, lp._call_ones)]))
        """
    )
    env = {"NUMBA_CACHE_DIR": str(tmp_path / "numba"), "ETOBS_CACHE_DIR": str(tmp_path / "etobs")}

    def run() -> list:
        out = subprocess.run(
            [sys.executable, "-c", code],
            env={**os.environ, **env},
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert out.returncode == 0, out.stderr
        return json.loads(out.stdout.strip().splitlines()[-1])

    assert run() == [[0, 1], [0, 1]]  # each loop compiled (hits, misses), by the first process
    files = sorted(p.name for p in (tmp_path / "numba").rglob("*_call_*"))
    assert run() == [[1, 0], [1, 0]]  # loaded from the disk cache
    assert sorted(p.name for p in (tmp_path / "numba").rglob("*_call_*")) == files
