"""The solver contract (module docstring of etobs.hybrid.solver) on every backend.

One contract, two solvers: each contract test takes the ``backend`` fixture and runs
on the compiled engine and the scipy reference, against closed forms and the contract's
defining properties. Tests about one solver's own behaviour
(the batched form's messages, where a wrong shape surfaces) say which solver they cover.
"""

import numpy as np
import pytest

from etobs.errors import InputError
from etobs.hybrid import BatchedSystem, HybridSystem, SaveAt, SolverOptions, Status, solve
from etobs.hybrid.options import step_grid

from .systems import (
    G,
    bouncing_ball,
    clipped_clock,
    cubed_clock,
    grazing_oscillator,
    late_clock,
    twin_grazers,
    two_clocks,
)

BACKENDS = ("engine", "scipy")


@pytest.fixture(params=BACKENDS)
def backend(request):
    return request.param


def _no_guard(t, x):
    return np.zeros(0)


def _keep(k, t, x):
    return x


# ---- the contract, on every backend --------------------------------------------------


def test_bouncing_ball_impact_times_match_closed_form(backend):
    # Drop from h0 at rest: first impact at sqrt(2 h0 / g); each bounce with speed
    # r*v lasts 2 r v / g.
    h0, r = 1.0, 0.5
    sol = solve(bouncing_ball(r), [h0, 0.0], (0.0, 1.2), backend=backend)
    v = np.sqrt(2 * G * h0)
    expected = [v / G]
    for _ in range(2):
        v *= r
        expected.append(expected[-1] + 2 * v / G)
    np.testing.assert_allclose(sol.jumps.t, expected, atol=1e-10)
    assert sol.status.tolist() == [Status.COMPLETED]
    assert sol.backend == backend
    assert sol.rule_names == ("impact",)


def test_entry_into_a_jump_set_where_the_guard_is_flat_at_zero_is_exact(backend):
    # min(tau - 1, 0) is 0 on all of tau >= 1: every point there is a root of the guard.
    # Before, the reference's brentq stopped at whichever it met: jumps at 1.0106,
    # 2.1242, 3.1396 (the engine and the closed form: 1, 2, 3)
    xtol = SolverOptions().event_xtol
    sol = solve(clipped_clock(1.0), [0.0], (0.0, 3.5), backend=backend)
    assert sol.status_labels() == ["completed"]
    t = sol.jumps.t
    assert len(t) == 3
    # each jump is at most event_xtol after the entry, and the clock restarts there
    periods = np.diff(np.concatenate([[0.0], t]))
    assert np.all(periods >= 1.0 - 1e-14), periods - 1.0
    assert np.all(periods <= 1.0 + xtol), periods - 1.0


def test_a_jump_due_at_the_final_time_is_not_applied_on_either_backend(backend):
    # min(t - 1.5, tau - 0.5) >= 0: jumps at 1.5, 2, 2.5, 3. Before, the one at t_end = 3
    # was kept by the reference (3.0) and dropped by the engine (its clock 5e-13 late):
    # kept or dropped by rounding. Rule (docs/solver.md): a jump within event_xtol of
    # t_end is not applied, and the run ends on its flow at t_end.
    sol = solve(late_clock(1.5, 0.5), [0.0], (0.0, 3.0), backend=backend)
    assert sol.status_labels() == ["completed"]
    np.testing.assert_allclose(sol.jumps.t, [1.5, 2.0, 2.5], atol=1e-11)
    assert sol.t_final[0] == 3.0
    assert sol.x_final[0, 0] == pytest.approx(0.5, abs=1e-11)  # flowed on, not reset


