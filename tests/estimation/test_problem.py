import numpy as np
import pytest

from etobs import (
    DynamicRule,
    EstimationProblem,
    InputError,
    InputTypeError,
    Linear,
    ModelError,
    Node,
    Observer,
    Plant,
    Quadratic,
    SaveAt,
    linear_luenberger,
    linear_plant,
    luenberger,
    simulate,
)
from etobs.estimation import max_estimation_error, min_inter_event_time, transmission_counts
from etobs.examples import robot_arm


def rule():
    return DynamicRule(gamma=Quadratic(1.0), alpha=Linear(1.0), sigma=1.0, c=0.1, b=1.0, eps=1.0, eta0=1.0)


def plant(n_x=3, n_y=3, **kw):
    return Plant(f_p=lambda t, x, u, v: -x, h=lambda x: x[:n_y], n_x=n_x, n_y=n_y, **kw)


def observer(n_z=3):
    return Observer(f_o=lambda t, z, u, ybar, yhat: -z, n_z=n_z)


def test_layout():
    pb = EstimationProblem(plant(), observer(), [Node((0, 2), rule()), Node((1,), rule())])
    lay = pb.layout
    assert (lay.x, lay.z, lay.ybar) == (slice(0, 3), slice(3, 6), slice(6, 9))
    assert lay.rule == (slice(9, 10), slice(10, 11))
    assert lay.n == 11


@pytest.mark.parametrize(
    ("nodes", "match"),
    [
        ([Node((0, 1), rule()), Node((1, 2), rule())], r"output 1 is claimed by nodes \[0, 1\]"),
        ([Node((0,), rule()), Node((1,), rule())], r"outputs \[2\] belong to no node"),
        ([Node((0, 1, 2, 3), rule())], r"outputs \[3\] do not exist \(n_y = 3\)"),
    ],
)
def test_nodes_must_partition_the_outputs(nodes, match):
    with pytest.raises(InputError, match="must partition the outputs 0..2: " + match.split(": ")[-1]):
        EstimationProblem(plant(), observer(), nodes)


def test_shape_errors_name_the_function():
    # each function is called once, for one run, when the problem is built
    bad_f = Plant(f_p=lambda t, x, u, v: x[:2], h=lambda x: x, n_x=3, n_y=3)
    with pytest.raises(
        ModelError, match=r"`f_p` returned shape \(2,\) for one run; expected \(3,\) = \(n_x,\)$"
    ):
        EstimationProblem(bad_f, observer(), [Node((0, 1, 2), rule())])
    bad_h = Plant(f_p=lambda t, x, u, v: x, h=lambda x: x[:1], n_x=3, n_y=3)
    with pytest.raises(
        ModelError, match=r"`h` returned shape \(1,\) for one run; expected \(3,\) = \(n_y,\)"
    ):
        EstimationProblem(bad_h, observer(), [Node((0, 1, 2), rule())])
    bad_o = Observer(f_o=lambda t, z, u, ybar, yhat: z[:1], n_z=3)
    with pytest.raises(
        ModelError, match=r"`f_o` returned shape \(1,\) for one run; expected \(3,\) = \(n_z,\)"
    ):
        EstimationProblem(plant(), bad_o, [Node((0, 1, 2), rule())])
    bad_psi = Observer(f_o=lambda t, z, u, ybar, yhat: -z, n_z=4, psi=lambda z: z)
    with pytest.raises(
        ModelError, match=r"`psi` returned shape \(4,\) for one run; expected \(3,\) = \(n_x,\)"
    ):
        EstimationProblem(plant(), bad_psi, [Node((0, 1, 2), rule())])


def test_a_function_written_for_a_batch_is_rejected_with_a_hint():
    # the old convention (runs on axis 0): f_p gives (1, n_x) for x of shape (n_x,)
    batched = Plant(f_p=lambda t, x, u, v: -np.atleast_2d(x), h=lambda x: x, n_x=3, n_y=3)
    with pytest.raises(
        ModelError,
        match=r"`f_p` returned shape \(1, 3\) for one run; expected \(3,\) = \(n_x,\): functions are "
        r"written for one run \(1-D arrays\), not a batch",
    ):
        EstimationProblem(batched, observer(), [Node((0, 1, 2), rule())])


