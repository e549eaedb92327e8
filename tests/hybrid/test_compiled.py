"""The engine (compile_system + solve_compiled) against closed forms and the scipy reference.

The systems of ``systems.py`` are written once, for one run: ``system.compiled()`` is
their engine form (solved here with ``solve_compiled``), ``solve(..., backend="scipy")``
runs them on the scipy reference. The contract itself is checked on both backends in
``test_solver.py``; this file checks what is the engine's own (parameter rows, threads,
buffers, compilation, failures) and that its numbers match.
"""

import numba
import numpy as np
import pytest

from etobs.compile import functions as cfun
from etobs.errors import InputError, InputTypeError, ModelError
from etobs.hybrid import HybridSystem, SaveAt, SolverOptions, Status, _kernel, solve
from etobs.hybrid import compiled as comp
from etobs.hybrid.compiled import CompiledSystem, compile_system, solve_compiled
from etobs.hybrid.options import MAX_STEPS

from .systems import G, bouncing_ball, grazing_oscillator

X0 = np.array([[1.0, 0.0], [2.0, 1.0], [0.5, -1.0]])


@pytest.fixture(scope="module")
def ball():
    """The bouncing ball's engine form; ``p = (restitution, g)``."""
    return bouncing_ball().compiled()


def bounce_times(h0, v0, r, n, g=G):
    """Closed form: first impact from (h0, v0), then flights of 2 v_k / g."""
    v = np.sqrt(v0**2 + 2 * g * h0)  # impact speed
    t = (v0 + v) / g
    out = [t]
    for _ in range(n - 1):
        v *= r
        t += 2 * v / g
        out.append(t)
    return np.array(out)


# ---- against the closed form and the scipy reference ------------------------------------


def test_status_codes_match_the_enum():
    for status in Status:
        assert getattr(_kernel, status.name) == status.value


def test_ball_matches_closed_form_and_scipy_reference(ball):
    grid = np.linspace(0.0, 1.5, 31)
    save = SaveAt(steps=True, grid=grid)
    ours = solve_compiled(ball, X0, (0.0, 1.5), params=[0.8, G], save=save)
    sci = solve(bouncing_ball(0.8), X0, (0.0, 1.5), save=save, backend="scipy")
    # the front door passes the system's params to the same compiled system
    front = solve(bouncing_ball(0.8), X0, (0.0, 1.5), save=save, backend="engine")
    np.testing.assert_array_equal(front.jumps.t, ours.jumps.t)
    np.testing.assert_array_equal(front.grid.x, ours.grid.x)
    assert ours.backend == "engine" and ours.ok and sci.backend == "scipy"
    assert ours.rule_names == ("impact",)
    for r, (h0, v0) in enumerate(X0):
        t = ours.jumps.times(r, 0)
        assert t.size == sci.jumps.times(r, 0).size >= 1
        np.testing.assert_allclose(t, bounce_times(h0, v0, 0.8, t.size), rtol=0, atol=1e-9)
        np.testing.assert_allclose(t, sci.jumps.times(r, 0), rtol=0, atol=1e-9)
        # the arc holds both sides of every jump: j steps by one at each impact time
        arc = ours.arcs[r]
        at_jump = np.flatnonzero(np.diff(arc.j) == 1)
        np.testing.assert_array_equal(arc.t[at_jump], t)
        np.testing.assert_array_equal(arc.t[at_jump + 1], t)
        np.testing.assert_allclose(arc.x[at_jump + 1, 1], -0.8 * arc.x[at_jump, 1], rtol=1e-12)
    np.testing.assert_array_equal(ours.grid.j, sci.grid.j)
    np.testing.assert_allclose(ours.grid.x, sci.grid.x, atol=1e-8)
    np.testing.assert_allclose(ours.x_final, sci.x_final, atol=1e-8)


def test_short_excursions_are_found_at_loose_tolerances():
    # Loose tolerances make steps of ~2 s while the event function is positive for only
    # 0.09 s around each peak (test_solver checks that every backend finds all 7): the
    # engine finds them near where it does at tight tolerances, the scipy reference too.
    loose = SolverOptions(rtol=1e-3, atol=1e-3)
    x0, span = [0.0, 1.0], (0.0, 20.0)
    system = grazing_oscillator()
    guarded = solve_compiled(system.compiled(), x0, span, params=system.params, options=loose)
    tight = solve_compiled(system.compiled(), x0, span, params=system.params)
    sci = solve(system, x0, span, backend="scipy")
    assert len(guarded.jumps) == len(tight.jumps) == len(sci.jumps) == 7
    # at rtol = 1e-3 the crossings drift by integration error (0.084 s at most here)
    np.testing.assert_allclose(guarded.jumps.t, tight.jumps.t, rtol=0, atol=0.15)
    # grazing crossings (g' ~ 0.045): bound the error in g, not in t
    assert np.all(np.abs(tight.jumps.t - sci.jumps.t) * np.cos(np.arcsin(0.999)) < 1e-9)


