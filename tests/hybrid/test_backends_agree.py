"""Property: the engine and the scipy reference give the same event sequence.

Hypothesis draws small hybrid systems; each family is ONE compiled system whose numbers
travel in ``params`` (module-level, closure-free functions), so that the examples cost a
solve each, not a compilation. Two independent integrators and event locators agree on
the rules that jump, their order and their number, and on the jump times to 1e-7 s.
They also agree on the state entries each system logs after every jump
(``log_columns``, ``JumpLog.x``), to the same tolerance as the final states.
The draws keep every crossing transversal and every two events of different rules
apart by more than 1e-6 s: simultaneous events (where the scipy reference may report
the second rule a rounding error later) are tested on their own in test_solver.py.

Event times are compared to what the method can give, not to ``event_xtol``: the
root finder brackets the crossing of the dense output to 1e-12 s, but the dense output
itself is off by up to a few 1e-7 in the state inside a long step of a stiff segment
(see test_oscillator_slow_crossing_against_closed_form), and a state error ``dx`` moves
a crossing of speed ``|g'|`` by ``dx / |g'|``.
"""

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st
from scipy.integrate import DOP853
from scipy.optimize import brentq

from etobs.hybrid import HybridSystem, SaveAt, SolverOptions, solve

TIME_TOL = 1e-7  # s; both backends locate events to event_xtol = 1e-12 at rtol = 1e-10
STATE_TOL = 1e-6  # final and logged states, where the solution is exact along steps (clocks)
# The oscillator's dense output inside a step of its stiff segments (eigenvalues up to
# 34 times apart) is off by up to 2.3e-7 in position and 4e-6 in speed at rtol = 1e-10
# (measured on the closed form: test_oscillator_slow_crossing_against_closed_form, and
# up to 1.7e-7 in position on 585 random draws with zeta = 3). The bounds leave five
# times that margin, for the sum of the two backends' errors.
DENSE_X_TOL = 1e-6  # position at an event
DENSE_STATE_TOL = 2e-5  # position and speed at a jump and at the end (speed error = lambda * position error)
N_CLOCKS = 3
CLOCK_HORIZON = 2.0
OSCILLATOR_HORIZON = 4.0


def _agree(system, x0, t_end, crossing_speed=None, state_tol=STATE_TOL):
    """Solve on both backends; return the engine's log after checking it against scipy's.

    Event times agree to TIME_TOL, or, given ``crossing_speed`` (the speed ``|g'|`` of
    each crossing, from the engine's solution), to TIME_TOL + DENSE_X_TOL / speed.
    """
    sci = solve(system, x0, (0.0, t_end), backend="scipy")
    # an event within the time tolerance of t_end may fall on either side of it
    assume(np.all(np.abs(sci.jumps.t - t_end) > 1e-6))
    eng = solve(system, x0, (0.0, t_end), backend="engine")
    assert eng.status_labels() == sci.status_labels() == ["completed"]
    assert eng.jumps.rule.tolist() == sci.jumps.rule.tolist()
    time_tol = TIME_TOL if crossing_speed is None else TIME_TOL + DENSE_X_TOL / crossing_speed(eng)
    np.testing.assert_array_less(np.abs(eng.jumps.t - sci.jumps.t), time_tol)
    np.testing.assert_allclose(eng.x_final, sci.x_final, rtol=0, atol=state_tol)
    assert eng.jumps.names == sci.jumps.names and eng.jumps.x.shape[1] == len(system.log_columns) > 0
    np.testing.assert_allclose(eng.jumps.x, sci.jumps.x, rtol=0, atol=state_tol)
    return eng.jumps


# ---- n independent clocks: x_i' = a_i, reset to 0 when x_i reaches c_i (rule i) ------


def _clock_rates(t, x, p):
    return p[:N_CLOCKS] * 1.0


def _clock_levels(t, x, p):
    return x - p[N_CLOCKS:]


def _clock_reset(k, t, x, p):
    out = x.copy()
    out[k] = 0.0
    return out


def _clock_events(rates, levels, x0, t_end):
    """Closed form: clock i first fires at (c_i - x0_i) / a_i, then every c_i / a_i."""
    events = []
    for i, (a, c, x) in enumerate(zip(rates, levels, x0, strict=True)):
        t = (c - x) / a
        while t < t_end:
            events.append((t, i))
            t += c / a
    return sorted(events)


