"""Property: on problems with the extensions, the engine and the scipy reference agree.

Hypothesis draws the numbers of three problem structures (so that each structure
compiles once and every example costs a solve): output nodes of one and two outputs
with an input node and a lossy, delayed network; the observer-copy hold with noise;
a network with bursty loss, random delays (reordering) and a small capacity. The
engine and the ``solve_ivp`` reference (an independent integrator and event locator on
the Python functions) send the same transmissions in the same order, at the same times
to 1e-6 s, and lose, drop and apply the same packets. Draws with two events of
different rules within 1e-6 s of each other or of the horizon are left out
(simultaneous events are tested on their own in tests/hybrid/test_solver.py).
"""

import numpy as np
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from etobs import Node, simulate
from etobs.estimation import transmission_counts
from etobs.hybrid import SaveAt, SolverOptions
from etobs.model import (
    DynamicRule,
    GilbertElliottLoss,
    InputNode,
    Linear,
    Link,
    Network,
    PeriodicRule,
    Quadratic,
    RelativeRule,
    Sinusoid,
    StaticRule,
    UniformDelay,
    send_on_delta,
)

from .chain import chain

T_END = 1.0
TIGHT = SolverOptions(rtol=1e-12, atol=1e-12)


def _dynamic(eps, sigma):
    return DynamicRule(gamma=Quadratic(4.0), alpha=Linear(1.0), sigma=sigma, c=0.2, b=0.5, eps=eps, eta0=0.05)


def _input_node_and_network(d):
    nodes = [Node((0, 2), _dynamic(d["eps"], d["sigma"])), Node((1,), send_on_delta(d["delta"]))]
    inputs = [InputNode((1,), StaticRule(gamma=Linear(1.0), eps=d["delta"]))]
    net = Network(Link(delay=d["delay"], loss=d["loss"]), seed=d["seed"])
    return chain(nodes, input_nodes=inputs, network=net)


def _copy_hold(d):
    nodes = [Node((0, 2), _dynamic(d["eps"], d["sigma"])), Node((1,), RelativeRule(rho=0.05, eps=d["delta"]))]
    # section 7.2's condition eps > gamma(2 m) holds: 4 (2 * 0.054)^2 eps < eps
    m = np.sqrt(d["eps"])
    noise = Sinusoid(amplitude=[0.05 * m, 0.0, 0.02 * m], omega=7.0)
    return chain(nodes, hold="innovation", m=noise)


def _bursty_network(d):
    nodes = [Node((0, 2), PeriodicRule(d["period"])), Node((1,), send_on_delta(d["delta"]))]
    link = Link(
        delay=UniformDelay(0.0, d["delay"] * 8), loss=GilbertElliottLoss(p_gb=d["loss"], p_bg=0.4), capacity=2
    )
    return chain(nodes, network=Network([link, Link(delay=d["delay"])], seed=d["seed"]))


STRUCTURES = {
    "input node and network": _input_node_and_network,
    "copy hold": _copy_hold,
    "bursty": _bursty_network,
}

numbers = st.fixed_dictionaries(
    {
        "eps": st.floats(0.002, 0.02),
        "sigma": st.floats(0.0, 4.0),
        "delta": st.floats(0.02, 0.08),
        "period": st.floats(0.03, 0.09),
        "delay": st.floats(0.001, 0.03),
        "loss": st.floats(0.0, 0.5),
        "seed": st.integers(0, 2**40),
        "x0": st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3),
    }
)


@settings(max_examples=6, deadline=None)
@given(st.sampled_from(sorted(STRUCTURES)), numbers)
def test_engine_and_reference_agree_on_drawn_extension_problems(structure, d):
    pb = STRUCTURES[structure](d)
    x0 = np.array([d["x0"]])
    save = SaveAt(steps=False)
    sci = simulate(pb, x0, T_END, save=save, backend="scipy", options=TIGHT)
    log = sci.solution.jumps
    order = np.argsort(log.t, kind="stable")
    t, rule = log.t[order], log.rule[order]
    apart = np.diff(t) > 1e-6
    assume(np.all(apart | (rule[1:] == rule[:-1])) and np.all(np.abs(t - T_END) > 1e-6))
    eng = simulate(pb, x0, T_END, save=save)
    assert eng.backend == "engine" and eng.ok and sci.ok
    np.testing.assert_array_equal(transmission_counts(eng), transmission_counts(sci))
    assert eng.solution.jumps.rule.tolist() == log.rule.tolist()
    np.testing.assert_allclose(eng.solution.jumps.t, log.t, rtol=0, atol=1e-6)
    if pb.network is not None:
        ours, ref = eng.network_stats(), sci.network_stats()
        for key in ours:
            np.testing.assert_array_equal(ours[key], ref[key], err_msg=key)
