"""Estimation problems on the engine: closed forms, the scipy reference,
every rule, K-function and signal kind, and the choice of backend."""

import math
from dataclasses import dataclass

import numpy as np
import pytest

from etobs import EstimationProblem, Node, Observer, Plant, simulate
from etobs.errors import InputError, ModelError
from etobs.estimation import transmission_counts
from etobs.estimation.compiled import compile_problem
from etobs.examples import L_PAPER, X0_PAPER, random_initial_states, robot_arm
from etobs.hybrid import SaveAt, SolverOptions
from etobs.model import (
    Constant,
    Custom,
    DynamicRule,
    FunctionSignal,
    GeneralizedRule,
    InputNode,
    Linear,
    Link,
    Network,
    PeriodicRule,
    Power,
    Quadratic,
    RelativeRule,
    Sinusoid,
    StaticRule,
    send_on_delta,
)

from . import linear, scalar

TIGHT = SolverOptions(rtol=1e-12, atol=1e-12)


# ---- small one-run problems ----------------------------------------------------------------


def slopes(k, rules):
    """``x_i' = k_i``, ``y = x``, node i sends ``y_i`` with ``rules[i]``; observer at rest."""
    n = len(k)
    kk = np.asarray(k, dtype=float)
    plant = Plant(f_p=lambda t, x, u, v: kk.copy(), h=lambda x: x.copy(), n_x=n, n_y=n)
    observer = Observer(f_o=lambda t, z, u, ybar, yhat: np.zeros(n), n_z=n)
    return EstimationProblem(
        plant=plant, observer=observer, nodes=[Node((i,), r) for i, r in enumerate(rules)]
    )


def _oscillator(x, u, p):
    """A damped oscillator driven by ``u``: a helper the model functions call."""
    return np.array([x[1], -p[0] * x[0] - p[1] * x[1] + u[0]])


L_OSC = np.array([[3.0, 0.5], [-0.5, 3.0]])


def oscillator(rules, u=None, v=None, m=None):
    """Two outputs ``y = x + m``, node i sends ``y_i``; plant numbers in ``params``."""
    plant = Plant(
        f_p=lambda t, x, u, v, p: _oscillator(x, u, p) + v,
        h=lambda x, p: x.copy(),
        n_x=2,
        n_y=2,
        n_u=1,
        n_v=2,
        params=[2.0, 0.3],
    )
    observer = Observer(
        f_o=lambda t, z, u, ybar, yhat: _oscillator(z, u, np.array([2.0, 0.3])) + L_OSC @ (ybar - yhat),
        n_z=2,
    )
    nodes = [Node((i,), r, name=f"y{i}") for i, r in enumerate(rules)]
    return EstimationProblem(plant=plant, observer=observer, nodes=nodes, u=u, v=v, m=m)


SINE_U = Sinusoid(amplitude=[1.0], omega=1.0)

