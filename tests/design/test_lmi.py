"""LMI observer design (section 8): feasibility, the eigenvalue re-check, the paper's gain."""

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

pytest.importorskip("cvxpy")

from etobs.design import check_gain, observer_gain, slope_vertices
from etobs.errors import DesignError, InputError
from etobs.examples.robot_arm import L_PAPER, SECTOR, A, C, G

H = np.array([[0.0, 0.0, 1.0, 0.0]])
VERTS = slope_vertices(G[:, None], H, [(-SECTOR, SECTOR)])


def test_vertices_are_the_papers_G1_G2():
    G1 = np.zeros((4, 4))
    G1[3, 2] = 3.3  # the paper's G_1 (section 8); G_2 = -G_1
    assert len(VERTS) == 2
    np.testing.assert_array_equal(VERTS[0], G1)
    np.testing.assert_array_equal(VERTS[1], -G1)


def test_papers_printed_gain_satisfies_its_own_lmis():
    g = check_gain(A, C, L_PAPER, VERTS)
    assert g.ok and g.notes == ()
    assert np.all(g.residuals <= g.margin)
    assert np.all(g.abscissa < 0)
    assert np.linalg.eigvalsh(g.P).min() > 0


def test_a_gain_that_does_not_stabilize_fails_the_check():
    g = check_gain(A, C, np.zeros((4, 2)), VERTS)
    assert not g.ok
    assert "no common quadratic Lyapunov function" in g.notes[0]


@pytest.mark.parametrize("objective,max_gain", [("min_gain", None), ("max_decay", 100.0)])
def test_robot_arm_design_is_feasible_and_passes_the_recheck(objective, max_gain):
    g = observer_gain(A, C, VERTS, objective=objective, max_gain=max_gain)
    assert g.ok and g.solver_status == "optimal"
    # the re-check: P A_cl,k + A_cl,k' P + Q <= margin at both vertices, A_cl,k Hurwitz
    for Ak in VERTS:
        Acl = A + Ak - g.L @ C
        assert np.linalg.eigvalsh(g.P @ Acl + Acl.T @ g.P + np.eye(4)).max() < 0
        assert np.linalg.eigvals(Acl).real.max() < 0
    if max_gain is not None:
        assert np.linalg.norm(g.L, 2) <= max_gain * (1 + 1e-6)
        # a faster guaranteed rate than the paper's gain under the same Q = I
        assert g.decay_rate > check_gain(A, C, L_PAPER, VERTS).decay_rate


@pytest.mark.filterwarnings("ignore:the SDP solver .* reports:RuntimeWarning")  # re-checked below
@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(2, 3))
def test_luenberger_design_for_random_observable_linear_plants(seed, n):
    rng = np.random.default_rng(seed)
    A_ = rng.normal(size=(n, n))
    C_ = rng.normal(size=(1, n))
    obs = np.vstack([C_ @ np.linalg.matrix_power(A_, k) for k in range(n)])
    # well observable plants (seen: 268/268 designed; badly conditioned ones may need
    # larger gains than the solver resolves, and then raise DesignError)
    assume(np.linalg.cond(obs) < 50)
    g = observer_gain(A_, C_)
    assert g.ok
    assert np.linalg.eigvals(A_ - g.L @ C_).real.max() < 0


def test_unobservable_unstable_mode_is_infeasible():
    A_ = np.diag([1.0, -1.0])  # x_1 is unstable and not seen by y = x_2
    with pytest.raises(DesignError, match="the observer LMIs have no solution"):
        observer_gain(A_, [[0.0, 1.0]])


