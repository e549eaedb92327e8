"""What ``disturbance`` bounds: the ISS gain theta is for how v enters the plant, and certify says what it assumed.

Reproductions of a new user's trial (issue 15): with the disturbance entering as
``E = 30 e_4`` the certificate said "ok, bound 0.676" while the error reached 1.60; with a
constant wind of 1 and no ``disturbance`` given it said 0.377 while the error reached 1.09;
``certify(p, a_U=0.1, disturbance=0.01)`` without ISS gains said "all conditions hold".
"""

import html
import math

import numpy as np
import pytest

pytest.importorskip("cvxpy")

from etobs import Constant, EstimationProblem, Plant, SaveAt, Sinusoid, simulate
from etobs.design import QuadraticISS, certify, observer_gain, propose_rules, quadratic_iss_gains
from etobs.design.iss import plant_disturbance_matrix
from etobs.errors import InputError
from etobs.estimation import max_estimation_error
from etobs.model import linear_plant
from tests.design import wind_chain as wc

GAIN = observer_gain(wc.A, wc.C, objective="max_decay", max_gain=5.0)


def _params(iss, **target):
    rules = propose_rules(iss, c=[0.05, 0.05], **target).rules
    return {
        "L": GAIN.L.tolist(),
        "sigma": [r.sigma for r in rules],
        "c": [r.c for r in rules],
        "a": [r.alpha.a for r in rules],
        "ell": [r.gamma.ell for r in rules],
        "eps": [r.eps for r in rules],
    }


def test_theta_is_for_the_disturbance_matrix_given():
    E_v = wc.disturbance_matrix(30.0)
    iss = quadratic_iss_gains(GAIN, wc.NODES, c_v=0.1, c=[0.1, 0.1], E_v=E_v)
    assert iss.k_v == pytest.approx(np.linalg.norm(GAIN.P @ E_v, 2) ** 2 / 0.1, rel=1e-12)
    assert np.array_equal(iss.E_v, E_v) and not iss.E_v.flags.writeable
    default = quadratic_iss_gains(GAIN, wc.NODES, c_v=0.1, c=[0.1, 0.1])
    assert np.array_equal(default.E_v, np.eye(4))  # the paper's x' = ... + v (section 8)
    assert default.k_v == pytest.approx(np.linalg.norm(GAIN.P, 2) ** 2 / 0.1, rel=1e-12)
    assert iss.a == default.a and iss.k == default.k  # only theta depends on E_v
    with pytest.raises(InputError, match=r"`E_v` has shape \(3, 1\); expected \(4, '\*'\)"):
        quadratic_iss_gains(GAIN, wc.NODES, c_v=0.1, c=[0.1, 0.1], E_v=np.ones((3, 1)))


@pytest.mark.parametrize("e_scale", [1.0, 30.0])
def test_the_certified_bound_holds_when_v_enters_through_E(e_scale):
    # the new user's design: static rules, mu = 1e-4, a constant wind of 0.05 on mass 1
    E_v = wc.disturbance_matrix(e_scale)
    iss = quadratic_iss_gains(GAIN, wc.NODES, c_v=0.1, c=[0.1, 0.1], E_v=E_v)
    a_U = 0.5 * iss.a
    params = _params(iss, sigma=[0.0, 0.0], a_U=a_U, mu=1e-4)
    problem = wc.mychain(**params, wind=0.05, e_scale=e_scale, const=True)
    cert = certify(problem, iss, a_U=a_U, E=[5.0, 5.0], disturbance=0.05)
    assert cert.ok and cert.notes == () and cert.disturbance == 0.05
    r = simulate(problem, [[0.0, 0.0, 0.0, 0.0]], 60.0, save=SaveAt(grid=np.linspace(0.0, 60.0, 6001)))
    worst = float(max_estimation_error(r, (40.0, 60.0))[0])
    # the linear steady state |A_cl^-1 E v| is 0.0534 e_scale; before, the bound was 0.676 for both
    assert worst == pytest.approx(0.0534 * e_scale, rel=0.02)
    assert worst <= cert.error_bound


