"""Sampled rules: the eta filter's exact discretization, and agreement with the simulator."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from etobs import simulate
from etobs.examples import robot_arm
from etobs.formulas import RULE_KINDS
from etobs.model import Linear, Power, Quadratic
from etobs.runtime.sampled_rule import RuleSpecError, SampledRule

DYN = {
    "kind": "dynamic",
    "gamma": ["quadratic", 5.0],
    "alpha": ["linear", 2.0],
    "sigma": 600.0,
    "c": 0.001,
    "b": 1.0,
    "eps": 10.0,
    "eta0": 10.0,
}


def test_linear_filter_is_exact_for_a_held_gap():
    """With e held at 0.5 (never firing: sigma alpha(eta) large), eta follows
    eta(t) = e^{-2t} eta0 + c gamma(0.5) (1 - e^{-2t}) / 2 exactly, at every sample."""
    rule = SampledRule(DYN | {"eps": 1e9}, period=0.01)
    forcing = 0.001 * 5.0 * 0.25
    for k in range(1, 301):
        assert not rule.decide([0.5], [0.0])
        t = 0.01 * k
        assert rule.eta == pytest.approx(
            math.exp(-2 * t) * 10.0 + forcing * (1 - math.exp(-2 * t)) / 2, rel=1e-12
        )


def test_nonlinear_filter_matches_the_closed_form_of_a_quadratic_decay():
    """alpha(s) = s^2, no forcing: eta' = -eta^2 gives eta(t) = eta0 / (1 + eta0 t)."""
    spec = DYN | {"alpha": ["power", 1.0, 2.0], "eps": 1e9, "eta0": 2.0}
    rule = SampledRule(spec, period=0.05)
    for k in range(1, 41):
        rule.decide([0.0], [0.0])
        assert rule.eta == pytest.approx(2.0 / (1 + 2.0 * 0.05 * k), rel=1e-7)


def test_decision_and_jump_follow_eq_14_15():
    rule = SampledRule(DYN | {"b": 0.5}, period=0.001)
    eta = rule.eta
    assert not rule.decide([0.1], [0.0])  # 5 * 0.01 < 600 * 2 * 10 + 10
    big = math.sqrt((600 * 2 * rule.eta + 10) / 5) + 1e-6
    before = rule.eta
    assert rule.decide([big], [0.0])
    decay = math.exp(-2 * 0.001)
    assert rule.eta == pytest.approx(decay * 0.5 * before, rel=1e-12)  # eta+ = b eta, then a quiet period
    assert eta > before


