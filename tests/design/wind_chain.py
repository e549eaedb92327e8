"""Two masses on springs with a wind on mass 1's velocity that enters as ``E = e_scale e_4``.

The model of a new user's trial (issue 15): with ``e_scale = 30`` the ISS gains for
``x' = ... + v`` (the identity) gave a certified error bound 30 times too small.
``mychain`` is marked as a factory so that ``etobs check`` specs can name this file.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

import etobs
from etobs import DynamicRule, EstimationProblem, Linear, Node, Quadratic, Sinusoid
from etobs.model import linear_luenberger, linear_plant

A = np.array([[0, 1, 0, 0], [-2.0, -0.05, 1, 0], [0, 0, 0, 1], [1, 0, -1, -0.05]], dtype=float)
C = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
NODES = [[0], [1]]


def disturbance_matrix(e_scale: float) -> np.ndarray:
    """``E``: the wind pushes on mass 1's velocity, ``e_scale`` times."""
    return np.array([[0.0], [0.0], [0.0], [e_scale]])


@etobs.factory
def mychain(
    L: Sequence[Sequence[float]],
    sigma: Sequence[float],
    c: Sequence[float],
    a: Sequence[float],
    ell: Sequence[float],
    eps: Sequence[float],
    wind: float = 0.01,
    e_scale: float = 1.0,
    const: bool = False,
) -> EstimationProblem:
    """The chain, a Luenberger observer with gain ``L``, one DynamicRule per node; ``v`` constant or a sinusoid."""
    rules = [
        DynamicRule(gamma=Quadratic(ell[i]), alpha=Linear(a[i]), sigma=sigma[i], c=c[i], b=1.0, eps=eps[i])
        for i in range(2)
    ]
    v = [wind] if const else Sinusoid(amplitude=[wind], omega=0.5)
    return EstimationProblem(
        linear_plant(A, C=C, E=disturbance_matrix(e_scale)),
        linear_luenberger(A, np.asarray(L)),
        [Node((0,), rules[0], name="m0"), Node((1,), rules[1], name="m1")],
        v=v,
    )
