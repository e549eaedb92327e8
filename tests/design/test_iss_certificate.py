"""ISS gains (section 8), the certificate of Theorems 1, 2 and 4 and the noise condition, tied to simulation."""

import json
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

pytest.importorskip("cvxpy")

from etobs import SaveAt, simulate
from etobs.design import certify, check_gain, estimate_output_rate, quadratic_iss_gains, slope_vertices
from etobs.errors import InputError
from etobs.estimation import min_inter_event_time
from etobs.examples.robot_arm import L_PAPER, SECTOR, X0_PAPER, A, C, G, random_initial_states, robot_arm

H = np.array([[0.0, 0.0, 1.0, 0.0]])
VERTS = slope_vertices(G[:, None], H, [(-SECTOR, SECTOR)])
GAIN = check_gain(A, C, L_PAPER, VERTS)
ISS = quadratic_iss_gains(GAIN, [[0], [1]], c_v=0.1, c=[0.1, 0.1])


def test_gains_are_the_papers_formulas():
    P, L = GAIN.P, GAIN.L
    lmax = np.linalg.eigvalsh(P).max()
    assert ISS.a == pytest.approx((1.0 - 0.1 - 0.2) / lmax, rel=1e-12)
    assert ISS.k_v == pytest.approx(np.linalg.norm(P, 2) ** 2 / 0.1, rel=1e-12)
    for i in range(2):
        assert ISS.k[i] == pytest.approx(np.linalg.norm(P @ L[:, [i]], 2) ** 2 / 0.1, rel=1e-12)


@settings(max_examples=200, deadline=None)
@given(
    x=st.lists(st.floats(-20, 20), min_size=4, max_size=4),
    xi=st.lists(st.floats(-5, 5), min_size=4, max_size=4),
    e=st.lists(st.floats(-3, 3), min_size=2, max_size=2),
    v=st.lists(st.floats(-1, 1), min_size=4, max_size=4),
)
def test_assumption_2_holds_with_these_gains(x, xi, e, v):
    # eq. (13) for V = xi' P xi along the robot arm and observer (57) fed with ybar = y + e
    x, xi, e, v = (np.array(a) for a in (x, xi, e, v))
    xhat = x - xi
    dxi = A @ xi + G * SECTOR * (np.sin(x[2]) - np.sin(xhat[2])) + v - L_PAPER @ (C @ xi + e)
    V = xi @ GAIN.P @ xi
    lhs = 2 * xi @ GAIN.P @ dxi
    rhs = -ISS.a * V + ISS.k[0] * e[0] ** 2 + ISS.k[1] * e[1] ** 2 + ISS.k_v * (v @ v)
    assert lhs <= rhs + 1e-9 * (1 + abs(rhs))


def test_split_constants_are_checked():
    with pytest.raises(InputError, match=r"lambda_min\(Q\) - c_v - sum\(c\) > 0; got 1 - 0.5 - 0.6 = -0.1"):
        quadratic_iss_gains(GAIN, [[0], [1]], c_v=0.5, c=[0.3, 0.3])
    with pytest.raises(InputError, match=r"`c` must have one constant per node \(2\); got 1"):
        quadratic_iss_gains(GAIN, [[0], [1]], c_v=0.1, c=[0.1])
    # a number raised TypeError: 'float' object is not iterable (issue 15)
    with pytest.raises(
        InputError,
        match=r"`c` must be a sequence with one constant per node \(2\); got the number 0.1: "
        r"write c=\[0.1, 0.1\] for 0.1 on every node",
    ):
        quadratic_iss_gains(GAIN, [[0], [1]], c_v=0.1, c=0.1)
    with pytest.raises(InputError, match=r"`c\[1\]` must be > 0; got 0"):
        quadratic_iss_gains(GAIN, [[0], [1]], c_v=0.1, c=[0.1, 0.0])
    with pytest.raises(InputError, match=r"`nodes\[1\]` must list output indices in 0..1; got \[2\]"):
        quadratic_iss_gains(GAIN, [[0], [2]], c_v=0.1, c=[0.1, 0.1])
    bad = check_gain(A, C, np.zeros((4, 2)), VERTS)
    with pytest.raises(InputError, match="`gain` does not pass its LMI re-check"):
        quadratic_iss_gains(bad, [[0], [1]], c_v=0.1, c=[0.1, 0.1])


