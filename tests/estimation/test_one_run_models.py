"""Models written once, for one run: parameter vectors, user K-functions and signals on the engine."""

import math

import numpy as np
import pytest

from etobs import (
    Custom,
    DynamicRule,
    EstimationProblem,
    Linear,
    ModelError,
    Node,
    Observer,
    Plant,
    Quadratic,
    SaveAt,
    Sinusoid,
    SolverOptions,
    simulate,
)
from etobs.model import FunctionSignal
from tests.estimation import linear

X0 = np.array([[1.0, -0.5], [-2.0, 1.0]])
TIGHT = SolverOptions(rtol=1e-12, atol=1e-12)
# the oscillator of tests/estimation/linear.py as numbers: x'' = -K x - D x' + u, y = G x, gain L
K, D, G, L0, L1 = 1.0, 0.2, 1.0, 4.8, 4.04


def _rule():
    return DynamicRule(gamma=Quadratic(4.0), alpha=Linear(1.0), sigma=2.0, c=0.2, b=1.0, eps=0.01, eta0=0.1)


def _hard_coded():
    plant = Plant(
        f_p=lambda t, x, u, v: np.array([x[1], -1.0 * x[0] - 0.2 * x[1] + u[0]]),
        h=lambda x: np.array([1.0 * x[0]]),
        n_x=2,
        n_y=1,
        n_u=1,
    )

    def f_o(t, z, u, ybar, yhat):
        r = ybar[0] - yhat[0]
        return np.array([z[1] + 4.8 * r, -1.0 * z[0] - 0.2 * z[1] + u[0] + 4.04 * r])

    return plant, Observer(f_o=f_o, n_z=2)


def _with_params(k=K):
    plant = Plant(
        f_p=lambda t, x, u, v, p: np.array([x[1], -p[0] * x[0] - p[1] * x[1] + u[0]]),
        h=lambda x, p: np.array([p[2] * x[0]]),
        n_x=2,
        n_y=1,
        n_u=1,
        params=[k, D, G],
    )

    def f_o(t, z, u, ybar, yhat, p):
        r = ybar[0] - yhat[0]
        return np.array([z[1] + p[2] * r, -p[0] * z[0] - p[1] * z[1] + u[0] + p[3] * r])

    return plant, Observer(f_o=f_o, n_z=2, psi=lambda z, p: z[:2], params=[k, D, L0, L1])


def _problem(plant, observer):
    u = Sinusoid(amplitude=[1.0], omega=1.0)
    return EstimationProblem(plant=plant, observer=observer, nodes=[Node((0,), _rule())], u=u)


