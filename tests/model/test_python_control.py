"""Plants from python-control systems (etobs.model.python_control)."""

import json
import re
import subprocess
import sys

import numpy as np
import pytest

ct = pytest.importorskip("control", reason="python-control (the 'control' extra) is not installed")

from etobs import (  # noqa: E402 - after the skip
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
    python_control_plant,
    simulate,
)
from etobs.errors import InputError, InputTypeError, ModelError  # noqa: E402
from etobs.estimation.compiled import compile_problem  # noqa: E402

# the oscillator of test_linear_plant: a known force and a wind disturbance, two outputs
A = np.array([[0.0, 1.0], [-2.0, -0.5]])
B = np.array([[0.0, 0.2], [1.0, 0.3]])  # columns: force, wind
C = np.array([[1.0, 0.0], [0.5, 1.0]])
L = np.array([[1.0, 0.2], [0.5, 1.0]])
RULE = DynamicRule(gamma=Quadratic(1.0), alpha=Linear(1.0), eps=1e-3)
X0 = [[1.0, 0.0], [-1.0, 2.0]]


def _oscillator(**kw):
    kw = {"inputs": ["force", "wind"], "outputs": ["pos", "mix"], "name": "oscillator", **kw}
    return ct.ss(A, B, C, np.zeros((2, 2)), **kw)


def _problem(plant, observer, nodes=None, v=(0.5,)):
    return EstimationProblem(
        plant=plant,
        observer=observer,
        nodes=nodes or (Node(outputs=(0,), rule=RULE), Node(outputs=(1,), rule=RULE)),
        u=Sinusoid(amplitude=[1.0], omega=2.0) if plant.n_u else None,
        v=list(v) if plant.n_v else None,
    )


def _same_transmissions(a, b):
    """Bit-identical logs: runs, nodes, times, hybrid times and the values sent."""
    ta, tb = a.transmissions, b.transmissions
    assert len(ta) == len(tb) > 10
    for name in ("run", "rule", "t", "j", "x"):
        np.testing.assert_array_equal(getattr(ta, name), getattr(tb, name), err_msg=name)


# ---- StateSpace ------------------------------------------------------------------------


def test_a_statespace_and_the_same_matrices_give_identical_transmissions():
    observer = linear_luenberger(A, L, B[:, :1])
    from_control = python_control_plant(_oscillator(), disturbances=["wind"])
    from_matrices = linear_plant(A, B[:, :1], C, E=B[:, 1:])
    res = [simulate(_problem(p, observer), X0, 5.0) for p in (from_control, from_matrices)]
    assert [r.backend for r in res] == ["engine", "engine"]
    _same_transmissions(*res)
    # one implementation: the same functions' code and the same numbers
    assert from_control.params.tolist() == from_matrices.params.tolist()
    assert from_control.f_p.__code__ is from_matrices.f_p.__code__


def test_inputs_split_into_u_and_v_by_label_or_index_in_the_order_given():
    sys3 = ct.ss(A, np.array([[0.0, 0.1, 0.2], [1.0, 0.3, -0.4]]), C, 0, inputs=["a", "b", "c"])
    plant = python_control_plant(sys3, disturbances=["c", 0])  # v = (c, a); u = (b,)
    assert (plant.n_u, plant.n_v) == (1, 2)
    rng = np.random.default_rng(3)
    for _ in range(3):
        x, u, w = rng.normal(size=2), rng.normal(size=1), rng.normal(size=2)
        full = np.array([w[1], u[0], w[0]])  # the system's input vector (a, b, c)
        np.testing.assert_allclose(plant.call_f_p(0.0, x, u, w), sys3.dynamics(0.0, x, full), rtol=1e-14)
    assert python_control_plant(sys3, disturbances=[2, 0]).params.tolist() == plant.params.tolist()