def test_certificate_of_the_papers_parameters():
    cert = certify(robot_arm(), ISS, E=[10.0, 20.0], noise=[0.0, 0.01])
    assert cert.ok
    # Theorem 1 by hand: d* = sigma/(1 - sigma c) = 1500, 4000; d = 2 d*;
    # nu = sum (1 + d c) eps = 4*10 + 9*10 = 130; its infimum sum eps/(1 - sigma c) = 25 + 50
    assert [nd.d_star for nd in cert.nodes] == pytest.approx([1500.0, 4000.0])
    assert [nd.delta for nd in cert.nodes] == pytest.approx([3000 - 600 * 4, 8000 - 800 * 9])
    assert cert.nu == pytest.approx(130.0) and cert.nu_inf == pytest.approx(75.0)
    # Theorem 4 with section 7.2's noise: tau_i = (gamma^{-1}(eps) - 2 m_i)/E_i, gamma^{-1}(10) = sqrt(2)
    assert [nd.tau for nd in cert.nodes] == pytest.approx([math.sqrt(2) / 10, (math.sqrt(2) - 0.02) / 20])
    # Theorem 2: a_U = 0.9 min(a, 2 (1 - 0.6), 3 (1 - 0.8)); mu = (1 + max d_i c_i) sum eps / a_U
    a_U = 0.9 * min(ISS.a, 0.8, 0.6)
    d2 = [600 / (1 - 0.6 - a_U / 2), 800 / (1 - 0.8 - a_U / 3)]
    assert cert.a_U == pytest.approx(a_U)
    assert cert.mu == pytest.approx((1 + max(d * 0.001 for d in d2)) * 20 / a_U)
    assert cert.scale == pytest.approx(min(5 / (2 * k) for k in ISS.k))  # with noise: 2 k_i
    text = cert.format()
    assert "certificate: all conditions hold" in text and "nu = 130" in text
    assert cert.to_dict()["ok"] is True


def test_a_violated_condition_names_the_node():
    with pytest.warns(RuntimeWarning, match=r"node 1 \('sensor 2'\): sigma\*c = 1200\*0.001 = 1.2 >= 1"):
        pb = robot_arm(sigma=(600.0, 1200.0))
    cert = certify(pb)
    assert not cert.ok
    (fail,) = cert.failures()
    assert fail.node == 1 and fail.name == "sigma*c < 1 (Theorem 1)" and "1.2" in fail.detail
    assert math.isnan(cert.nu)
    with pytest.warns(RuntimeWarning, match="section 7.2's condition fails"):
        problem = robot_arm(eps=(10.0, 1e-4))
    noisy = certify(problem, noise=[0.0, 0.01])
    assert [(c.node, c.name) for c in noisy.failures()] == [(1, "eps > gamma(2 m) (section 7.2)")]
    fast = certify(robot_arm(), ISS, a_U=0.7)
    assert [c.name for c in fast.failures()] == ["a_U <= a and a_i > a_U / (1 - sigma_i c_i) (Theorem 2)"]


def test_certify_rejects_bad_input():
    with pytest.raises(InputError, match=r"`d` must have one value per node \(2\); got 1"):
        certify(robot_arm(), d=[1.0])
    with pytest.raises(InputError, match=r"`E\[0\]` must be > 0; got -1"):
        certify(robot_arm(), E=-1.0)
    with pytest.raises(InputError, match=r"`noise` must have one bound per node \(2\); got 1"):
        certify(robot_arm(), noise=[0.1])
    with pytest.raises(InputError, match="`problem` must be an EstimationProblem; got str"):
        certify("robot arm")


def test_observed_inter_event_times_are_never_below_tau():
    # Theorem 4 on simulated runs, with E_i estimated on the same runs (plus 5 % for the
    # grid); no measurement noise: the rule sees y itself
    pb = robot_arm(noise=False)
    x0 = np.vstack([X0_PAPER, random_initial_states(5, seed=3)])
    E = 1.05 * estimate_output_rate(pb, x0, 10.0)
    cert = certify(pb, E=list(E))
    res = simulate(pb, x0, 10.0, save=SaveAt(steps=False))
    mins = min_inter_event_time(res)
    for i, nd in enumerate(cert.nodes):
        assert np.nanmin(mins[:, i]) >= nd.tau > 0


