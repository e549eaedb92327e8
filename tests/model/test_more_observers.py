"""The extended Kalman filter and the high-gain observer, alone and event-triggered."""

import numpy as np
import pytest
from scipy.linalg import solve_continuous_are

from etobs import DynamicRule, EstimationProblem, Linear, Node, Plant, Quadratic, SaveAt, Sinusoid, simulate
from etobs.errors import InputError
from etobs.estimation import max_estimation_error, transmission_counts
from etobs.model import ekf_initial_state, extended_kalman_filter, high_gain_gain, high_gain_observer

A = np.array([[0.0, 1.0], [-2.0, -0.5]])
C = np.array([[1.0, 0.0]])


def linear(t, x, u):
    return A @ x


def test_ekf_on_a_linear_plant_converges_to_the_kalman_bucy_covariance():
    # reference: P solves the filter Riccati equation A P + P A' + Qn - P C' R^-1 C P = 0
    Qn, R = np.diag([0.1, 0.2]), np.array([[0.05]])
    ekf = extended_kalman_filter(linear, lambda x: x[:1], n_x=2, Qn=Qn, R=R)
    plant = Plant(f_p=lambda t, x, u, v: A @ x, h=lambda x: x[:1], n_x=2, n_y=1)
    rule = DynamicRule(gamma=Quadratic(1.0), alpha=Linear(1.0), eps=1e-6)
    pb = EstimationProblem(plant=plant, observer=ekf, nodes=(Node(outputs=(0,), rule=rule),))
    res = simulate(
        pb, [1.0, 0.0], 20.0, z0=ekf_initial_state([0.0, 0.0], np.eye(2)), save=SaveAt(steps=False)
    )
    P = res.solution.x_final[0, pb.layout.z][2:].reshape(2, 2)
    np.testing.assert_allclose(P, solve_continuous_are(A.T, C.T, Qn, R), rtol=1e-6)


def test_finite_difference_jacobians_match_analytic_ones():
    def f(t, x, u):
        return np.array([x[1], -np.sin(x[0]) - 0.3 * x[1]])

    def jf(t, x, u):
        return np.array([[0.0, 1.0], [-np.cos(x[0]), -0.3]])

    kw = dict(n_x=2, Qn=np.eye(2) * 0.1, R=[[0.1]])
    a = extended_kalman_filter(f, lambda x: x[:1], **kw)
    b = extended_kalman_filter(f, lambda x: x[:1], jac_f=jf, jac_h=lambda x: np.array([[1.0, 0.0]]), **kw)
    states = [
        (ekf_initial_state([0.3, -0.2], np.diag([1.0, 2.0])), 0.5),
        (ekf_initial_state([1.0, 0.5], np.eye(2)), 0.1),
    ]
    for z, ybar in states:
        args = (0.0, z, np.zeros(0), np.array([ybar]), z[:1])
        np.testing.assert_allclose(a.call_f_o(*args), b.call_f_o(*args), rtol=1e-6, atol=1e-8)


def _pendulum(observer, z0=None, noise=False):
    # x1' = x2, x2' = -sin(x1) - 0.3 x2 + u, y = x1, u = 0.5 sin t; one node, dynamic rule
    def f(t, x, u):
        return np.array([x[1], -np.sin(x[0]) - 0.3 * x[1] + u[0]])

    plant = Plant(f_p=lambda t, x, u, v: f(t, x, u), h=lambda x: x[:1], n_x=2, n_y=1, n_u=1)
    rule = DynamicRule(gamma=Quadratic(1.0), alpha=Linear(1.0), sigma=0.5, c=0.5, eps=1e-4)
    pb = EstimationProblem(
        plant=plant,
        observer=observer(f),
        nodes=(Node(outputs=(0,), rule=rule),),
        u=Sinusoid(amplitude=[0.5], omega=1.0),
    )
    grid = np.arange(0.0, 15.0001, 0.01)
    return simulate(pb, [[1.0, 0.0], [-0.5, 1.0]], 15.0, z0=z0, save=SaveAt(steps=False, grid=grid))


@pytest.mark.parametrize("kind", ["ekf", "high-gain"])
def test_event_triggered_estimate_converges(kind):
    if kind == "ekf":
        res = _pendulum(
            lambda f: extended_kalman_filter(f, lambda x: x[:1], n_x=2, Qn=np.eye(2), R=[[0.01]]),
            z0=ekf_initial_state([0.0, 0.0], np.eye(2)),
        )
    else:
        res = _pendulum(lambda f: high_gain_observer(f, 2, 5.0))
    assert res.ok
    early = max_estimation_error(res, (0.0, 0.5))
    late = max_estimation_error(res, (10.0, 15.0))
    assert np.all(late < 0.05) and np.all(late < early / 10)
    assert np.all(transmission_counts(res) > 10)


def test_high_gain_gain_and_errors():
    np.testing.assert_allclose(high_gain_gain(2, 4.0).ravel(), [8.0, 16.0])  # k = (2, 1): (s + 1)^2
    np.testing.assert_allclose(high_gain_gain(2, 2.0, k=[3.0, 2.0]).ravel(), [6.0, 8.0])
    with pytest.raises(
        InputError, match=r"`k` must make the companion matrix Hurwitz; got k = \[-1.0, 1.0\]"
    ):
        high_gain_gain(2, 1.0, k=[-1.0, 1.0])
    with pytest.raises(InputError, match="`theta` must be > 0; got 0"):
        high_gain_gain(2, 0.0)


def test_ekf_errors():
    with pytest.raises(InputError, match="`R` must be positive definite; its smallest eigenvalue is 0"):
        extended_kalman_filter(linear, lambda x: x, n_x=2, Qn=np.eye(2), R=np.zeros((2, 2)))
    with pytest.raises(InputError, match="`Qn` must be a symmetric matrix"):
        extended_kalman_filter(linear, lambda x: x, n_x=2, Qn=[[1.0, 1.0], [0.0, 1.0]], R=np.eye(2))
    with pytest.raises(InputError, match="`P0` must be positive definite"):
        ekf_initial_state([0.0, 0.0], -np.eye(2))