@pytest.mark.parametrize("backend", ["engine", "scipy"])
def test_params_give_the_same_run_as_the_numbers_written_in(backend):
    save = SaveAt(steps=False, grid=np.linspace(0.0, 8.0, 81))
    ref = simulate(_problem(*_hard_coded()), X0, 8.0, backend=backend, save=save)
    res = simulate(_problem(*_with_params()), X0, 8.0, backend=backend, save=save)
    assert res.ok and ref.ok and res.backend == backend
    assert len(ref.transmissions) > 10
    np.testing.assert_array_equal(res.transmissions.run, ref.transmissions.run)
    np.testing.assert_allclose(res.transmissions.t, ref.transmissions.t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(res.on_grid().x, ref.on_grid().x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(res.on_grid().xhat, ref.on_grid().xhat, rtol=0, atol=1e-12)
    # the parameters are used: another spring constant gives another run
    other = simulate(_problem(*_with_params(k=2.0)), X0, 8.0, backend=backend, save=save)
    assert np.abs(other.on_grid().x - ref.on_grid().x).max() > 0.1


def test_params_reach_the_functions_through_the_call_helpers():
    plant, observer = _with_params()
    x = np.array([2.0, -1.0])
    np.testing.assert_allclose(plant.call_f_p(0.0, x, np.array([0.5]), np.zeros(0)), [-1.0, -1.3])
    np.testing.assert_allclose(plant.call_h(x), [2.0])
    z = np.array([1.0, 3.0])
    np.testing.assert_allclose(
        observer.call_f_o(0.0, z, np.zeros(1), np.array([1.5]), np.array([1.0])), [3.0 + 2.4, -1.6 + 2.02]
    )
    np.testing.assert_allclose(observer.call_psi(z, 2), z)


def _custom_problem(u):
    # gamma(s) = 4 s^2 + s and alpha(s) = s + s^3: K-infinity functions with no built-in form
    rule = DynamicRule(
        gamma=Custom(lambda s: 4.0 * s * s + s),
        alpha=Custom(lambda s: s + s**3),
        sigma=2.0,
        c=0.2,
        b=0.5,
        eps=0.1,
        eta0=0.1,
    )
    return linear.problem(rule, u=u)


@pytest.mark.parametrize(
    "u",
    [
        FunctionSignal(lambda t: np.array([math.sin(t) + 0.5 * math.cos(3.0 * t)]), 1),
        lambda t: np.array([math.sin(t) + 0.5 * math.cos(3.0 * t)]),  # wrapped as a FunctionSignal
    ],
    ids=["FunctionSignal", "callable"],
)
def test_custom_k_functions_and_function_signals_run_on_the_engine(u):
    pb = _custom_problem(u)
    assert isinstance(pb.u, FunctionSignal)
    res = simulate(pb, X0, 10.0, z0=np.zeros(2))
    assert res.backend == "engine" and res.ok
    ref = simulate(pb, X0, 10.0, z0=np.zeros(2), backend="scipy", options=TIGHT)
    assert ref.backend == "scipy" and ref.ok
    assert len(res.transmissions) > 20
    np.testing.assert_array_equal(res.transmissions.run, ref.transmissions.run)
    np.testing.assert_allclose(res.transmissions.t, ref.transmissions.t, rtol=0, atol=1e-6)


def test_a_function_numba_cannot_compile_names_itself_and_scipy_still_runs_it():
    table = {"k": 1.0}

    def f_p(t, x, u, v):
        return -table["k"] * x  # a dict: Python, not numba

    pb = EstimationProblem(
        Plant(f_p=f_p, h=lambda x: x, n_x=1, n_y=1),
        Observer(f_o=lambda t, z, u, ybar, yhat: ybar - z, n_z=1),
        [Node((0,), DynamicRule(gamma=Quadratic(1.0), eps=0.01))],
    )
    with pytest.raises(ModelError, match=r"^`f_p` cannot be compiled: .*backend='scipy'"):
        simulate(pb, [1.0], 1.0, backend="engine")
    res = simulate(pb, [1.0], 1.0, backend="scipy", save=SaveAt(grid=[1.0]))
    assert res.ok and res.on_grid().x[0, 0, 0] == pytest.approx(math.exp(-1.0), rel=1e-6)


def _wide(n):
    """One node sending all ``n`` outputs of ``x' = -x``."""
    return EstimationProblem(
        Plant(f_p=lambda t, x, u, v: -x, h=lambda x: x, n_x=n, n_y=n),
        Observer(f_o=lambda t, z, u, ybar, yhat: -z + (ybar - yhat), n_z=n),
        [Node(tuple(range(n)), _rule())],
    )


def test_the_model_text_does_not_grow_with_a_node_s_outputs():
    # unrolled per component, 100 outputs took 278 s to compile and 5,000 overflowed the recursion
    from etobs.estimation import _model_source as ms
    from etobs.estimation.compiled import engine_form_of

    def code(n):
        pb = _wide(n)
        src = ms.model_source(pb, [engine_form_of(ch.rule) for ch in pb.layout.channels])
        # the lane form is there while its arrays fit on the stack (ms.LANE_STACK)
        assert src.lanes == (n == 2)
        text = src.text.split("def est_lanes")[0]
        return [line for line in text.splitlines() if " = np.array(" not in line]  # not the tables

    lines = code(2)
    assert len(code(5000)) == len(lines) and max(map(len, code(5000))) < 200
    assert any("for cc in range(2):" in line for line in lines)


def test_one_node_with_5000_outputs_compiles_and_runs():
    n = 5000
    res = simulate(_wide(n), np.ones(n), 0.5, z0=np.zeros(n))
    assert res.ok and res.backend == "engine"
    # the one node sends: its norm runs over all 5,000 components of e = ybar - y
    assert len(res.transmissions) >= 1 and set(res.transmissions.rule.tolist()) == {0}