CASES = {
    "dynamic": (
        [
            DynamicRule(gamma=Quadratic(4.0), alpha=Linear(1.0), sigma=2.0, c=0.2, b=0.5, eps=0.01, eta0=0.1),
            DynamicRule(gamma=Power(3.0, 1.5), alpha=Quadratic(2.0), sigma=1.0, c=0.1, eps=0.02, eta0=0.3),
        ],
        dict(u=SINE_U),
    ),
    "dynamic-custom": (
        [
            DynamicRule(
                gamma=Custom(lambda s: 4.0 * s * s, name="4s^2"),
                alpha=Custom(lambda s: s + s**3, name="s+s^3"),
                sigma=2.0,
                c=0.2,
                eps=0.01,
                eta0=0.1,
            ),
            DynamicRule(
                gamma=Custom(lambda s: s * (1.0 + math.log1p(s))), alpha=Linear(2.0), sigma=0.5, eps=0.005
            ),
        ],
        dict(u=Constant([0.5]), m=Sinusoid(amplitude=[0.01, 0.0], omega=5.0)),
    ),
    "static": (
        [StaticRule(gamma=Linear(2.0), eps=0.05), StaticRule(gamma=Power(1.0, 2.0), eps=0.002)],
        dict(u=Constant([0.5])),
    ),
    "send_on_delta": (
        [send_on_delta(0.05), send_on_delta(0.03)],
        dict(u=FunctionSignal(lambda t: np.array([np.cos(2.0 * t)]), 1), m=Constant([0.01, -0.02])),
    ),
    "periodic": (
        [PeriodicRule(period=0.3, first=0.05), PeriodicRule(period=0.27)],
        dict(u=SINE_U, v=Sinusoid(amplitude=[0.0, 0.1], omega=0.7, phase=0.2, offset=0.01)),
    ),
    "relative": (
        [RelativeRule(rho=0.1, eps=0.02), RelativeRule(rho=0.2, eps=0.01)],
        dict(
            u=SINE_U,
            v=FunctionSignal(lambda t: np.array([0.0, 0.05 * np.sin(3.0 * t)]), 2),
            m=lambda t: np.array([0.01 * np.cos(t), 0.0]),  # a callable: wrapped as a FunctionSignal
        ),
    ),
    "generalized": (
        [
            GeneralizedRule(
                gamma=Quadratic(1.0),
                gamma_check=Quadratic(0.5),
                alpha_check=Linear(2.0),
                d_prime=4.0,
                sigma=0.5,
                eps=0.01,
                b=0.8,
                eta0=0.1,
            ),
            GeneralizedRule(
                gamma=Custom(lambda s: s * math.sqrt(s)),
                gamma_check=Custom(lambda s: s * s + s),
                alpha_check=Power(1.0, 1.2),
                d_prime=Linear(2.0),
                sigma=0.5,
                eps=0.01,
                eta0=0.2,
            ),
        ],
        dict(u=SINE_U),
    ),
}
X0_OSC = np.array([[1.0, -0.5], [0.3, 0.8]])


@pytest.mark.parametrize("case", list(CASES))
def test_every_rule_function_and_signal_kind_matches_scipy(case):
    rules, signals = CASES[case]
    pb = oscillator(rules, **signals)
    ours = simulate(pb, X0_OSC, 4.0, backend="engine")
    sci = simulate(pb, X0_OSC, 4.0, backend="scipy", options=TIGHT)
    assert ours.backend == "engine" and sci.backend == "scipy"
    assert ours.ok and sci.ok
    counts = transmission_counts(ours)
    assert np.all(counts >= 3), counts
    np.testing.assert_array_equal(counts, transmission_counts(sci))
    assert ours.transmissions.rule.tolist() == sci.transmissions.rule.tolist()
    np.testing.assert_allclose(ours.transmissions.t, sci.transmissions.t, rtol=0, atol=1e-6)
    np.testing.assert_allclose(ours.solution.x_final, sci.solution.x_final, rtol=0, atol=1e-6)


# ---- closed forms ----------------------------------------------------------------------


def test_dynamic_rule_event_times_match_closed_form():
    res = simulate(scalar.problem(), [0.0], 6.0, backend="engine")
    assert res.backend == "engine" and res.backend_reason == "asked for"
    t = res.solution.jumps.times(0, 0)
    np.testing.assert_allclose(t[:6], scalar.event_times(6), rtol=0, atol=1e-9)


def test_static_and_periodic_rules_match_closed_form():
    # static: |e| = k tau reaches sqrt(eps/ell) every sqrt(eps/ell)/k; periodic: every period
    rules = [StaticRule(gamma=Quadratic(4.0), eps=1.0), PeriodicRule(period=0.3, first=0.1)]
    res = simulate(slopes([2.0, 1.0], rules), [0.0, 0.0], 1.95, backend="engine")
    np.testing.assert_allclose(res.solution.jumps.times(0, 0), 0.25 * np.arange(1, 8), atol=1e-9)
    np.testing.assert_allclose(res.solution.jumps.times(0, 1), 0.1 + 0.3 * np.arange(7), atol=1e-9)


# ---- the robot arm ----------------------------------------------------------------------