@pytest.mark.slow
def test_dopri5_matches_closed_form(ball):
    opts = SolverOptions(method="dopri5", rtol=1e-9, atol=1e-9)
    save = SaveAt(steps=False)
    ours = solve_compiled(ball, X0, (0.0, 1.5), params=[0.8, G], options=opts, save=save)
    eight = solve_compiled(ball, X0, (0.0, 1.5), params=[0.8, G], save=save)
    assert ours.ok and not np.array_equal(ours.n_steps, eight.n_steps)  # another method ran
    for r, (h0, v0) in enumerate(X0):
        t = ours.jumps.times(r, 0)
        np.testing.assert_allclose(t, bounce_times(h0, v0, 0.8, t.size), rtol=0, atol=1e-8)


# ---- parameters, threads, buffers, limits ------------------------------------------------


def test_params_change_results_without_recompiling(ball):
    # One CompiledSystem, per-run rows of (restitution, g): dropped from rest at h, each
    # run's first impact is at sqrt(2 h / g) and then bounces with its own restitution.
    P = np.array([[0.5, 9.81], [0.8, 1.62], [0.9, 24.79]])
    h = np.array([1.0, 1.0, 0.5])
    addresses, compiled = ball.addresses, len(cfun._MEMO)
    sol = solve_compiled(ball, np.c_[h, np.zeros(3)], (0.0, 1.2), params=P, save=SaveAt(steps=False))
    assert ball.addresses == addresses and len(cfun._MEMO) == compiled  # nothing compiled
    assert sol.ok
    first = [sol.jumps.times(r, 0)[0] for r in range(3)]
    np.testing.assert_allclose(first, np.sqrt(2 * h / P[:, 1]), rtol=0, atol=1e-9)
    assert len(set(np.round(first, 6))) == 3
    for r in range(3):
        t = sol.jumps.times(r, 0)
        np.testing.assert_allclose(t, bounce_times(h[r], 0.0, P[r, 0], t.size, P[r, 1]), atol=1e-9)
    # one row for all runs
    same = solve_compiled(ball, np.c_[h, np.zeros(3)], (0.0, 1.2), params=P[1], save=SaveAt(steps=False))
    np.testing.assert_allclose(
        [same.jumps.times(r, 0)[0] for r in range(3)], np.sqrt(2 * h / P[1, 1]), atol=1e-9
    )


def test_per_run_parameters_and_thread_split_do_not_change_runs(ball):
    P = np.array([[0.5, G], [0.8, G], [0.9, G]])
    many = solve_compiled(ball, X0, (0.0, 1.0), params=P, save=SaveAt(steps=False))
    for r in range(3):
        one = solve_compiled(ball, X0[r], (0.0, 1.0), params=P[r], save=SaveAt(steps=False), parallel=False)
        np.testing.assert_array_equal(one.jumps.t, many.jumps.select(run=r).t)
        np.testing.assert_array_equal(one.x_final[0], many.x_final[r])


def test_small_buffers_are_regrown_without_changing_results(ball, monkeypatch):
    # With restitution 0.9 the ball dropped from (0.5, -1) is Zeno at t ~ 6.2 s: it stops
    # at max_jumps = 300 (without the limit it would make a million jumps), more than the
    # smallest first-pass buffer of 64 entries, so that run is solved again with room.
    opts, save = SolverOptions(max_jumps=300), SaveAt(steps=True)
    big = solve_compiled(ball, X0, (0.0, 8.0), params=[0.9, G], options=opts, save=save)
    monkeypatch.setattr(comp, "_BUFFER_BUDGET", 1)
    small = solve_compiled(ball, X0, (0.0, 8.0), params=[0.9, G], options=opts, save=save)
    assert big.status_labels() == small.status_labels() == ["completed", "completed", "max_jumps"]
    assert len(small.jumps) == len(big.jumps) > 300
    assert small.arcs[2].t.size > 2 * 300
    np.testing.assert_array_equal(small.jumps.t, big.jumps.t)
    for a, b in zip(small.arcs, big.arcs, strict=True):
        np.testing.assert_array_equal(a.x, b.x)


# ---- what a system can be made of ------------------------------------------------------


def _decay_rate(x):
    """A plain Python helper called by a flow: compiled with it."""
    return -1.5 * x


@numba.njit
def _double(k, t, x):
    return 2.0 * x


