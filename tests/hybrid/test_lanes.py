"""The engine's lanes: a run's numbers do not depend on its lane, and each ends on its own.

The engine advances ``LANES`` runs side by side per thread (:mod:`etobs.hybrid._kernel_body`).
These tests check the defining property of the design: every run gives bit for bit the
numbers it gives alone, whatever lane it had, however many lanes there were, whichever
runs shared its thread and however the batch was cut; and every way a run can end
(every :class:`Status`) happens in one lane while the other lanes complete.
"""

import numpy as np
import pytest

from etobs import SaveAt, SolverOptions, simulate
from etobs.examples import robot_arm
from etobs.hybrid import HybridSystem, Status
from etobs.hybrid.compiled import LANES, solve_compiled

# ---- every status in one lane ---------------------------------------------------------

COMPLETE, ZENO_, MANY_JUMPS, MANY_STEPS, ESCAPE, INF_JUMP, NAN_GUARD = range(7)


def _flow(t, x, p):
    mode = p[0]
    if mode == MANY_STEPS:
        dy = 1e4 * np.cos(1e4 * t)  # a fast oscillation: many small steps
    elif mode == ESCAPE:
        dy = x[0] * x[0]  # escapes to infinity at t = 1/y0: the step collapses there
    else:
        dy = -x[0]
    return np.array([dy, 1.0])


def _guard(t, x, p):
    mode = p[0]
    if mode == NAN_GUARD and t > 0.5:
        return np.array([np.nan])
    period = 1e-4 if mode == MANY_JUMPS else 0.25
    return np.array([x[1] - period])


def _jump(k, t, x, p):
    if p[0] == ZENO_:
        return np.array([x[0], x[1]])  # the clock is not reset: it jumps again at once
    if p[0] == INF_JUMP:
        return np.array([np.inf, 0.0])
    return np.array([x[0], 0.0])


def _modes():
    system = HybridSystem(n=2, n_rules=1, flow=_flow, guard=_guard, jump=_jump, params=[0.0])
    # completed runs around every failing one, more runs than lanes (lanes are refilled)
    modes = [COMPLETE, ZENO_, COMPLETE, MANY_JUMPS, MANY_STEPS, COMPLETE, ESCAPE, INF_JUMP, COMPLETE]
    modes += [NAN_GUARD, COMPLETE] + [COMPLETE, ESCAPE] * 4
    x0 = np.array([[1.0 + 0.1 * k, 0.0] for k in range(len(modes))])
    return system, np.array(modes, dtype=float)[:, None], x0


_OPTIONS = SolverOptions(max_jumps=2000, max_steps=20_000)
_EXPECTED = {
    COMPLETE: Status.COMPLETED,
    ZENO_: Status.ZENO,
    MANY_JUMPS: Status.MAX_JUMPS,
    MANY_STEPS: Status.MAX_STEPS,
    ESCAPE: Status.STEP_UNDERFLOW,
    INF_JUMP: Status.NONFINITE,
    NAN_GUARD: Status.MODEL_ERROR,
}


def _same_run(batch, b, alone):
    """Run ``b`` of ``batch`` gave bit for bit what ``alone`` (one run) gave."""
    assert batch.status[b] == alone.status[0]
    for key in ("t_final", "j_final", "x_final", "n_steps", "n_rejected"):
        np.testing.assert_array_equal(getattr(batch, key)[b], getattr(alone, key)[0], err_msg=key)
    assert batch.failures[b] == alone.failures[0]
    mine = batch.jumps.select(run=b)
    for key in ("rule", "t", "j", "x"):
        np.testing.assert_array_equal(getattr(mine, key), getattr(alone.jumps, key), err_msg=key)


@pytest.mark.parametrize("lanes", [None, 4])
def test_every_status_ends_one_lane_while_the_others_complete(lanes):
    system, modes, x0 = _modes()
    compiled = system.compiled()
    span = (0.0, 2.0)
    sol = solve_compiled(
        compiled,
        x0,
        span,
        params=modes,
        options=_OPTIONS,
        save=SaveAt(steps=False),
        lanes=lanes,
        parallel=False,
    )
    assert [Status(s) for s in sol.status] == [_EXPECTED[int(m)] for m in modes[:, 0]]
    assert "returned NaN" in sol.failures[list(modes[:, 0]).index(NAN_GUARD)]
    assert sol.lanes is not None and sol.lanes.width == (LANES if lanes is None else lanes)
    for b in range(len(modes)):
        alone = solve_compiled(
            compiled, x0[b], span, params=modes[b], options=_OPTIONS, save=SaveAt(steps=False), lanes=1
        )
        _same_run(sol, b, alone)


# ---- the numbers do not depend on lanes, threads or chunks ------------------------------