@pytest.mark.parametrize(("past_end", "jumps"), [(-0.5, 1), (0.5, 1), (5.0, 2)])
def test_the_final_time_rule_on_both_sides_of_its_boundary(backend, past_end, jumps):
    # jumps at 1.5 and 3: with t_end = 3 + past_end * event_xtol the jump at 3 is applied
    # only when it is more than event_xtol before t_end (a coarse event_xtol keeps the
    # boundary far from rounding)
    xtol = 1e-6
    options = SolverOptions(event_xtol=xtol)
    t_end = 3.0 + past_end * xtol
    sol = solve(late_clock(1.5, 1.5), [0.0], (0.0, t_end), options=options, backend=backend)
    assert sol.status_labels() == ["completed"]
    assert len(sol.jumps) == jumps, sol.jumps.t
    np.testing.assert_allclose(sol.jumps.t, [1.5, 3.0][:jumps], atol=2 * xtol)
    assert sol.t_final[0] == t_end


def test_two_crossings_between_the_same_samples_jump_at_the_earlier_root(backend):
    # guards against: the later of two roots in one bracket taken (the reference is the
    # oracle of every agreement test). Clocks of periods 1 and 1 + 1e-4 cross 1e-4 s
    # apart, inside one sub-interval of the long steps of a constant flow: each rule
    # jumps at its own closed-form time, rule 0 first.
    sol = solve(two_clocks(1.0, 1.0 + 1e-4), [0.0, 0.0], (0.0, 2.5), backend=backend)
    assert sol.status_labels() == ["completed"]
    log = sol.jumps
    assert log.rule.tolist() == [0, 1, 0, 1]
    np.testing.assert_allclose(log.t, [1.0, 1.0001, 2.0, 2.0002], rtol=0, atol=5e-12)
    assert sol.n_steps[0] < 20  # long steps: both crossings lie between the same samples


def test_two_excursions_found_between_the_same_samples_jump_at_the_earlier_root(backend):
    # the same inside one step: no sign change at the step ends, so the sampled bracket
    # (not solve_ivp's own event) holds both crossings; rule 1 (sin(t + d) > level) enters
    # first, at arcsin(level) - d
    level, d = 0.999, 1e-4
    sol = solve(twin_grazers(level, d), [0.0, 1.0], (0.0, 1.6), backend=backend)
    assert sol.status_labels() == ["completed"]
    log = sol.jumps
    assert log.rule.tolist() == [1]
    # the grazing crossing (speed 0.045) turns a state error of rtol into 2e-9 s
    assert log.t[0] == pytest.approx(np.arcsin(level) - d, abs=1e-8)


@pytest.mark.parametrize("period", [0.3, 15.0, 40.0])
def test_jump_times_are_within_event_xtol_on_long_steps(backend, period):
    # guards against: the event tolerance no longer scaled by the step length (a bracket
    # of event_xtol in the step's unit interval is h * event_xtol in time: 15x on a 15 s
    # step). The guard (tau - period)^3 has zero slope at its root, so the located time
    # is as good as the bracket; each jump is at most event_xtol after the entry.
    xtol = 1e-6
    options = SolverOptions(event_xtol=xtol)
    sol = solve(cubed_clock(period), [0.0], (0.0, 3.5 * period), options=options, backend=backend)
    assert sol.status_labels() == ["completed"]
    assert len(sol.jumps) == 3
    late = np.diff(np.concatenate([[0.0], sol.jumps.t])) - period
    assert np.all(late >= -1e-12 * period), late
    assert np.all(late <= xtol), late / xtol


@pytest.mark.parametrize("method", ["dop853", "dopri5"])
def test_event_time_on_dense_output_is_accurate(backend, method):
    # (the scipy reference ignores `method`: it always runs solve_ivp's DOP853)
    options = SolverOptions(method=method)
    sol = solve(grazing_oscillator(), [0.0, 1.0], (0.0, 20.0), options=options, backend=backend)
    first = np.arcsin(0.999)
    # The crossing is grazing (g' = cos t ~ 0.045), so the time error is the state
    # error (~rtol = 1e-10) divided by g': bound the error in g, not in t.
    assert abs(sol.jumps.t[0] - first) * np.cos(first) < 1e-10
    assert len(sol.jumps) >= 6