def test_a_gain_L_of_another_size_than_the_plant_is_refused_naming_L():
    # before: ValueError "matmul: Input operand 1 has a mismatch..." raised inside etobs
    one_output = Plant(f_p=lambda t, x, u, v: -x, h=lambda x: x[:1], n_x=2, n_y=1)
    with pytest.raises(
        InputError,
        match=r"the observer's gain `L` has shape \(2, 2\); expected \(n_x, n_y\) = \(2, 1\) for this "
        r"plant \(one row per state, one column per output\)$",
    ):
        EstimationProblem(
            one_output, luenberger(lambda t, x, u: -x, L=[[1.0, 0.0], [1.0, 0.0]]), [Node((0,), rule())]
        )
    # before: "observer `n_z` = 1 is smaller than the plant's n_x = 2", without a word of L
    with pytest.raises(
        InputError, match=r"`L` has shape \(1, 2\); expected .* = \(2, 1\) .*: is L transposed\?"
    ):
        EstimationProblem(one_output, luenberger(lambda t, x, u: -x, L=[[1.0, 1.0]]), [Node((0,), rule())])
    a = -np.eye(4)
    two_outputs = linear_plant(a, C=np.eye(4)[:2])
    with pytest.raises(InputError, match=r"`L` has shape \(4, 3\); expected \(n_x, n_y\) = \(4, 2\)"):
        EstimationProblem(two_outputs, linear_luenberger(a, np.ones((4, 3))), [Node((0, 1), rule())])
    # the same gain on the right plant is accepted
    EstimationProblem(two_outputs, linear_luenberger(a, np.ones((4, 2))), [Node((0, 1), rule())])


def test_a_function_that_raises_at_construction_is_a_model_error_naming_it_and_the_call():
    # before: the user's raw IndexError, from the shape check at construction
    uses_v = Plant(f_p=lambda t, x, u, v: -x + v[0], h=lambda x: x[:1], n_x=2, n_y=1)
    with pytest.raises(
        ModelError,
        match=r"^`f_p` raised IndexError: index 0 is out of bounds for axis 0 with size 0; etobs called it "
        r"once at construction, to check its output's shape, as f_p\(t=0.0, x of shape \(2,\), u of shape "
        r"\(0,\), v of shape \(0,\)\)\. u and v are empty \(the plant's n_u, n_v = 0\): if `f_p` reads "
        r"one of them, give the Plant its size \(n_u=..., n_v=...\)$",
    ) as info:
        EstimationProblem(uses_v, observer(2), [Node((0,), rule())])
    assert isinstance(info.value.__cause__, IndexError)
    # an index past x: the message has no hint on n_u, n_v; params are shown when there are any
    past_x = Plant(f_p=lambda t, x, u, v, p: x[2] * p, h=lambda x, p: x[:1], n_x=2, n_y=1, params=[1.0])
    with pytest.raises(
        ModelError,
        match=r"`f_p` raised IndexError: index 2 is out of bounds .* as f_p\(t=0.0, x of shape \(2,\), "
        r"u of shape \(0,\), v of shape \(0,\), p of shape \(1,\)\)$",
    ):
        EstimationProblem(past_x, observer(2), [Node((0,), rule())])
    # an observer of one's own that multiplies ybar by a gain of the wrong size
    gain = np.ones((2, 2))
    bad_o = Observer(f_o=lambda t, z, u, ybar, yhat: -z + gain @ (ybar - yhat), n_z=2)
    with pytest.raises(
        ModelError,
        match=r"^`f_o` raised ValueError: matmul.* as f_o\(t=0.0, z of shape \(2,\), u of shape \(0,\), "
        r"ybar of shape \(1,\), yhat of shape \(1,\)\)$",
    ):
        EstimationProblem(plant(2, 1), bad_o, [Node((0,), rule())])


def test_nodes_must_be_a_list_even_for_one_node():
    # before: TypeError: 'Node' object is not iterable
    with pytest.raises(
        InputTypeError,
        match=r"`nodes` must be a list or tuple of Node objects \(one Node is nodes=\[Node\(...\)\]\); got Node",
    ):
        EstimationProblem(plant(), observer(), Node((0, 1, 2), rule()))
    with pytest.raises(
        InputTypeError, match=r"`nodes` must be a non-empty sequence of Node objects; got \['int'\]"
    ):
        EstimationProblem(plant(), observer(), [0])


