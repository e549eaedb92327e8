"""The cost report (issue 23): per-function time per call on the engine, the slow ones named.

Times depend on the machine and its load, so no test asserts one: they check the report's
structure, and that a deliberately slow function (a loop of 20,000 iterations, thousands
of times any other call here) is the one named.
"""

import numpy as np
import pytest

from etobs import Custom, DynamicRule, EstimationProblem, Linear, Node, Plant, Quadratic
from etobs.errors import InputError, ModelError
from etobs.estimation.cost import SLOW_NS, FunctionCost, ModelCost, model_cost
from etobs.model import luenberger


def slow_flow(t, x, u, v):
    acc = 0.0
    for k in range(20_000):  # deliberately slow: the function the report must name
        acc += 1e-9 * np.sin(k * x[0])
    return np.array([x[1], -x[0] + 1e-12 * acc])


def fast_flow(t, x, u, v):
    return np.array([x[1], -x[0]])


def slow_gamma(s):
    acc = 0.0
    for k in range(20_000):
        acc += np.sin(k * s) ** 2  # >= 0, and 0 at s = 0
    return s * s * (1.0 + 1e-12 * acc)


def _problem(flow, gamma=None):
    rule = DynamicRule(
        gamma=Quadratic(2.0) if gamma is None else Custom(gamma),
        alpha=Linear(1.0),
        sigma=2.0,
        c=0.1,
        eps=0.01,
    )
    plant = Plant(flow, lambda x: x[:1], n_x=2, n_y=1, name="spring")
    observer = luenberger(lambda t, x, u: np.array([x[1], -x[0]]), L=[[2.0], [1.0]])
    return EstimationProblem(plant, observer, nodes=[Node((0,), rule, name="y")])


def test_the_slow_plant_function_is_named():
    cost = model_cost(_problem(slow_flow), [1.0, 0.0], horizon=0.5, repeats=1)
    assert isinstance(cost, ModelCost) and cost.problem == "spring"
    assert cost.functions[0].name == "f_p"  # slowest first
    assert sorted(f.name for f in cost.functions) == ["f_o", "f_p", "h"]
    assert cost.slow == ("f_p",)
    f_p = cost.functions[0]
    assert f_p.slow and f_p.ns_per_call > SLOW_NS and f_p.share > 0.5
    assert sum(f.share for f in cost.functions) == pytest.approx(1.0)
    assert cost.us_per_step > 0 and cost.steps_per_second > 0 and cost.horizon == 0.5
    assert cost.seconds_for(10.0, runs=2) == pytest.approx(
        2 * 10.0 * cost.steps_per_second * cost.us_per_step * 1e-6
    )
    text = repr(cost).splitlines()
    assert text[0] == "ModelCost of 'spring' on the engine (time per call, slowest first):"
    assert text[1].lstrip().startswith("f_p") and text[1].rstrip().endswith("slow")
    assert len(text) == 1 + 3 + 1 + 1  # title, three functions, the step, the slow line
    assert text[-1].startswith("  slow: f_p (over 250 ns a call and over an equal share)")


def test_a_slow_k_function_is_named_by_its_node():
    cost = model_cost(_problem(fast_flow, slow_gamma), [1.0, 0.0], horizon=0.5, repeats=1)
    assert cost.slow == ("gamma of node 0",)
    assert "gamma of node 0" in [f.name for f in cost.functions]


def test_the_python_control_plant_is_named_with_its_reason():
    ct = pytest.importorskip("control")
    from etobs.model import python_control_plant

    def upd(t, x, u, params):
        return np.array([x[1], -params["k"] * x[0]])

    sys = ct.nlsys(upd, lambda t, x, u, params: x[:1], states=2, inputs=0, outputs=1, params={"k": 1.0})
    rule = DynamicRule(gamma=Quadratic(2.0), alpha=Linear(1.0), sigma=2.0, c=0.1, eps=0.01)
    observer = luenberger(lambda t, x, u: np.array([x[1], -x[0]]), L=[[2.0], [1.0]])
    pb = EstimationProblem(python_control_plant(sys), observer, nodes=[Node((0,), rule)])
    cost = model_cost(pb, [1.0, 0.0], horizon=0.2, repeats=1)
    notes = {f.name: f.note for f in cost.functions}
    assert notes["f_p"] == "a python-control system: every call builds its params dict, docs/models.md"
    assert notes["f_o"] == ""
    assert "builds its params dict" in repr(cost)


def test_bad_arguments_are_named():
    pb = _problem(fast_flow)
    with pytest.raises(InputError, match=r"`problem` must be an EstimationProblem; got int"):
        model_cost(3)
    with pytest.raises(InputError, match=r"`x0` must have 2 entries"):
        model_cost(pb, [1.0, 2.0, 3.0])
    with pytest.raises(InputError, match=r"`horizon` must be > 0"):
        model_cost(pb, horizon=0.0)
    with pytest.raises(InputError, match=r"`repeats` must be an integer >= 1; got 0"):
        model_cost(pb, repeats=0)


def test_a_function_that_fails_where_it_is_called_is_a_model_error():
    # one entry too many beyond x_0 = 5 (the problem's own probe, at the origin, passes)
    pb = _problem(lambda t, x, u, v: np.array([x[1], -x[0], 0.0]) if x[0] > 5 else np.array([x[1], -x[0]]))
    with pytest.raises(ModelError, match=r"^`f_p` .* at the point the cost report calls it at$"):
        model_cost(pb, [10.0, 0.0], repeats=1)


def test_function_cost_is_plain_data():
    f = FunctionCost("h", 12.0, 0.1, False)
    assert (f.name, f.ns_per_call, f.share, f.slow, f.note) == ("h", 12.0, 0.1, False, "")