@settings(max_examples=6, deadline=None)
@given(
    sigma=st.floats(0.0, 900.0),
    eps=st.floats(1.0, 50.0),
    a=st.floats(0.5, 5.0),
    b=st.floats(0.0, 1.0),
    seed=st.integers(0, 1000),
)
def test_U_never_increases_at_jumps_and_obeys_the_flow_bound(sigma, eps, a, b, seed):
    # Theorem 1 (ii)-(iii) along simulated arcs of the robot arm (paper's L, no v, m)
    pb = robot_arm(sigma=sigma, eps=eps, a=a, b=b, noise=False, disturbance=False)
    cert = certify(pb, ISS)
    assert cert.ok
    _check_U(pb, cert, GAIN.P, ISS.a, random_initial_states(1, seed=seed), 3.0)


def _check_U(pb, cert, P, rate, x0, t_end):
    """U = lambda V + sum d_i eta_i (V' = lambda V the scaled ISS Lyapunov function) along arcs."""
    lam, d = cert.scale, np.array([nd.d for nd in cert.nodes])
    res = simulate(pb, x0, t_end, save=SaveAt(steps=True))
    assert res.ok
    for run in range(res.n_runs):
        arc = res.arc(run)
        xi = arc.x - arc.xhat
        U = lam * np.einsum("ki,ij,kj->k", xi, P, xi) + arc.eta @ d
        jumps = np.flatnonzero(np.diff(arc.j) > 0)
        assert np.all(U[jumps + 1] <= U[jumps] * (1 + 1e-12) + 1e-12)  # Theorem 1 (iii)
        # Theorem 1 (ii), theta(|v|) = 0: dU/dt <= -a V' - sum delta_i alpha_i(eta_i) + nu
        flows = np.flatnonzero(np.diff(arc.j) == 0)
        k = flows[np.diff(arc.t)[flows] > 0]
        dU = (U[k + 1] - U[k]) / (arc.t[k + 1] - arc.t[k])
        eta_mid = 0.5 * (arc.eta[k + 1] + arc.eta[k])
        V_mid = 0.5 * (U[k + 1] + U[k]) - eta_mid @ d
        alpha_eta = np.stack([nd.rule.alpha(eta_mid[:, i]) for i, nd in enumerate(pb.nodes)], axis=1)
        bound = -rate * V_mid - alpha_eta @ np.array([nd.delta for nd in cert.nodes]) + cert.nu
        # a secant slope against the bound at the midpoint: allow the O(h^2) gap of the secant
        assert np.all(dU <= bound + 1e-3 * (1 + np.abs(bound)))


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 10_000), sigma=st.floats(0.0, 5.0), nu=st.floats(0.01, 1.0))
def test_U_on_random_linear_plants_with_designed_gains_and_proposed_rules(seed, sigma, nu):
    # random observable 2-state plant, two nodes (y_1 = x_1, y_2 = x_2), L from the LMIs,
    # ISS gains from P, rules from propose_rules(nu): the certificate holds and U behaves
    from etobs import EstimationProblem, Node, Plant, luenberger
    from etobs.design import observer_gain, propose_rules

    rng = np.random.default_rng(seed)
    A_ = rng.normal(size=(2, 2))
    assume(np.all(np.abs(np.linalg.eigvals(A_)) < 3))  # keep the horizon's growth moderate
    g = observer_gain(A_, np.eye(2), objective="max_decay", max_gain=20.0)
    iss = quadratic_iss_gains(g, [[0], [1]], c_v=0.1, c=[0.2, 0.2])
    prop = propose_rules(iss, sigma=[sigma, sigma], c=[0.1, 0.1], nu=nu, a=[1.0, 1.0])
    plant = Plant(f_p=lambda t, x, u, v: A_ @ x, h=lambda x: x, n_x=2, n_y=2)
    obs = luenberger(lambda t, x, u: A_ @ x, g.L)
    nodes = tuple(Node(outputs=(i,), rule=r) for i, r in enumerate(prop.rules))
    pb = EstimationProblem(plant=plant, observer=obs, nodes=nodes)
    cert = certify(pb, iss)
    assert cert.ok and cert.nu == pytest.approx(nu) and cert.scale == pytest.approx(1.0)
    x0 = rng.uniform(-3, 3, size=(2, 2))
    _check_U(pb, cert, g.P, iss.a, x0, 2.0)