def test_event_function_is_zero_from_below_at_every_event(backend):
    system = grazing_oscillator()
    sol = solve(system, [[0.0, 1.0], [0.5, 0.2]], (0.0, 15.0), backend=backend)
    assert len(sol.jumps) > 4
    for run in range(2):
        arc = sol.arcs[run]
        jumps = np.flatnonzero(np.diff(arc.j) == 1)
        assert jumps.size == len(sol.jumps.select(run=run))
        for k in jumps:
            g_pre = system.call_guard(arc.t[k], arc.x[k])[0]
            assert 0.0 <= g_pre < 1e-8
            assert arc.t[k] == arc.t[k + 1]


def test_a_short_excursion_inside_one_step_is_not_missed(backend):
    # Loose tolerances make steps of ~2 s while the event function is positive for
    # only 0.09 s around each peak. A sign test at step ends alone misses every event
    # (event_samples=1), on the scipy reference too (solve_ivp's own sign test is at
    # step ends); the sampled guard with the parabolic peak probe finds them all.
    loose = {"rtol": 1e-3, "atol": 1e-3}
    x0, span = [0.0, 1.0], (0.0, 20.0)
    system = grazing_oscillator()
    sign_only = solve(system, x0, span, options=SolverOptions(event_samples=1, **loose), backend=backend)
    guarded = solve(system, x0, span, options=SolverOptions(**loose), backend=backend)
    tight = solve(system, x0, span, backend=backend)
    assert len(sign_only.jumps) == 0
    # 7 = the closed form: the mirror jump sends sin t from 0.999 to -0.999, so events lie
    # at t_k = (2k + 1) arcsin(0.999) = 1.526 (2k + 1), and t_6 = 19.84 < 20 < t_7
    assert len(guarded.jumps) == len(tight.jumps) == 7
    np.testing.assert_allclose(tight.jumps.t, (2 * np.arange(7) + 1) * np.arcsin(0.999), rtol=0, atol=1e-6)


def test_simultaneous_events_jump_once_each_in_rule_order(backend):
    # Clocks of periods 0.5 (rule 0) and 0.25 (rule 1): rule 1 alone at 0.25 and 0.75,
    # both at 0.5 and 1.0, rule 0 first. The engine jumps both at
    # one time; the scipy reference may find rule 1 a rounding error later (its clock
    # restarted at a located time), within the event accuracy `event_xtol`.
    sol = solve(two_clocks(0.5, 0.25), [0.0, 0.0], (0.0, 1.01), backend=backend)
    log = sol.jumps
    assert log.rule.tolist() == [1, 0, 1, 1, 0, 1]
    np.testing.assert_allclose(log.t, [0.25, 0.5, 0.5, 0.75, 1.0, 1.0], rtol=0, atol=1e-9)
    assert log.j.tolist() == list(range(6))
    xtol = SolverOptions().event_xtol
    assert abs(log.t[2] - log.t[1]) <= xtol and abs(log.t[5] - log.t[4]) <= xtol
    if backend != "scipy":
        assert log.t[1] == log.t[2] and log.t[4] == log.t[5]


def test_max_jumps_stops_a_zeno_run_and_not_the_others(backend):
    # The bouncing ball with restitution 0.5 is Zeno: infinitely many impacts before
    # t = 3 sqrt(2 h0 / g) = 1.35 s for h0 = 1. The second run, dropped from 40 m, has
    # not landed by t = 2 and completes.
    opts = SolverOptions(max_jumps=30)
    sol = solve(bouncing_ball(), [[1.0, 0.0], [40.0, 0.0]], (0.0, 2.0), options=opts, backend=backend)
    assert sol.status.tolist() == [Status.MAX_JUMPS, Status.COMPLETED]
    assert sol.j_final[0] == 30 and len(sol.jumps.select(run=0)) == 30
    assert "max_jumps" in sol.messages()[0]
    alone = solve(bouncing_ball(), [40.0, 0.0], (0.0, 2.0), options=opts, backend=backend)
    np.testing.assert_array_equal(alone.x_final[0], sol.x_final[1])


def _square(t, x):
    return x * x


