"""A model of a user's own, written once for one run (used by bench_user_model.py).

A 4-state model: two coupled damped pendulums driven by a time-varying input, observed
by a Luenberger observer, with two nodes: a vector node sending both angles and a scalar
node sending one velocity. Node 0 uses a ``Custom`` K-function.
"""

from __future__ import annotations

import math

import numpy as np

from etobs import (
    Custom,
    DynamicRule,
    EstimationProblem,
    FunctionSignal,
    Linear,
    Node,
    Plant,
    Quadratic,
    factory,
)
from etobs.model import luenberger

K = 0.4  # coupling


def model(t, x, u, p):
    """Two pendulums; ``p = (damping, coupling)``."""
    return np.array(
        [
            x[1],
            -math.sin(x[0]) - p[0] * x[1] + p[1] * (x[2] - x[0]) + u[0],
            x[3],
            -math.sin(x[2]) - p[0] * x[3] + p[1] * (x[0] - x[2]),
        ]
    )


def drive(t):
    """The input: a chirp-like time-varying force."""
    return np.array([0.5 * math.sin(0.7 * t + 0.1 * t * t)])


def gamma(s):
    """A custom class-K function: ``s^2 (1 + s)``."""
    return s * s * (1.0 + s)


@factory  # a spec may name it: system.factory = "path/to/user_model.py:problem"
def problem(damping: float = 0.3) -> EstimationProblem:
    """The estimation problem; ``damping`` travels in ``params`` (no recompile)."""
    plant = Plant(
        lambda t, x, u, v, p: model(t, x, u, p),
        lambda x, p: np.array([x[0], x[2], x[3]]),
        n_x=4,
        n_y=3,
        n_u=1,
        params=[damping, K],
    )
    L = np.array([[2.0, 0.0, 0.0], [1.0, 0.5, 0.0], [0.0, 2.0, 1.0], [0.0, 1.0, 2.0]])
    obs = luenberger(lambda t, x, u: model(t, x, u, np.array([0.3, K])), L)
    custom = DynamicRule(gamma=Custom(gamma), alpha=Linear(1.0), sigma=5.0, c=0.05, eps=1e-3, eta0=0.1)
    plain = DynamicRule(gamma=Quadratic(2.0), alpha=Linear(2.0), sigma=5.0, c=0.05, eps=1e-3, eta0=0.1)
    return EstimationProblem(
        plant,
        obs,
        nodes=[Node((0, 1), custom, name="angles"), Node((2,), plain, name="velocity")],
        u=FunctionSignal(drive, 1),
    )
