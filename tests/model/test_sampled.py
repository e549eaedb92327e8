"""The sampled rule in the simulator (:class:`etobs.model.Sampled`) against the sensor node.

Reference: the sensor node's own :class:`~etobs.runtime.sampled_rule.SampledRule`, fed the
samples the simulation read (``result.samples``): the same samples send, and the filter
has the same value at every sample, bit for bit (one implementation,
:func:`etobs.formulas.sample_decision`).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from etobs import formulas as fm
from etobs.errors import InputError, InputTypeError
from etobs.estimation import EstimationProblem, simulate
from etobs.examples.robot_arm import X0_PAPER, robot_arm
from etobs.hybrid.options import SaveAt, SolverOptions
from etobs.model import (
    Custom,
    DynamicRule,
    Linear,
    Node,
    PeriodicRule,
    Power,
    Quadratic,
    RelativeRule,
    Sampled,
    StaticRule,
    linear_luenberger,
    linear_plant,
)
from etobs.model.rules import StatelessRule
from etobs.runtime.sampled_rule import SampledRule


def sampled(pb: EstimationProblem, period: float, phase: float = 0.0) -> EstimationProblem:
    """``pb`` with every node's rule sampled."""
    nodes = tuple(
        dataclasses.replace(nd, rule=Sampled(nd.rule, period=period, phase=phase)) for nd in pb.nodes
    )
    return dataclasses.replace(pb, nodes=nodes)


def sensor_replay(rule: Sampled, y: np.ndarray, initial: np.ndarray) -> tuple[list[int], list[float]]:
    """The samples at which the sensor node's rule sends, and its filter after each sample.

    ``initial`` is the value the observer holds at ``t0`` (``ytilde(t0)``: the node's
    initial value; at a phase ``> 0`` it is not its first sample).
    """
    node = SampledRule(rule.sensor_spec(), rule.period)
    sent, fires, etas = [float(v) for v in initial], [], []
    for k, yk in enumerate(y):
        yk = [float(v) for v in yk]
        if node.decide([s - v for s, v in zip(sent, yk, strict=True)], yk):
            fires.append(k)
            sent = yk
        etas.append(node.eta)
    return fires, etas


def check_against_sensor(res, pb: EstimationProblem, run: int = 0) -> dict[int, int]:
    """Every sampled node of ``res`` sends where the sensor node fed its samples does; transmissions per node."""
    arc = res.arc(run)
    log = res.solution.jumps
    counts = {}
    for i, nd in enumerate(pb.nodes):
        t, y = res.samples(run, i)
        T, phase = nd.rule.period, nd.rule.phase
        assert (
            np.array_equal(t, phase + T * np.arange(len(t)))
            or np.max(np.abs(t - phase - T * np.arange(len(t)))) < 1e-9
        )
        fires, etas = sensor_replay(nd.rule, y, arc.ybar[0, list(nd.outputs)])
        sent_t = res.transmission_times(run, i)
        assert np.array_equal(sent_t, t[fires])  # the same samples, at the same times
        # the values sent: the samples themselves
        tr = res.transmissions
        rows = (tr.run == run) & (tr.rule == i)
        cols = [tr.names.index(f"sent_y{k}") for k in nd.outputs]
        assert np.array_equal(tr.x[rows][:, cols], y[fires])
        if nd.rule.base.kind.state == "eta":  # the filter at every sample: eta_{k+1}
            rule = pb.sample_rule(i)
            after = np.searchsorted(
                res.solution.arcs[run].j, log.j[(log.run == run) & (log.rule == rule)] + 1
            )
            assert np.array_equal(arc.eta[after, i], np.array(etas))
        counts[i] = len(fires)
    return counts


def test_robot_arm_1e5_samples_send_as_the_sensor_node_bit_for_bit() -> None:
    """10^5 samples per node (100 s at 1 ms), the engine: the same samples send, the same eta."""
    pb = sampled(robot_arm(noise=False), 0.001)
    res = simulate(pb, np.array(X0_PAPER), 100.0, backend="engine", save=SaveAt(steps=True))
    assert res.ok
    t, _ = res.samples(0, 0)
    assert len(t) == 100_000  # 0 .. 99.999: a jump due at t_end is not applied
    counts = check_against_sensor(res, pb)
    assert counts[0] > 50 and counts[1] > 50  # it does send (192 and 182 seen)


def docs_model(rule) -> EstimationProblem:
    """The linear model of docs/models.md ("From matrices"), without its wind, two nodes."""
    A = np.array([[0.0, 1.0], [-2.0, -0.5]])
    B = np.array([[0.0], [1.0]])
    C = np.array([[1.0, 0.0], [0.5, 1.0]])
    L = np.array([[1.0, 0.2], [0.5, 1.0]])
    from etobs.model import Sinusoid

    return EstimationProblem(
        linear_plant(A, B, C),
        linear_luenberger(A, L, B),
        nodes=[Node([0], rule), Node([1], rule)],
        u=Sinusoid(amplitude=[1.0], omega=2.0),
    )


