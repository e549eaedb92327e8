"""The flexible-joint robot arm of the paper's case study (section 7).

``x' = A x + B u + G*3.3*sin(x_3) + v``, ``y = C x + m`` with ``u = sin t``,
``v = 0.02 (0, 1, 0, 1) sin(0.4 t)`` and ``m = 0.01 (0, 1) sin(0.3 t)``; observer
(57) ``xhat' = A xhat + B u + G*3.3*sin(xhat_3) + L (ybar - C xhat)``; two nodes,
node 0 sends ``y_1 = x_1`` and node 1 sends ``y_2 = x_2``, each with the dynamic rule
``gamma_i(s) = ell_i s^2``, ``alpha_i(s) = a_i s``. Every number is the paper's.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.estimation.problem import EstimationProblem
from etobs.model import DynamicRule, JitObserver, JitPlant, Linear, Node, Observer, Plant, Quadratic, Sinusoid

A = np.array(
    [
        [0.0, 1.0, 0.0, 0.0],
        [-48.6, -1.25, 48.6, 0.0],
        [0.0, 0.0, 0.0, 1.0],
        [19.5, 0.0, -19.5, 0.0],
    ]
)
B = np.array([0.0, 21.6, 0.0, 0.0])
G = np.array([0.0, 0.0, 0.0, -1.0])
C = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])
#: The observer gain printed in the paper (section 7).
L_PAPER = np.array([[0.58, -42.96], [-4.67, 2.83], [3.16, 49.25], [16.34, 88.46]])
#: The initial condition of the paper's figures.
X0_PAPER = (3.0, 2.0, 3.0, -2.0)
#: Sector bound of the nonlinearity 3.3*sin(x_3): its slope lies in [-3.3, 3.3].
SECTOR = 3.3

for _arr in (A, B, G, C, L_PAPER):
    _arr.setflags(write=False)


def _matvec(M: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Rows of ``x @ M.T`` as elementwise multiply-adds in a fixed order.

    A BLAS product may sum in an order that depends on the batch size; this keeps each
    run's result bit-for-bit independent of the other runs it is batched with.
    """
    out = x[:, :1] * M[:, 0]
    for k in range(1, M.shape[1]):
        out += x[:, k : k + 1] * M[:, k]
    return out


def _model(t: np.ndarray, x: np.ndarray, u: np.ndarray) -> np.ndarray:
    return _matvec(A, x) + u * B + (SECTOR * np.sin(x[:, 2]))[:, None] * G


def _pair(name: str, value: Any) -> tuple[float, float]:
    if np.ndim(value) == 0:
        value = (value, value)
    arr = v.vector(name, value, 2)
    return float(arr[0]), float(arr[1])


def robot_arm(
    *,
    sigma: Sequence[float] | float = (600.0, 800.0),
    c: Sequence[float] | float = (0.001, 0.001),
    b: Sequence[float] | float = (1.0, 1.0),
    a: Sequence[float] | float = (2.0, 3.0),
    ell: Sequence[float] | float = (5.0, 5.0),
    eps: Sequence[float] | float = (10.0, 10.0),
    eta0: Sequence[float] | float = (10.0, 10.0),
    L: Any = L_PAPER,
    noise: bool = True,
    disturbance: bool = True,
) -> EstimationProblem:
    """Build the robot-arm estimation problem; defaults are the paper's first simulation.

    Parameters
    ----------
    sigma, c, b, a, ell, eps, eta0 : float or pair of float
        Rule parameters of nodes 0 and 1 (``alpha_i(s) = a_i s``, ``gamma_i(s) = ell_i s^2``).
    L : array_like, shape (4, 2)
        Observer gain (default: the paper's).
    noise, disturbance : bool
        Include the measurement noise ``m`` and the disturbance ``v``.

    Returns
    -------
    EstimationProblem

    """
    gain = v.matrix("L", L, (4, 2))
    amp_v = 0.02 * np.array([0.0, 1.0, 0.0, 1.0]) if disturbance else np.zeros(4)
    amp_m = 0.01 * np.array([0.0, 1.0]) if noise else np.zeros(2)

    def f_p(t: np.ndarray, x: np.ndarray, u: np.ndarray, dist: np.ndarray) -> np.ndarray:
        return _model(t, x, u) + dist

    def f_o(t: np.ndarray, z: np.ndarray, u: np.ndarray, ybar: np.ndarray, yhat: np.ndarray) -> np.ndarray:
        # eq. (57) run on the held outputs: xhat' = A xhat + B u + G σ(H xhat) + L (ybar - C xhat)
        return _model(t, z, u) + _matvec(gain, ybar - yhat)

    jit_plant, jit_observer = _jit(gain)
    plant = Plant(f_p=f_p, h=lambda x: x[:, :2], n_x=4, n_y=2, n_u=1, n_v=4, name="robot arm", jit=jit_plant)
    observer = Observer(f_o=f_o, n_z=4, name="polytopic Luenberger", jit=jit_observer)
    params = {
        k: _pair(k, val) for k, val in dict(sigma=sigma, c=c, b=b, a=a, ell=ell, eps=eps, eta0=eta0).items()
    }
    nodes = tuple(
        Node(
            outputs=(i,),
            rule=DynamicRule(
                gamma=Quadratic(params["ell"][i]),
                alpha=Linear(params["a"][i]),
                sigma=params["sigma"][i],
                c=params["c"][i],
                b=params["b"][i],
                eps=params["eps"][i],
                eta0=params["eta0"][i],
            ),
            name=f"sensor {i + 1}",
        )
        for i in range(2)
    )
    return EstimationProblem(
        plant=plant,
        observer=observer,
        nodes=nodes,
        u=Sinusoid(amplitude=[1.0], omega=1.0),
        v=Sinusoid(amplitude=amp_v, omega=0.4),
        m=Sinusoid(amplitude=amp_m, omega=0.3),
    )


