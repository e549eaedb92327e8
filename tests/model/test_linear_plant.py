"""Linear plants and observers from matrices (etobs.model.linear)."""

import numpy as np
import pytest

from etobs import (
    DynamicRule,
    EstimationProblem,
    Linear,
    Node,
    Plant,
    Quadratic,
    Sinusoid,
    linear_luenberger,
    linear_plant,
    luenberger,
    simulate,
)
from etobs.errors import InputError, InputTypeError
from etobs.estimation.compiled import compile_problem

# a damped oscillator with a known force (B) and a disturbance (E), two outputs
A = np.array([[0.0, 1.0], [-2.0, -0.5]])
B = np.array([[0.0], [1.0]])
E = np.array([[0.2], [0.3]])
C = np.array([[1.0, 0.0], [0.5, 1.0]])
L = np.array([[1.0, 0.2], [0.5, 1.0]])
RULE = DynamicRule(gamma=Quadratic(1.0), alpha=Linear(1.0), eps=1e-3)


def _problem(plant, observer):
    return EstimationProblem(
        plant=plant,
        observer=observer,
        nodes=(Node(outputs=(0,), rule=RULE), Node(outputs=(1,), rule=RULE)),
        u=Sinusoid(amplitude=[1.0], omega=2.0),
        v=[0.5],
    )


def test_linear_plant_is_the_affine_field_and_output():
    plant = linear_plant(A, B, C, E=E, name="oscillator")
    assert (plant.n_x, plant.n_u, plant.n_v, plant.n_y, plant.name) == (2, 1, 1, 2, "oscillator")
    rng = np.random.default_rng(1)
    for _ in range(5):
        x, u, w = rng.normal(size=2), rng.normal(size=1), rng.normal(size=1)
        np.testing.assert_allclose(plant.call_f_p(0.3, x, u, w), A @ x + B @ u + E @ w, rtol=1e-15)
        np.testing.assert_allclose(plant.call_h(x), C @ x, rtol=1e-15)
    # the matrices are the parameters, flattened row by row in the order A, B, E, C
    np.testing.assert_array_equal(plant.params, np.concatenate([A.ravel(), B.ravel(), E.ravel(), C.ravel()]))


def test_defaults_no_input_no_disturbance_and_the_state_as_output():
    plant = linear_plant(A)
    assert (plant.n_x, plant.n_u, plant.n_v, plant.n_y) == (2, 0, 0, 2)
    x = np.array([1.0, -2.0])
    np.testing.assert_array_equal(plant.call_f_p(0.0, x, np.zeros(0), np.zeros(0)), A @ x)
    np.testing.assert_array_equal(plant.call_h(x), x)
    # a zero D is the paper's y = h(x), accepted
    assert linear_plant(A, B, C, D=np.zeros((2, 1))).n_y == 2


def test_linear_plant_and_observer_run_on_the_engine_and_agree_with_closures_and_the_reference():
    pb = _problem(linear_plant(A, B, C, E=E), linear_luenberger(A, L, B))
    res = simulate(pb, [[1.0, 0.0], [-1.0, 2.0]], 5.0)
    assert res.backend == "engine", res.backend_reason
    assert res.status_labels() == ["completed", "completed"]
    # the same model written as closures over the matrices (the hand-written way)
    plant = Plant(lambda t, x, u, v: A @ x + B @ u + E @ v, lambda x: C @ x, n_x=2, n_y=2, n_u=1, n_v=1)
    hand = simulate(
        _problem(plant, luenberger(lambda t, x, u: A @ x + B @ u, L)), [[1.0, 0.0], [-1.0, 2.0]], 5.0
    )
    ref = simulate(pb, [[1.0, 0.0], [-1.0, 2.0]], 5.0, backend="scipy")
    # the same arithmetic in the same order on the engine (matrices read from params or
    # frozen into the code): bit-identical; the reference agrees to its tolerance
    for name in ("run", "rule", "t", "x"):
        np.testing.assert_array_equal(getattr(hand.transmissions, name), getattr(res.transmissions, name))
    assert len(ref.transmissions) == len(res.transmissions) > 10
    np.testing.assert_array_equal(ref.transmissions.rule, res.transmissions.rule)
    np.testing.assert_allclose(ref.transmissions.t, res.transmissions.t, rtol=0, atol=1e-6)