def test_finite_escape_is_reported_per_run(backend):
    # x' = x^2 escapes at t = 1/x0: run 0 (x0 = 1) blows up before t = 2, run 1 does not.
    system = HybridSystem(n=1, n_rules=0, flow=_square, guard=_no_guard, jump=_keep)
    sol = solve(system, [[1.0], [-1.0]], (0.0, 2.0), backend=backend)
    assert sol.status[0] in (Status.NONFINITE, Status.STEP_UNDERFLOW)
    assert sol.t_final[0] < 1.0 + 1e-6
    assert sol.status[1] == Status.COMPLETED
    assert sol.x_final[1, 0] == pytest.approx(-1.0 / 3.0, rel=1e-9)


def _explosive(t, x):
    return 1e200 * x


def test_a_first_step_of_zero_ends_the_run_with_a_status_not_a_hang_or_an_exception(backend):
    # x' = 1e200 x: the scaled norm of the flow overflows, so the automatic first step is
    # 0 (the engine divided by it: ZeroDivisionError; a zero step never moves t)
    system = HybridSystem(n=1, n_rules=0, flow=_explosive, guard=_no_guard, jump=_keep)
    sol = solve(system, [[1.0], [0.0]], (0.0, 1.0), backend=backend)
    assert sol.status[0] in (Status.STEP_UNDERFLOW, Status.NONFINITE)
    assert sol.t_final[0] < 1.0
    assert sol.status[1] == Status.COMPLETED  # x = 0 stays 0


def test_a_tiny_first_step_grows_and_completes(backend):
    system = HybridSystem(
        n=2, n_rules=0, flow=lambda t, x: np.array([x[1], -x[0]]), guard=_no_guard, jump=_keep
    )
    sol = solve(system, [1.0, 0.0], (0.0, 1.0), options=SolverOptions(first_step=1e-300), backend=backend)
    assert sol.status.tolist() == [Status.COMPLETED]
    assert sol.x_final[0, 0] == pytest.approx(np.cos(1.0), rel=1e-8)


def test_max_steps_status(backend):
    # The scipy reference checks max_steps between flow segments only (after a jump),
    # so it stops later than the others, but with the same status.
    options = SolverOptions(max_steps=5)
    sol = solve(grazing_oscillator(), [0.0, 1.0], (0.0, 20.0), options=options, backend=backend)
    assert sol.status.tolist() == [Status.MAX_STEPS]
    assert "max_steps" in sol.messages()[0]
    assert sol.t_final[0] < 20.0
    clocks = solve(
        two_clocks(0.1, 0.07), [0.0, 0.0], (0.0, 5.0), options=SolverOptions(max_steps=10), backend=backend
    )
    assert clocks.status.tolist() == [Status.MAX_STEPS]


def test_grid_keeps_the_value_before_a_jump(backend):
    save = SaveAt(grid=[0.0, 0.25, 0.5, 0.75])
    sol = solve(two_clocks(0.5, 0.3), [0.0, 0.0], (0.0, 1.0), save=save, backend=backend)
    g = sol.grid
    np.testing.assert_allclose(g.x[0, :, 0], [0.0, 0.25, 0.5, 0.25], atol=1e-12)
    assert g.j[0, 2] < g.j[0, 3]


def test_grid_only_keeps_no_arcs(backend):
    save = SaveAt(steps=False, grid=[1.0])
    sol = solve(two_clocks(0.5, 0.3), [0.0, 0.0], (0.0, 1.0), save=save, backend=backend)
    assert sol.arcs is None
    np.testing.assert_allclose(sol.grid.x[0, 0], sol.x_final[0])