@pytest.mark.parametrize("backend", ["engine", "scipy"])
def test_the_docs_model_sends_as_the_sensor_node_on_both_backends(backend: str) -> None:
    rule = DynamicRule(gamma=Quadratic(1.0), alpha=Linear(1.0), sigma=0.5, c=0.5, eps=1e-3, eta0=0.01)
    pb = sampled(docs_model(rule), 0.01, phase=0.004)
    t_end = 20.0 if backend == "engine" else 4.0
    res = simulate(pb, [1.0, 0.0], t_end, backend=backend, save=SaveAt(steps=True))
    assert res.ok
    counts = check_against_sensor(res, pb)
    assert min(counts.values()) > 5


@pytest.mark.parametrize(
    "rule",
    [
        DynamicRule(gamma=Quadratic(5.0), alpha=Quadratic(2.0), sigma=600, c=0.001, eps=10.0, eta0=10.0),
        DynamicRule(
            gamma=Power(5.0, 1.5), alpha=Power(3.0, 1.5), sigma=400, c=0.002, b=0.5, eps=10.0, eta0=5.0
        ),
        StaticRule(gamma=Quadratic(5.0), eps=10.0),
        RelativeRule(rho=0.1, eps=0.2),
    ],
    ids=["quadratic-alpha", "power", "static", "relative"],
)
def test_every_kind_a_node_runs_sends_as_the_sensor_node(rule) -> None:
    """Filters integrated by Runge--Kutta substeps (alpha not linear), and rules without one."""
    base = robot_arm(noise=False)
    pb = sampled(
        dataclasses.replace(base, nodes=tuple(dataclasses.replace(nd, rule=rule) for nd in base.nodes)), 0.005
    )
    res = simulate(pb, np.array(X0_PAPER), 10.0, backend="engine", save=SaveAt(steps=True))
    assert res.ok
    counts = check_against_sensor(res, pb)
    assert min(counts.values()) > 0


def test_engine_and_reference_agree_on_which_samples_send() -> None:
    pb = sampled(robot_arm(), 0.005)  # with noise and disturbance
    x0 = np.array([X0_PAPER, [1.0, 0.5, -1.0, 2.0]])
    eng = simulate(pb, x0, 3.0, backend="engine")
    ref = simulate(pb, x0, 3.0, backend="scipy")
    sent = 0
    for run in range(2):
        for i in range(2):
            a, b = eng.transmission_times(run, i), ref.transmission_times(run, i)
            assert np.array_equal(np.rint(a / 0.005), np.rint(b / 0.005))
            sent += len(a)
    assert sent > 10