def test_gains_for_another_disturbance_input_are_refused():
    iss = quadratic_iss_gains(GAIN, wc.NODES, c_v=0.1, c=[0.1, 0.1])  # the identity: n_v = 4
    problem = wc.mychain(**_params(iss, sigma=[2.0, 2.0], nu=0.05), e_scale=30.0, const=True)
    with pytest.raises(
        InputError,
        match=r"E_v the identity, quadratic_iss_gains' default; the plant "
        r"'linear plant' has n_x = 4 states and n_v = 1 .* E_v must have shape \(4, 1\)",
    ):
        certify(problem, iss)
    unit = quadratic_iss_gains(GAIN, wc.NODES, c_v=0.1, c=[0.1, 0.1], E_v=wc.disturbance_matrix(1.0))
    with pytest.raises(
        InputError,
        match=r"the plant 'linear plant' has E_v = \[\[0.0\], \[0.0\], \[0.0\], "
        r"\[30.0\]\] \(read from f_p.*quadratic_iss_gains\(\.\.\., E_v=\.\.\.\)",
    ):
        certify(problem, unit)


def test_gains_by_hand_are_taken_on_trust_with_a_note():
    given = QuadraticISS(a=0.4, k_v=30.0, k=(60.0, 40.0), lambda_min_P=1.0, lambda_max_P=2.0)
    problem = wc.mychain(**_params(given, sigma=[2.0, 2.0], nu=0.05), e_scale=30.0)
    cert = certify(problem, given)
    assert any(n.startswith("the ISS gains carry no E_v (given by hand)") for n in cert.notes)
    assert "note: the ISS gains carry no E_v" in cert.format()


def test_the_disturbance_matrix_is_read_from_f_p():
    plant = linear_plant(wc.A, C=wc.C, E=[[0.0, 1.0], [2.0, 0.0], [0.0, 0.0], [0.0, 3.0]])
    assert plant_disturbance_matrix(plant).tolist() == [[0.0, 1.0], [2.0, 0.0], [0.0, 0.0], [0.0, 3.0]]
    quadratic = Plant(
        f_p=lambda t, x, u, v: wc.A @ x + np.array([0, 0, 0, v[0] ** 2]),
        h=lambda x: wc.C @ x,
        n_x=4,
        n_y=2,
        n_v=1,
        name="square wind",
    )
    with pytest.raises(InputError, match=r"the plant 'square wind' is not affine in its disturbance v\[0\]"):
        plant_disturbance_matrix(quadratic)


def _wind(iss, wind):
    return wc.mychain(**_params(iss, sigma=[2.0, 2.0], nu=0.05), wind=wind, const=True)


def test_a_known_v_is_bounded_and_noted_when_disturbance_is_not_given():
    iss = quadratic_iss_gains(GAIN, wc.NODES, c_v=0.1, c=[0.1, 0.1], E_v=wc.disturbance_matrix(1.0))
    problem = _wind(iss, 1.0)
    cert = certify(problem, iss)
    note = "disturbance not given: the error bound is for |v| <= sup_t |v(t)| = 1, of problem.v (Constant)"
    assert cert.notes == (note,) and cert.disturbance == 1.0
    assert cert.to_dict()["notes"] == [note] and cert.to_dict()["disturbance"] == 1.0
    assert f"note: {note}" in cert.format() and f"  note: {note}" in repr(cert)
    assert f"<th style='text-align:left'>note</th><td>{html.escape(note)}</td>" in cert._repr_html_()
    assert "for |v| <= 1\n" in cert.format()
    r = simulate(problem, [[0.0, 0.0, 0.0, 0.0]], 40.0, save=SaveAt(grid=np.linspace(0.0, 40.0, 4001)))
    worst = float(max_estimation_error(r, (30.0, 40.0))[0])
    assert worst == pytest.approx(1.09, abs=0.01) and worst <= cert.error_bound  # before: bound 0.377
    with pytest.raises(
        InputError,
        match=r"`disturbance` = 0.5 is below sup_t \|v\(t\)\| = 1 of the problem's "
        r"v \(Constant\): the error bound would not hold",
    ):
        certify(problem, iss, disturbance=0.5)
    assert certify(problem, iss, disturbance=1.5).notes == ()


