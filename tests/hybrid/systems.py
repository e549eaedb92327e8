"""Small hybrid systems with known solutions, shared by the solver tests."""

import numpy as np

from etobs.hybrid import HybridSystem

G = 9.81


def bouncing_ball(restitution=0.5):
    """x = (height, velocity); impact when the ball falls through height 0."""
    return HybridSystem(
        n=2,
        n_rules=1,
        flow=lambda t, x: np.stack([x[:, 1], np.full(x.shape[0], -G)], axis=1),
        guard=lambda t, x: np.where(x[:, 1] < 0, -x[:, 0], -1.0)[:, None],
        jump=lambda k, t, x: np.stack([np.zeros(x.shape[0]), -restitution * x[:, 1]], axis=1),
        rule_names=("impact",),
    )


def grazing_oscillator(level=0.999):
    """x = (sin t, cos t) until sin t >= level; the jump mirrors the position.

    The event function sin(t) - level is positive only for 2*arccos(level) ~ 0.089 s
    around each peak: a sign test at step ends misses it when steps are long.
    """
    return HybridSystem(
        n=2,
        n_rules=1,
        flow=lambda t, x: np.stack([x[:, 1], -x[:, 0]], axis=1),
        guard=lambda t, x: (x[:, 0] - level)[:, None],
        jump=lambda k, t, x: x * np.array([-1.0, 1.0]),
    )


def two_clocks(period_a, period_b):
    """Two clocks x_k' = 1 reset to 0 when they reach their period."""
    periods = np.array([period_a, period_b])

    def jump(k, t, x):
        out = x.copy()
        out[:, k] = 0.0
        return out

    return HybridSystem(
        n=2,
        n_rules=2,
        flow=lambda t, x: np.ones_like(x),
        guard=lambda t, x: x - periods,
        jump=jump,
    )
