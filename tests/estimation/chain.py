"""A 3-state linear plant with 2 inputs and a Luenberger observer, for the extensions' tests.

``x' = A x + B u``, ``y = C x = x``; the observer ``z' = A z + B u + L (ybar - yhat)``.
"""

import numpy as np

from etobs import EstimationProblem, Observer, Plant
from etobs.model import Sinusoid

A = np.array([[0.0, 1.0, 0.0], [-2.0, -0.3, 1.0], [0.0, 0.0, -0.5]])
B = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
C = np.eye(3)
L = np.array([[3.0, 1.0, 0.0], [-1.0, 3.0, 0.0], [0.0, 0.0, 2.0]])


def chain(nodes, **kw) -> EstimationProblem:
    """A 3-state linear plant with 2 inputs ``u`` and outputs ``y = x``; a Luenberger observer."""
    plant = Plant(f_p=lambda t, x, u, v: A @ x + B @ u, h=lambda x: C @ x, n_x=3, n_y=3, n_u=2)
    observer = Observer(f_o=lambda t, z, u, ybar, yhat: A @ z + B @ u + L @ (ybar - yhat), n_z=3)
    kw.setdefault("u", Sinusoid(amplitude=[1.0, 0.5], omega=2.0, offset=[0.0, 0.2]))
    return EstimationProblem(plant=plant, observer=observer, nodes=nodes, **kw)