def test_other_matrices_of_the_same_shape_reuse_the_compiled_model():
    first = compile_problem(_problem(linear_plant(A, B, C, E=E), linear_luenberger(A, L, B)))
    A2, L2 = A + 0.1, 2.0 * L
    second = compile_problem(_problem(linear_plant(A2, B, C, E=E), linear_luenberger(A2, L2, B)))
    assert second.system.addresses == first.system.addresses  # one compiled model
    assert not np.array_equal(second.params, first.params)  # the matrices are its numbers


def test_linear_luenberger_is_the_luenberger_observer_of_the_linear_model():
    obs = linear_luenberger(A, L, B, name="obs")
    ref = luenberger(lambda t, x, u: A @ x + B @ u, L)
    assert (obs.n_z, obs.name) == (2, "obs")
    rng = np.random.default_rng(2)
    for _ in range(5):
        z, u, ybar, yhat = rng.normal(size=2), rng.normal(size=1), rng.normal(size=2), rng.normal(size=2)
        np.testing.assert_allclose(
            obs.call_f_o(0.0, z, u, ybar, yhat), ref.call_f_o(0.0, z, u, ybar, yhat), rtol=1e-14
        )


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (
            {"A": [[0.0, 1.0, 2.0], [1.0, 2.0, 3.0]]},
            r"`A` has shape \(2, 3\); expected a square \(n_x, n_x\)",
        ),
        ({"A": [1.0, 2.0]}, r"`A` has shape \(2,\)"),
        ({"A": np.zeros((0, 0))}, r"`A` has shape \(0, 0\); expected a square"),
        ({"A": [[np.nan, 0.0], [0.0, 1.0]]}, r"`A` must be finite"),
        ({"B": np.ones((3, 1))}, r"`B` has shape \(3, 1\); expected \(2, '\*'\)"),
        ({"E": np.ones((1, 2))}, r"`E` has shape \(1, 2\); expected \(2, '\*'\)"),
        ({"C": np.ones((1, 3))}, r"`C` has shape \(1, 3\); expected \('\*', 2\)"),
        ({"C": np.ones((0, 2))}, r"`C` must have at least one row.*got shape \(0, 2\)"),
        ({"D": np.ones((2, 2))}, r"`D` has shape \(2, 2\); expected \(2, 1\)"),
        (
            {"D": [[0.0], [0.5]]},
            r"`D` must be zero: etobs's output map is y = h\(x\) \(eq. \(2\)\).*got D of shape \(2, 1\) "
            r"with nonzero entries at \[\(1, 0\)\] \(max \|D\| = 0.5\)",
        ),
    ],
)
def test_linear_plant_names_the_bad_matrix_and_its_expected_shape(kwargs, match):
    args = {"A": A, "B": B, "C": C, **kwargs}
    with pytest.raises(InputError, match=match):
        linear_plant(args.pop("A"), args.pop("B"), args.pop("C"), args.pop("D", None), E=args.pop("E", None))


def test_linear_plant_refuses_a_matrix_of_non_numbers():
    with pytest.raises(InputTypeError, match="`B` must be a matrix of real numbers"):
        linear_plant(A, [["a"], ["b"]])


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((A, np.ones((3, 1))), r"`L` has shape \(3, 1\); expected \(2, '\*'\)"),
        ((A, np.ones((2, 0))), r"`L` must have at least one column.*got shape \(2, 0\)"),
        ((A, L, np.ones((1, 1))), r"`B` has shape \(1, 1\); expected \(2, '\*'\)"),
        ((np.ones((2, 3)), L), r"`A` has shape \(2, 3\); expected a square"),
    ],
)
def test_linear_luenberger_names_the_bad_matrix(args, match):
    with pytest.raises(InputError, match=match):
        linear_luenberger(*args)