def test_transmissions_fall_on_samples_only_and_samples_are_not_transmissions() -> None:
    T, phase = 0.02, 0.0125
    pb = sampled(robot_arm(), T, phase)
    res = simulate(pb, np.array(X0_PAPER), 5.0)
    assert pb.rule_names == ("sensor 1", "sensor 2", "sample sensor 1", "sample sensor 2")
    for i in range(2):
        t = res.transmission_times(0, i)
        k = (t - phase) / T
        assert np.allclose(k, np.rint(k), atol=1e-9) and len(t) > 3
        assert np.min(np.diff(t)) >= T - 1e-12  # the inter-event time is at least T
    assert set(np.unique(res.transmissions.rule)) == {0, 1}
    samples = res.solution.jumps.rule >= 2
    assert samples.sum() == 2 * (int((5.0 - phase) // T) + 1)  # every sample of [0, 5] of both nodes


def test_samples_count_towards_max_jumps() -> None:
    pb = sampled(robot_arm(), 0.01)
    res = simulate(pb, np.array(X0_PAPER), 5.0, options=SolverOptions(max_jumps=100))
    assert list(res.status_labels()) == ["max_jumps"]
    assert len(res.solution.jumps.t) == 100


def test_eta_of_a_sampled_stateless_rule_is_nan_and_of_a_filter_its_value() -> None:
    pb = sampled(robot_arm(), 0.01)
    static = dataclasses.replace(
        pb,
        nodes=(
            pb.nodes[0],
            dataclasses.replace(pb.nodes[1], rule=Sampled(StaticRule(Quadratic(5.0), 10.0), 0.01)),
        ),
    )
    res = simulate(static, np.array(X0_PAPER), 1.0, save=SaveAt(steps=True))
    eta = res.arc(0).eta
    assert np.isnan(eta[:, 1]).all() and np.isfinite(eta[:, 0]).all() and eta[0, 0] == 10.0


# ---- the discretization ----------------------------------------------------------------


@given(
    e=st.floats(0.0, 1e3),
    y=st.floats(0.0, 1e3),
    s=st.floats(0.0, 1e3),
    a=st.floats(1e-3, 1e3),
    p=st.floats(0.5, 3.0),
)
@settings(max_examples=200, deadline=None)
def test_a_filter_flow_is_its_drive_minus_its_decay_bit_for_bit(e, y, s, a, p) -> None:
    """eta_period integrates ``drive - K(eta)``: equal to each kind's flow, bit for bit (RuleKind.decay)."""
    for kind in fm.RULE_KINDS.values():
        if kind.state != "eta":
            continue
        assert kind.decay is not None
        fns = {slot.name: functools.partial(fm.power, a + i, p) for i, slot in enumerate(kind.slots)}
        rule = SimpleNamespace(**fns, **{n.name: 0.5 for n in kind.numbers})
        flow = fm.evaluator(kind.flow, kind.constants)
        drive = flow(rule, e, y, 0.0)
        assert flow(rule, e, y, s) == drive - getattr(rule, kind.decay)(s)


def test_eta_period_linear_is_the_closed_form_and_others_converge_to_it() -> None:
    eta, drive, a, T = 7.0, 3.0, 2.0, 0.01
    exact = math.exp(-a * T) * eta + drive * (1 - math.exp(-a * T)) / a
    assert fm.eta_period(fm.LINEAR)(eta, drive, a, 0.0, T) == exact
    # power with p = 1 is the same linear decay, integrated by 20 RK4 substeps: O((T/20)^4) per period
    assert fm.eta_period(fm.POWER)(eta, drive, a, 1.0, T) == pytest.approx(exact, abs=1e-13)
    # a filter that would go below 0 stays at 0
    assert fm.eta_period(fm.QUADRATIC)(0.0, 0.0, 1e9, 0.0, 1.0) == 0.0


# ---- bad input --------------------------------------------------------------------------

DYN = DynamicRule(gamma=Quadratic(5.0), alpha=Linear(2.0), sigma=600, c=0.001, eps=10.0, eta0=10.0)


def test_period_and_phase_at_their_limits() -> None:
    with pytest.raises(InputError, match=r"`period` must be > 0; got 0"):
        Sampled(DYN, period=0.0)
    with pytest.raises(InputError, match=r"`phase` must be in \[0, period\) = \[0, 0.01\); got 0.01"):
        Sampled(DYN, period=0.01, phase=0.01)
    assert Sampled(DYN, period=0.01, phase=math.nextafter(0.01, 0.0)).phase < 0.01
    with pytest.raises(InputError, match=r"`phase` must be >= 0; got -1e-12"):
        Sampled(DYN, period=0.01, phase=-1e-12)
    assert Sampled(DYN, period=0.01, phase=0.0).phase == 0.0


def test_rules_a_node_does_not_run_are_refused_naming_them() -> None:
    class Mine(StatelessRule):
        def trigger(self, t, e, s, y=None):
            return e[:, 0]

    with pytest.raises(
        InputError,
        match=r"Sampled runs the rules a sensor node runs \(dynamic, static, relative, "
        r"generalized\); got Mine, a rule of your own",
    ):
        Sampled(Mine(), period=0.01)
    with pytest.raises(InputError, match=r"a PeriodicRule sends at fixed times already"):
        Sampled(PeriodicRule(0.1), period=0.01)
    with pytest.raises(InputError, match=r"`rule` is Sampled already"):
        Sampled(Sampled(DYN, 0.01), period=0.01)
    with pytest.raises(InputTypeError, match=r"`rule` must be a TriggerRule; got float"):
        Sampled(1.0, period=0.01)
    custom = DynamicRule(gamma=Custom(lambda s: 5 * s * s), alpha=Linear(2.0), eps=10.0)
    with pytest.raises(
        InputError, match=r"a sensor node runs the K-functions of etobs' kinds .*; `gamma` is Custom"
    ):
        Sampled(custom, period=0.01)


# ---- in a comparison spec ----------------------------------------------------------------


def _compare(rules: list[dict]) -> object:
    import tomllib
    from importlib.resources import files

    from etobs.experiments.compare_spec import parse_compare_spec

    raw = tomllib.loads(files("etobs.experiments").joinpath("data/robot_arm_sampled.toml").read_text())
    raw["rules"] = rules
    return parse_compare_spec(raw)


def test_a_comparison_entry_runs_its_rule_sampled_per_node() -> None:
    spec = _compare(
        [{"name": "s", "kind": "static", "eps": 10.0, "sample_period": 0.005, "sample_phase": [0.0, 0.002]}]
    )
    nodes = spec.problem(0).nodes
    assert [type(nd.rule).__name__ for nd in nodes] == ["Sampled", "Sampled"]
    assert [(nd.rule.period, nd.rule.phase, type(nd.rule.rule).__name__) for nd in nodes] == [
        (0.005, 0.0, "StaticRule"),
        (0.005, 0.002, "StaticRule"),
    ]
    assert [type(nd.rule).__name__ for nd in _compare([{"name": "c", "kind": "base"}]).problem(0).nodes] == [
        "DynamicRule",
        "DynamicRule",
    ]


def test_comparison_sampling_mistakes_name_the_key() -> None:
    from etobs._spec import SpecError

    with pytest.raises(SpecError, match=r"`rules\[0\]`, node 0: `sample_period` must be > 0; got 0"):
        _compare([{"name": "s", "kind": "base", "sample_period": 0.0}]).problem(0)
    with pytest.raises(SpecError, match=r"`rules\[0\].sample_phase` needs `rules\[0\].sample_period`"):
        _compare([{"name": "s", "kind": "base", "sample_phase": 0.001}])
    with pytest.raises(
        SpecError,
        match=r"`rules\[0\]`, node 1: `sample_phase` must be in \[0, period\) = \[0, 0.005\); got 0.005",
    ):
        _compare(
            [{"name": "s", "kind": "base", "sample_period": 0.005, "sample_phase": [0.0, 0.005]}]
        ).problem(0)
    with pytest.raises(
        SpecError, match=r"`rules\[0\]`, node 0: Sampled: a PeriodicRule sends at fixed times already"
    ):
        _compare([{"name": "p", "kind": "periodic", "period": 0.1, "sample_period": 0.005}]).problem(0)


# ---- what the certificate says ---------------------------------------------------------------


@pytest.mark.parametrize("T", [0.05, 1.0])
def test_the_certificate_of_a_sampled_rule_keeps_tau_and_leaves_out_what_is_not_proven(T) -> None:
    """tau_i becomes max(T_i, tau_i) (0.283 s without sampling, E = 5): on both sides of it."""
    from etobs.design import certify

    cont = certify(robot_arm(), E=5.0, noise=[0.0, 0.01])
    samp = certify(robot_arm(sample_period=T), E=5.0, noise=[0.0, 0.01])
    assert samp.conditions == cont.conditions and samp.ok
    taus = [nd.tau for nd in cont.nodes]
    assert 0.05 < min(taus) and max(taus) < 1.0  # T = 0.05 is below both, T = 1.0 above both
    assert [nd.tau for nd in samp.nodes] == [max(T, tau) for tau in taus]
    assert math.isnan(samp.nu) and math.isnan(samp.mu) and math.isnan(samp.error_bound)
    assert math.isfinite(cont.nu)
    assert any(
        "sampled rules (node 0 at T = " in n and "not proven for sampled rules" in n for n in samp.notes
    )


def test_the_robot_arm_factory_samples_its_rules_on_request() -> None:
    assert [type(nd.rule).__name__ for nd in robot_arm(sample_period=0.01).nodes] == ["Sampled", "Sampled"]
    with pytest.raises(InputError, match=r"`sample_period` must be > 0; got -0.01"):
        robot_arm(sample_period=-0.01)


def test_a_run_that_starts_late_samples_from_its_first_sample_not_before_t0() -> None:
    """t0 = 2.004 with samples every 10 ms at phase 0: the first sample is at 2.01, none is replayed at t0."""
    pb = sampled(robot_arm(noise=False), 0.01)
    res = simulate(pb, np.array(X0_PAPER), 2.5, t0=2.004, save=SaveAt(steps=True))
    assert res.ok
    t, _ = res.samples(0, 0)
    assert len(t) == 49 and t[0] == pytest.approx(2.01, abs=1e-12) and t[-1] == pytest.approx(2.49, abs=1e-12)
    on = simulate(pb, np.array(X0_PAPER), 2.5, t0=2.0, save=SaveAt(steps=True))
    assert on.samples(0, 1)[0][0] == 2.0  # a sample at t0 itself is taken
    assert [Sampled(DYN, 0.01, 0.004).first_sample(t0) for t0 in (0.0, 0.004, 0.0041, 1.0)] == [0, 0, 1, 100]


def test_samples_names_a_bad_node_or_run() -> None:
    res = simulate(sampled(robot_arm(), 0.01), np.array(X0_PAPER), 0.1, save=SaveAt(steps=True))
    for bad in ("0", 0.0, True, 2):
        with pytest.raises(InputError, match=r"`node` must be a sampled output node, one of \[0, 1\]; got "):
            res.samples(0, bad)
    with pytest.raises(InputError, match=r"`run` must be an integer in 0..0; got '0'"):
        res.samples("0", 0)
    with pytest.raises(InputError, match=r"this result kept no arcs"):
        grid = SaveAt(steps=False, grid=np.linspace(0.0, 0.1, 3))
        simulate(sampled(robot_arm(), 0.01), np.array(X0_PAPER), 0.1, save=grid).samples(0, 0)