def test_outputs_choose_and_order_y_and_a_feedthrough_on_an_unmeasured_output_is_allowed():
    D = np.array([[0.0, 0.0], [0.7, 0.0]])  # the second output feeds the force through
    sys_d = ct.ss(A, B, C, D, inputs=["force", "wind"], outputs=["pos", "mix"])
    plant = python_control_plant(sys_d, disturbances=["wind"], outputs=["pos"])
    assert plant.n_y == 1
    np.testing.assert_array_equal(plant.call_h(np.array([2.0, 3.0])), [2.0])
    swapped = python_control_plant(_oscillator(), outputs=[1, "pos"])
    np.testing.assert_allclose(swapped.call_h(np.array([2.0, 3.0])), [4.0, 2.0])
    with pytest.raises(
        InputError,
        match=r"`D` must be zero: etobs's output map is y = h\(x\).*\[\(1, 0\)\] \(output 'mix' on input "
        r"'force'\).* or choose the outputs without feedthrough: outputs=\['pos'\]$",
    ):
        python_control_plant(sys_d, disturbances=["wind"])
    with pytest.raises(
        InputError, match=r"\(output 'pos' on input 'force'.*\(every output of the system has"
    ):
        python_control_plant(
            ct.ss(A, B, C, np.ones((2, 2)), inputs=["force", "wind"], outputs=["pos", "mix"])
        )


def test_a_plant_passed_a_python_control_system_as_a_function_says_what_to_use():
    with pytest.raises(InputTypeError, match=r"`f_p` is a python-control StateSpace.*python_control_plant"):
        Plant(f_p=_oscillator(), h=lambda x: x, n_x=2, n_y=2)


@pytest.mark.parametrize(
    ("make", "kwargs", "error", "match"),
    [
        (
            lambda: _oscillator(dt=0.1),
            {},
            InputError,
            r"`sys` must be continuous-time \(dt = 0\); got dt = 0.1",
        ),
        (lambda: _oscillator(dt=True), {}, InputError, r"continuous-time \(dt = 0\); got dt = True"),
        (lambda: ct.tf([1.0], [1.0, 1.0]), {}, InputTypeError, r"TransferFunction.*pass control.ss\(sys\)"),
        (lambda: A, {}, InputTypeError, r"`sys` must be a control.StateSpace or control.NonlinearIOSystem"),
        (_oscillator, {"disturbances": ["gust"]}, InputError, r"`disturbances\[0\]` = 'gust' is not one of"),
        (
            _oscillator,
            {"disturbances": [2]},
            InputError,
            r"`disturbances\[0\]` must be an input index in 0..1 or an input label \(the system has 2 inputs: "
            r"\['force', 'wind'\]\); got 2",
        ),
        (  # before: "must be an integer <= 0; got 3"
            lambda: ct.ss(A, B[:, :1], C, 0),
            {"disturbances": [3]},
            InputError,
            r"`disturbances\[0\]` must be an input index in 0..0 or an input label \(the system has 1 input: "
            r"\['u\[0\]'\]\); got 3",
        ),
        (
            lambda: ct.ss(A, np.zeros((2, 0)), C, np.zeros((2, 0))),
            {"disturbances": [0]},
            InputError,
            r"`disturbances\[0\]` = 0 names an input, but the system has no inputs",
        ),
        (_oscillator, {"disturbances": [-1]}, InputError, r"must be an input index in 0..1 .*; got -1"),
        (_oscillator, {"outputs": [2]}, InputError, r"`outputs\[0\]` must be an output index in 0..1"),
        (_oscillator, {"disturbances": ["wind", 1]}, InputError, r"must not name an input twice"),
        (_oscillator, {"disturbances": 1.5}, InputTypeError, r"`disturbances` must be a sequence"),
        (_oscillator, {"outputs": []}, InputError, r"`outputs` must name at least one output"),
        (_oscillator, {"outputs": ["speed"]}, InputError, r"`outputs\[0\]` = 'speed' is not one of"),
        (_oscillator, {"params": {"k": 1.0}}, InputError, r"`params` applies to a NonlinearIOSystem"),
    ],
)
def test_bad_systems_and_arguments_are_refused_by_name(make, kwargs, error, match):
    with pytest.raises(error, match=match):
        python_control_plant(make(), **kwargs)


