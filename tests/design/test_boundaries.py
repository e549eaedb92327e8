"""Every inequality a certificate checks, at its boundary and on both sides (issue 23, item 7).

A planted ``d >= d*`` (Theorem 1 needs ``d > d*``) and a ``check_gain`` judged only with
``Q = I`` went unnoticed before these tests.
"""

import math

import numpy as np
import pytest

pytest.importorskip("cvxpy")

from etobs import Quadratic
from etobs.design import certify, check_gain, quadratic_iss_gains, slope_vertices
from etobs.examples.robot_arm import L_PAPER, SECTOR, A, C, G, robot_arm

VERTS = slope_vertices(G[:, None], [[0.0, 0.0, 1.0, 0.0]], [(-SECTOR, SECTOR)])
GAIN = check_gain(A, C, L_PAPER, VERTS)
ISS = quadratic_iss_gains(GAIN, [[0], [1]], c_v=0.1, c=[0.1, 0.1])


def _holds(cert, name, node=None):
    (cond,) = [c for c in cert.conditions if c.name == name and c.node == node]
    return cond.holds


@pytest.mark.parametrize(("step", "holds"), [(0, False), (1, True)])
def test_d_must_exceed_d_star_strictly(step, holds):
    d_star = 600.0 / (1 - 600.0 * 0.001)  # node 0 of the paper's rules
    d0 = d_star if step == 0 else math.nextafter(d_star, math.inf)
    cert = certify(robot_arm(), d=[d0, 8000.0])
    assert cert.nodes[0].d_star == d_star
    assert _holds(cert, "d > d* (Theorem 1)", 0) is holds and cert.ok is holds


@pytest.mark.parametrize(("sigma", "holds"), [(1000.0, False), (math.nextafter(1000.0, 0.0), True)])
def test_sigma_c_must_be_below_one_strictly(sigma, holds, recwarn):
    cert = certify(robot_arm(sigma=(sigma, 800.0)))
    assert (sigma * 0.001 < 1) is holds
    assert _holds(cert, "sigma*c < 1 (Theorem 1)", 0) is holds
    assert math.isfinite(cert.nu) is holds
    assert [str(w.message).startswith("node 0 ('sensor 1'): sigma*c") for w in recwarn] == (
        [] if holds else [True]
    )


@pytest.mark.parametrize(("up", "holds"), [(False, False), (True, True)])
def test_eps_must_exceed_gamma_of_twice_the_noise_strictly(up, holds, recwarn):
    g2m = float(Quadratic(5.0)(np.array(0.02)))  # node 1: m = 0.01, gamma = 5 s^2
    eps = math.nextafter(g2m, math.inf) if up else g2m
    cert = certify(robot_arm(eps=(10.0, eps)))
    assert _holds(cert, "eps > gamma(2 m) (section 7.2)", 1) is holds
    assert len(recwarn) == (0 if holds else 1)  # the problem warns at the boundary too


@pytest.mark.parametrize(("up", "holds"), [(False, True), (True, False)])
def test_a_U_may_equal_a_but_not_exceed_it(up, holds):
    a_U = math.nextafter(ISS.a, math.inf) if up else ISS.a
    cert = certify(robot_arm(), ISS, a_U=a_U)
    assert _holds(cert, "a_U <= a and a_i > a_U / (1 - sigma_i c_i) (Theorem 2)") is holds
    assert math.isfinite(cert.mu) is holds


@pytest.mark.parametrize(("down", "holds"), [(False, False), (True, True)])
def test_a_i_must_exceed_a_U_over_one_minus_sigma_c_strictly(down, holds):
    # node 1 with a = 0.5: a_i (1 - sigma_i c_i) = 0.1 < a, so this limit binds first
    limit = 0.5 * (1 - 800.0 * 0.001)
    assert limit < ISS.a
    a_U = math.nextafter(limit, 0.0) if down else limit
    cert = certify(robot_arm(a=(2.0, 0.5)), ISS, a_U=a_U)
    assert _holds(cert, "a_U <= a and a_i > a_U / (1 - sigma_i c_i) (Theorem 2)") is holds


def _vertex_residuals(P, L, Q):
    return np.array(
        [np.linalg.eigvalsh(P @ Acl + Acl.T @ P + Q).max() for Acl in (A + V - L @ C for V in VERTS)]
    )


def test_check_gain_judges_with_the_Q_it_is_given():
    # Q far from the identity: the P found must meet it at every vertex, as an independent check shows
    Q = np.diag([1.0, 4.0, 0.5, 40.0])
    gain = check_gain(A, C, L_PAPER, VERTS, Q=Q)
    assert gain.ok and np.array_equal(gain.Q, Q)
    assert np.allclose(gain.residuals, _vertex_residuals(gain.P, L_PAPER, Q), rtol=1e-9, atol=1e-12)
    assert np.all(_vertex_residuals(gain.P, L_PAPER, Q) < 0)
    iss = quadratic_iss_gains(gain, [[0], [1]], c_v=0.1, c=[0.1, 0.1])
    assert iss.a == pytest.approx((0.5 - 0.3) / np.linalg.eigvalsh(gain.P).max(), rel=1e-12)


@pytest.mark.parametrize(("scale", "holds"), [(0.999, True), (1.001, False)])
def test_a_given_P_is_rechecked_with_the_given_Q_on_both_sides(scale, holds):
    # the largest Q = s Q0 that GAIN.P meets: s* = min over vertices of the decrease along Q0
    Q0 = np.diag([1.0, 4.0, 0.5, 40.0])
    R = np.linalg.cholesky(Q0)
    Ri = np.linalg.inv(R)
    decrease = [
        -np.linalg.eigvalsh(Ri @ (GAIN.P @ Acl + Acl.T @ GAIN.P) @ Ri.T).max()
        for Acl in (A + V - L_PAPER @ C for V in VERTS)
    ]
    s_star = min(decrease)
    gain = check_gain(A, C, L_PAPER, VERTS, P=GAIN.P, Q=scale * s_star * Q0)
    assert gain.ok is holds
    assert bool(np.all(_vertex_residuals(GAIN.P, L_PAPER, scale * s_star * Q0) < 0)) is holds
