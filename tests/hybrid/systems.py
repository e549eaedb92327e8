"""Small hybrid systems with known solutions, shared by the solver tests.

Each is a one-run :class:`~etobs.hybrid.HybridSystem` whose numbers travel in
``params``: the functions are module-level and closure-free, so each compiles once per
session, whatever the numbers.
"""

import numpy as np

from etobs.hybrid import HybridSystem

G = 9.81


def _ball_flow(t, x, p):
    return np.array([x[1], -p[1]])


def _ball_guard(t, x, p):
    # only a falling ball can hit the floor: a ball resting at 0 after a jump flows on
    return np.array([-x[0] if x[1] < 0 else -1.0])


def _ball_jump(k, t, x, p):
    return np.array([0.0, -p[0] * x[1]])


def bouncing_ball(restitution=0.5, g=G):
    """x = (height, velocity), p = (restitution, g); impact when the ball falls through 0."""
    return HybridSystem(
        n=2,
        n_rules=1,
        flow=_ball_flow,
        guard=_ball_guard,
        jump=_ball_jump,
        rule_names=("impact",),
        params=[restitution, g],
    )


def _rotation(t, x, p):
    return np.array([x[1], -x[0]])


def _above_level(t, x, p):
    return np.array([x[0] - p[0]])


def _mirror(k, t, x, p):
    return np.array([-x[0], x[1]])


def grazing_oscillator(level=0.999):
    """x = (sin t, cos t) until sin t >= level = p[0]; the jump mirrors the position.

    The event function sin(t) - level is positive only for 2*arccos(level) ~ 0.089 s
    around each peak: a sign test at step ends misses it when steps are long.
    """
    return HybridSystem(n=2, n_rules=1, flow=_rotation, guard=_above_level, jump=_mirror, params=[level])


def _unit_rates(t, x, p):
    return np.ones(2)


def _past_period(t, x, p):
    return x - p


def _reset_clock(k, t, x, p):
    out = x.copy()
    out[k] = 0.0
    return out


def two_clocks(period_a, period_b):
    """Two clocks x_k' = 1 reset to 0 when they reach their period p[k] (rule k)."""
    return HybridSystem(
        n=2,
        n_rules=2,
        flow=_unit_rates,
        guard=_past_period,
        jump=_reset_clock,
        params=[period_a, period_b],
    )


def _clock_rate(t, x, p):
    return np.ones(1)


def _clipped_guard(t, x, p):
    # exactly 0 on the whole jump set tau >= period, as clipped guards of HyEQ-style models
    return np.array([min(x[0] - p[0], 0.0)])


def _reset_all(k, t, x, p):
    return np.zeros_like(x)


def clipped_clock(period=1.0):
    """tau' = 1, reset to 0 when ``min(tau - period, 0) >= 0``: a guard that is flat at 0."""
    return HybridSystem(
        n=1, n_rules=1, flow=_clock_rate, guard=_clipped_guard, jump=_reset_all, params=[period]
    )


def _late_clock_guard(t, x, p):
    # time-varying: no jump before t = p[0], then one each time tau reaches p[1]
    return np.array([min(t - p[0], x[0] - p[1])])


def late_clock(start=1.5, period=0.5):
    """tau' = 1, reset to 0 when ``min(t - start, tau - period) >= 0``: jumps at start + k period."""
    return HybridSystem(
        n=1, n_rules=1, flow=_clock_rate, guard=_late_clock_guard, jump=_reset_all, params=[start, period]
    )


def _cubed_guard(t, x, p):
    # (tau - period)^3: a sign change with zero slope, so the root finder ends on its
    # bracket width (bisection), not on an exact secant
    return np.array([(x[0] - p[0]) ** 3])


def cubed_clock(period):
    """tau' = 1, reset to 0 when ``(tau - period)^3 >= 0``: jumps at period, 2 period, ..."""
    return HybridSystem(
        n=1, n_rules=1, flow=_clock_rate, guard=_cubed_guard, jump=_reset_all, params=[period]
    )


def _two_levels(t, x, p):
    # sin(t) - level and sin(t + d) - level on x = (sin t, cos t)
    return np.array([x[0] - p[0], x[0] * np.cos(p[1]) + x[1] * np.sin(p[1]) - p[0]])


def twin_grazers(level=0.999, d=1e-4):
    """x = (sin t, cos t); rule 0 is above ``level`` around pi/2, rule 1 ``d`` s earlier.

    Both excursions (2 arccos(level) ~ 0.089 s) start ``d`` apart inside one step, with
    no sign change at its ends: found by sampling, both in one bracket.
    """
    return HybridSystem(n=2, n_rules=2, flow=_rotation, guard=_two_levels, jump=_mirror, params=[level, d])
