"""The fast solver against closed forms, and its defining properties."""

import numpy as np
import pytest

from etobs.errors import InputError, ModelError
from etobs.hybrid import HybridSystem, SaveAt, SolverOptions, Status, solve, solve_reference

from .systems import G, bouncing_ball, grazing_oscillator, two_clocks

BACKENDS = [solve, solve_reference]


@pytest.mark.parametrize("solver", BACKENDS)
def test_bouncing_ball_impact_times_match_closed_form(solver):
    # Drop from h0 at rest: first impact at sqrt(2 h0 / g); each bounce with speed
    # r*v lasts 2 r v / g.
    h0, r = 1.0, 0.5
    sol = solver(bouncing_ball(r), [h0, 0.0], (0.0, 1.2))
    v = np.sqrt(2 * G * h0)
    expected = [v / G]
    for _ in range(2):
        v *= r
        expected.append(expected[-1] + 2 * v / G)
    np.testing.assert_allclose(sol.jumps.t, expected, atol=1e-10)
    assert sol.status.tolist() == [Status.COMPLETED]


@pytest.mark.parametrize("method", ["dop853", "dopri5"])
def test_event_time_on_dense_output_is_accurate(method):
    sol = solve(grazing_oscillator(), [0.0, 1.0], (0.0, 20.0), options=SolverOptions(method=method))
    first = np.arcsin(0.999)
    # The crossing is grazing (g' = cos t ~ 0.045), so the time error is the state
    # error (~rtol = 1e-10) divided by g': bound the error in g, not in t.
    assert abs(sol.jumps.t[0] - first) * np.cos(first) < 1e-10
    assert len(sol.jumps) >= 6


@pytest.mark.parametrize("solver", BACKENDS)
def test_event_function_is_zero_from_below_at_every_event(solver):
    system = grazing_oscillator()
    sol = solver(system, [[0.0, 1.0], [0.5, 0.2]], (0.0, 15.0))
    assert len(sol.jumps) > 4
    for run in range(2):
        arc = sol.arcs[run]
        jumps = np.flatnonzero(np.diff(arc.j) == 1)
        for k in jumps:
            g_pre = system.guard(arc.t[k : k + 1], arc.x[k : k + 1])[0, 0]
            assert 0.0 <= g_pre < 1e-8
            assert arc.t[k] == arc.t[k + 1]


@pytest.mark.parametrize("solver", BACKENDS)
def test_a_short_excursion_inside_one_step_is_not_missed(solver):
    # Loose tolerances make steps of ~2 s while the event function is positive for
    # only 0.09 s around each peak. A sign test at step ends alone misses every event
    # (event_samples=1); the sampled guard with the parabolic peak probe finds them.
    loose = {"rtol": 1e-3, "atol": 1e-3}
    sign_only = solver(
        grazing_oscillator(), [0.0, 1.0], (0.0, 20.0), options=SolverOptions(event_samples=1, **loose)
    )
    guarded = solver(grazing_oscillator(), [0.0, 1.0], (0.0, 20.0), options=SolverOptions(**loose))
    tight = solve(grazing_oscillator(), [0.0, 1.0], (0.0, 20.0))
    if solver is solve:
        assert len(sign_only.jumps) == 0
    assert len(guarded.jumps) == len(tight.jumps) == 7


@pytest.mark.parametrize("solver", BACKENDS)
def test_simultaneous_events_jump_once_each_in_rule_order(solver):
    sol = solver(two_clocks(0.5, 0.25), [0.0, 0.0], (0.0, 1.01))
    log = sol.jumps
    at_half = np.flatnonzero(np.isclose(log.t, 0.5, atol=1e-9))
    assert log.rule[at_half].tolist() == [0, 1]
    assert np.diff(log.j[at_half]).tolist() == [1]
    assert np.bincount(log.rule).tolist() == [2, 4]


def test_max_jumps_stops_a_zeno_run_and_not_the_others():
    # The bouncing ball with restitution 0.5 is Zeno: infinitely many impacts before
    # t = 3 sqrt(2 h0 / g) = 1.35 s for h0 = 1. The second run, dropped from 40 m, has
    # not landed by t = 2 and completes.
    opts = SolverOptions(max_jumps=30)
    sol = solve(bouncing_ball(), [[1.0, 0.0], [40.0, 0.0]], (0.0, 2.0), options=opts)
    assert sol.status.tolist() == [Status.MAX_JUMPS, Status.COMPLETED]
    assert sol.j_final[0] == 30
    assert "max_jumps" in sol.messages()[0]
    alone = solve(bouncing_ball(), [40.0, 0.0], (0.0, 2.0), options=opts)
    np.testing.assert_array_equal(alone.x_final[0], sol.x_final[1])