clock = st.tuples(st.floats(0.2, 3.0), st.floats(0.2, 1.5), st.floats(0.0, 0.95))


@settings(max_examples=30)
@given(st.lists(clock, min_size=N_CLOCKS, max_size=N_CLOCKS))
def test_clocks_jump_alike_on_engine_and_scipy(clocks):
    rates, levels, fractions = (np.array(col) for col in zip(*clocks, strict=True))
    x0 = fractions * levels
    expected = _clock_events(rates, levels, x0, CLOCK_HORIZON)
    times = np.array([t for t, _ in expected] + [CLOCK_HORIZON])
    assume(np.all(np.diff(times) > 1e-6))  # no near-simultaneous events, none at t_end
    system = HybridSystem(
        n=N_CLOCKS,
        n_rules=N_CLOCKS,
        flow=_clock_rates,
        guard=_clock_levels,
        jump=_clock_reset,
        params=np.r_[rates, levels],
        log_columns=tuple(range(N_CLOCKS)),
    )
    log = _agree(system, x0, CLOCK_HORIZON)
    assert log.rule.tolist() == [i for _, i in expected]
    np.testing.assert_allclose(log.t, times[:-1], rtol=0, atol=TIME_TOL)
    # after its jump the clock that fired is at 0; the others at rate * time since their reset
    assert np.all(log.x[np.arange(len(log)), log.rule] == 0.0)


# ---- an overdamped oscillator pulled above a level, reset below it when it gets there --


def _pulled(t, x, p):
    # x'' + 2 zeta omega x' + omega^2 x = omega^2 target, with p = (omega, zeta, target, ...)
    omega, zeta, target = p[0], p[1], p[2]
    return np.array([x[1], omega * omega * (target - x[0]) - 2.0 * zeta * omega * x[1]])


def _oscillator(params, log_columns=()):
    """The overdamped oscillator reset below its level, with ``params = (omega, zeta, target, level, d, r)``."""
    return HybridSystem(
        n=2,
        n_rules=1,
        flow=_pulled,
        guard=_reaches_level,
        jump=_reset_below,
        params=params,
        log_columns=log_columns,
    )


def _reaches_level(t, x, p):
    return np.array([x[0] - p[3]])


def _reset_below(k, t, x, p):
    # x+ = level - d, v+ = -r v with p = (..., level, d, r)
    return np.array([p[3] - p[4], -p[5] * x[1]])


def _crossing_speed(eng):
    """``g' = x[1]`` at each jump: the engine's last arc point before it (the jump's ``j``)."""
    arc = eng.arcs[0]
    speed = np.array([arc.x[arc.j == j][-1, 1] for j in eng.jumps.j])
    assert np.all(speed > 0)  # transversal crossings, as the draws promise
    return speed


@settings(max_examples=30)
# a slow crossing (speed 0.13) of a stiff segment: the engine's step holding the event,
# 0.75 s at eigenvalues -0.51 and -17.5, lies beyond the method's stability boundary
# for the fast mode; the dense output there is 1.7e-7 off in position, the event 1.3e-6 s
# early (scipy, on other steps: 1.5e-7 s late)
@example(omega=3.0, zeta=3.0, level=0.75, d=0.8125, r=0.0, below=0.125, v0=0.0)
@given(
    omega=st.floats(1.0, 6.0),
    zeta=st.floats(1.0, 3.0),
    level=st.floats(-1.0, 0.8),
    d=st.floats(0.1, 1.0),
    r=st.floats(0.0, 0.9),
    below=st.floats(0.1, 2.0),
    v0=st.floats(-1.0, 0.0),
)
def test_oscillator_jumps_alike_on_engine_and_scipy(omega, zeta, level, d, r, below, v0):
    # Overdamped (zeta >= 1), x - target is a sum of two decaying exponentials: from
    # below the target 1 >= level + 0.2 with v <= 0 the position has at most one
    # minimum, then rises monotonically towards the target. The reset puts it at least
    # 0.1 below the level with v <= 0 again, so every crossing of the level is
    # transversal (the speed there is bounded away from zero).
    system = _oscillator([omega, zeta, 1.0, level, d, r], log_columns=(0, 1))
    log = _agree(system, [level - below, v0], OSCILLATOR_HORIZON, _crossing_speed, DENSE_STATE_TOL)
    assert set(log.rule.tolist()) <= {0}
    np.testing.assert_array_equal(log.x[:, 0], level - d)  # the reset position, exactly