def test_import_etobs_does_not_import_control_and_a_missing_control_says_how_to_install(monkeypatch):
    code = "import sys, etobs, etobs.model; etobs.python_control_plant; print('control' in sys.modules)"
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=300
    )
    assert out.stdout.strip() == "False"
    monkeypatch.setitem(sys.modules, "control", None)  # what `import control` does when it is missing
    with pytest.raises(ImportError, match=r"pip install 'etobs\[control\]'"):
        python_control_plant(object())


# ---- NonlinearIOSystem ------------------------------------------------------------------


def vdp_update(t, x, u, params):
    mu = params.get("mu", 1.0)
    return np.array([x[1], mu * (1 - x[0] ** 2) * x[1] - x[0] + u[0]])


def vdp_output(t, x, u, params):
    return x[:1]


def _vdp(**kw):
    kw = {"states": 2, "inputs": ["d"], "outputs": ["y"], "params": {"mu": 1.5}, "name": "vdp", **kw}
    return ct.nlsys(vdp_update, vdp_output, **kw)


def _vdp_observer():
    return luenberger(lambda t, x, u: np.array([x[1], 1.5 * (1 - x[0] ** 2) * x[1] - x[0]]), L=[[2.0], [3.0]])


VDP_NODES = (Node(outputs=(0,), rule=RULE),)


def test_a_nonlinear_system_with_params_runs_on_the_engine_as_the_same_etobs_plant():
    plant = python_control_plant(_vdp(), disturbances=["d"])
    assert (plant.n_x, plant.n_u, plant.n_v, plant.n_y, plant.name) == (2, 0, 1, 1, "vdp")
    assert plant.params.tolist() == [1.5]  # the params dict's values, in its order
    hand = Plant(
        lambda t, x, u, v, p: np.array([x[1], p[0] * (1 - x[0] ** 2) * x[1] - x[0] + v[0]]),
        lambda x, p: x[:1],
        n_x=2,
        n_y=1,
        n_v=1,
        params=[1.5],
    )
    res = [simulate(_problem(p, _vdp_observer(), VDP_NODES, v=(0.1,)), X0, 10.0) for p in (plant, hand)]
    assert [r.backend for r in res] == ["engine", "engine"]
    # same arithmetic in the same order: bit-identical
    _same_transmissions(*res)
    ref = simulate(_problem(plant, _vdp_observer(), VDP_NODES, v=(0.1,)), X0[:1], 10.0, backend="scipy")
    eng = res[0].transmissions.select(run=0)
    assert len(ref.transmissions) == len(eng)
    np.testing.assert_allclose(ref.transmissions.t, eng.t, rtol=0, atol=1e-6)


def test_other_param_values_reuse_the_compiled_model_and_change_the_result():
    pb = [
        _problem(
            python_control_plant(_vdp(), disturbances=["d"], params=p), _vdp_observer(), VDP_NODES, (0.1,)
        )
        for p in (None, {"mu": 0.5})
    ]
    assert pb[1].plant.params.tolist() == [0.5]
    assert compile_problem(pb[0]).system.addresses == compile_problem(pb[1]).system.addresses
    counts = [len(simulate(p, X0[0], 10.0).transmissions) for p in pb]
    assert counts[0] != counts[1]