def test_finite_escape_is_reported_per_run():
    # x' = x^2 escapes at t = 1/x0: run 0 (x0 = 1) blows up before t = 2, run 1 does not.
    system = HybridSystem(
        n=1,
        n_rules=0,
        flow=lambda t, x: x * x,
        guard=lambda t, x: np.empty((x.shape[0], 0)),
        jump=lambda k, t, x: x,
    )
    sol = solve(system, [[1.0], [-1.0]], (0.0, 2.0))
    assert sol.status[0] in (Status.NONFINITE, Status.STEP_UNDERFLOW)
    assert sol.t_final[0] < 1.0 + 1e-6
    assert sol.status[1] == Status.COMPLETED
    assert sol.x_final[1, 0] == pytest.approx(-1.0 / 3.0, rel=1e-9)


def test_max_steps_status():
    sol = solve(grazing_oscillator(), [0.0, 1.0], (0.0, 20.0), options=SolverOptions(max_steps=5))
    assert sol.status.tolist() == [Status.MAX_STEPS]
    assert "max_steps" in sol.messages()[0]


def test_grid_keeps_the_value_before_a_jump():
    sol = solve(two_clocks(0.5, 0.3), [0.0, 0.0], (0.0, 1.0), save=SaveAt(grid=[0.0, 0.25, 0.5, 0.75]))
    g = sol.grid
    np.testing.assert_allclose(g.x[0, :, 0], [0.0, 0.25, 0.5, 0.25], atol=1e-12)
    assert g.j[0, 2] < g.j[0, 3]


def test_grid_only_keeps_no_arcs():
    sol = solve(two_clocks(0.5, 0.3), [0.0, 0.0], (0.0, 1.0), save=SaveAt(steps=False, grid=[1.0]))
    assert sol.arcs is None
    np.testing.assert_allclose(sol.grid.x[0, 0], sol.x_final[0])


def test_initial_state_in_the_jump_set_jumps_at_t0():
    sol = solve(two_clocks(0.5, 0.3), [0.7, 0.0], (0.0, 0.1))
    assert sol.jumps.t.tolist() == [0.0]
    assert sol.x_final[0, 0] == pytest.approx(0.1)


def test_model_function_with_wrong_shape_is_named():
    bad = HybridSystem(
        n=2,
        n_rules=1,
        flow=lambda t, x: x[:, :1],
        guard=lambda t, x: -np.ones((len(t), 1)),
        jump=lambda k, t, x: x,
    )
    with pytest.raises(ModelError, match=r"`flow` returned an array of shape \(1, 1\); expected \(1, 2\)"):
        solve(bad, [0.0, 0.0], (0.0, 1.0))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"x0": [[0.0, np.nan]]}, r"`x0` must be finite; runs \[0\]"),
        ({"x0": [0.0, 0.0, 0.0]}, r"`x0` has shape \(3,\); expected \(2,\)"),
        ({"t_span": (1.0, 0.0)}, r"`t_span` must satisfy t0 <= t_end"),
        ({"t_span": 3.0}, r"`t_span` must be a pair"),
    ],
)
def test_bad_solve_arguments(kwargs, match):
    args = {"x0": [0.0, 0.0], "t_span": (0.0, 1.0)} | kwargs
    with pytest.raises(InputError, match=match):
        solve(two_clocks(1, 1), args["x0"], args["t_span"])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"method": "rk4"}, r"`method` must be one of \('dop853', 'dopri5'\); got 'rk4'"),
        ({"rtol": 0.0}, r"`rtol` must be >= 1e-14; got 0"),
        ({"atol": -1.0}, r"`atol` must be > 0; got -1"),
        ({"max_jumps": -1}, r"`max_jumps` must be an integer >= 0; got -1"),
        ({"event_samples": 0}, r"`event_samples` must be an integer >= 1; got 0"),
        ({"max_step": 0.0}, r"`max_step` must be > 0; got 0"),
    ],
)
def test_bad_options(kwargs, match):
    with pytest.raises(InputError, match=match):
        SolverOptions(**kwargs)