def _arm(proposal):
    r = proposal.rules
    return robot_arm(
        sigma=[x.sigma for x in r],
        c=[x.c for x in r],
        b=[x.b for x in r],
        a=[x.alpha.a for x in r],
        ell=[x.gamma.ell for x in r],
        eps=[x.eps for x in r],
        noise=False,  # the proposals certify the noise-free case
    )


def test_proposed_rules_meet_the_requested_nu():
    from etobs.design import propose_rules

    prop = propose_rules(ISS, sigma=[600.0, 800.0], c=[0.001, 0.001], nu=50.0, a=[2.0, 3.0])
    cert = certify(_arm(prop), ISS)
    assert cert.ok and cert.nu == pytest.approx(50.0) and cert.scale == pytest.approx(1.0)


def test_proposed_rules_meet_the_requested_rate_and_bound():
    from etobs.design import propose_rules

    a_U = 0.5 * ISS.a
    prop = propose_rules(ISS, sigma=[600.0, 800.0], c=[0.001, 0.001], a_U=a_U, mu=2.0)
    cert = certify(_arm(prop), ISS, a_U=a_U)
    assert cert.ok and cert.a_U == pytest.approx(a_U) and cert.mu == pytest.approx(2.0)
    # with a_i = 2 a_U / (1 - sigma_i c_i), item (iv)'s d_i is 2 d_i*
    assert list(prop.d) == pytest.approx([2 * 600 / 0.4, 2 * 800 / 0.2])


def test_propose_rules_rejects_impossible_requests():
    from etobs.design import propose_rules

    with pytest.raises(InputError, match="give either `nu` \\(Theorem 1\\) or both `a_U` and `mu`"):
        propose_rules(ISS, sigma=[1.0, 1.0], c=[0.1, 0.1], a_U=0.1)
    with pytest.raises(InputError, match=r"node 1: sigma\*c must be < 1 \(Theorem 1\); got 20\*0.1 = 2"):
        propose_rules(ISS, sigma=[1.0, 20.0], c=[0.1, 0.1], nu=1.0)
    with pytest.raises(InputError, match=r"node 0: a must be > a_U / \(1 - sigma\*c\)"):
        propose_rules(ISS, sigma=[1.0, 1.0], c=[0.5, 0.5], a_U=0.1, mu=1.0, a=[0.1, 1.0])
    with pytest.raises(InputError, match=r"`a_U` must be <= "):
        propose_rules(ISS, sigma=[1.0, 1.0], c=[0.5, 0.5], a_U=10.0, mu=1.0)


@settings(max_examples=10, deadline=None)
@given(eps=st.floats(1e-4, 1e-1), sigma=st.floats(0.0, 5.0), x0=st.floats(0.5, 5.0))
def test_transmissions_stop_when_the_output_stays_in_a_small_ball(eps, sigma, x0):
    # Lemma 1: once |y(t) - y*| < gamma^{-1}(eps)/2 for all later t, at most one more
    # transmission (the one that resets e) happens. Plant x' = -x, y = x -> y* = 0.
    from etobs import DynamicRule, EstimationProblem, Linear, Node, Plant, Quadratic, luenberger

    plant = Plant(f_p=lambda t, x, u, v: -x, h=lambda x: x, n_x=1, n_y=1)
    obs = luenberger(lambda t, x, u: -x, [[1.0]])
    rule = DynamicRule(gamma=Quadratic(1.0), alpha=Linear(1.0), sigma=sigma, c=0.1, eps=eps)
    pb = EstimationProblem(plant=plant, observer=obs, nodes=(Node(outputs=(0,), rule=rule),))
    res = simulate(pb, [x0], 20.0, save=SaveAt(steps=False))
    T = np.log(x0 / (0.5 * np.sqrt(eps)))  # |y(t)| = x0 e^{-t} < sqrt(eps)/2 for t > T
    late = res.transmission_times(0, 0)
    assert np.sum(late > T) <= 1
    assert late.size >= 1  # it did transmit before


