"""The generalized rule (section 7.1), send-on-delta, and the noise condition of section 7.2."""

import warnings

import numpy as np
import pytest

from etobs import EstimationProblem, Linear, Node, Plant, Quadratic, SaveAt, Sinusoid, luenberger, simulate
from etobs.errors import InputError
from etobs.model import DynamicRule, GeneralizedRule, send_on_delta


def scalar_problem(rule, m=None):
    # x' = sin t, y = x, written for one run (t a float, x of shape (1,))
    plant = Plant(f_p=lambda t, x, u, v: np.sin(t) + 0.0 * x, h=lambda x: x, n_x=1, n_y=1)
    obs = luenberger(lambda t, x, u: np.sin(t) + 0.0 * x, [[2.0]])
    return EstimationProblem(plant=plant, observer=obs, nodes=(Node(outputs=(0,), rule=rule),), m=m)


def test_generalized_rule_formula_and_reduction_to_the_base_rule():
    # d' = d constant, gamma_check = c gamma, alpha_check = alpha: (45) is
    # (1 + d c) gamma(|e|) - sigma d alpha(eta) - eps, and eta' is eq. (14)'s
    g = GeneralizedRule(
        gamma=Quadratic(2.0),
        gamma_check=Quadratic(0.2),
        alpha_check=Linear(3.0),
        d_prime=5.0,
        sigma=0.4,
        eps=0.5,
    )
    base = DynamicRule(gamma=Quadratic(2.0), alpha=Linear(3.0), c=0.1, sigma=0.4, eps=0.5)
    t, e, s = np.zeros(3), np.array([[0.1], [1.0], [-2.0]]), np.array([[0.0], [1.0], [7.0]])
    np.testing.assert_allclose(
        g.trigger(t, e, s), (1 + 5 * 0.1) * 2 * e[:, 0] ** 2 - 0.4 * 5 * 3 * s[:, 0] - 0.5
    )
    np.testing.assert_allclose(g.derivative(t, e, s), base.derivative(t, e, s))
    np.testing.assert_allclose(g.reset(t, s), s)
    weighted = GeneralizedRule(
        gamma=Quadratic(1.0), gamma_check=Linear(1.0), d_prime=Linear(2.0), sigma=0.5, eps=1.0
    )
    np.testing.assert_allclose(weighted.weight(np.array([0.0, 3.0])), [0.0, 6.0])


def test_generalized_rule_trigger_is_zero_at_every_transmission():
    rule = GeneralizedRule(
        gamma=Quadratic(1.0), gamma_check=Quadratic(0.5), d_prime=Linear(1.0), sigma=0.5, eps=0.01, eta0=1.0
    )
    res = simulate(scalar_problem(rule), [0.0], 10.0, save=SaveAt(steps=True))
    arc = res.arc(0)
    jumps = np.flatnonzero(np.diff(arc.j) > 0)
    assert jumps.size > 5
    g = rule.trigger(arc.t[jumps], arc.e[jumps], arc.eta[jumps])
    np.testing.assert_allclose(g, 0.0, atol=1e-8)


def test_send_on_delta_transmits_when_the_gap_reaches_delta():
    res = simulate(scalar_problem(send_on_delta(0.1)), [0.0], 10.0, save=SaveAt(steps=True))
    arc = res.arc(0)
    jumps = np.flatnonzero(np.diff(arc.j) > 0)
    assert jumps.size > 5
    np.testing.assert_allclose(np.abs(arc.e[jumps, 0]), 0.1, atol=1e-8)
    with pytest.raises(InputError, match="`delta` must be > 0; got 0"):
        send_on_delta(0.0)


def test_generalized_rule_validates():
    with pytest.raises(InputError, match=r"`sigma` must be < 1; got 1"):
        GeneralizedRule(gamma=Quadratic(1.0), gamma_check=Linear(1.0), sigma=1.0)
    with pytest.raises(InputError, match="`d_prime` must be > 0; got 0"):
        GeneralizedRule(gamma=Quadratic(1.0), gamma_check=Linear(1.0), d_prime=0.0)


def test_noise_condition_warns_when_it_fails():
    rule = DynamicRule(gamma=Quadratic(1.0), eps=0.01)
    with pytest.warns(
        RuntimeWarning, match=r"node 0 .*eps = 0.01 <= gamma\(2 m\) = 0.04 with noise bound m = 0.1"
    ):
        scalar_problem(rule, m=Sinusoid(amplitude=[0.1], omega=1.0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scalar_problem(rule, m=Sinusoid(amplitude=[0.01], omega=1.0))  # gamma(0.02) = 4e-4 < eps
        scalar_problem(rule, m=Sinusoid(amplitude=[0.0], omega=1.0, offset=[5.0]))  # a bias cancels in e