def test_max_distance_is_the_grid_maximum_without_keeping_the_grid(backend):
    # the two clocks' distance |x0 - x1| on a grid crossing both resets, and the
    # distance of x0 to itself and x1 (two pairs): the same maximum as from the kept grid
    grid = np.linspace(0.0, 2.0, 81)
    x0 = [[0.0, 0.0], [0.1, 0.05]]
    args = (two_clocks(0.5, 0.3), x0, (0.0, 2.0))
    full = solve(*args, save=SaveAt(steps=False, grid=grid), backend=backend)
    for pairs in (([0], [1]), ([0, 1], [1, 1])):
        sol = solve(*args, save=SaveAt(steps=False, grid=grid, max_distance=pairs), backend=backend)
        assert sol.grid is None and sol.arcs is None
        d = full.grid.x[..., pairs[0]] - full.grid.x[..., pairs[1]]
        np.testing.assert_allclose(sol.grid_max.value, np.sqrt((d * d).sum(axis=-1)).max(axis=1), rtol=1e-15)
        np.testing.assert_array_equal(sol.grid_max.t, grid)
        assert np.all(sol.grid_max.value > 0)
    # same jumps and steps as when the grid is kept
    np.testing.assert_array_equal(sol.jumps.t, full.jumps.t)
    np.testing.assert_array_equal(sol.n_steps, full.n_steps)


def test_max_distance_is_nan_for_a_run_that_stops_before_the_grid_ends(backend):
    system = HybridSystem(n=1, n_rules=0, flow=_square, guard=_no_guard, jump=_keep)
    save = SaveAt(steps=False, grid=np.linspace(0.0, 2.0, 21), max_distance=([0], [0]))
    sol = solve(system, [[1.0], [-1.0]], (0.0, 2.0), save=save, backend=backend)
    assert np.isnan(sol.grid_max.value[0]) and sol.grid_max.value[1] == 0.0


def test_max_distance_is_nan_when_grid_points_lie_before_the_start(backend):
    pairs = ([0], [1])
    args = (two_clocks(0.5, 0.3), [0.0, 0.0], (0.75, 2.0))
    for grid, n in (([0.5, 1.0, 1.5], 1), ([0.2, 0.4], 2)):
        with pytest.warns(
            RuntimeWarning, match=rf"`save.grid`: {n} of {len(grid)} points lie before t0 = 0.75"
        ):
            sol = solve(*args, save=SaveAt(steps=False, grid=grid, max_distance=pairs), backend=backend)
        assert np.isnan(sol.grid_max.value[0])
    sol = solve(*args, save=SaveAt(steps=False, grid=[0.75, 1.5], max_distance=pairs), backend=backend)
    assert np.isfinite(sol.grid_max.value[0])  # t0 itself is reached: nothing said


def test_grid_points_past_t_end_are_said_and_nan_and_t_end_itself_is_reached(backend):
    """np.arange(1, 2 + 1e-9, 0.1) ends a rounding error past 2.0: said, not left NaN in silence."""
    pairs = ([0], [1])
    args = (two_clocks(0.5, 0.3), [0.0, 0.0], (0.0, 2.0))
    past = [1.0, np.nextafter(2.0, 3.0)]
    with pytest.warns(
        RuntimeWarning, match=r"1 of 2 points lie after t_end = 2.0 \(the last at 2.0000000000000004"
    ) as said:
        sol = solve(*args, save=SaveAt(steps=False, grid=past, max_distance=pairs), backend=backend)
    assert [w.filename for w in said] == [__file__]  # the caller's line, to filter by module
    assert np.isnan(sol.grid_max.value[0])
    with pytest.warns(RuntimeWarning, match=r"np.linspace\(start, t_end, n\) rather than np.arange"):
        kept = solve(*args, save=SaveAt(steps=False, grid=past), backend=backend)
    assert np.isfinite(kept.grid.x[0, 0]).all() and np.isnan(kept.grid.x[0, 1]).all()
    sol = solve(*args, save=SaveAt(steps=False, grid=[1.0, 2.0], max_distance=pairs), backend=backend)
    assert np.isfinite(sol.grid_max.value[0])  # t_end itself: reached, nothing said


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"max_distance": ([0], [1])}, r"`max_distance` needs a `grid`"),
        ({"grid": [1.0], "max_distance": ([0, 1], [1])}, r"two equal-length, non-empty lists of state"),
        ({"grid": [1.0], "max_distance": ([], [])}, r"two equal-length, non-empty lists"),
        ({"grid": [1.0], "max_distance": ([0.5], [1])}, r"two equal-length, non-empty lists"),
        (
            {"grid": [1.0], "max_distance": "error"},
            r"a pair of index lists or 'estimation_error'; got 'error'",
        ),
    ],
)
def test_bad_max_distance(kwargs, match):
    with pytest.raises(InputError, match=match):
        SaveAt(**kwargs)