def test_other_problem_errors():
    with pytest.raises(InputError, match=r"observer `n_z` = 2 is smaller than the plant's n_x = 3"):
        EstimationProblem(plant(), observer(2), [Node((0, 1, 2), rule())])
    with pytest.raises(InputTypeError, match=r"`plant` must be a Plant; got dict"):
        EstimationProblem({}, observer(), [Node((0,), rule())])  # type: ignore[arg-type]
    with pytest.raises(InputTypeError, match=r"`nodes` must be a non-empty sequence of Node"):
        EstimationProblem(plant(), observer(), [])
    with pytest.raises(InputError, match=r"`m` has dimension 2; expected 3"):
        EstimationProblem(plant(), observer(), [Node((0, 1, 2), rule())], m=[0.1, 0.1])
    with pytest.raises(InputError, match=r"`n_x` must be an integer >= 1; got 0"):
        plant(n_x=0)


@pytest.mark.parametrize(
    ("kwargs", "exc", "match"),
    [
        ({"x0": [3, 2, np.inf, -2]}, InputError, r"`x0` must be finite; runs \[0\] are not"),
        ({"x0": [3, 2, 3]}, InputError, r"`x0` has shape \(3,\); expected \(4,\) for one run or \(B, 4\)"),
        (
            {"x0": [[3, 2, 3, -2]] * 2, "z0": np.zeros((3, 4))},
            InputError,
            r"`z0` has 3 runs but x0 has 2; give one row or 2 rows",
        ),
        ({"t_end": -1.0}, InputError, r"`t_end` must be >= t0 = 0; got -1"),
        (
            {"backend": "rk4"},
            InputError,
            r"`backend` must be one of \('auto', 'engine', 'scipy'\) \(or 'numba' for 'engine'\); got 'rk4'",
        ),
        ({"e0": [0.0]}, InputError, r"`e0` has shape \(1,\); expected \(2,\)"),
        (  # before: AttributeError: 'numpy.ndarray' object has no attribute 'max_distance'
            {"save": np.linspace(0.0, 0.1, 3)},
            InputTypeError,
            r"`save` must be a SaveAt or None; the states on a time grid are save=SaveAt\(grid=times\); "
            r"got ndarray \[0.0, 0.05, 0.1\]",
        ),
        (  # before: AttributeError: 'dict' object has no attribute 'rtol'
            {"options": {"rtol": 1e-6}},
            InputTypeError,
            r"`options` must be a SolverOptions, e.g. options=SolverOptions\(rtol=1e-8\), or None; got dict "
            r"\{'rtol': 1e-06\} \(a dict of settings is SolverOptions\(\*\*settings\)\)",
        ),
    ],
)
def test_bad_simulate_arguments(kwargs, exc, match):
    args = {"x0": [3, 2, 3, -2], "t_end": 0.1} | kwargs
    x0, t_end = args.pop("x0"), args.pop("t_end")
    with pytest.raises(exc, match=match):
        simulate(robot_arm(), x0, t_end, **args)


def test_metrics_errors_and_edge_cases():
    res = simulate(robot_arm(), [3, 2, 3, -2], 0.5)
    with pytest.raises(InputError, match=r"this result kept no grid: simulate with save=SaveAt\(grid=...\)"):
        max_estimation_error(res, (0.0, 0.5))
    with pytest.raises(InputError, match=r"`window` must satisfy t_start <= t_stop; got \(2, 1\)"):
        transmission_counts(res, (2.0, 1.0))
    assert np.isnan(min_inter_event_time(res)).all()  # no node transmits twice in 0.5 s
    res = simulate(robot_arm(), [3, 2, 3, -2], 0.5, save=SaveAt(steps=False, grid=[0.0, 0.5]))
    with pytest.raises(InputError, match=r"the save grid has no point in the window \[0.1, 0.2\]"):
        max_estimation_error(res, (0.1, 0.2))
    with pytest.raises(InputError, match=r"this result kept no arcs"):
        res.arc(0)