@pytest.mark.parametrize("noise", [True, False])
def test_robot_arm_engine_matches_scipy(noise):
    pb = robot_arm(noise=noise, disturbance=noise)
    x0 = np.vstack([X0_PAPER, random_initial_states(1, seed=7)])
    grid = np.linspace(20.0, 30.0, 201)
    save = SaveAt(steps=False, grid=grid)
    ours = simulate(pb, x0, 30.0, backend="engine", save=save)
    sci = simulate(pb, x0, 30.0, backend="scipy", options=TIGHT, save=save)
    assert ours.backend == "engine" and sci.backend == "scipy"
    np.testing.assert_array_equal(transmission_counts(ours, (0, 30)), transmission_counts(sci, (0, 30)))
    assert ours.solution.jumps.rule.tolist() == sci.solution.jumps.rule.tolist()
    np.testing.assert_allclose(ours.solution.jumps.t, sci.solution.jumps.t, rtol=0, atol=1e-8)
    np.testing.assert_allclose(ours.solution.grid.x, sci.solution.grid.x, rtol=0, atol=1e-6)
    if noise:
        # x0 = X0_PAPER with noise and disturbance (the paper's first simulation, which does not
        # report its counts): 52 / 55 transmissions on [0, 30] is etobs's own reference value,
        # from the scipy reference at rtol = atol = 1e-12 (`sci` above), in docs/robot-arm.md
        assert transmission_counts(ours, (0, 30))[0].tolist() == [52, 55]


def test_the_model_text_does_not_grow_with_the_number_of_nodes():
    """Nodes of one kind share one loop over constant tables: compile time stays flat in N."""
    from etobs.estimation._model_source import model_source
    from etobs.examples.robot_arm import robot_arm_network
    from etobs.model.rules import engine_form_of

    def text(arms):
        pb = robot_arm_network(arms)
        return model_source(pb, [engine_form_of(nd.rule) for nd in pb.nodes]).text

    small, large = text(2), text(40)
    assert len(large.splitlines()) == len(small.splitlines())  # 4 nodes or 80: the same code
    assert "for jj in range(80):" in large and "for jj in range(4):" in small


def test_another_observer_gain_compiles_nothing_new():
    one = compile_problem(robot_arm())
    two = compile_problem(robot_arm(L=2 * L_PAPER))
    assert one.system.addresses == two.system.addresses
    assert [f.address for f in one.system.keep] == [f.address for f in two.system.keep]
    assert not np.array_equal(one.params, two.params)  # the gain travels in the parameters
    a = simulate(robot_arm(), X0_PAPER, 5.0, backend="engine")
    b = simulate(robot_arm(L=2 * L_PAPER), X0_PAPER, 5.0, backend="engine")
    assert not np.array_equal(a.solution.x_final, b.solution.x_final)


# ---- failures ----------------------------------------------------------------------------


class _Opaque:
    def __call__(self, x):
        return x


def test_a_function_numba_cannot_compile_is_named_and_scipy_runs_it():
    opaque = _Opaque()  # an arbitrary Python object
    plant = Plant(f_p=lambda t, x, u, v: opaque(-x), h=lambda x: x.copy(), n_x=1, n_y=1)
    observer = Observer(f_o=lambda t, z, u, ybar, yhat: ybar - yhat, n_z=1)
    pb = EstimationProblem(plant=plant, observer=observer, nodes=[Node((0,), send_on_delta(0.1))])
    with pytest.raises(ModelError, match=r"^`f_p` cannot be compiled: .*backend='scipy'"):
        simulate(pb, [1.0], 1.0, backend="engine")
    res = simulate(pb, [1.0], 1.0, backend="scipy")
    assert res.ok and len(res.transmissions) > 0


def _fails_past(f_p):
    """Two runs of ``x' = 1 + t`` whose ``f_p`` fails once ``x > 1.5``: from 1 (at t = sqrt(2) - 1) and -5."""
    plant = Plant(f_p=f_p, h=lambda x: x.copy(), n_x=1, n_y=1)
    observer = Observer(f_o=lambda t, z, u, ybar, yhat: np.zeros(1), n_z=1)
    pb = EstimationProblem(plant=plant, observer=observer, nodes=[Node((0,), send_on_delta(0.1))])
    res = simulate(pb, [[1.0], [-5.0]], 1.0, backend="engine")
    assert res.status_labels() == ["model_error", "completed"]
    t_final, x_final = res.solution.t_final[0], res.solution.x_final[0, 0]
    assert t_final <= math.sqrt(2.0) - 1.0 + 1e-9  # x = 1 + t + t^2/2 reaches 1.5 there
    # the run ends at its last good state: no step is taken on an output left unwritten
    assert x_final == pytest.approx(1.0 + t_final + t_final**2 / 2, abs=1e-8)
    grid = simulate(pb, [[1.0]], 1.0, backend="engine", save=SaveAt(steps=False, grid=np.linspace(0, 1, 101)))
    filled = grid.solution.grid.t[grid.solution.grid.j[0] >= 0]
    assert filled.max() <= t_final + 1e-12  # nothing saved past the failure
    return res


