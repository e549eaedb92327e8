"""Simultaneous events (contract point 4 of etobs.hybrid.solver): in rule order, once each.

At an event every rule whose event function is ``>= 0`` jumps once, in rule order, each
with its own ``j``. The cases make the events exactly simultaneous on both solvers
(identical event functions of identical states, or several rules in the jump set at
``t0``) and give them a jump map whose outcome depends on the order, so that an order
mistake shows in the state as well as in the log.
"""

import numpy as np
import pytest

from etobs import EstimationProblem, Node, Observer, Plant, simulate
from etobs.hybrid import HybridSystem, SolverOptions, solve
from etobs.model import PeriodicRule

BACKENDS = ("engine", "scipy")


@pytest.fixture(params=BACKENDS)
def backend(request):
    return request.param


def _twin_rates(t, x, p):
    return np.array([1.0, 1.0, 0.0])


def _twin_guard(t, x, p):
    # identical functions of identical clocks: the two rules cross at the same instant
    return np.array([x[0] - p[0], x[1] - p[0]])


def _twin_jump(k, t, x, p):
    # rule k resets its clock and appends its digit k + 1 to acc in base 2:
    # acc -> 2 acc + k + 1 does not commute (0 then 1: 4 acc + 4; 1 then 0: 4 acc + 5)
    out = x.copy()
    out[k] = 0.0
    out[2] = 2.0 * x[2] + (k + 1.0)
    return out


def twin_clocks(period=1.0):
    """x = (clock 0, clock 1, acc); rule k fires when clock k reaches the period."""
    return HybridSystem(n=3, n_rules=2, flow=_twin_rates, guard=_twin_guard, jump=_twin_jump, params=[period])


def _rounds(n):
    acc = 0.0
    for _ in range(n):
        acc = 4.0 * acc + 4.0  # rule 0 (digit 1), then rule 1 (digit 2)
    return acc


def test_simultaneous_rules_jump_in_rule_order_with_their_own_j(backend):
    # guards against: the order of simultaneous jumps reversed (kernel's _jump_until_flow, reference's jumps())
    # both clocks start in the jump set (round at t0), then reach the period together at 1, 2, 3
    sol = solve(twin_clocks(), [1.5, 1.5, 0.0], (0.0, 3.5), backend=backend)
    log = sol.jumps
    assert log.rule.tolist() == [0, 1] * 4, f"simultaneous rules must jump in rule order: {log.rule.tolist()}"
    assert log.j.tolist() == list(range(8))  # one jump each, each with its own j
    assert np.array_equal(log.t[0::2], log.t[1::2])  # each pair at one instant
    np.testing.assert_allclose(log.t[0::2], [0.0, 1.0, 2.0, 3.0], rtol=0, atol=1e-9)
    # the order shows in the state: 340 = 4 rounds of acc -> 4 acc + 4 (reversed: 425)
    assert sol.x_final[0, 2] == _rounds(4) == 340.0
    assert sol.j_final.tolist() == [8]


def test_the_order_is_the_rules_not_the_order_they_entered_the_jump_set(backend):
    # guards against: simultaneous jumps taken in reverse, or by which function is largest
    # clock 1 is further past its period at t0 (g = (0.25, 0.75)): rule 0 still goes first
    sol = solve(twin_clocks(), [1.25, 1.75, 0.0], (0.0, 0.5), backend=backend)
    assert sol.jumps.rule.tolist() == [0, 1]
    assert sol.jumps.t.tolist() == [0.0, 0.0]
    assert sol.x_final[0, 2] == 4.0  # 2 * (2 * 0 + 1) + 2; reversed: 5


def _still(n):
    plant = Plant(f_p=lambda t, x, u, v: np.zeros(n), h=lambda x: x.copy(), n_x=n, n_y=n)
    observer = Observer(f_o=lambda t, z, u, ybar, yhat: np.zeros(n), n_z=n)
    return plant, observer


def test_simultaneous_nodes_send_in_node_order_each_with_its_own_j(backend):
    # guards against: the estimation model's simultaneous transmissions logged or applied in reverse
    # three nodes with one clock each (same period and start): all three send at 0, 0.5 and 1
    plant, observer = _still(3)
    nodes = [Node((i,), PeriodicRule(period=0.5, first=0.0), name=f"y{i}") for i in range(3)]
    pb = EstimationProblem(plant=plant, observer=observer, nodes=nodes)
    # (bounded: a solver that stalls on the sends at t0, where g = 0, ends with max_steps)
    res = simulate(pb, [1.0, 2.0, 3.0], 1.2, backend=backend, options=SolverOptions(max_steps=5000))
    log = res.transmissions
    assert log.rule.tolist() == [0, 1, 2] * 3, f"nodes must send in node order: {log.rule.tolist()}"
    assert log.j.tolist() == list(range(9))
    for r in range(3):  # one instant per round, one transmission per node
        assert np.all(log.t[3 * r : 3 * r + 3] == log.t[3 * r])
    np.testing.assert_allclose(log.t[0::3], [0.0, 0.5, 1.0], rtol=0, atol=1e-9)
    for node in range(3):  # each node's j: its place in the round
        assert res.transmissions.select(rule=node).j.tolist() == [node, 3 + node, 6 + node]