@pytest.mark.parametrize("backend", ["engine", "scipy"])
def test_estimation_error_folded_during_the_solve_is_the_one_from_the_grid(backend):
    grid = np.linspace(0.5, 2.0, 151)
    x0 = [[3, 2, 3, -2], [10, 5, 15, 2]]
    full = simulate(robot_arm(), x0, 2.0, save=SaveAt(steps=False, grid=grid), backend=backend)
    save = SaveAt(steps=False, grid=grid, max_distance="estimation_error")
    folded = simulate(robot_arm(), x0, 2.0, save=save, backend=backend)
    assert folded.solution.grid is None and folded.notes == ()
    want = max_estimation_error(full, (0.5, 2.0))
    np.testing.assert_allclose(max_estimation_error(folded, (0.0, 2.0)), want, rtol=1e-14)
    assert np.all(want > 0)
    np.testing.assert_array_equal(folded.solution.jumps.t, full.solution.jumps.t)
    with pytest.raises(
        InputError, match=r"kept only max \|x - xhat\| over its grid \(151 points on \[0.5, 2\] s\)"
    ):
        max_estimation_error(folded, (1.0, 2.0))
    with pytest.raises(InputError, match=r"kept only max \|x - xhat\| over its grid \(SaveAt\(max_distance"):
        folded.on_grid()
    with pytest.raises(
        InputError, match=r"must be 'estimation_error' \(max \|x - xhat\|\); got \(\(0,\), \(4,\)\)"
    ):
        simulate(robot_arm(), x0, 2.0, save=SaveAt(grid=grid, max_distance=([0], [4])), backend=backend)


def test_estimation_error_with_psi_is_reduced_after_the_solve_and_says_so():
    from tests.estimation.test_one_run_models import _problem, _with_params

    pb = _problem(*_with_params())
    grid = np.linspace(1.0, 3.0, 41)
    full = simulate(pb, [[1.0, 0.0], [0.5, -1.0]], 3.0, save=SaveAt(steps=False, grid=grid))
    save = SaveAt(steps=False, grid=grid, max_distance="estimation_error")
    folded = simulate(pb, [[1.0, 0.0], [0.5, -1.0]], 3.0, save=save)
    assert folded.solution.grid is None
    assert folded.notes and "psi is not compiled into the solver" in folded.notes[0]
    np.testing.assert_array_equal(
        max_estimation_error(folded, (1.0, 3.0)), max_estimation_error(full, (1.0, 3.0))
    )


@pytest.mark.parametrize("backend", ["engine", "scipy"])
def test_a_huge_initial_state_ends_with_a_status(backend):
    # the audit's case: the engine raised ZeroDivisionError (the first step was 0)
    with np.errstate(all="ignore"):
        res = simulate(robot_arm(), [1e150, 0, 0, 0], 1.0, backend=backend)
    assert res.status_labels()[0] in ("step_underflow", "nonfinite")
    assert res.solution.t_final[0] < 1.0


def test_sigma_c_of_one_or_more_warns_naming_the_node():
    with pytest.warns(
        RuntimeWarning, match=r"node 0 \('sensor 1'\): sigma\*c = 1000\*0.001 = 1 >= 1: Theorem 1"
    ):
        robot_arm(sigma=(1000.0, 600.0))


def test_an_estimation_run_ending_zeno_gets_the_estimation_layers_advice():
    # the generic solver speaks of guards and jumps; the estimation result adds eps and
    # Theorem 4 (before: the generic solver's message held them, for any hybrid system)
    from etobs.hybrid import SolverOptions
    from etobs.model import StaticRule

    p = Plant(f_p=lambda t, x, u, v: np.cos(t) + 0 * x, h=lambda x: x.copy(), n_x=1, n_y=1)
    o = Observer(f_o=lambda t, z, u, ybar, yhat: ybar - z, n_z=1)
    pb = EstimationProblem(p, o, [Node((0,), StaticRule(gamma=Quadratic(1.0), eps=1e-300))])
    res = simulate(
        pb, [1.0], 1.0, backend="scipy", options=SolverOptions(zeno_jumps=50), save=SaveAt(steps=False)
    )
    assert res.status_labels() == ["zeno"]
    (message,) = res.messages()
    assert "every jump map leaves its guard's jump set" in message
    assert "The jumps are transmissions: check that every eps is > 0" in message
    assert "Theorem 4" in message
    assert "eps" not in res.solution.messages()[0]