def test_helpers_njit_functions_and_systems_without_rules():
    system = compile_system(lambda t, x: _decay_rate(x), lambda t, x: np.array([0.5 - x[0]]), _double, 1, 1)
    sol = solve_compiled(system, [1.0], (0.0, 1.0))
    t_hit = np.log(2.0) / 1.5  # x = exp(-1.5 t) reaches 0.5 and is doubled back to 1
    np.testing.assert_allclose(sol.jumps.t, [t_hit, 2 * t_hit], atol=1e-9)
    np.testing.assert_allclose(sol.x_final[0, 0], np.exp(-1.5 * (1.0 - 2 * t_hit)), rtol=1e-9)
    free = compile_system(lambda t, x: -x, lambda t, x: np.zeros(0), _double, 1, 0)
    sol = solve_compiled(free, [[1.0], [2.0]], (0.0, 1.0))
    assert free.n_rules == 0 and len(sol.jumps) == 0 and sol.ok
    np.testing.assert_allclose(sol.x_final[:, 0], [np.exp(-1.0), 2 * np.exp(-1.0)], rtol=1e-9)


def test_wrong_shape_during_a_run_is_a_model_error_naming_the_function():
    def flow(t, x, p):
        if p[0] > 0 and x[0] < 0.5:  # the flagged run goes wrong half way down
            return np.zeros(3)
        return np.array([x[1], -G])

    system = compile_system(
        flow,
        lambda t, x, p: np.array([-x[0] if x[1] < 0 else -1.0]),
        lambda k, t, x, p: np.array([0.0, -0.5 * x[1]]),
        n=2,
        n_rules=1,
        n_params=1,
    )
    sol = solve_compiled(system, [[1.0, 0.0], [1.0, 0.0]], (0.0, 0.4), params=[[1.0], [0.0]])
    assert sol.status_labels() == ["model_error", "completed"]
    assert Status.MODEL_ERROR.label == "model_error"
    assert sol.failures[0].startswith("`flow` returned the wrong shape") and sol.failures[1] == ""
    assert "`flow` returned the wrong shape" in sol.messages()[0]
    assert 0.0 < sol.t_final[0] <= np.sqrt(2 * 0.5 / G)  # stopped before x = 0.5
    assert sol.t_final[1] == 0.4


class _Gain:
    def __call__(self, x):
        return 2.0 * x


def test_a_function_numba_cannot_compile_is_a_model_error():
    gain = _Gain()  # an arbitrary Python object

    def flow(t, x):
        return gain(x)

    with pytest.raises(ModelError, match=r"^`flow` cannot be compiled: .*backend='scipy'"):
        compile_system(flow, lambda t, x: x, lambda k, t, x: x, n=1, n_rules=1)
    with pytest.raises(ModelError, match="`jump` cannot be compiled"):
        compile_system(lambda t, x: x, lambda t, x: x, lambda k, t, x: gain.missing(x), n=1, n_rules=1)
    # the way out the message gives: the scipy reference runs any Python
    system = HybridSystem(n=1, n_rules=1, flow=flow, guard=lambda t, x: x - 2.0, jump=lambda k, t, x: x / 2)
    with pytest.raises(ModelError, match=r"^`flow` cannot be compiled: .*backend='scipy'"):
        solve(system, [1.0], (0.0, 1.0), backend="engine")
    sol = solve(system, [1.0], (0.0, 1.0), backend="scipy")
    t_hit = np.log(2.0) / 2.0  # x = exp(2 t) reaches 2 and is halved back to 1
    np.testing.assert_allclose(sol.jumps.t, [t_hit, 2 * t_hit], atol=1e-9)
    np.testing.assert_allclose(sol.x_final[0, 0], np.exp(2.0 * (1.0 - 2 * t_hit)), rtol=1e-8)


def test_bad_inputs_are_named(ball):
    with pytest.raises(InputError, match=r"`params` must have shape \(2,\) or \(3, 2\); got \(3,\)"):
        solve_compiled(ball, X0, (0.0, 1.0), params=[0.5, 0.5, 0.5])
    with pytest.raises(InputError, match="`params` is required: the system has n_params=2"):
        solve_compiled(ball, X0, (0.0, 1.0))
    with pytest.raises(InputError, match="`params` must be finite"):
        solve_compiled(ball, X0, (0.0, 1.0), params=[0.5, np.nan])
    with pytest.raises(InputError, match=r"`x0` .*"):
        solve_compiled(ball, [1.0, 2.0, 3.0], (0.0, 1.0), params=[0.5, G])
    with pytest.raises(InputTypeError, match="`system` must be a CompiledSystem; got HybridSystem"):
        solve_compiled(bouncing_ball(0.5), X0, (0.0, 1.0))
    with pytest.raises(InputError, match="`rule_names` has 2 names; expected n_rules=1"):
        compile_system(
            lambda t, x: x, lambda t, x: x, lambda k, t, x: x, n=1, n_rules=1, rule_names=("a", "b")
        )
    with pytest.raises(InputError, match="`n`"):
        compile_system(lambda t, x: x, lambda t, x: x, lambda k, t, x: x, n=0, n_rules=1)
    assert isinstance(ball, CompiledSystem)