def _oscillator_error(omega, zeta, e0, v0, t):
    """Closed form of ``x - target`` and ``x'`` for ``zeta > 1`` (two real eigenvalues)."""
    root = np.sqrt(zeta * zeta - 1.0)
    lam = -omega * (zeta - root), -omega * (zeta + root)
    b = (v0 - lam[0] * e0) / (lam[1] - lam[0])
    a = e0 - b
    return a * np.exp(lam[0] * t) + b * np.exp(lam[1] * t), a * lam[0] * np.exp(lam[0] * t) + b * lam[
        1
    ] * np.exp(lam[1] * t)


def test_oscillator_slow_crossing_against_closed_form():
    # The draw that showed the limit of the event times (see the @example above), against
    # the closed form: with r = 0 every segment after a reset starts at (level - d, 0) and
    # takes the same time to reach the level. Both backends locate the crossing of their
    # dense output to event_xtol, but the dense output inside the long step that holds
    # the second event is off by 1.7e-7 (engine) in position: the step (hλ = -13 for the
    # fast mode) is beyond DOP853's stability boundary, where the interpolant multiplies
    # the fast mode's rounding-level part of the state (8e-12) by up to 5e5, and the
    # error estimate (whose 3rd-order correction is dominated by the slow mode) let the
    # step pass. At the crossing speed 0.13 that is 1.3e-6 s: far above event_xtol, and
    # within DENSE_X_TOL / speed.
    omega, zeta, level, d, below = 3.0, 3.0, 0.75, 0.8125, 0.125
    system = _oscillator([omega, zeta, 1.0, level, d, 0.0], log_columns=(0, 1))

    def reach(e0, v0):
        def g(t):
            return _oscillator_error(omega, zeta, e0, v0, t)[0] - (level - 1.0)

        t = brentq(g, 0.0, 10.0, xtol=1e-15, rtol=1e-15)
        return t, _oscillator_error(omega, zeta, e0, v0, t)[1]

    first, _ = reach(level - below - 1.0, 0.0)
    period, speed = reach(level - d - 1.0, 0.0)
    expected = first + period * np.arange(2)
    assert expected[-1] + period > OSCILLATOR_HORIZON and speed == pytest.approx(0.128, abs=1e-3)
    for backend in ("engine", "scipy"):
        sol = solve(system, [level - below, 0.0], (0.0, OSCILLATOR_HORIZON), backend=backend)
        assert sol.status_labels() == ["completed"] and sol.jumps.rule.tolist() == [0, 0]
        error = np.abs(sol.jumps.t - expected)
        # the first event on a short, accurate step; the second within the bound (it is
        # 1.3e-6 s early on the engine, 1.5e-7 s late on scipy, which steps otherwise)
        assert error[0] < 1e-10
        assert error[1] <= TIME_TOL + DENSE_X_TOL / speed


def test_engine_dense_output_is_scipys_on_the_same_step():
    # The engine's DOP853 dense output (seven coefficients, three extra stages) against
    # scipy's on one step of the same size from the same state (loose tolerances so that
    # both accept it): equal to rounding (a few ulps: the sums run in another order), so
    # the event times differ only where the backends take different steps.
    omega, zeta, x0, h = 3.0, 3.0, np.array([-0.0625, 0.3]), 0.15
    system = _oscillator([omega, zeta, 1.0, 10.0, 0.5, 0.0])  # the level is never reached
    theta = np.linspace(0.0, 1.0, 21)[1:-1]
    grid = theta * h
    eng = solve(
        system,
        x0,
        (0.0, h),
        options=SolverOptions(rtol=1e-3, atol=1e-3, first_step=h),
        save=SaveAt(grid=grid),
        backend="engine",
    )
    assert eng.n_steps.tolist() == [1] and eng.n_rejected.tolist() == [0]
    params = np.array([omega, zeta, 1.0])
    sci = DOP853(lambda t, x: _pulled(t, x, params), 0.0, x0, h, rtol=1e-3, atol=1e-3, first_step=h)
    sci.step()
    assert sci.t == h
    np.testing.assert_allclose(eng.grid.x[0], sci.dense_output()(grid).T, rtol=0, atol=1e-14)
    np.testing.assert_allclose(eng.x_final[0], sci.y, rtol=0, atol=1e-14)
