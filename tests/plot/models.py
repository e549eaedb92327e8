"""The small estimation problems the plot tests draw."""

import numpy as np

from etobs import (
    DynamicRule,
    EstimationProblem,
    Linear,
    Node,
    Plant,
    Quadratic,
    Sinusoid,
    luenberger,
)

A = np.array([[0.0, 1.0], [-2.0, -0.5]])
X0 = [[1.0, 0.0], [0.0, 2.0]]
T_END = 5.0


def _plant(t, x, u, v):
    return A @ x + v


def _h(x):
    return x


def _model(t, x, u):
    return A @ x


def rule() -> DynamicRule:
    return DynamicRule(gamma=Quadratic(5.0), alpha=Linear(2.0), sigma=10.0, c=0.01, b=1.0, eps=0.01, eta0=1.0)


def two_sensors(**kwargs) -> EstimationProblem:
    """The README's oscillator: node 0 measures x_1, node 1 measures x_2 (h is the identity)."""
    plant = Plant(f_p=_plant, h=_h, n_x=2, n_y=2, n_v=2)
    observer = luenberger(_model, L=np.eye(2) * 3.0)
    nodes = [Node((0,), rule(), name="sensor 1"), Node((1,), rule(), name="sensor 2")]
    return EstimationProblem(
        plant, observer, nodes=nodes, v=Sinusoid(amplitude=[0.0, 0.1], omega=1.0), **kwargs
    )


#: Names and units of the oscillator's states and outputs (h is the identity: y = x).
NAMES = {
    "state_names": ["position", "velocity"],
    "state_units": ["m", "m/s"],
    "output_names": ["position", "velocity"],
    "output_units": ["m", "m/s"],
}


def named_sensors() -> EstimationProblem:
    """``two_sensors()`` with its states and outputs named, with units (``NAMES``)."""
    pb = two_sensors()
    return EstimationProblem(
        Plant(f_p=_plant, h=_h, n_x=2, n_y=2, n_v=2, **NAMES), pb.observer, nodes=pb.nodes, v=pb.v
    )