def test_unspecified_sizes_default_output_and_no_params():
    # no inputs, no params, outfcn None (python-control's default output y = x)
    sys0 = ct.nlsys(lambda t, x, u, params: np.array([x[1], -x[0]]), None, states=2, name="harmonic")
    plant = python_control_plant(sys0, outputs=[0])
    assert (plant.n_u, plant.n_v, plant.n_y, plant.params.size) == (0, 0, 1, 0)
    np.testing.assert_array_equal(
        plant.call_f_p(0.0, np.array([1.0, 2.0]), np.zeros(0), np.zeros(0)), [2.0, -1.0]
    )
    # outputs left open: counted from what outfcn returns
    sys1 = ct.nlsys(lambda t, x, u, params: -x, lambda t, x, u, params: x[:1] + x[1:], states=2)
    assert python_control_plant(sys1).n_y == 1
    res = simulate(
        _problem(plant, luenberger(lambda t, x, u: np.array([x[1], -x[0]]), [[1.0], [1.0]]), VDP_NODES),
        X0[0],
        3.0,
    )
    assert res.backend == "engine" and res.status_labels() == ["completed"]


def test_an_output_that_depends_on_t_or_u_is_refused():
    with_u = ct.nlsys(vdp_update, lambda t, x, u, p: x[:1] + 0.1 * u[0], states=2, inputs=1, outputs=1)
    with pytest.raises(
        InputError, match=r"the outfcn of `sys` .* depends on t or u.*y = h\(x\) \(eq. \(2\)\)"
    ):
        python_control_plant(with_u)
    with_t = ct.nlsys(vdp_update, lambda t, x, u, p: x[:1] * np.cos(t), states=2, inputs=1, outputs=1)
    with pytest.raises(InputError, match=r"depends on t or u: .* at t = 0.7"):
        python_control_plant(with_t)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"params": {"mu": "fast"}}, InputTypeError, r"`params\['mu'\]` must be a real number; got 'fast'"),
        ({"params": {"mu": np.nan}}, InputError, r"`params\['mu'\]` must be a finite real number"),
        ({"params": {1: 2.0}}, InputTypeError, r"`params` keys must be strings \(names\); got 1"),
        ({"params": [1.5]}, InputTypeError, r"`params` must be a dict of parameter values; got list"),
    ],
)
def test_bad_params_are_refused_by_key(kwargs, error, match):
    with pytest.raises(error, match=match):
        python_control_plant(_vdp(), **kwargs)


def test_functions_that_raise_or_return_the_wrong_length_are_named():
    short = ct.nlsys(lambda t, x, u, p: x[:1], vdp_output, states=2, outputs=1, name="short")
    with pytest.raises(ModelError, match=r"the updfcn of 'short' returned shape \(1,\); expected \(2,\)"):
        python_control_plant(short)
    broken = ct.nlsys(lambda t, x, u, p: p["missing"] * x, vdp_output, states=2, outputs=1, name="broken")
    with pytest.raises(ModelError, match=r"the updfcn of 'broken' raised KeyError: 'missing'"):
        python_control_plant(broken)
    with pytest.raises(InputError, match=r"`sys` must have at least one state"):
        python_control_plant(ct.nlsys(None, lambda t, x, u, p: u, inputs=1, outputs=1))


class _Gains:  # a Python object: numba cannot compile a function that reads it
    mu = 1.5


GAINS = _Gains()


def test_python_numba_cannot_compile_is_a_clear_engine_error_and_runs_on_the_reference():
    def update(t, x, u, params):
        return np.array([x[1], GAINS.mu * (1 - x[0] ** 2) * x[1] - x[0]])

    plant = python_control_plant(ct.nlsys(update, vdp_output, states=2, outputs=1, name="object"))
    pb = _problem(plant, _vdp_observer(), VDP_NODES)
    with pytest.raises(
        ModelError,
        match=r"^`f_p` \(it runs the updfcn 'update' of the python-control system 'object'\) cannot be "
        r"compiled: .*GAINS.*backend='scipy'",
    ):
        simulate(pb, X0[0], 1.0)
    res = simulate(pb, X0[0], 1.0, backend="scipy")
    assert res.status_labels() == ["completed"] and len(res.transmissions) > 0


