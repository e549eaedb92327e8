"""The paper's extensions in simulation: the triggered input (section 7.3), the
relative-threshold baseline and the observer-copy variant of Remark 3."""

import numpy as np
import pytest

from etobs import DynamicRule, EstimationProblem, Linear, Quadratic, SaveAt, simulate
from etobs.errors import InputError, InputTypeError
from etobs.estimation.metrics import input_transmission_counts, transmission_counts
from etobs.model import InputNode, RelativeRule, StaticRule
from tests.estimation import linear

X0 = np.array([[1.0, -0.5], [-2.0, 1.0], [0.5, 2.0]])
Z0 = np.zeros(2)


def _jump_rows(arc, rule_times):
    """Indices of the arc rows just before each jump at the given times."""
    rows = []
    for t in rule_times:
        k = np.flatnonzero(arc.t == t)
        rows.append(k[0])
    return np.array(rows)


# -- section 7.3: triggering the input ------------------------------------------------


def test_static_input_rule_keeps_the_error_under_the_linear_iss_bound():
    """With sigma = 0 both gaps stay under their thresholds, so the linear bound of
    tests/estimation/linear.py holds: |e_x| <= decay + eps_y ||G_y||_1 + eps_u ||G_u||_1."""
    eps_y, eps_u = 0.05, 0.1
    pb = linear.problem(
        StaticRule(gamma=Linear(1.0), eps=eps_y),
        input_nodes=[InputNode((0,), StaticRule(gamma=Linear(1.0), eps=eps_u), name="u")],
    )
    res = simulate(pb, X0, 20.0, z0=Z0, save=SaveAt(steps=True, grid=np.linspace(0, 20, 2001)))
    assert res.ok
    counts = transmission_counts(res)
    u_counts = input_transmission_counts(res)
    assert counts.shape == (3, 1) and u_counts.shape == (3, 1)
    assert np.all(counts > 5) and np.all(u_counts > 5)  # both channels are used, counted apart
    assert len(res.transmissions) == counts.sum() + u_counts.sum()
    bound = eps_y * linear.l1_gain(linear.L) + eps_u * linear.l1_gain(linear.B)
    g = res.on_grid()
    late = g.t[0] >= 10.0  # exp(-2 * 10) |e_x(0)| is negligible
    assert np.max(g.error[:, late]) <= bound
    assert np.max(g.error[:, late]) > 0.05 * bound  # the input's hold matters: not trivially small


def test_dynamic_input_rule_triggers_exactly_on_its_threshold():
    rule_u = DynamicRule(gamma=Quadratic(4.0), alpha=Linear(1.0), sigma=2.0, c=0.2, b=0.5, eps=0.01, eta0=1.0)
    pb = linear.problem(
        StaticRule(gamma=Linear(1.0), eps=0.05), input_nodes=[InputNode((0,), rule_u, name="u")]
    )
    res = simulate(pb, X0[:1], 15.0, z0=Z0, save=SaveAt(steps=True))
    a = res.solution.arcs[0]
    lay = pb.layout
    ch = lay.channels[1]
    times = res.transmission_times(0, 1)
    assert times.size > 5
    rows = _jump_rows(a, times)
    u = pb.u(a.t[rows])
    e_u = a.x[rows][:, ch.held] - u
    g = rule_u.trigger(a.t[rows], e_u, a.x[rows][:, ch.rule_state])
    np.testing.assert_allclose(g, 0.0, atol=1e-7)  # eq. (54) holds with equality at each send
    after = a.x[rows + 1]
    np.testing.assert_allclose(after[:, ch.held], u, atol=1e-12)  # ubar+ = u
    np.testing.assert_allclose(after[:, ch.rule_state], 0.5 * a.x[rows][:, ch.rule_state])  # eta_u+ = b eta_u
    err = res.arc(0).error
    assert np.all(np.isfinite(err)) and err[a.t >= 10].max() < 0.5


def test_observer_runs_on_held_input_not_the_true_one():
    """With the input node silent (huge eps_u), the observer sees ubar = u(0) = 0
    forever: the estimate then follows a plant driven by no input."""
    pb = linear.problem(
        StaticRule(gamma=Linear(1.0), eps=0.02),
        input_nodes=[InputNode((0,), StaticRule(gamma=Linear(1.0), eps=1e6), name="u")],
    )
    res = simulate(pb, X0[:1], 20.0, z0=Z0, save=SaveAt(grid=np.linspace(15, 20, 51)))
    assert input_transmission_counts(res)[0, 0] == 0
    # the output hold alone accounts for at most 0.02 ||G_y||_1 = 0.046
    assert res.on_grid().error.max() > 0.3  # the unsent input shows in the estimate


def test_input_nodes_are_validated():
    rule = StaticRule(gamma=Linear(1.0), eps=0.1)
    with pytest.raises(InputError, match=r"input node 0 sends input 1, which does not exist \(n_u = 1\)"):
        linear.problem(rule, input_nodes=[InputNode((1,), rule)])
    with pytest.raises(InputError, match=r"input 0 is sent by input nodes 0 and 1"):
        linear.problem(rule, input_nodes=[InputNode((0,), rule), InputNode((0,), rule)])
    with pytest.raises(InputTypeError, match=r"`input_nodes` must be a sequence of InputNode"):
        linear.problem(rule, input_nodes=[rule])
    with pytest.raises(InputTypeError, match=r"`rule` must be a TriggerRule; got float"):
        InputNode((0,), 1.0)


