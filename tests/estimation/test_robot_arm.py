"""The paper's case study (section 8): cross-checks, defining properties, reference values."""

import numpy as np
import pytest

from etobs import SaveAt, SolverOptions, simulate
from etobs.estimation import min_inter_event_time, transmission_counts
from etobs.examples import L_PAPER, X0_PAPER, random_initial_states, robot_arm
from etobs.examples.robot_arm import A, B, C, G

T_END = 30.0
TIGHT = SolverOptions(rtol=1e-12, atol=1e-12)


@pytest.fixture(scope="module")
def paper_run():
    return simulate(robot_arm(), X0_PAPER, T_END)


def assert_backends_agree(res, ref):
    np.testing.assert_array_equal(transmission_counts(res), transmission_counts(ref))
    assert res.transmissions.rule.tolist() == ref.transmissions.rule.tolist()
    np.testing.assert_allclose(res.transmissions.t, ref.transmissions.t, rtol=0, atol=1e-8)


def test_engine_and_scipy_backend_agree_on_the_paper_run(paper_run):
    ref = simulate(robot_arm(), X0_PAPER, T_END, backend="scipy", options=TIGHT)
    assert ref.ok and paper_run.ok
    assert (paper_run.backend, ref.backend) == ("engine", "scipy")  # "auto" takes the engine
    assert_backends_agree(paper_run, ref)


@pytest.mark.slow
def test_engine_and_scipy_backend_agree_on_random_runs():
    x0 = random_initial_states(3, seed=2024)
    res = simulate(robot_arm(), x0, T_END)
    ref = simulate(robot_arm(), x0, T_END, backend="scipy", options=TIGHT)
    assert_backends_agree(res, ref)


def test_minimum_inter_event_times_match_the_paper(paper_run):
    # Section 8: "the minimum inter-event time measured is 0.201 s for sensor 1 and
    # 0.112 s for sensor 2" (three decimals, so we compare rounded values).
    mins = min_inter_event_time(paper_run)[0]
    assert np.round(mins, 3).tolist() == [0.201, 0.112]


def test_trigger_is_zero_from_below_at_every_transmission(paper_run):
    pb = robot_arm()
    system = pb.hybrid_system()
    arc = paper_run.solution.arcs[0]
    g = system.guard(arc.t, arc.x)
    pre = np.flatnonzero(np.diff(arc.j) == 1)
    log = paper_run.transmissions
    assert pre.size == len(log) > 50
    for k, node in zip(pre, log.rule, strict=True):
        # the transmitting node's trigger function has just reached zero ...
        assert 0.0 <= g[k, node] < 1e-6
        # ... from below: at the previous point of the same flow interval it was negative
        assert arc.j[k - 1] == arc.j[k] and arc.t[k - 1] < arc.t[k]
        assert g[k - 1, node] < 0
    flowing = np.ones(arc.t.size, bool)
    flowing[pre] = False
    assert np.all(g[flowing] < 0)  # every other point is in the flow set


def test_jump_map_of_eq_22(paper_run):
    pb = robot_arm()
    arc = paper_run.arc(0)
    pre = np.flatnonzero(np.diff(arc.j) == 1)
    for k, node in zip(pre, paper_run.transmissions.rule, strict=True):
        other = 1 - node
        assert arc.e[k + 1, node] == pytest.approx(0.0, abs=1e-14)  # e_i+ = 0
        assert arc.e[k + 1, other] == arc.e[k, other]  # e_j+ = e_j
        b = pb.nodes[node].rule.b
        assert arc.eta[k + 1, node] == b * arc.eta[k, node]  # eta_i+ = b_i eta_i
        assert arc.eta[k + 1, other] == arc.eta[k, other]
        np.testing.assert_array_equal(arc.x[k + 1], arc.x[k])
        np.testing.assert_array_equal(arc.z[k + 1], arc.z[k])


def test_eta_stays_nonnegative(paper_run):
    arc = paper_run.arc(0)
    assert np.all(arc.eta >= 0)
    x0 = random_initial_states(8, seed=3)
    res = simulate(robot_arm(b=(0.2, 0.0)), x0, 10.0, save=SaveAt(steps=False, grid=np.linspace(0, 10, 2001)))
    assert np.all(res.on_grid().eta >= 0)