def test_bad_inputs_are_named():
    with pytest.raises(
        InputError, match=r"`objective` must be one of \('min_gain', 'max_decay'\); got 'fast'"
    ):
        observer_gain(A, C, VERTS, objective="fast")
    with pytest.raises(InputError, match="`max_gain` is required with objective='max_decay'"):
        observer_gain(A, C, VERTS, objective="max_decay")
    with pytest.raises(InputError, match="`A` must be square; got shape"):
        observer_gain(np.ones((2, 3)), C)
    with pytest.raises(InputError, match="`Q` must be symmetric positive definite"):
        observer_gain(A, C, VERTS, Q=-np.eye(4))
    with pytest.raises(
        InputError, match=r"`slopes` must give \(low, high\) for each of the 1 components; got 2"
    ):
        slope_vertices(G[:, None], H, [(-1, 1), (0, 1)])
    with pytest.raises(InputError, match=r"`slopes\[0\]` must be finite with low <= high"):
        slope_vertices(G[:, None], H, [(1, -1)])
    with pytest.raises(InputError, match=r"`L` has shape \(2, 2\); expected \(4, 2\)"):
        check_gain(A, C, np.zeros((2, 2)))


def test_missing_cvxpy_is_reported(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "cvxpy", None)
    with pytest.raises(
        InputError, match=r"LMI design needs the optional dependency cvxpy; .*etobs\[design\]"
    ):
        observer_gain(A, C)


def test_designed_gain_runs_like_the_papers():
    # The rules see only y, so the transmissions do not depend on L; the estimation error
    # with our gain converges to a neighbourhood like the paper's (seen: max |x - xhat| on
    # [20, 30] 3.1 with ours, 8.7 with the paper's, from the paper's x0).
    from etobs import SaveAt, simulate
    from etobs.estimation import max_estimation_error, transmission_counts
    from etobs.examples.robot_arm import X0_PAPER, robot_arm

    ours = observer_gain(A, C, VERTS, objective="max_decay", max_gain=100.0)
    grid = np.arange(0.0, 30.0005, 0.01)
    res = {
        name: simulate(robot_arm(L=L), [X0_PAPER], 30.0, save=SaveAt(steps=False, grid=grid))
        for name, L in (("paper", L_PAPER), ("ours", ours.L))
    }
    np.testing.assert_array_equal(transmission_counts(res["ours"]), transmission_counts(res["paper"]))
    early = max_estimation_error(res["ours"], (0.0, 1.0))[0]
    late = max_estimation_error(res["ours"], (20.0, 30.0))[0]
    paper_late = max_estimation_error(res["paper"], (20.0, 30.0))[0]
    assert late < early and late < paper_late


def test_margins_are_validated():
    with pytest.raises(InputError, match=r"`margin` must be <= 1 % of lambda_min\(Q\) = 0.01; got 0.1"):
        observer_gain(A, C, VERTS, margin=0.1)
    with pytest.raises(InputError, match="`margin` must be > 0; got -1"):
        check_gain(A, C, L_PAPER, VERTS, margin=-1.0)


def test_min_gain_on_a_stable_linear_plant_is_no_gain():
    # what observer_gain's docstring says of "min_gain": with A Hurwitz, a large P alone meets Q
    from tests.design import chain

    g = observer_gain(chain.A, chain.C)
    assert g.ok and np.abs(g.L).max() < 1e-6
    fast = observer_gain(chain.A, chain.C, objective="max_decay", max_gain=5.0)
    assert fast.ok and fast.decay_rate > 10 * g.decay_rate


def test_a_given_p_uses_the_margin_and_refuses_a_solver():
    # x' = -x, C = 1, L = 0, P = 1: P A + A' P + Q = -2 + Q, so Q = 2 - 1e-13 holds by 1e-13
    gain = check_gain([[-1.0]], [[1.0]], [[0.0]], P=[[1.0]], Q=[[2.0 - 1e-13]], margin=1e-3)
    assert gain.ok  # true, but by less than the margin asked for: said, not hidden
    assert any("by less than margin = 0.001" in n for n in gain.notes)
    roomy = check_gain([[-1.0]], [[1.0]], [[0.0]], P=[[1.0]], Q=[[1.0]], margin=1e-3)
    assert roomy.ok and not any("margin" in n for n in roomy.notes)
    with pytest.raises(
        InputError, match=r"`solver` = 'CLARABEL' has no use with `P`: a given P is re-checked"
    ):
        check_gain([[-1.0]], [[1.0]], [[0.0]], P=[[1.0]], solver="CLARABEL")
