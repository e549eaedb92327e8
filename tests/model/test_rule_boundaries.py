"""Rule boundaries: a node sends exactly when its trigger function is ``>= 0``, on every form.

The rules (eq. (15), (45), the baselines) send when the trigger function is ``>= 0``
(:mod:`etobs.model.rules`): equality sends. Each case below reaches equality exactly in
floating point, and each form must send there, and not one ulp below it:

* the engine and the scipy reference at ``t0`` (the held value set by ``e0``), and when a
  trigger function rises to zero and stays there (a measurement or input that levels off);
* the sensor node's sampled rule (:class:`~etobs.runtime.sampled_rule.SampledRule`) at a
  sample.

Numbers are chosen so that every operation is exact in binary (halves and quarters), and
each test first checks that the trigger function is exactly zero, so that a failure says
the comparison is wrong, not the case.
"""

import math

import numpy as np
import pytest

from etobs import EstimationProblem, Node, Observer, Plant, simulate
from etobs.hybrid import SolverOptions
from etobs.model import (
    DynamicRule,
    FunctionSignal,
    GeneralizedRule,
    InputNode,
    Linear,
    PeriodicRule,
    Quadratic,
    RelativeRule,
    StaticRule,
    send_on_delta,
)
from etobs.runtime.sampled_rule import SampledRule

BACKENDS = ("engine", "scipy")
#: A solver that does not send while a trigger function sits at 0 can creep along it one
#: event sample at a time (the scipy reference does): bounded, it ends with max_steps.
#: These runs take fewer than 100 steps.
BOUNDED = SolverOptions(max_steps=2000)

#: Rules with (y(t0), e(t0)) at which the trigger function is exactly 0:
#: dynamic 5 * 1^2 - 2 * (2 * 1) - 1; static 0.5 - 0.5; send-on-delta 0.25 - 0.25;
#: relative 0.5 - 0.5 * 0.5 - 0.25; generalized 1 + 1 * 1 - 0.5 * 1 * 0.5 - 1.75;
#: periodic with first = 0: tau(0) - period = 1 - 1. The filters' eta grows at t0
#: (dynamic: -2 + 0.45 * 5, generalized: -0.5 + 1), so a node below equality stays quiet.
AT_START = {
    "dynamic": (
        DynamicRule(gamma=Quadratic(5.0), alpha=Linear(2.0), sigma=2.0, c=0.45, b=1.0, eps=1.0, eta0=1.0),
        0.0,
        1.0,
    ),
    "static": (StaticRule(gamma=Linear(1.0), eps=0.5), 0.0, 0.5),
    "send_on_delta": (send_on_delta(0.25), 0.0, 0.25),
    "relative": (RelativeRule(rho=0.5, eps=0.25), 0.5, 0.5),
    "generalized": (
        GeneralizedRule(
            gamma=Linear(1.0),
            gamma_check=Linear(1.0),
            alpha_check=Linear(1.0),
            d_prime=1.0,
            sigma=0.5,
            eps=1.75,
            eta0=0.5,
        ),
        0.0,
        1.0,
    ),
    "periodic": (PeriodicRule(period=1.0, first=0.0), 0.0, 0.0),
}


def _still(rule, **signals):
    """``x' = 0``, ``y = x + m``, one node with ``rule``; observer at rest."""
    plant = Plant(f_p=lambda t, x, u, v: np.zeros(1), h=lambda x: x.copy(), n_x=1, n_y=1, **signals)
    observer = Observer(f_o=lambda t, z, u, ybar, yhat: np.zeros(1), n_z=1)
    return plant, observer


def _output_problem(rule, m=None):
    plant, observer = _still(rule)
    return EstimationProblem(plant=plant, observer=observer, nodes=[Node((0,), rule)], m=m)


def _trigger_at_start(pb, y0, e0):
    """The node's trigger function at ``t0 = 0`` (the scipy reference's model, uncompiled)."""
    q0 = pb.initial_state(np.array([[y0]]), np.zeros((1, 1)), np.array([[e0]]), 0.0)
    return float(pb.hybrid_system().guard(np.zeros(1), q0)[0, 0])


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name", list(AT_START))
def test_equality_at_the_start_sends_on_every_rule_and_solver(name, backend):
    # guards against: the solvers' `g >= 0` made `g > 0` (the kernel's _any_nonneg, the reference's jumps())
    rule, y0, e0 = AT_START[name]
    pb = _output_problem(rule)
    assert _trigger_at_start(pb, y0, e0) == 0.0  # the case: exact equality at t0
    res = simulate(pb, [y0], 0.5, e0=[e0], backend=backend, options=BOUNDED)
    sent = res.transmissions.t.tolist()
    assert sent == [0.0], f"{name}: equality at t0 must send at t0; sent at {sent}, {res.status_labels()}"
    assert res.transmissions.j.tolist() == [0]
    assert res.ok and res.backend == backend
    assert res.solution.n_steps[0] < 100


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name", [k for k in AT_START if k != "periodic"])
def test_one_ulp_below_equality_at_the_start_does_not_send(name, backend):
    # guards against: the comparison moved the other way (g > -tiny), which the test above cannot see
    rule, y0, e0 = AT_START[name]
    below = math.nextafter(y0 + e0, 0.0) - y0  # one ulp below in ybar = y0 + e0 (exact)
    pb = _output_problem(rule)
    assert _trigger_at_start(pb, y0, below) < 0.0
    res = simulate(pb, [y0], 0.5, e0=[below], backend=backend, options=BOUNDED)
    assert res.ok and len(res.transmissions) == 0


def _ramp(t):
    """0 at t = 0, rising to 0.5 at t = 0.1, then exactly 0.5 (min gives 1.0 exactly)."""
    return np.array([0.5 * min(10.0 * t, 1.0)])