def test_noise_shortens_tau_and_enters_the_error_bound():
    # section 7.2: |e~| <= E s + 2 m after a transmission, so tau = (gamma^{-1}(eps) - 2 m) / E;
    # the observer's error is e~ + m: lambda = min ell / (2 k), plus sum 2 lambda k m^2 / a_U
    quiet = certify(robot_arm(noise=False), ISS, E=[10.0, 20.0], noise=[0.0, 0.0])
    noisy = certify(robot_arm(), ISS, E=[10.0, 20.0], noise=[0.0, 0.01])
    assert noisy.nodes[1].tau == pytest.approx((math.sqrt(2) - 0.02) / 20)
    assert noisy.nodes[0].tau == pytest.approx(quiet.nodes[0].tau)
    assert noisy.scale == pytest.approx(quiet.scale / 2)
    lam = noisy.scale
    expected = math.sqrt((noisy.mu + 2 * lam * ISS.k[1] * 0.01**2 / noisy.a_U) / (lam * ISS.lambda_min_P))
    assert noisy.error_bound == pytest.approx(expected)
    assert quiet.error_bound == pytest.approx(math.sqrt(quiet.mu / (quiet.scale * ISS.lambda_min_P)))
    assert len(noisy.d_U) == 2 and "with d_i = (" in noisy.format()


def test_more_input_checks():
    from etobs.design import even_split, propose_rules

    assert certify(robot_arm(), E=np.float32(3.0)).nodes[0].tau == pytest.approx(math.sqrt(2) / 3, rel=1e-6)
    with pytest.raises(InputError, match=r"`nodes` must share out the outputs 0..1 of L, each exactly once"):
        quadratic_iss_gains(GAIN, [[0]], c_v=0.1, c=[0.1])
    with pytest.raises(InputError, match=r"`a` must have one value per node \(2\); got 1"):
        propose_rules(ISS, sigma=[1.0, 1.0], c=[0.1, 0.1], nu=1.0, a=[1.0])
    with pytest.raises(InputError, match="`n_nodes` must be an integer >= 1; got 0"):
        even_split(GAIN, 0)


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        ({"hold": "innovation"}, r"the observer-copy hold \(nodes send ytilde - yhat"),
        ({"network": "lossy"}, r"a network with loss or delay on every node"),
        ({"network": "late sensor 2"}, r"a network with loss or delay on node\(s\) \[1\]"),
        ({"input_nodes": "one"}, r"1 input node\(s\) \(section 7.3: Assumption 4's ISS gain gamma_u"),
    ],
)
def test_certify_refuses_what_the_theorems_do_not_cover(change, reason):
    # Each of these certified before with the base problem's numbers: a false guarantee
    # (the copy hold's inter-event times are ~250x shorter than the certified tau on the
    # robot arm; 90 % loss and 0.5 s delay quadruple the error)
    from dataclasses import replace

    from etobs import Link, Network
    from etobs.model import InputNode, send_on_delta

    values = {
        "lossy": Network(Link(loss=0.9, delay=0.5)),
        "late sensor 2": Network([Link(), Link(delay=0.01)]),
        "one": (InputNode((0,), send_on_delta(0.05)),),
    }
    kw = {k: values.get(v, v) for k, v in change.items()}
    with pytest.raises(
        InputError, match=r"the paper's results \(Theorems 1-4\) do not cover this problem, .*" + reason
    ):
        certify(replace(robot_arm(), **kw), ISS)


def test_an_ideal_network_is_covered():
    from dataclasses import replace

    from etobs import Link, Network

    for network in (Network(Link()), Network(Link(loss=0.0, capacity=2))):
        assert certify(replace(robot_arm(), network=network), ISS).ok


def test_a_certificate_carries_the_P_and_gains_it_rests_on():
    # before: nothing in a certificate said which P (and so which ISS gains) it used
    cert = certify(robot_arm(), ISS, E=[10.0, 20.0], noise=[0.0, 0.01])
    assert cert.iss is ISS and np.array_equal(cert.iss.P, GAIN.P)
    assert not cert.iss.P.flags.writeable and cert.iss.P is not GAIN.P  # a copy the caller cannot change
    data = json.loads(cert.to_json())
    assert data["iss"]["P"] == GAIN.P.tolist() and data["iss"]["k"] == list(ISS.k)
    assert data["iss"]["c_v"] == 0.1 and data["iss"]["c"] == [0.1, 0.1]
    assert data["iss"]["P_origin"].startswith("found by check_gain for the given L")
    text = cert.format()
    assert "rests on the ISS gains (Assumption 2) alpha(s) = 0.19" in text
    assert "P found by check_gain for the given L" in text
    assert f"{GAIN.P[0, 0]:11.6g}" in text.split("P found by check_gain")[1]
    assert certify(robot_arm(), E=10.0).iss is None and certify(robot_arm(), E=10.0).to_dict()["iss"] is None