def test_periodic_static_relative():
    per = SampledRule({"kind": "periodic", "period": 0.05, "first": 0.05}, period=0.01)
    fired = [per.decide([0.0], [0.0]) for _ in range(20)]
    assert [k for k, f in enumerate(fired) if f] == [5, 10, 15]  # t = 0.05, 0.10, 0.15 as PeriodicRule
    at_zero = SampledRule({"kind": "periodic", "period": 0.05, "first": 0.0}, period=0.01)
    assert [k for k in range(12) if at_zero.decide([0.0], [0.0])] == [0, 5, 10]
    sta = SampledRule({"kind": "static", "gamma": ["linear", 1.0], "eps": 0.1}, period=0.01)
    assert sta.decide([0.1], [0.0]) and not sta.decide([0.0999], [0.0])
    rel = SampledRule({"kind": "relative", "rho": 0.1, "eps": 0.01}, period=0.01)
    assert rel.decide([0.2101], [2.0]) and not rel.decide([0.2099], [2.0])  # 0.1 * 2 + 0.01


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        (
            {"kind": "magic"},
            rf"`kind` must be one of {', '.join(RULE_KINDS)}; got 'magic'",
        ),
        (DYN | {"gamma": ["cubic", 1.0]}, r"`gamma` must be \['linear', a\]"),
        (DYN | {"sigma": -1.0}, r"`sigma` must be >= 0; got -1.0"),
        (DYN | {"gamma": ["linear", -1.0]}, r"`gamma\[1\]` must be > 0; got -1.0"),
        (DYN | {"alpha": ["power", 1.0, 0.0]}, r"`alpha\[2\]` must be > 0; got 0.0"),
        ({k: v for k, v in DYN.items() if k != "alpha"}, r"missing key `alpha`"),
        (
            {
                "kind": "generalized",
                "gamma": ["linear", 1.0],
                "gamma_check": ["linear", 1.0],
                "alpha_check": ["linear", 1.0],
                "d_prime": ["constant", 1.0],
                "sigma": 0.5,
                "b": 1.0,
                "eps": 1.0,
                "eta0": 0.0,
            },
            r"`d_prime` must be \['linear', a\]",
        ),
        ({k: v for k, v in DYN.items() if k != "eps"}, r"missing key `eps`"),
        (DYN | {"b": 2.0}, r"`b` must be <= 1; got 2.0"),
        ({"kind": "periodic", "period": 0.015}, r"must be a multiple of the sampling period 0.01"),
        ({"kind": "static", "gamma": ["linear", 1.0], "eps": "x"}, r"`eps` must be a finite number"),
    ],
)
def test_bad_specs_name_the_key(spec, message):
    with pytest.raises(RuleSpecError, match=message):
        SampledRule(spec, period=0.01)


def test_fine_sampling_approaches_the_continuous_rule():
    """On the robot arm (paper's x0, 30 s), the sampled rule at 1 ms sends within a few
    transmissions of the continuous one; the event times are within a few samples."""
    from etobs.runtime.packet import node_keys
    from etobs.runtime.replay import replay, sample_outputs

    pb = robot_arm()
    cont = simulate(pb, [3, 2, 3, -2], 10.0)
    t, y = sample_outputs(pb, [3, 2, 3, -2], 10.0, 0.001)
    rep = replay(pb, node_keys(b"k", [0, 1]), t, y, 0.001)
    counts = np.bincount(cont.transmissions.rule, minlength=2)
    assert np.all(np.abs(np.array(rep.transmissions) - counts) <= 0.1 * counts + 2)
    first = [min(p[2] for p in rep.packets if p[0] == i) for i in range(2)]
    np.testing.assert_allclose(first, [cont.transmission_times(0, i)[0] for i in range(2)], atol=0.005)


def test_sensor_spec_refuses_what_a_node_cannot_run():
    from etobs.errors import InputError
    from etobs.model import Custom, Linear, StaticRule
    from etobs.model.rules import StatelessRule

    class Own(StatelessRule):
        def trigger(self, t, e, s, y=None):
            return np.abs(e[:, 0]) - 1.0

    assert robot_arm().nodes[0].rule.sensor_spec()["gamma"] == ["quadratic", 5.0]
    with pytest.raises(
        InputError,
        match=rf"a sensor node runs the rules of etobs' kinds \({', '.join(RULE_KINDS)}\); got Own, a rule of your own",
    ):
        Own().sensor_spec()
    with pytest.raises(InputError, match=r"`gamma` is Custom"):
        StaticRule(gamma=Custom(lambda s: s, name="id"), eps=1.0).sensor_spec()
    assert StaticRule(gamma=Linear(2.0), eps=1.0).sensor_spec() == {
        "kind": "static",
        "gamma": ["linear", 2.0],
        "eps": 1.0,
    }


class _Scheduled:
    """A test-only rule sending at given times: state k (packets sent so far)."""

    def __init__(self, times):
        from etobs.model.rules import TriggerRule

        class Rule(TriggerRule):
            n_state = 1

            def initial_state(self):
                return np.zeros(1)

            def derivative(self, t, e, s, y=None):
                return np.zeros_like(s)

            def trigger(self, t, e, s, y=None):
                k = np.minimum(s[:, 0].astype(int), len(times))
                nxt = np.asarray([*times, 1e30])[k]  # no more sends after the last
                return np.maximum(t - nxt, -1.0)

            def reset(self, t, s):
                return s + 1.0

        self.rule = Rule()