def _jit(gain: np.ndarray) -> tuple[JitPlant | None, JitObserver | None]:
    """Compiled versions of the model for ``backend="numba"`` (when numba is installed)."""
    from etobs.hybrid.compiled import numba_available

    if not numba_available():
        return None, None
    from etobs.examples import _robot_arm_jit as jit

    return JitPlant(f_p=jit.f_p, h=jit.h), JitObserver(f_o=jit.f_o, theta=gain.ravel())


def random_initial_states(n: int, seed: int | np.random.Generator | None = 0) -> np.ndarray:
    """The paper's random initial states for Table 1.

    ``x_1(0), x_3(0)`` uniform in ``[0, 20]`` and ``x_2(0), x_4(0)`` uniform in ``[0, 10]``.

    Returns
    -------
    ndarray, shape (n, 4)

    """
    n = v.integer("n", n, lower=1)
    rng = np.random.default_rng(seed)
    hi = np.array([20.0, 10.0, 20.0, 10.0])
    return rng.uniform(0.0, 1.0, size=(n, 4)) * hi


def robot_arm_network(n_arms: int, **rule: Any) -> EstimationProblem:
    """``n_arms`` independent robot arms observed together: ``N = 2 n_arms`` sensor nodes.

    A scalable version of the case study for benchmarks: plant and observer are the
    paper's arm repeated (``4 n_arms`` states each), node ``2k`` sends ``x_1`` and node
    ``2k + 1`` sends ``x_2`` of arm ``k``, all with the paper's rule (keyword arguments
    as in :func:`robot_arm`, e.g. ``eps=(10, 10)``), noise and disturbance.
    """
    n_arms = v.integer("n_arms", n_arms, lower=1)
    one = robot_arm(**rule)
    blocks = [slice(4 * k, 4 * k + 4) for k in range(n_arms)]
    outs = np.array([i for k in range(n_arms) for i in (4 * k, 4 * k + 1)])
    amp_v = np.tile(one.v.amplitude, n_arms)
    amp_m = np.tile(one.m.amplitude, n_arms)

    def f_p(t: np.ndarray, x: np.ndarray, u: np.ndarray, dist: np.ndarray) -> np.ndarray:
        return np.concatenate([one.plant.f_p(t, x[:, b], u, dist[:, b]) for b in blocks], axis=1)

    def f_o(t: np.ndarray, z: np.ndarray, u: np.ndarray, ybar: np.ndarray, yhat: np.ndarray) -> np.ndarray:
        parts = [
            one.observer.f_o(t, z[:, b], u, ybar[:, 2 * k : 2 * k + 2], yhat[:, 2 * k : 2 * k + 2])
            for k, b in enumerate(blocks)
        ]
        return np.concatenate(parts, axis=1)

    n = 4 * n_arms
    plant = Plant(
        f_p=f_p,
        h=lambda x: x[:, outs],
        n_x=n,
        n_y=2 * n_arms,
        n_u=1,
        n_v=n,
        name="robot arms",
        jit=one.plant.jit,
    )
    observer = Observer(f_o=f_o, n_z=n, name="polytopic Luenberger (per arm)", jit=one.observer.jit)
    nodes = tuple(
        Node(outputs=(2 * k + i,), rule=one.nodes[i].rule, name=f"arm {k + 1} sensor {i + 1}")
        for k in range(n_arms)
        for i in range(2)
    )
    return EstimationProblem(
        plant=plant,
        observer=observer,
        nodes=nodes,
        u=one.u,
        v=Sinusoid(amplitude=amp_v, omega=0.4),
        m=Sinusoid(amplitude=amp_m, omega=0.3),
    )