# -- relative threshold -------------------------------------------------------------------


def test_relative_rule_fires_when_gap_reaches_rho_y_plus_eps():
    rule = RelativeRule(rho=0.1, eps=0.01)
    pb = linear.problem(rule)
    res = simulate(pb, X0[:1], 10.0, z0=Z0, save=SaveAt(steps=True))
    a = res.solution.arcs[0]
    times = res.transmission_times(0, 0)
    assert times.size > 10
    rows = _jump_rows(a, times)
    y = pb.ytilde(a.t[rows], a.x[rows][:, pb.layout.x])
    e = a.x[rows][:, pb.layout.ybar] - y
    np.testing.assert_allclose(np.abs(e[:, 0]), 0.1 * np.abs(y[:, 0]) + 0.01, atol=1e-7)


def test_relative_rule_validation_and_missing_y():
    with pytest.raises(InputError, match=r"`rho` must be > 0; got -0.1"):
        RelativeRule(rho=-0.1, eps=0.1)
    with pytest.raises(InputError, match=r"RelativeRule.trigger needs the current measurement `y`"):
        RelativeRule(rho=0.1, eps=0.1).trigger(np.zeros(1), np.zeros((1, 1)), np.empty((1, 0)))


# -- Remark 3: the observer copy -------------------------------------------------------------


def test_observer_copy_holds_the_output_estimation_error_and_sends_less():
    """The copy variant sends ytilde - yhat (checked at every send). Its gap stops growing
    once the estimate converges, so it sends far less than holding y, whose gap grows
    as long as the plant moves (the oscillator keeps moving under u = sin t)."""
    rule = StaticRule(gamma=Linear(1.0), eps=0.02)
    copy = linear.problem(rule, hold="innovation")
    base = linear.problem(rule)
    rc = simulate(copy, X0, 20.0, z0=Z0, save=SaveAt(steps=True, grid=np.linspace(10, 20, 201)))
    rb = simulate(base, X0, 20.0, z0=Z0, save=SaveAt(grid=np.linspace(10, 20, 201)))
    a = rc.solution.arcs[0]
    times = rc.transmission_times(0, 0)
    rows = _jump_rows(a, times) + 1  # right after each send
    xhat = copy.psi(a.x[rows][:, copy.layout.z])
    yhat = np.array([copy.plant.call_h(row) for row in xhat])  # h is written for one run
    innov = copy.ytilde(a.t[rows], a.x[rows][:, copy.layout.x]) - yhat
    np.testing.assert_allclose(a.x[rows][:, copy.layout.ybar], innov, atol=1e-12)
    late_copy = transmission_counts(rc, window=(10, 20)).sum()
    late_base = transmission_counts(rb, window=(10, 20)).sum()
    assert late_copy * 5 < late_base
    assert rc.on_grid().error.max() < 2 * 0.02 * linear.l1_gain(linear.L)  # same ISS bound as holding y


def test_hold_is_validated():
    rule = StaticRule(gamma=Linear(1.0), eps=0.1)
    with pytest.raises(InputError, match=r"`hold` must be 'output' or 'innovation'; got 'copy'"):
        linear.problem(rule, hold="copy")


def test_problem_defaults_keep_the_paper_layout():
    pb = linear.problem(StaticRule(gamma=Linear(1.0), eps=0.1))
    assert isinstance(pb, EstimationProblem) and not pb.extended
    assert pb.layout.n == 2 + 2 + 1 and pb.layout.run is None


def test_rules_written_without_y_keep_working():
    """A user rule with the pre-`y` signature trigger(t, e, s): y is passed only to rules
    that declare reads_y."""
    from etobs.model.rules import StatelessRule

    class Band(StatelessRule):
        def trigger(self, t, e, s):
            return np.abs(e[:, 0]) - 0.05

    res = simulate(linear.problem(Band()), X0[:1], 3.0, z0=Z0)
    assert res.ok and len(res.transmissions) > 5
    assert res.backend == "scipy" and "a rule of your own" in res.backend_reason  # auto: no engine form


def test_relative_rule_reads_the_measurement_also_with_the_observer_copy():
    rule = RelativeRule(rho=0.2, eps=0.01)
    pb = linear.problem(rule, hold="innovation")
    res = simulate(pb, X0[:1], 5.0, z0=Z0, save=SaveAt(steps=True))
    a = res.solution.arcs[0]
    rows = _jump_rows(a, res.transmission_times(0, 0))
    assert rows.size > 3
    x, z = a.x[rows][:, pb.layout.x], a.x[rows][:, pb.layout.z]
    y = pb.ytilde(a.t[rows], x)
    innov = y - np.array([pb.plant.call_h(xhat) for xhat in pb.psi(z)])
    gap = a.x[rows][:, pb.layout.ybar] - innov
    np.testing.assert_allclose(np.abs(gap[:, 0]), 0.2 * np.abs(y[:, 0]) + 0.01, atol=1e-7)


def test_input_node_arguments_give_clear_errors():
    rule = StaticRule(gamma=Linear(1.0), eps=0.1)
    with pytest.raises(
        InputTypeError, match=r"`input_nodes` must be a list or tuple of InputNode objects; got NoneType"
    ):
        linear.problem(rule, input_nodes=None)
    with pytest.raises(InputTypeError, match=r"got InputNode"):
        linear.problem(rule, input_nodes=InputNode((0,), rule))
    with pytest.raises(InputError, match=r"`inputs` must name at least one input index"):
        InputNode((), rule)
