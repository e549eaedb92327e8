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


def _nodes() -> list[Node]:
    """A vector node sending both angles (a ``Custom`` gamma) and a scalar node sending one velocity."""
    custom = DynamicRule(gamma=Custom(gamma), alpha=Linear(1.0), sigma=5.0, c=0.05, eps=1e-3, eta0=0.1)
    plain = DynamicRule(gamma=Quadratic(2.0), alpha=Linear(2.0), sigma=5.0, c=0.05, eps=1e-3, eta0=0.1)
    return [Node((0, 1), custom, name="angles"), Node((2,), plain, name="velocity")]


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
    return EstimationProblem(plant, obs, nodes=_nodes(), u=FunctionSignal(drive, 1))


# ---- the same model written for the engine's lanes: tuples, no arrays made per call ------


def tuple_model(t, x, u, p):
    """:func:`model` returning a tuple (no array made per call: the lanes' vector code)."""
    return (
        x[1],
        -math.sin(x[0]) - p[0] * x[1] + p[1] * (x[2] - x[0]) + u[0],
        x[3],
        -math.sin(x[2]) - p[0] * x[3] + p[1] * (x[0] - x[2]),
    )


def tuple_drive(t):
    """:func:`drive` as a tuple."""
    return (0.5 * math.sin(0.7 * t + 0.1 * t * t),)


GAIN = ((2.0, 0.0, 0.0), (1.0, 0.5, 0.0), (0.0, 2.0, 1.0), (0.0, 1.0, 2.0))


def tuple_observer(t, z, u, ybar, yhat):
    """Luenberger's observer of :func:`tuple_model` with the gain :data:`GAIN`, as a tuple."""
    m = tuple_model(t, z, u, (0.3, K))
    r0, r1, r2 = ybar[0] - yhat[0], ybar[1] - yhat[1], ybar[2] - yhat[2]
    g = GAIN
    return (
        m[0] + g[0][0] * r0 + g[0][1] * r1 + g[0][2] * r2,
        m[1] + g[1][0] * r0 + g[1][1] * r1 + g[1][2] * r2,
        m[2] + g[2][0] * r0 + g[2][1] * r1 + g[2][2] * r2,
        m[3] + g[3][0] * r0 + g[3][1] * r1 + g[3][2] * r2,
    )


def tuple_problem(damping: float = 0.3) -> EstimationProblem:
    """:func:`problem` written with tuples: the same numbers, vector code in the engine's lanes."""
    from etobs import Observer

    plant = Plant(
        lambda t, x, u, v, p: tuple_model(t, x, u, p),
        lambda x, p: (x[0], x[2], x[3]),
        n_x=4,
        n_y=3,
        n_u=1,
        params=[damping, K],
    )
    obs = Observer(f_o=tuple_observer, n_z=4)
    return EstimationProblem(plant, obs, nodes=_nodes(), u=FunctionSignal(tuple_drive, 1))
