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
"""

import numpy as np
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from etobs.hybrid import HybridSystem, solve

TIME_TOL = 1e-7  # s; both backends locate events to event_xtol = 1e-12 at rtol = 1e-10
N_CLOCKS = 3
CLOCK_HORIZON = 2.0
OSCILLATOR_HORIZON = 4.0


def _agree(system, x0, t_end):
    """Solve on both backends; return the engine's log after checking it against scipy's."""
    sci = solve(system, x0, (0.0, t_end), backend="scipy")
    # an event within the time tolerance of t_end may fall on either side of it
    assume(np.all(np.abs(sci.jumps.t - t_end) > 1e-6))
    eng = solve(system, x0, (0.0, t_end), backend="engine")
    assert eng.status_labels() == sci.status_labels() == ["completed"]
    assert eng.jumps.rule.tolist() == sci.jumps.rule.tolist()
    np.testing.assert_allclose(eng.jumps.t, sci.jumps.t, rtol=0, atol=TIME_TOL)
    np.testing.assert_allclose(eng.x_final, sci.x_final, rtol=0, atol=1e-6)
    assert eng.jumps.names == sci.jumps.names and eng.jumps.x.shape[1] == len(system.log_columns) > 0
    np.testing.assert_allclose(eng.jumps.x, sci.jumps.x, rtol=0, atol=1e-6)
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


def _reaches_level(t, x, p):
    return np.array([x[0] - p[3]])


def _reset_below(k, t, x, p):
    # x+ = level - d, v+ = -r v with p = (..., level, d, r)
    return np.array([p[3] - p[4], -p[5] * x[1]])


@settings(max_examples=30)
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
    system = HybridSystem(
        n=2,
        n_rules=1,
        flow=_pulled,
        guard=_reaches_level,
        jump=_reset_below,
        params=[omega, zeta, 1.0, level, d, r],
        log_columns=(0, 1),
    )
    log = _agree(system, [level - below, v0], OSCILLATOR_HORIZON)
    assert set(log.rule.tolist()) <= {0}
    np.testing.assert_array_equal(log.x[:, 0], level - d)  # the reset position, exactly
