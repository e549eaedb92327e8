"""The flexible-joint robot arm of the paper's case study (section 8).

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
from etobs._spec import factory
from etobs.estimation.problem import EstimationProblem
from etobs.model import DynamicRule, Linear, Node, Observer, Plant, Quadratic, Sampled, Sinusoid

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
#: The observer gain printed in the paper (section 8).
L_PAPER = np.array([[0.58, -42.96], [-4.67, 2.83], [3.16, 49.25], [16.34, 88.46]])
#: The initial condition of the paper's figures.
X0_PAPER = (3.0, 2.0, 3.0, -2.0)
#: Sector bound of the nonlinearity 3.3*sin(x_3): its slope lies in [-3.3, 3.3].
SECTOR = 3.3

#: The flexible-joint arm's states (Raff and Allgower's model, the paper's reference for it):
#: motor angle and velocity, link angle and velocity; the sensors measure the motor's two.
NAMES_AND_UNITS = {
    "state_names": ("motor angle", "motor velocity", "link angle", "link velocity"),
    "state_units": ("rad", "rad/s", "rad", "rad/s"),
    "output_names": ("motor angle", "motor velocity"),
    "output_units": ("rad", "rad/s"),
}

for _arr in (A, B, G, C, L_PAPER):
    _arr.setflags(write=False)


def _model(x: np.ndarray, u: float) -> tuple[float, float, float, float]:
    """``A x + B u + G*3.3*sin(x_3)`` for one arm (the model part of eq. (57)).

    A tuple, not an array: it costs no allocation, and these functions run hundreds of
    thousands of times per run.
    """
    return (
        x[1],
        A[1, 0] * x[0] + A[1, 1] * x[1] + A[1, 2] * x[2] + B[1] * u,
        x[3],
        A[3, 0] * x[0] + A[3, 2] * x[2] - SECTOR * np.sin(x[2]),
    )


def _pair(name: str, value: Any) -> tuple[float, float]:
    if np.ndim(value) == 0:
        value = (value, value)
    arr = v.vector(name, value, 2)
    return float(arr[0]), float(arr[1])


@factory
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
    sample_period: float | None = None,
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
    sample_period : float, optional
        Run each node's rule sampled every ``sample_period`` seconds, as a sensor node
        does (:class:`~etobs.model.Sampled`); default the continuous rule of the paper.

    Returns
    -------
    EstimationProblem

    """
    gain = v.matrix("L", L, (4, 2))
    amp_v = 0.02 * np.array([0.0, 1.0, 0.0, 1.0]) if v.flag("disturbance", disturbance) else np.zeros(4)
    amp_m = 0.01 * np.array([0.0, 1.0]) if v.flag("noise", noise) else np.zeros(2)

    plant = Plant(f_p=_plant, h=_output, n_x=4, n_y=2, n_u=1, n_v=4, name="robot arm", **NAMES_AND_UNITS)
    # the gain travels as the observer's parameters: another L compiles nothing
    observer = Observer(
        f_o=_observer,
        n_z=4,
        name="polytopic Luenberger",
        params=gain.ravel(),
        state_names=NAMES_AND_UNITS["state_names"],
        state_units=NAMES_AND_UNITS["state_units"],
    )
    params = {
        k: _pair(k, val) for k, val in dict(sigma=sigma, c=c, b=b, a=a, ell=ell, eps=eps, eta0=eta0).items()
    }
    nodes = tuple(
        Node(
            outputs=(i,),
            rule=_sampled(
                DynamicRule(
                    gamma=Quadratic(params["ell"][i]),
                    alpha=Linear(params["a"][i]),
                    sigma=params["sigma"][i],
                    c=params["c"][i],
                    b=params["b"][i],
                    eps=params["eps"][i],
                    eta0=params["eta0"][i],
                ),
                sample_period,
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


def _sampled(rule: DynamicRule, period: float | None) -> DynamicRule | Sampled:
    """``rule``, or ``rule`` sampled every ``period`` seconds."""
    return (
        rule
        if period is None
        else Sampled(rule, period=v.real("sample_period", period, lower=0.0, lower_open=True))
    )


def _plant(t: float, x: np.ndarray, u: np.ndarray, v: np.ndarray) -> tuple[float, ...]:
    """Plant ``x' = A x + B u + G*3.3*sin(x_3) + v`` (section 8)."""
    m = _model(x, u[0])
    return (m[0] + v[0], m[1] + v[1], m[2] + v[2], m[3] + v[3])


def _output(x: np.ndarray) -> np.ndarray:
    """``y = (x_1, x_2)``."""
    return x[:2]


def _observer(
    t: float, z: np.ndarray, u: np.ndarray, ybar: np.ndarray, yhat: np.ndarray, p: np.ndarray
) -> tuple[float, ...]:
    """Observer (57) on the held outputs; ``p`` is the gain ``L`` (4 x 2) row by row.

    ``xhat' = A xhat + B u + G σ(H xhat) + L (ybar - C xhat)``.
    """
    r0 = ybar[0] - yhat[0]
    r1 = ybar[1] - yhat[1]
    m = _model(z, u[0])
    return (
        m[0] + p[0] * r0 + p[1] * r1,
        m[1] + p[2] * r0 + p[3] * r1,
        m[2] + p[4] * r0 + p[5] * r1,
        m[3] + p[6] * r0 + p[7] * r1,
    )


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


@factory
def robot_arm_network(n_arms: int, **rule: Any) -> EstimationProblem:
    """``n_arms`` independent robot arms observed together: ``N = 2 n_arms`` sensor nodes.

    A scalable version of the case study for benchmarks: plant and observer are the
    paper's arm repeated (``4 n_arms`` states each), node ``2k`` sends ``x_1`` and node
    ``2k + 1`` sends ``x_2`` of arm ``k``, all with the paper's rule (keyword arguments
    as in :func:`robot_arm`, e.g. ``eps=(10, 10)``), noise and disturbance.
    """
    n_arms = v.integer("n_arms", n_arms, lower=1)
    one = robot_arm(**rule)
    amp_v = np.tile(one.v.amplitude, n_arms)
    amp_m = np.tile(one.m.amplitude, n_arms)

    def f_p(t: float, x: np.ndarray, u: np.ndarray, dist: np.ndarray) -> np.ndarray:
        out = np.empty(4 * n_arms)
        for k in range(n_arms):
            r = _plant(t, x[4 * k : 4 * k + 4], u, dist[4 * k : 4 * k + 4])
            for i in range(4):
                out[4 * k + i] = r[i]
        return out

    def h(x: np.ndarray) -> np.ndarray:
        out = np.empty(2 * n_arms)
        for k in range(n_arms):
            out[2 * k : 2 * k + 2] = x[4 * k : 4 * k + 2]
        return out

    def f_o(
        t: float, z: np.ndarray, u: np.ndarray, ybar: np.ndarray, yhat: np.ndarray, p: np.ndarray
    ) -> np.ndarray:
        out = np.empty(4 * n_arms)
        for k in range(n_arms):
            r = _observer(t, z[4 * k : 4 * k + 4], u, ybar[2 * k : 2 * k + 2], yhat[2 * k : 2 * k + 2], p)
            for i in range(4):
                out[4 * k + i] = r[i]
        return out

    n = 4 * n_arms
    plant = Plant(f_p=f_p, h=h, n_x=n, n_y=2 * n_arms, n_u=1, n_v=n, name="robot arms")
    observer = Observer(f_o=f_o, n_z=n, name="polytopic Luenberger (per arm)", params=one.observer.params)
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