@pytest.fixture(scope="module")
def arm_batch():
    """40 runs of the robot arm for 3 s (more than two threads' lanes: lanes are refilled)."""
    rng = np.random.default_rng(3)
    x0 = rng.uniform(-2.0, 2.0, (40, 4))
    save = SaveAt(steps=False, grid=np.linspace(0.0, 3.0, 31), max_distance="estimation_error")
    return robot_arm(), x0, save


def _arm(problem, x0, save, **kw):
    res = simulate(problem, x0, 3.0, backend="engine", save=save, progress=False, **kw)
    return res.solution


def _same(a, b, rows=None):
    rows = np.arange(a.status.size) if rows is None else rows
    for key in ("status", "t_final", "j_final", "x_final", "n_steps", "n_rejected"):
        np.testing.assert_array_equal(getattr(a, key)[rows], getattr(b, key), err_msg=key)
    np.testing.assert_array_equal(a.grid_max.value[rows], b.grid_max.value)
    for k, r in enumerate(rows):
        x, y = a.jumps.select(run=r), b.jumps.select(run=k)
        for key in ("rule", "t", "j", "x"):
            np.testing.assert_array_equal(getattr(x, key), getattr(y, key), err_msg=key)


def test_a_run_gives_the_same_numbers_in_any_lane_batch_and_chunk(arm_batch, monkeypatch):
    from etobs.hybrid import compiled as comp

    problem, x0, save = arm_batch
    base = _arm(problem, x0, save)  # two threads of 20 runs in 16 lanes (the lane form)
    assert base.lanes.vector and base.lanes.width == LANES and base.lanes.events > 0
    assert np.all(base.status == Status.COMPLETED) and base.jumps.t.size > 100
    for lanes in (1, 5):  # fewer lanes: the one-run form, lane by lane
        monkeypatch.setattr(comp, "LANES", lanes)
        narrow = _arm(problem, x0, save)
        assert narrow.lanes.width == lanes and not narrow.lanes.vector
        _same(base, narrow)
    monkeypatch.undo()
    _same(base, _arm(problem, x0[::-1], save), rows=np.arange(39, -1, -1))  # other lanes, other neighbours
    _same(base, _arm(problem, x0[7:30], save), rows=np.arange(7, 30))  # a chunk
    _same(base, _arm(problem, x0[11:12], save), rows=np.array([11]))  # alone


def test_a_flow_that_leaves_its_constant_entries_unwritten_runs_in_one_lane():
    # guards against: the one-run path copying the flow's unwritten entries (n_flow on) from a
    # scratch that held the guard's values (more event functions than flowing entries): the
    # run ended with model_error ("nonzero derivative for an entry from n_flow on")
    from etobs import EstimationProblem, Node, Observer, Plant
    from etobs.model import Linear as Lin
    from etobs.model import Link, Network, StaticRule

    plant = Plant(f_p=lambda t, x, u, v: (-x[0],), h=lambda x: (x[0], 2.0 * x[0], 3.0 * x[0]), n_x=1, n_y=3)
    observer = Observer(f_o=lambda t, z, u, ybar, yhat: (ybar[0] - z[0],), n_z=1)
    nodes = [Node((i,), StaticRule(gamma=Lin(1.0), eps=0.05)) for i in range(3)]
    pb = EstimationProblem(plant, observer, nodes=nodes, network=Network(Link(delay=0.01), seed=1))
    assert pb.layout.n_flow < len(pb.rule_names)  # more event functions than flowing entries
    eng = simulate(pb, [1.0], 2.0, save=SaveAt(steps=False), progress=False)
    ref = simulate(pb, [1.0], 2.0, save=SaveAt(steps=False), backend="scipy")
    assert eng.backend == "engine" and eng.solution.status.tolist() == [Status.COMPLETED]
    assert eng.solution.jumps.rule.tolist() == ref.solution.jumps.rule.tolist()


@pytest.mark.parametrize(
    ("lanes", "match"), [(0, r"`lanes` must be an integer >= 1; got 0"), (2.5, r"`lanes`")]
)
def test_a_bad_lane_count_is_named(lanes, match):
    from etobs.errors import InputError, InputTypeError

    system, modes, x0 = _modes()
    with pytest.raises((InputError, InputTypeError), match=match):
        solve_compiled(system.compiled(), x0[:1], (0.0, 1.0), params=modes[:1], lanes=lanes)


def test_runs_share_their_parameters_only_when_every_bit_is_the_same():
    from etobs.hybrid.compiled import _shared

    P = np.array([[1.0, 0.0], [1.0, 0.0], [1.0, -0.0], [1.0 + 2e-16, 0.0]])
    assert _shared(P, np.array([0, 1])) and _shared(P, np.array([2])) and _shared(P, np.array([], dtype=int))
    assert not _shared(P, np.array([0, 2]))  # -0.0 is not 0.0 to a model's copysign or 1/p
    assert not _shared(P, np.array([1, 3]))