def test_the_models_page_runs_as_written(capsys):
    from pathlib import Path

    from tests.docs_blocks import run_python_blocks

    ns = run_python_blocks(Path(__file__).parents[2] / "docs" / "models.md")
    out = capsys.readouterr().out
    assert "engine" in out and "completed" in out
    # the page's claim: the StateSpace and the matrices give the same transmissions
    np.testing.assert_array_equal(ns["from_control"].transmissions.x, ns["from_matrices"].transmissions.x)


class _Oscillator:
    """A model written as a class: its bound method is the updfcn."""

    def update(self, t, x, u, params):
        return np.array([x[1], -x[0]])


def test_systems_known_not_to_compile_run_on_the_reference_under_auto_and_say_why():
    gain = ct.nlsys(None, lambda t, x, u, p: -0.5 * u, inputs=["y"], outputs=["d"], name="k")
    closed = ct.interconnect([_vdp(), gain], inputs=[], outputs=["y"], name="closed")
    method = ct.nlsys(_Oscillator().update, vdp_output, states=2, outputs=1, name="method")
    for sys_, why in (
        (closed, r"the plant 'closed' is a python-control InterconnectedSystem, .*numba cannot compile"),
        (method, r"the plant 'method' has an updfcn that is a method, not a function"),
    ):
        pb = _problem(python_control_plant(sys_), _vdp_observer(), VDP_NODES)
        res = simulate(pb, X0[0], 1.0)
        assert res.backend == "scipy" and res.status_labels() == ["completed"]
        assert re.search(f"auto: {why}", res.backend_reason), res.backend_reason
        assert "so the scipy reference runs it" in res.backend_reason
        with pytest.raises(InputError, match=f"backend='engine': {why}.*use backend='scipy'"):
            simulate(pb, X0[0], 1.0, backend="engine")


def test_a_plant_sent_by_value_to_another_process_compiles_there():
    # dask sends functions with cloudpickle; the worker never called python_control_plant,
    # so numba there learns the params dict when the plant's functions are unpickled
    cloudpickle = pytest.importorskip("cloudpickle", reason="cloudpickle (the dask extra) is not installed")
    from pathlib import Path

    pb = _problem(python_control_plant(_vdp(), disturbances=["d"]), _vdp_observer(), VDP_NODES, (0.1,))
    here = str(Path(__file__).parent)
    code = (
        f"import sys, json, cloudpickle; sys.path.insert(0, {here!r}); from etobs import simulate; "
        "pb = cloudpickle.loads(sys.stdin.buffer.read()); r = simulate(pb, [1.0, 0.0], 10.0); "
        "print(json.dumps([r.backend, r.transmissions.t.tolist()]))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], input=cloudpickle.dumps(pb), capture_output=True, timeout=600
    )
    assert out.returncode == 0, out.stderr.decode()[-2000:]
    backend, times = json.loads(out.stdout.decode().strip().splitlines()[-1])
    assert backend == "engine"
    np.testing.assert_array_equal(times, simulate(pb, [1.0, 0.0], 10.0).transmissions.t)


def test_the_systems_own_labels_become_the_plants_names_and_defaults_stay_unnamed():
    system = ct.ss(
        [[0, 1], [-2, -0.5]],
        [[0, 0], [1, 0.3]],
        [[1, 0], [0, 1]],
        0,
        states=["position", "velocity"],
        inputs=["force", "wind"],
        outputs=["range", "speed"],
    )
    plant = python_control_plant(system, disturbances=["wind"], outputs=["speed"])
    assert plant.state_names == ("position", "velocity")
    assert plant.output_names == ("speed",) and plant.input_names == ("force",)
    assert [q.label for q in plant.quantities("y")] == ["speed"]
    bare = python_control_plant(ct.ss([[0, 1], [-2, -0.5]], [[0], [1]], [[1, 0]], 0))
    assert bare.state_names is bare.output_names is bare.input_names is None
    assert [q.label for q in bare.quantities("x")] == ["$x_{1}$", "$x_{2}$"]
