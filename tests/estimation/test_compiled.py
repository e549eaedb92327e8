"""Estimation problems on the compiled backend: closed form, numpy solver, unsupported parts."""

import numpy as np
import pytest

numba = pytest.importorskip("numba")

from etobs import EstimationProblem, Node, Observer, Plant, simulate  # noqa: E402
from etobs.errors import InputError  # noqa: E402
from etobs.estimation import transmission_counts  # noqa: E402
from etobs.examples import X0_PAPER, random_initial_states, robot_arm  # noqa: E402
from etobs.hybrid import SaveAt  # noqa: E402
from etobs.model import (  # noqa: E402
    Custom,
    DynamicRule,
    JitObserver,
    JitPlant,
    Linear,
    PeriodicRule,
    Quadratic,
    StaticRule,
)

from . import scalar  # noqa: E402


@numba.njit
def slope_f_p(t, x, u, v, theta, out):
    for i in range(x.shape[0]):
        out[i] = theta[i]


@numba.njit
def identity_h(x, theta, out):
    for i in range(x.shape[0]):
        out[i] = x[i]


@numba.njit
def still_f_o(t, z, u, ybar, yhat, theta, out):
    for i in range(z.shape[0]):
        out[i] = 0.0


def slopes(k, rules):
    """``x_i' = k_i``, ``y = x``, node i sends ``y_i`` with ``rules[i]``; observer at rest."""
    n = len(k)
    kk = np.asarray(k, dtype=float)
    plant = Plant(
        f_p=lambda t, x, u, v: np.broadcast_to(kk, x.shape).copy(),
        h=lambda x: x,
        n_x=n,
        n_y=n,
        jit=JitPlant(f_p=slope_f_p, h=identity_h, theta=kk),
    )
    observer = Observer(
        f_o=lambda t, z, u, ybar, yhat: np.zeros_like(z), n_z=n, jit=JitObserver(f_o=still_f_o)
    )
    return EstimationProblem(
        plant=plant, observer=observer, nodes=[Node((i,), r) for i, r in enumerate(rules)]
    )


def test_dynamic_rule_event_times_match_closed_form():
    rule = DynamicRule(
        gamma=Quadratic(scalar.ELL),
        alpha=Linear(scalar.A),
        sigma=scalar.SIGMA,
        c=scalar.C,
        b=scalar.B,
        eps=scalar.EPS,
        eta0=scalar.ETA0,
    )
    res = simulate(slopes([scalar.K], [rule]), [0.0], 6.0, backend="numba")
    t = res.solution.jumps.times(0, 0)
    np.testing.assert_allclose(t[:6], scalar.event_times(6), rtol=0, atol=1e-9)


def test_static_and_periodic_rules_match_closed_form():
    # static: |e| = k tau reaches sqrt(eps/ell) every sqrt(eps/ell)/k; periodic: every period
    rules = [StaticRule(gamma=Quadratic(4.0), eps=1.0), PeriodicRule(period=0.3, first=0.1)]
    res = simulate(slopes([2.0, 1.0], rules), [0.0, 0.0], 1.95, backend="numba")
    np.testing.assert_allclose(res.solution.jumps.times(0, 0), 0.25 * np.arange(1, 8), atol=1e-9)
    np.testing.assert_allclose(res.solution.jumps.times(0, 1), 0.1 + 0.3 * np.arange(7), atol=1e-9)


@pytest.mark.parametrize("noise", [True, False])
def test_robot_arm_matches_the_numpy_solver(noise):
    pb = robot_arm(noise=noise, disturbance=noise)
    x0 = np.vstack([X0_PAPER, random_initial_states(3, seed=7)])
    grid = np.linspace(20.0, 30.0, 201)
    save = SaveAt(steps=False, grid=grid)
    ours = simulate(pb, x0, 30.0, backend="numba", save=save)
    ref = simulate(pb, x0, 30.0, backend="fast", save=save)
    np.testing.assert_array_equal(transmission_counts(ours, (0, 30)), transmission_counts(ref, (0, 30)))
    np.testing.assert_array_equal(ours.solution.jumps.rule, ref.solution.jumps.rule)
    np.testing.assert_allclose(ours.solution.jumps.t, ref.solution.jumps.t, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ours.solution.grid.x, ref.solution.grid.x, rtol=0, atol=1e-7)
    if noise:  # the paper's first simulation: 52 and 55 transmissions (docs/robot-arm.md)
        assert transmission_counts(ours, (0, 30))[0].tolist() == [52, 55]


def test_unsupported_parts_are_named():
    plain = scalar.problem()
    with pytest.raises(InputError, match="needs compiled plant functions: give Plant\\(jit=JitPlant"):
        simulate(plain, [0.0], 1.0, backend="numba")
    pb = robot_arm()
    custom = Node((0,), DynamicRule(gamma=Custom(lambda s: s**3, name="cube"), eps=1.0), name="cubic")
    bad = EstimationProblem(pb.plant, pb.observer, (custom, pb.nodes[1]), u=pb.u, v=pb.v, m=pb.m)
    with pytest.raises(InputError, match="gamma of node 'cubic' is a Custom"):
        simulate(bad, X0_PAPER, 1.0, backend="numba")
    fn_u = EstimationProblem(pb.plant, pb.observer, pb.nodes, u=lambda t: np.cos(t)[:, None], v=pb.v, m=pb.m)
    with pytest.raises(InputError, match="signal `u` is a FunctionSignal"):
        simulate(fn_u, X0_PAPER, 1.0, backend="numba")
    with pytest.raises(InputError, match=r"`backend` must be one of \('fast', 'scipy', 'numba'\)"):
        simulate(pb, X0_PAPER, 1.0, backend="jax")


def test_jit_holders_are_validated():
    from etobs.errors import InputTypeError

    with pytest.raises(InputTypeError, match="`jit` must be a JitPlant; got dict"):
        Plant(f_p=lambda t, x, u, v: x, h=lambda x: x, n_x=1, n_y=1, jit={})
    with pytest.raises(InputError, match=r"`jit\.psi` must be given exactly when `psi` is"):
        Observer(f_o=lambda *a: None, n_z=1, psi=lambda z: z, jit=JitObserver(f_o=still_f_o))
