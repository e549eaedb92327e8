"""A linear mass-spring chain of three masses observed by three nodes (a second test system).

Node ``i`` sends the position and velocity of mass ``i``. The chain is damped, so the
``"min_gain"`` design would return ``L = 0``; the tests use ``"max_decay"`` instead.
``chain`` is marked as a factory so that ``etobs check`` specs can name this file.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

import etobs
from etobs import DynamicRule, EstimationProblem, Linear, Node, Plant, Quadratic, Sinusoid, luenberger

_K = np.array([[2.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 1.0]])  # unit masses and springs
A = np.block([[np.zeros((3, 3)), np.eye(3)], [-_K, -0.2 * np.eye(3)]])
C = np.eye(6)[[0, 3, 1, 4, 2, 5]]
NODES = [[0, 1], [2, 3], [4, 5]]
#: x0 of the test runs (seeded)
X0 = np.random.default_rng(0).uniform(-1.0, 1.0, (4, 6))


@etobs.factory
def chain(
    *,
    L: Sequence[Sequence[float]],
    sigma: Sequence[float],
    c: Sequence[float],
    a: Sequence[float],
    ell: Sequence[float],
    eps: Sequence[float],
) -> EstimationProblem:
    """The chain with observer gain ``L`` and one ``DynamicRule`` per node (``b = 1``, ``eta0 = 0``)."""
    plant = Plant(f_p=lambda t, x, u, v: A @ x + v, h=lambda x: C @ x, n_x=6, n_y=6, n_v=6)
    observer = luenberger(lambda t, x, u: A @ x, L=np.asarray(L, dtype=float))
    nodes = [
        Node(
            tuple(NODES[i]),
            DynamicRule(
                gamma=Quadratic(ell[i]), alpha=Linear(a[i]), sigma=sigma[i], c=c[i], b=1.0, eps=eps[i]
            ),
        )
        for i in range(3)
    ]
    return EstimationProblem(
        plant, observer, nodes, v=Sinusoid(amplitude=[0, 0, 0, 0.02, 0.02, 0.02], omega=0.5)
    )


def rule_params(rules: Sequence[DynamicRule]) -> dict[str, list[float]]:
    """The keyword arguments of :func:`chain` (and of ``robot_arm``) that give these rules."""
    return {
        "sigma": [r.sigma for r in rules],
        "c": [r.c for r in rules],
        "a": [r.alpha.a for r in rules],
        "ell": [r.gamma.ell for r in rules],
        "eps": [r.eps for r in rules],
    }