def test_the_sup_of_a_sinusoid_is_exact():
    # |a s + o| is convex in s = sin(...): its sup is at s = +-1, here |(2, 0)| = |(0, -2)| = 2
    # (Sinusoid.bound, |(|a| + |o|)| = 2.83, is larger and would refuse valid bounds)
    plant = linear_plant(wc.A, C=wc.C, E=np.eye(4)[:, :2])
    iss = quadratic_iss_gains(GAIN, wc.NODES, c_v=0.1, c=[0.1, 0.1], E_v=np.eye(4)[:, :2])
    base = wc.mychain(**_params(iss, sigma=[2.0, 2.0], nu=0.05))
    v = Sinusoid(amplitude=[1.0, 1.0], omega=0.5, offset=[1.0, -1.0])
    problem = EstimationProblem(plant, base.observer, base.nodes, v=v)
    assert v.bound == pytest.approx(math.sqrt(8))
    assert certify(problem, iss).disturbance == pytest.approx(2.0, rel=1e-15)
    assert certify(problem, iss, disturbance=2.0).notes == ()
    with pytest.raises(InputError, match=r"`disturbance` = 1.9 is below sup_t \|v\(t\)\| = 2 "):
        certify(problem, iss, disturbance=1.9)
    still = EstimationProblem(plant, base.observer, base.nodes, v=Sinusoid([1.0, 1.0], omega=0.0, phase=0.5))
    assert certify(still, iss).disturbance == pytest.approx(math.sqrt(2) * math.sin(0.5), rel=1e-12)
    zero = EstimationProblem(plant, base.observer, base.nodes, v=Constant([0.0, 0.0]))
    assert certify(zero, iss).notes == () and certify(zero, iss).disturbance == 0.0


def test_a_function_v_has_no_error_bound_without_disturbance():
    iss = quadratic_iss_gains(GAIN, wc.NODES, c_v=0.1, c=[0.1, 0.1], E_v=wc.disturbance_matrix(1.0))
    base = _wind(iss, 1.0)
    problem = EstimationProblem(base.plant, base.observer, base.nodes, v=lambda t: np.array([np.sin(t) ** 3]))
    cert = certify(problem, iss)
    assert math.isnan(cert.error_bound) and math.isfinite(cert.mu) and cert.to_dict()["error_bound"] is None
    assert cert.notes == (
        "problem.v is a function (FunctionSignal), which certify cannot bound: no error bound without "
        "`disturbance` (a bound on |v(t)|)",
    )
    given = certify(problem, iss, disturbance=1.0)
    assert math.isfinite(given.error_bound) and given.disturbance == 1.0
    assert given.notes == (
        "disturbance = 1 is taken as a bound on |v(t)|; problem.v is a function "
        "(FunctionSignal), not checked",
    )


def test_a_U_and_disturbance_without_iss_are_refused():
    iss = quadratic_iss_gains(GAIN, wc.NODES, c_v=0.1, c=[0.1, 0.1], E_v=wc.disturbance_matrix(1.0))
    problem = _wind(iss, 0.01)
    with pytest.raises(
        InputError, match=r"`a_U` needs `iss`: .*; got a_U = 0.1, disturbance = 0.01 without `iss`"
    ):
        certify(problem, a_U=0.1, disturbance=0.01)
    with pytest.raises(InputError, match=r"`disturbance` needs `iss`: .*; got disturbance = 0.01 without"):
        certify(problem, disturbance=0.01)
    assert certify(problem).ok and certify(problem).notes == ()  # Theorem 1 alone needs neither
