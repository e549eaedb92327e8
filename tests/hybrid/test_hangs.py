"""Every run ends in bounded time with a named status (issue 14: hangs instead of a status).

Each test runs a system that used to take hours (or for ever) and asserts the status it
now ends with, on both solvers, and that it stopped after a bounded number of jumps or
steps: the tests assert counts, never wall-clock time. The horizons are long on
purpose: without the limits these runs would not end within any test timeout.
"""

import numpy as np
import pytest

from etobs.hybrid import HybridSystem, SaveAt, SolverOptions, Status, solve, status_message
from etobs.hybrid.zeno import zeno_window

from .systems import G, bouncing_ball, two_clocks

BACKENDS = ["engine", "scipy"]
#: The ball's Zeno time from a height of 1 with restitution 0.5: the first fall takes
#: t1 = sqrt(2/g), each flight after it half the one before, 2 t1 in all: 3 t1.
ZENO_TIME = 3.0 * np.sqrt(2.0 / G)


def _solve(system, x0, t_end, backend, **options):
    return solve(
        system, x0, (0.0, t_end), backend=backend, options=SolverOptions(**options), save=SaveAt(steps=False)
    )


# ---- the Zeno rule (etobs.hybrid.zeno) -----------------------------------------------------


def _largest_window(times, span):
    start, count, most = -np.inf, 0, 0
    for t in times:
        start, count = zeno_window(t, start, count, span)
        most = max(most, count)
    return most


def test_the_zeno_window_counts_jumps_within_its_span_relative_to_t():
    # ten jumps 1e-10 apart share a window of 1e-9 at t <= 1; 1e-8 apart, none do
    assert _largest_window(1.0 + 1e-10 * np.arange(10), 1e-9) == 10
    assert _largest_window(1.0 + 1e-8 * np.arange(10), 1e-9) == 1
    # the span grows with |t|: at t = 1e6 a window is 1e-3 wide
    assert _largest_window(1e6 + 1e-4 * np.arange(10), 1e-9) == 10
    # jumps at one instant (simultaneous rules, a rule that stays in its jump set)
    assert _largest_window(np.zeros(5), 0.0) == 5


def test_a_cluster_of_more_than_twice_the_limit_always_fills_one_window():
    # windows tumble: a cluster straddles at most two of them
    rng = np.random.default_rng(3)
    for _ in range(50):
        lead = np.sort(rng.uniform(0.0, 1.0, 20))
        cluster = 2.0 + np.sort(rng.uniform(0.0, 1e-9, 21))
        assert _largest_window(np.concatenate([lead, cluster]), 1e-9) > 10


# ---- zeno ----------------------------------------------------------------------------------


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_bouncing_ball_ends_zeno_at_its_zeno_time_not_after_a_million_jumps(backend):
    # before: status max_jumps after 1e6 jumps (engine 15 s; reference 1.1 ms a jump, 19 min;
    # 73 min on the retired numpy solver)
    sol = _solve(bouncing_ball(0.5), [1.0, 0.0], 10.0, backend)
    assert sol.status_labels() == ["zeno"]
    assert sol.j_final[0] < 5_000
    assert sol.t_final[0] == pytest.approx(ZENO_TIME, abs=1e-6)
    assert "the jumps piled up in time" in sol.messages()[0]


@pytest.mark.parametrize("backend", BACKENDS)
def test_jumps_closer_than_the_event_accuracy_end_zeno(backend):
    # a clock reset every 1e-13 s (below event_xtol = 1e-12): a billion billion jumps in 1e5 s
    sol = _solve(two_clocks(1e-13, 1.0), [0.0, 0.0], 1e5, backend)
    assert sol.status_labels() == ["zeno"]
    assert sol.j_final[0] < 5_000


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_zeno_rule_can_be_turned_off_and_max_jumps_still_bounds_the_run(backend):
    sol = _solve(bouncing_ball(0.5), [1.0, 0.0], 10.0, backend, zeno_jumps=None, max_jumps=3_000)
    assert sol.status_labels() == ["max_jumps"]
    assert sol.j_final[0] == 3_000


@pytest.mark.parametrize("backend", BACKENDS)
def test_many_jumps_the_solver_resolves_are_not_zeno(backend):
    # a period of 1e-9 s: jumps 1000 times the event accuracy apart are resolved, not Zeno;
    # a billion jumps in 1 s end with max_jumps (the engine: 6 s for the default million)
    sol = _solve(two_clocks(1e-9, 1.0), [0.0, 0.0], 1.0, backend, max_jumps=2_000)
    assert sol.status_labels() == ["max_jumps"]
    assert np.diff(sol.jumps.t).min() == pytest.approx(1e-9, rel=1e-2)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_rule_that_stays_in_its_jump_set_ends_zeno_at_its_instant(backend):
    # the jump does not leave the jump set (an eps = 0 rule at e = 0): jumps at one instant
    stuck = HybridSystem(
        n=1,
        n_rules=1,
        flow=lambda t, x: np.zeros(1),
        guard=lambda t, x: np.array([x[0]]),
        jump=lambda k, t, x: np.array([x[0]]),
    )
    sol = _solve(stuck, [0.0], 1.0, backend)
    assert sol.status_labels() == ["zeno"]
    assert sol.t_final[0] == 0.0
    assert sol.j_final[0] == 1_001  # more than zeno_jumps = 1000 in one window