def test_U_never_increases_at_jumps():
    # U = V(x, z) + sum_i d_i eta_i (eq. (24)); at a jump x and z are unchanged and
    # eta_i -> b_i eta_i, so U+ <= U for any V and any d_i > 0 (Theorem 1 (iii)).
    res = simulate(robot_arm(b=(0.5, 0.8)), X0_PAPER, 10.0)
    arc = res.arc(0)
    d = np.array([3.0, 7.0])
    xi = arc.x - arc.xhat
    U = np.einsum("ki,ki->k", xi, xi) + arc.eta @ d
    pre = np.flatnonzero(np.diff(arc.j) == 1)
    assert pre.size > 10
    assert np.all(U[pre + 1] <= U[pre])
    assert np.any(U[pre + 1] < U[pre])


def test_a_run_does_not_depend_on_its_batch():
    x0 = random_initial_states(6, seed=11)
    batch = simulate(robot_arm(), x0, 5.0, save=SaveAt(steps=False))
    alone = simulate(robot_arm(), x0[4], 5.0, save=SaveAt(steps=False))
    np.testing.assert_array_equal(batch.solution.x_final[4], alone.solution.x_final[0])
    np.testing.assert_array_equal(batch.transmissions.select(run=4).t, alone.transmissions.t)


def test_no_noise_and_no_disturbance():
    res = simulate(robot_arm(noise=False, disturbance=False), X0_PAPER, 2.0, save=SaveAt(grid=[0.0, 1.0]))
    traj = res.on_grid()
    # without noise, ybar(0) = C x(0) exactly (e(0, 0) = 0)
    np.testing.assert_array_equal(traj.ybar[0, 0], [3.0, 2.0])
    assert res.problem.m(np.array([1.0])).tolist() == [[0.0, 0.0]]


def test_paper_matrices_and_initial_conditions():
    # Transcribed from section 8 of the paper.
    assert A[1].tolist() == [-48.6, -1.25, 48.6, 0.0]
    assert A[3].tolist() == [19.5, 0.0, -19.5, 0.0]
    assert B.tolist() == [0.0, 21.6, 0.0, 0.0] and G.tolist() == [0.0, 0.0, 0.0, -1.0]
    assert C.tolist() == [[1, 0, 0, 0], [0, 1, 0, 0]]
    assert L_PAPER[:, 1].tolist() == [-42.96, 2.83, 49.25, 88.46]
    x0 = random_initial_states(1000, seed=0)
    assert x0.min() >= 0 and x0[:, [0, 2]].max() <= 20 and x0[:, [1, 3]].max() <= 10
    np.testing.assert_array_equal(x0, random_initial_states(1000, seed=0))
    rule = robot_arm().nodes[1].rule
    assert (rule.sigma, rule.c, rule.b, rule.alpha.a, rule.gamma.ell, rule.eps, rule.eta0) == (
        800,
        0.001,
        1,
        3,
        5,
        10,
        10,
    )


def test_robot_arm_network_repeats_the_arm():
    from etobs.examples import robot_arm_network

    x0 = random_initial_states(2, seed=1)
    single = simulate(robot_arm(), x0, 2.0, save=SaveAt(steps=False))
    net = simulate(
        robot_arm_network(3), np.concatenate([x0, x0[::-1], x0], axis=1), 2.0, save=SaveAt(steps=False)
    )
    assert net.n_nodes == 6
    per_arm = single.transmissions.counts(2, 2)
    np.testing.assert_array_equal(
        net.transmissions.counts(2, 6), np.hstack([per_arm, per_arm[::-1], per_arm])
    )


@pytest.mark.parametrize("name", ["noise", "disturbance"])
def test_switches_must_be_booleans(name):
    # a spec's noise = "false" (a string) counted as true, and runs.csv labelled it "false"
    from etobs.errors import InputTypeError

    with pytest.raises(InputTypeError, match=rf"`{name}` must be true or false; got 'false' \(str\)"):
        robot_arm(**{name: "false"})
    with pytest.raises(InputTypeError, match=rf"`{name}` must be true or false; got 1 \(int\)"):
        robot_arm(**{name: 1})
    robot_arm(**{name: False})