# ---- silent cost: limits and progress by simulated time (issue 23, section 3) ------------


@pytest.fixture(scope="module")
def clock():
    """``x' = 1`` without rules: the error estimate is zero, so only ``max_step`` bounds the steps."""
    return compile_system(
        lambda t, x: np.ones(1), lambda t, x: np.full(1, -1.0), lambda k, t, x: x, n=1, n_rules=0
    )


@pytest.fixture(scope="module")
def spring():
    """``x'' = -x`` without rules: steps of a fixed size however long the horizon."""
    return compile_system(
        lambda t, x: np.array([x[1], -x[0]]),
        lambda t, x: np.full(1, -1.0),
        lambda k, t, x: x,
        n=2,
        n_rules=0,
    )


@pytest.mark.parametrize(
    ("t_end", "options"),
    [(1e300, SolverOptions()), (1.0, SolverOptions(max_step=1e-12))],
    ids=["t_end=1e300", "max_step=1e-12"],
)
def test_a_runaway_run_ends_at_the_default_step_limit_with_a_status_naming_it(spring, t_end, options):
    # issue 23: t_end=1e300 or max_step=1e-12 ran 10,000,000 steps (the robot arm: 107 s
    # for max_step=1e-12, several minutes for t_end=1e300) before a word; the default now
    # stops it at 2,000,000 (about 20 s of the robot arm) with status max_steps
    assert SolverOptions().max_steps == MAX_STEPS == 2_000_000
    sol = solve_compiled(spring, [1.0, 0.0], (0.0, t_end), options=options, save=SaveAt(steps=False))
    assert sol.status.tolist() == [Status.MAX_STEPS]
    assert int(sol.n_steps[0] + sol.n_rejected[0]) == 2_000_000
    assert sol.t_final[0] < t_end
    assert "increase `SolverOptions(max_steps=...)`" in sol.messages()[0]


def test_the_step_limit_is_exact_on_both_sides(clock):
    # 1 s at max_step = 0.125 takes 8 steps: a run that needs max_steps steps completes,
    # one that needs one more stops with max_steps
    opts = {"max_step": 0.125, "first_step": 0.125}
    for limit, status in ((9, Status.COMPLETED), (8, Status.COMPLETED), (7, Status.MAX_STEPS)):
        sol = solve_compiled(clock, [0.0], (0.0, 1.0), options=SolverOptions(max_steps=limit, **opts))
        assert sol.status.tolist() == [status], limit
        assert sol.n_steps.tolist() == [min(limit, 8)]


def test_progress_reports_the_simulated_time_of_a_single_run(clock, monkeypatch):
    # issue 23: a single long run showed nothing until it ended (the engine reported whole
    # runs only); it now reports the time reached while the run goes on
    monkeypatch.setattr(comp, "POLL", 1e-3)
    opts = SolverOptions(max_step=2e-6, first_step=2e-6)  # 500,000 steps
    calls = []
    sol = solve_compiled(
        clock, [0.0], (0.0, 1.0), options=opts, save=SaveAt(steps=False), progress=calls.append
    )
    plain = solve_compiled(clock, [0.0], (0.0, 1.0), options=opts, save=SaveAt(steps=False))
    done = np.cumsum(calls)
    assert sol.ok and done[-1] == pytest.approx(1.0, rel=1e-12)
    assert np.any((done > 0.0) & (done < 1.0))  # a report while the run was going on
    assert all(c > 0 for c in calls)
    np.testing.assert_array_equal(sol.x_final, plain.x_final)
    np.testing.assert_array_equal(sol.n_steps, plain.n_steps)


def test_progress_counts_a_run_that_stops_early_as_done(clock):
    # a run stopped by a limit reports its whole share: the calls sum to B
    calls = []
    opts = SolverOptions(max_steps=10)
    sol = solve_compiled(clock, np.zeros((3, 1)), (-5.0, 1e300), options=opts, progress=calls.append)
    assert sol.status.tolist() == [Status.MAX_STEPS] * 3
    assert sum(calls) == pytest.approx(3.0, rel=1e-12)


def test_an_exception_in_the_watched_solve_reaches_the_caller(ball, monkeypatch):
    def broken(*args):
        raise RuntimeError("kernel gone")

    monkeypatch.setattr(comp, "_call", broken)
    with pytest.raises(RuntimeError, match="kernel gone"):
        solve_compiled(ball, X0, (0.0, 1.0), params=[0.8, G], progress=lambda k: None)