def test_zeno_options_are_checked():
    with pytest.raises(ValueError, match=r"^`zeno_jumps` must be an integer >= 1; got 0$"):
        SolverOptions(zeno_jumps=0)
    with pytest.raises(ValueError, match=r"^`zeno_span` must be >= 0"):
        SolverOptions(zeno_span=-1.0)


# ---- max_steps -----------------------------------------------------------------------------


def _stiff(t, x):
    return -1e6 * x


STIFF = HybridSystem(n=1, n_rules=0, flow=_stiff, guard=lambda t, x: np.zeros(0), jump=lambda k, t, x: x)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_stiff_flow_ends_with_max_steps_inside_one_segment(backend):
    # x' = -1e6 x needs ~156,000 explicit steps per second: 1e4 s is 1.6e9 steps (on the
    # reference, 0.5 ms each: 9 days). The reference checked max_steps only between flow
    # segments, and this run has one.
    sol = _solve(STIFF, [1.0], 1e4, backend, max_steps=3_000)
    assert sol.status_labels() == ["max_steps"]
    assert sol.n_steps[0] + sol.n_rejected[0] <= 3_000
    assert 0.0 < sol.t_final[0] < 1.0
    assert np.all(np.abs(sol.x_final) < 1.0)  # the state where it stopped, decayed


@pytest.mark.parametrize("backend", BACKENDS)
def test_max_steps_is_per_run(backend):
    # the stiff run stops at its own limit; the quiet one next to it completes
    # x = (state, its decay rate)
    decay = HybridSystem(
        n=2,
        n_rules=0,
        flow=lambda t, x: np.array([-x[1] * x[0], 0.0]),
        guard=lambda t, x: np.zeros(0),
        jump=lambda k, t, x: x,
    )
    sol = _solve(decay, [[1.0, 1e6], [1.0, 1.0]], 1e4, backend, max_steps=3_000)
    assert sol.status_labels() == ["max_steps", "completed"]


# ---- nonfinite -----------------------------------------------------------------------------


def _square(t, x):
    return x * x


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_finite_escape_ends_nonfinite_or_step_underflow(backend):
    # x' = x^2 from 1 escapes at t = 1
    escape = HybridSystem(
        n=1, n_rules=0, flow=_square, guard=lambda t, x: np.zeros(0), jump=lambda k, t, x: x
    )
    sol = _solve(escape, [1.0], 10.0, backend)
    assert sol.status_labels()[0] in ("nonfinite", "step_underflow")
    assert sol.t_final[0] == pytest.approx(1.0, abs=1e-3)


# ---- a NaN event function ------------------------------------------------------------------


def _nan_floor(t, x, p):
    # the floor is NaN below a height of 0.5: the ball would fall through it
    return np.array([np.nan if x[0] < 0.5 else -1.0])


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_nan_event_function_ends_the_run_naming_the_guard(backend):
    # before: a NaN guard never fired; the ball fell through the floor and "completed"
    ball = bouncing_ball(0.5)
    nan_ball = HybridSystem(
        n=2, n_rules=1, flow=ball.flow, guard=_nan_floor, jump=ball.jump, params=ball.params
    )
    sol = _solve(nan_ball, [1.0, 0.0], 2.0, backend)
    assert sol.status_labels() == ["model_error"]
    assert sol.failures[0].startswith("`guard` returned NaN")
    assert sol.x_final[0, 0] >= 0.5  # stopped before the guard went NaN, at its last good state
    assert sol.t_final[0] < np.sqrt(2 * 0.5 / G) + 1e-9


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_nan_event_function_at_the_start_ends_the_run(backend):
    always_nan = HybridSystem(
        n=1,
        n_rules=1,
        flow=lambda t, x: np.ones(1),
        guard=lambda t, x: np.full(1, np.nan),
        jump=lambda k, t, x: x,
    )
    sol = _solve(always_nan, [0.0], 1.0, backend)
    assert sol.status_labels() == ["model_error"]
    assert sol.t_final[0] == 0.0
    assert sol.failures[0].startswith("`guard` returned NaN")


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_plain_hybrid_system_ending_zeno_gets_advice_on_guards_not_nodes(backend):
    # before: "check that every eps is > 0 ... (Theorem 4's minimum inter-event time ...)",
    # advice about observer nodes for a bouncing ball that has none
    sol = _solve(bouncing_ball(0.5), [1.0, 0.0], 10.0, backend)
    (message,) = sol.messages()
    assert "every jump map leaves its guard's jump set" in message
    for word in ("eps", "node", "gamma", "Theorem", "transmission"):
        assert word not in message, f"{word!r} in a plain hybrid system's message: {message}"


def test_a_layer_above_adds_its_advice_to_the_generic_message():
    text = status_message(Status.ZENO, 2.0, advice={Status.ZENO: "Check the model's eps"})
    assert text.startswith("stopped at t=2: the jumps piled up in time")
    assert text.endswith("`zeno_jumps`/`zeno_span`. Check the model's eps")
    assert status_message(Status.MAX_STEPS, advice={Status.ZENO: "x"}) == status_message(Status.MAX_STEPS)