def test_bad_grid():
    with pytest.raises(InputError, match="`grid` must be strictly increasing"):
        SaveAt(grid=[0.0, 1.0, 1.0])


def test_unknown_keyword_is_a_type_error():
    with pytest.raises(TypeError):
        SolverOptions(rtl=1e-6)  # type: ignore[call-arg]
    with pytest.raises(TypeError):
        solve(two_clocks(1, 1), [0, 0], (0, 1), tolerance=1e-3)  # type: ignore[call-arg]


@pytest.mark.parametrize("solver", BACKENDS)
def test_first_step_survives_a_non_finite_trial_point(solver):
    # The flow is finite at x0 but NaN past x = 1, where the automatic first step's
    # trial Euler point lands; the run must still complete (it used to stall at t0).
    for bad in (np.nan, np.inf):
        system = HybridSystem(
            n=1,
            n_rules=0,
            flow=lambda t, x, bad=bad: np.where(x > 1, bad, 1 - x),
            guard=lambda t, x: np.empty((x.shape[0], 0)),
            jump=lambda k, t, x: x,
        )
        sol = solver(system, [0.9999], (0.0, 10.0), options=SolverOptions(max_steps=5000))
        assert sol.status.tolist() == [Status.COMPLETED]
        assert sol.x_final[0, 0] == pytest.approx(1 - 1e-4 * np.exp(-10.0), abs=1e-9)


def state_sensitive_system():
    """Unit rotation with g = K (r^2 - 1) + psi(t) - 10 c (c counts jumps).

    On the exact orbit r = 1, so g = psi(t) >= 0 for 0.30 s around t = 0.35. K is large
    so that a cubic Hermite interpolant's error over a 1 s step (which bends r^2 - 1 by
    about -1/K) hides the excursion; the method's own dense output does not.
    """
    K = 195.48248109138532

    def guard(t, x):
        psi = 0.26 - 1.26 * np.sin(np.pi * ((t % 1.0) - 0.5)) ** 2
        return (K * ((x[:, :2] ** 2).sum(1) - 1) + psi - 10 * x[:, 2])[:, None]

    def jump(k, t, x):
        out = x.copy()
        out[:, 2] += 1
        return out

    return HybridSystem(
        n=3,
        n_rules=1,
        guard=guard,
        jump=jump,
        flow=lambda t, x: np.stack([-x[:, 1], x[:, 0], 0 * x[:, 0]], 1),
    )


@pytest.mark.parametrize("solver", BACKENDS)
def test_long_excursion_of_a_state_sensitive_event_function_is_found(solver):
    opts = SolverOptions(first_step=1.0, max_step=1.0, rtol=1e-6, atol=1e-6)
    sol = solver(state_sensitive_system(), [1.0, 0.0, 0.0], (0.0, 3.0), options=opts)
    # psi(t) = 0 first at t = 0.5 - arcsin(sqrt(0.26/1.26))/pi
    expected = 0.5 - np.arcsin(np.sqrt(0.26 / 1.26)) / np.pi
    assert sol.jumps.t.tolist() == pytest.approx([expected], abs=2e-4)


@pytest.mark.parametrize("solver", BACKENDS)
def test_failure_reports_where_the_run_stopped(solver):
    # x' = x^2 escapes at t = 1; a clock rule jumps at t = 0.5 (the reference backend
    # used to report the start of its last segment instead of the escape point).
    system = HybridSystem(
        n=2,
        n_rules=1,
        flow=lambda t, x: np.stack([x[:, 0] ** 2, np.ones(x.shape[0])], 1),
        guard=lambda t, x: (x[:, 1] - 0.5)[:, None],
        jump=lambda k, t, x: x * [1, 0] - [0, 10],
    )
    sol = solver(system, [1.0, 0.0], (0.0, 2.0))
    assert sol.status[0] in (Status.STEP_UNDERFLOW, Status.NONFINITE)
    assert sol.t_final[0] == pytest.approx(1.0, abs=1e-6)
    assert sol.x_final[0, 0] > 1e6


def test_reference_max_steps():
    sol = solve_reference(two_clocks(0.1, 0.07), [0.0, 0.0], (0.0, 5.0), options=SolverOptions(max_steps=10))
    assert sol.status.tolist() == [Status.MAX_STEPS]