#: Rules whose trigger function is exactly 0 once |e| = |y| = 0.5 and below before:
#: |e| - 0.5; |e| - 0.5 |y| - 0.25; and the dynamic rule with c = 0 and eta0 = 0, whose
#: eta stays exactly 0 (eta' = -alpha(0) + 0), so that only |e| moves.
LEVELLING = {
    "static": StaticRule(gamma=Linear(1.0), eps=0.5),
    "send_on_delta": send_on_delta(0.5),
    "relative": RelativeRule(rho=0.5, eps=0.25),
    "dynamic": DynamicRule(gamma=Linear(1.0), alpha=Linear(1.0), sigma=1.0, c=0.0, eps=0.5, eta0=0.0),
}


def _input_problem(rule):
    plant, observer = _still(rule, n_u=1)
    return EstimationProblem(
        plant=plant,
        observer=observer,
        nodes=[Node((0,), PeriodicRule(period=10.0))],  # sends first at t = 10, past the horizon
        input_nodes=[InputNode((0,), rule, name="u")],
        u=FunctionSignal(_ramp, 1),
    )


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("channel", ["output", "input"])
@pytest.mark.parametrize("name", list(LEVELLING))
def test_a_trigger_function_that_rises_to_zero_and_stays_there_sends_once(name, channel, backend):
    # guards against: `g >= 0` made `g > 0` in event location along a flow (equality reached at t = 0.1)
    rule = LEVELLING[name]
    if channel == "output":  # the measurement noise levels off: ytilde = 0 + m(t), ybar = 0
        pb, node = _output_problem(rule, m=FunctionSignal(_ramp, 1)), 0
    else:  # the input levels off: e_u = ubar - u = 0 - u(t)
        pb, node = _input_problem(rule), 1
    # the case: the rule's own trigger function is exactly 0 on the plateau, negative before
    s = rule.initial_state()[None, :]
    y = {"y": np.array([[0.5]])} if rule.reads_y else {}
    assert rule.trigger(np.zeros(1), np.array([[-0.5]]), s, **y)[0] == 0.0
    y = {"y": np.array([[0.4]])} if rule.reads_y else {}
    assert rule.trigger(np.zeros(1), np.array([[-0.4]]), s, **y)[0] < 0.0
    res = simulate(pb, [0.0], 0.3, backend=backend, options=BOUNDED)
    log = res.transmissions.select(rule=node)
    assert len(log) == 1, (
        f"{name} on the {channel}: a trigger function held at 0 must send (once); "
        f"sent at {log.t.tolist()}, {res.status_labels()}"
    )
    assert res.ok and res.backend == backend
    assert res.solution.n_steps[0] < 100
    # sent on the plateau (where g = 0; then e = 0 and the rule is quiet): the engine
    # where it begins; the reference's brentq stops at any zero of g, so anywhere on it
    assert 0.1 - 1e-9 <= log.t[0] < 0.3
    if backend == "engine":
        assert abs(log.t[0] - 0.1) < 1e-9


def test_an_input_node_with_a_periodic_rule_sends_at_t0_when_first_is_zero():
    # guards against: `g >= 0` made `g > 0` for input nodes (tau(0) - period = 0 at t0)
    pb = _input_problem(PeriodicRule(period=0.25, first=0.0))
    for backend in BACKENDS:
        res = simulate(pb, [0.0], 0.3, backend=backend, options=BOUNDED)
        log = res.transmissions.select(rule=1)
        assert len(log) == 2 and log.t[0] == 0.0, (backend, log.t.tolist(), res.status_labels())
        assert abs(log.t[1] - 0.25) < 1e-9


# ---- the sensor node's sampled rule ----------------------------------------------------------

#: (rule, e, y) at which the rule's trigger function is exactly 0 at the first sample.
SAMPLED = {
    "dynamic": (AT_START["dynamic"][0], 1.0, 0.0),
    "static": (AT_START["static"][0], 0.5, 0.0),
    "send_on_delta": (AT_START["send_on_delta"][0], 0.25, 0.0),
    "relative": (AT_START["relative"][0], 0.75, 1.0),
}


@pytest.mark.parametrize("name", list(SAMPLED))
def test_the_sampled_rule_sends_at_equality_and_not_one_ulp_below(name):
    # guards against: SampledRule.decide's `>= 0.0` made `> 0.0` (the dynamic rule's first of all)
    rule, e, y = SAMPLED[name]
    s = rule.initial_state()[None, :]
    ys = {"y": np.array([[y]])} if rule.reads_y else {}
    assert rule.trigger(np.zeros(1), np.array([[e]]), s, **ys)[0] == 0.0  # the case
    assert SampledRule(rule.sensor_spec(), 0.01).decide([e], [y]), f"{name}: equality must send"
    below = math.nextafter(e, 0.0)
    assert rule.trigger(np.zeros(1), np.array([[below]]), s, **ys)[0] < 0.0
    assert not SampledRule(rule.sensor_spec(), 0.01).decide([below], [y])


def test_the_sampled_periodic_rule_sends_at_its_first_sample_and_every_period():
    # guards against: the sampled periodic rule's `count >= every` made `>` (one sample late)
    node = SampledRule(PeriodicRule(period=0.04, first=0.0).sensor_spec(), 0.01)
    sent = [k for k in range(13) if node.decide([0.0], [0.0])]
    assert sent == [0, 4, 8, 12]
    later = SampledRule(PeriodicRule(period=0.04, first=0.02).sensor_spec(), 0.01)
    assert [k for k in range(11) if later.decide([0.0], [0.0])] == [2, 6, 10]