def test_max_distance_indices_and_names_are_checked_by_the_solve(backend):
    args = (two_clocks(0.5, 0.3), [0.0, 0.0], (0.0, 1.0))
    with pytest.raises(InputError, match=r"`max_distance` indices must lie in 0 .. 1 \(the state size\)"):
        solve(*args, save=SaveAt(grid=[0.5], max_distance=([0], [2])), backend=backend)
    with pytest.raises(InputError, match=r"'estimation_error'` needs an estimation problem"):
        solve(*args, save=SaveAt(grid=[0.5], max_distance="estimation_error"), backend=backend)


def test_initial_state_in_the_jump_set_jumps_at_t0(backend):
    sol = solve(two_clocks(0.5, 0.3), [0.7, 0.0], (0.0, 0.1), backend=backend)
    assert sol.jumps.t.tolist() == [0.0]
    assert sol.x_final[0, 0] == pytest.approx(0.1)


def _nan_past_one(bad):
    def flow(t, x):
        return np.array([bad if x[0] > 1 else 1 - x[0]])

    return flow


def test_first_step_survives_a_non_finite_trial_point(backend):
    # The flow is finite at x0 but NaN past x = 1, where the automatic first step's
    # trial Euler point lands; the run must still complete (it used to stall at t0).
    for bad in (np.nan, np.inf):
        system = HybridSystem(n=1, n_rules=0, flow=_nan_past_one(bad), guard=_no_guard, jump=_keep)
        sol = solve(system, [0.9999], (0.0, 10.0), options=SolverOptions(max_steps=5000), backend=backend)
        assert sol.status.tolist() == [Status.COMPLETED]
        assert sol.x_final[0, 0] == pytest.approx(1 - 1e-4 * np.exp(-10.0), abs=1e-9)


# On the exact orbit r = 1 the event function is psi(t) >= 0 for 0.30 s around t = 0.35.
# K is large so that a cubic Hermite interpolant's error over a 1 s step (which bends
# r^2 - 1 by about -1/K) hides the excursion; the method's own dense output does not.
_K = 195.48248109138532


def _rotate_and_count(t, x):
    return np.array([-x[1], x[0], 0.0])


def _state_sensitive(t, x):
    # g = K (r^2 - 1) + psi(t) - 10 c, where c = x[2] counts the jumps
    psi = 0.26 - 1.26 * np.sin(np.pi * ((t % 1.0) - 0.5)) ** 2
    return np.array([_K * (x[0] ** 2 + x[1] ** 2 - 1) + psi - 10 * x[2]])


def _count(k, t, x):
    return np.array([x[0], x[1], x[2] + 1])


def test_long_excursion_of_a_state_sensitive_event_function_is_found(backend):
    system = HybridSystem(n=3, n_rules=1, flow=_rotate_and_count, guard=_state_sensitive, jump=_count)
    opts = SolverOptions(first_step=1.0, max_step=1.0, rtol=1e-6, atol=1e-6)
    sol = solve(system, [1.0, 0.0, 0.0], (0.0, 3.0), options=opts, backend=backend)
    # psi(t) = 0 first at t = 0.5 - arcsin(sqrt(0.26/1.26))/pi
    expected = 0.5 - np.arcsin(np.sqrt(0.26 / 1.26)) / np.pi
    assert sol.jumps.t.tolist() == pytest.approx([expected], abs=2e-4)


def _escape_and_clock(t, x):
    return np.array([x[0] ** 2, 1.0])


def _clock_at_half(t, x):
    return np.array([x[1] - 0.5])


def _clock_away(k, t, x):
    return np.array([x[0], -10.0])