def test_the_service_observer_agrees_with_the_hybrid_solver_on_the_same_packets():
    """Two independent integrators: ObserverCore's fixed-step RK4 (dt = 1 ms) on the
    replayed packets, and the hybrid solver (DOP853, rtol 1e-10) with nodes sending at
    exactly those sample times. The estimates agree to 1e-5 relative."""
    from dataclasses import replace

    from etobs import SaveAt, SolverOptions
    from etobs.runtime.packet import node_keys
    from etobs.runtime.replay import replay, sample_outputs

    pb = robot_arm()
    t, y = sample_outputs(pb, [3, 2, 3, -2], 6.0, 0.002)
    rep = replay(pb, node_keys(b"k", [0, 1]), t, y, 0.002)
    assert sum(rep.transmissions) > 8
    times = [[p[2] for p in rep.packets if p[0] == i] for i in range(2)]
    nodes = tuple(replace(nd, rule=_Scheduled(times[i]).rule) for i, nd in enumerate(pb.nodes))
    sched = replace(pb, nodes=nodes)
    res = simulate(
        sched,
        [3, 2, 3, -2],
        6.0,
        options=SolverOptions(rtol=1e-10, atol=1e-10),
        save=SaveAt(steps=False, grid=t),
    )
    assert [len(res.transmission_times(0, i)) for i in range(2)] == [len(x) for x in times]
    xhat = res.on_grid().xhat[0]
    scale = np.max(np.abs(rep.xhat))
    gap = np.max(np.abs(xhat - rep.xhat))
    print(f"max gap {gap:.2e}, scale {scale:.1f}, transmissions {rep.transmissions}")
    assert gap < 1e-5 * scale  # seen: 2.1e-5 on a scale of 19.5


@settings(max_examples=200, deadline=None)
@given(
    st.sampled_from(["dynamic", "static", "relative", "periodic"]),
    st.floats(0.0, 3.0),
    st.floats(0.0, 5.0),
    st.floats(-3.0, 3.0),
    st.sampled_from([Linear(2.0), Quadratic(5.0), Power(1.5, 1.7)]),
)
def test_a_node_decides_as_the_simulator_rule_triggers(kind, e, eta, y, gamma):
    """The sensor node and the simulator compute with the same formulas (etobs.formulas):
    at a sample, the node sends exactly when the rule object's trigger function is >= 0."""
    from etobs.model import DynamicRule, PeriodicRule, RelativeRule, StaticRule

    rule = {
        "dynamic": DynamicRule(
            gamma=gamma, alpha=Power(1.0, 1.3), sigma=0.7, c=0.3, b=0.5, eps=0.2, eta0=eta
        ),
        "static": StaticRule(gamma=gamma, eps=0.4),
        "relative": RelativeRule(rho=0.2, eps=0.1),
        "periodic": PeriodicRule(period=0.05, first=0.0),
    }[kind]
    node = SampledRule(rule.sensor_spec(), 0.01)
    s = rule.initial_state()[None, :]
    g = rule.trigger(np.zeros(1), np.array([[e]]), s, **({"y": np.array([[y]])} if rule.reads_y else {}))
    assert node.decide([e], [y]) == bool(g[0] >= 0.0)
    if kind == "dynamic":  # the filter then moves as eq. (14) with gamma(|e|) held
        e_held = 0.0 if g[0] >= 0 else e
        eta0 = eta * (0.5 if g[0] >= 0 else 1.0)
        deriv = rule.derivative(np.zeros(1), np.array([[e_held]]), np.array([[eta0]]))[0, 0]
        assert node.eta == pytest.approx(eta0 + 0.01 * deriv, abs=1e-3 * (1.0 + abs(deriv)))