def test_wrong_shape_during_a_run_is_a_model_error_naming_the_function():
    def f_p(t, x, u, v):
        if x[0] > 1.5:
            return np.zeros(2)
        return np.array([1.0 + t])

    assert "`f_p` returned the wrong shape" in _fails_past(f_p).messages()[0]


# numba's C function reports the exception as "unraisable" (printed with its traceback)
@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_a_function_that_raises_during_a_run_is_a_model_error_of_the_estimation_model():
    def f_p(t, x, u, v):
        if x[0] > 1.5:
            raise ValueError("x too large")
        return np.array([1.0 + t])

    # the user functions are compiled into the model: numba prints the exception, and the
    # message names the model's call, not a function that may not be the one that raised
    message = _fails_past(f_p).messages()[0]
    assert "`the estimation model's flow` raised an exception" in message


# ---- choosing the backend ------------------------------------------------------------------


def test_auto_picks_the_engine_for_the_base_setting():
    res = simulate(robot_arm(), X0_PAPER, 1.0)
    assert res.backend == "engine"
    assert res.backend_reason == "auto: the engine models this problem"
    assert simulate(robot_arm(), X0_PAPER, 1.0, backend="numba").backend == "engine"  # earlier name
    for retired in ("numpy", "fast"):
        with pytest.raises(
            InputError, match=rf"^`backend` '{retired}' \(the batched numpy solver\) was retired"
        ):
            simulate(robot_arm(), X0_PAPER, 1.0, backend=retired)


EXTENSIONS = {
    "input nodes": lambda rule: linear.problem(rule, input_nodes=[InputNode((0,), rule, name="u")]),
    "network": lambda rule: linear.problem(rule, network=Network(Link(delay=0.01), seed=1)),
    "hold='innovation'": lambda rule: linear.problem(rule, hold="innovation"),
}


@pytest.mark.parametrize("what", list(EXTENSIONS))
def test_auto_picks_the_engine_for_the_extensions(what):
    pb = EXTENSIONS[what](StaticRule(gamma=Linear(1.0), eps=0.05))
    res = simulate(pb, [1.0, 0.0], 1.0)
    assert res.backend == "engine" and res.ok
    assert res.backend_reason == "auto: the engine models this problem"


def test_a_rule_of_your_own_runs_on_the_scipy_reference():
    from etobs.model.rules import StatelessRule

    class Threshold(StatelessRule):
        def trigger(self, t, e, s, y=None):
            return np.abs(e[:, 0]) - 0.05

    pb = linear.problem(Threshold())
    res = simulate(pb, [1.0, 0.0], 1.0)
    assert res.backend == "scipy" and "Threshold" in res.backend_reason
    with pytest.raises(
        InputError,
        match=r"^backend='engine': the engine runs etobs' rules; this problem uses node 'y''s rule "
        r"Threshold \(a rule of your own\); use backend='scipy' \(the reference runs any Python\)$",
    ):
        simulate(pb, [1.0, 0.0], 1.0, backend="engine")
    same = simulate(linear.problem(send_on_delta(0.05)), [1.0, 0.0], 1.0)
    assert same.backend == "engine"
    np.testing.assert_allclose(res.transmissions.t, same.transmissions.t, rtol=0, atol=1e-8)


@dataclass(frozen=True)
class _DoubledThreshold(StaticRule):
    """A user's variant of a built-in rule: the threshold is twice ``eps``."""

    def trigger(self, t, e, s, y=None):
        return np.abs(e[:, 0]) - 2.0 * self.eps


def test_a_subclass_of_a_built_in_rule_is_not_run_as_its_parent():
    pb = linear.problem(_DoubledThreshold(gamma=Linear(1.0), eps=0.05))
    auto = simulate(pb, [1.0, 0.0], 2.0)
    ref = simulate(pb, [1.0, 0.0], 2.0, backend="scipy")
    assert auto.backend == "scipy"
    assert "_DoubledThreshold" in auto.backend_reason
    np.testing.assert_array_equal(transmission_counts(auto), transmission_counts(ref))


def test_unknown_backend_is_named():
    with pytest.raises(InputError, match=r"`backend` must be one of \('auto', 'engine', 'scipy'\)"):
        simulate(robot_arm(), X0_PAPER, 1.0, backend="jax")