def test_failure_reports_where_the_run_stopped(backend):
    # x' = x^2 escapes at t = 1; a clock rule jumps at t = 0.5 (the reference backend
    # used to report the start of its last segment instead of the escape point).
    system = HybridSystem(n=2, n_rules=1, flow=_escape_and_clock, guard=_clock_at_half, jump=_clock_away)
    sol = solve(system, [1.0, 0.0], (0.0, 2.0), backend=backend)
    assert sol.jumps.t.tolist() == pytest.approx([0.5], abs=1e-9)
    assert sol.status[0] in (Status.STEP_UNDERFLOW, Status.NONFINITE)
    assert sol.t_final[0] == pytest.approx(1.0, abs=1e-6)
    assert sol.x_final[0, 0] > 1e6


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"x0": [[0.0, np.nan]]}, r"`x0` must be finite; runs \[0\]"),
        ({"x0": [0.0, 0.0, 0.0]}, r"`x0` has shape \(3,\); expected \(2,\)"),
        ({"t_span": (1.0, 0.0)}, r"`t_span` must satisfy t0 <= t_end"),
        ({"t_span": 3.0}, r"`t_span` must be a pair"),
    ],
)
def test_bad_solve_arguments(backend, kwargs, match):
    args = {"x0": [0.0, 0.0], "t_span": (0.0, 1.0)} | kwargs
    with pytest.raises(InputError, match=match):
        solve(two_clocks(1, 1), args["x0"], args["t_span"], backend=backend)


# ---- a function returning the wrong shape: where each backend reports it --------------


def _flow_too_short(t, x):
    return x[:1]


def _guard_too_long(t, x):
    return np.array([-1.0, -1.0])


def _jump_too_short(k, t, x):
    return x[:1]


def _start_jumping(t, x):
    return np.array([1.0])


def _free_fall(t, x):
    return np.array([x[1], -G])


def _bad_system(name):
    """Two states, one rule; ``name`` returns the wrong shape (the jump fires at t0)."""
    if name == "flow":
        return HybridSystem(
            n=2, n_rules=1, flow=_flow_too_short, guard=lambda t, x: np.array([-1.0]), jump=_keep
        )
    if name == "guard":
        return HybridSystem(n=2, n_rules=1, flow=_free_fall, guard=_guard_too_long, jump=_keep)
    return HybridSystem(n=2, n_rules=1, flow=_free_fall, guard=_start_jumping, jump=_jump_too_short)


@pytest.mark.parametrize("name", ["flow", "guard", "jump"])
def test_wrong_shape_is_a_model_error_status_on_the_engine(name):
    sol = solve(_bad_system(name), [[0.0, 0.0], [1.0, 0.0]], (0.0, 1.0), backend="engine")
    assert sol.status_labels() == ["model_error", "model_error"]
    assert sol.failures == (f"`{name}` returned the wrong shape",) * 2
    assert f"`{name}` returned the wrong shape" in sol.messages()[0]


@pytest.mark.parametrize(("name", "got", "expected"), [("flow", 1, 2), ("guard", 2, 1), ("jump", 1, 2)])
def test_wrong_shape_is_a_model_error_status_on_the_scipy_reference(name, got, expected):
    # the reference calls the Python functions as they are and checks each result; the
    # failure ends the run with a status, as on the engine (it raised out of the solve)
    sol = solve(_bad_system(name), [[0.0, 0.0], [1.0, 0.0]], (0.0, 1.0), backend="scipy")
    assert sol.status_labels() == ["model_error", "model_error"]
    assert sol.failures == (f"`{name}` returned shape ({got},) for one run; expected ({expected},)",) * 2
    assert sol.failures[0] in sol.messages()[0]


# ---- the batched form (the scipy reference's) --------------------------------------------


def test_a_batched_system_gives_the_results_of_its_one_run_form():
    system = bouncing_ball(0.8)
    x0 = [[1.0, 0.0], [2.0, 1.0]]
    one_run = solve(system, x0, (0.0, 1.5))
    batched = system.batched()
    assert isinstance(batched, BatchedSystem) and batched.rule_names == ("impact",)
    for backend in ("auto", "scipy"):
        sci = solve(batched, x0, (0.0, 1.5), backend=backend)
        assert sci.backend == "scipy"
        np.testing.assert_allclose(sci.jumps.t, one_run.jumps.t, rtol=0, atol=1e-9)