def test_certificate_repr_is_short_and_names_failures():
    cert = certify(robot_arm(), ISS, E=[10.0, 20.0], noise=[0.0, 0.01])
    lines = repr(cert).splitlines()
    verdict = "all conditions hold, under the 2 assumptions stated (not checked)"
    assert lines[0] == f"Certificate: {verdict}" and len(lines) == 7
    assert lines[1] == "  nu = 130, a_U = 0.1719, mu = 768.5, error bound = 1.394e+04, min tau [s] = 0.06971"
    assert lines[2] == f"  rests on ISS gains from P: {GAIN.origin}"
    # what was assumed is in the short view too: complete solutions, E as a bound
    assert lines[3].startswith("  assumed (not checked): solutions are complete")
    assert lines[4].startswith("  assumed (not checked): E = (10, 20) bounds |dh_i/dx f_p|")
    # and what certify took from the problem: the arm's v = 0.02 (0, 1, 0, 1) sin(0.4 t)
    assert lines[5] == (
        "  note: disturbance not given: the error bound is for |v| <= sup_t |v(t)| = 0.0282843, "
        "of problem.v (Sinusoid)"
    )
    assert lines[6].startswith("  note: with noise:")
    html = cert._repr_html_()
    assert html.startswith("<table>") and f"<td>{verdict}</td>" in html and "&#x27;" not in html[:20]
    assert "<th style='text-align:left'>assumed (not checked)</th>" in html
    assert cert.to_dict()["assumptions"] == list(cert.assumptions) and len(cert.assumptions) == 2
    with pytest.warns(RuntimeWarning, match="Theorem 1 needs"):
        bad = certify(robot_arm(sigma=(600.0, 1200.0)), E=10.0)
    lines = repr(bad).splitlines()
    assert lines[0] == f"Certificate: 1 of {len(bad.conditions)} conditions fail"
    assert lines[1] == "  FAIL sigma*c < 1 (Theorem 1) [node 1]: sigma*c = 1200*0.001 = 1.2"
    assert "<th style='text-align:left'>FAIL [node 1]</th>" in bad._repr_html_()


def test_check_gain_with_a_given_P_only_rechecks_it():
    again = check_gain(A, C, L_PAPER, VERTS, P=GAIN.P)
    assert again.ok and again.solver_status == "P given" and np.array_equal(again.P, GAIN.P)
    assert again.origin == "given with L (re-checked with eigenvalues)"
    assert quadratic_iss_gains(again, [[0], [1]], c_v=0.1, c=[0.1, 0.1]).k == ISS.k
    small = check_gain(A, C, L_PAPER, VERTS, P=1e-3 * np.eye(4))
    assert not small.ok and "the given P does not fit L and Q" in small.notes[0]
    with pytest.raises(InputError, match=r"`P` must be symmetric; got P - P' with largest entry 1"):
        check_gain(A, C, L_PAPER, VERTS, P=np.triu(np.ones((4, 4))))
    with pytest.raises(InputError, match=r"`P` has shape \(2, 2\); expected \(4, 4\)"):
        check_gain(A, C, L_PAPER, VERTS, P=np.eye(2))


def test_iss_gains_refuse_a_P_that_is_not_theirs():
    from dataclasses import replace

    with pytest.raises(
        InputError, match=r"`P` has extreme eigenvalues \(0.19\d+, 3.6\d+\); got lambda_min_P = 1"
    ):
        replace(ISS, lambda_min_P=1.0)


def test_estimate_output_rate_shows_progress_through_simulate(capsys):
    # issue 15, item 4: check's E_estimate ran its simulations without any progress shown
    problem = robot_arm(noise=False)
    quiet = estimate_output_rate(problem, X0_PAPER, 0.5, grid_step=1e-2, progress=False)
    assert capsys.readouterr().err == ""
    shown = estimate_output_rate(problem, X0_PAPER, 0.5, grid_step=1e-2, progress=True)
    assert "simulate" in capsys.readouterr().err and np.array_equal(quiet, shown)
    with pytest.raises(
        InputError, match=r"`progress` must be None \(a bar when stderr is a terminal\), True"
    ):
        estimate_output_rate(problem, X0_PAPER, 0.5, progress="yes")