def test_a_batched_system_cannot_run_on_the_engine():
    with pytest.raises(InputError, match="backend='engine' needs a HybridSystem written for one run"):
        solve(bouncing_ball().batched(), [1.0, 0.0], (0.0, 1.0), backend="engine")


def test_batched_function_with_wrong_shape_is_named():
    bad = BatchedSystem(
        n=2,
        n_rules=1,
        flow=lambda t, x: x[:, :1],
        guard=lambda t, x: -np.ones((len(t), 1)),
        jump=lambda k, t, x: x,
    )
    sol = solve(bad, [0.0, 0.0], (0.0, 1.0))
    assert sol.status_labels() == ["model_error"]
    assert sol.failures == ("`flow` returned an array of shape (1, 1); expected (1, 2)",)


def test_unknown_and_retired_backends_are_named():
    with pytest.raises(
        InputError,
        match=r"^`backend` must be one of \('auto', 'engine', 'scipy'\) \(or 'numba' for 'engine'\); got 'jax'$",
    ):
        solve(two_clocks(1, 1), [0.0, 0.0], (0.0, 1.0), backend="jax")
    for name in ("numpy", "fast"):
        with pytest.raises(
            InputError, match=rf"^`backend` '{name}' \(the batched numpy solver\) was retired: "
        ):
            solve(two_clocks(1, 1), [0.0, 0.0], (0.0, 1.0), backend=name)
    assert solve(two_clocks(1, 1), [0.0, 0.0], (0.0, 1.0), backend="numba").backend == "engine"


def test_auto_is_the_engine_for_a_one_run_system():
    assert solve(two_clocks(1, 1), [0.0, 0.0], (0.0, 1.0)).backend == "engine"


# ---- options ----------------------------------------------------------------------------


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


def test_entries_from_n_flow_on_are_constant_on_the_engine_or_the_run_says_why():
    """``n_flow`` lets the engine leave entries out of the integration (a network's
    packets); a flow that moves one anyway ends the run with model_error naming the
    promise it broke, instead of freezing the entry silently. The reference integrates
    every entry."""
    promise_kept = HybridSystem(
        n=2, n_rules=0, flow=lambda t, x: np.array([-x[0], 0.0]), guard=_no_guard, jump=_keep, n_flow=1
    )
    for backend in BACKENDS:
        sol = solve(promise_kept, [1.0, 0.5], (0.0, 1.0), backend=backend)
        assert sol.ok
        np.testing.assert_allclose(sol.x_final[0], [np.exp(-1.0), 0.5], rtol=1e-9)
    broken = HybridSystem(
        n=2, n_rules=0, flow=lambda t, x: np.array([-x[0], 1.0]), guard=_no_guard, jump=_keep, n_flow=1
    )
    sol = solve(broken, [1.0, 0.0], (0.0, 1.0), backend="engine")
    assert sol.status_labels() == ["model_error"]
    assert sol.failures[0] == (
        "`flow` returned a nonzero derivative for an entry from n_flow on (those must be constant along flows)"
    )
    np.testing.assert_array_equal(sol.x_final[0], [1.0, 0.0])  # no step was taken
    ref = solve(broken, [1.0, 0.0], (0.0, 1.0), backend="scipy")
    np.testing.assert_allclose(ref.x_final[0], [np.exp(-1.0), 1.0], rtol=1e-9)


@pytest.mark.parametrize("end", [0.7, 3.3, 30.0])
@pytest.mark.parametrize("step", [1e-3, 1e-2, 0.1])
def test_step_grids_end_at_or_before_their_end_and_miss_no_step(end, step):
    """``np.arange(0, end + step / 2, step)`` ends a rounding error past 0.7 and 3.3: left out."""
    g = step_grid(0.0, end, step)
    full = np.arange(0.0, end + step / 2, step)
    assert g[-1] <= end and np.array_equal(g, full[: g.size])
    assert full.size - g.size == int(full[-1] > end)  # only a point past the end is dropped
