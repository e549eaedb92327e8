"""The paper's extensions and networks on the engine, against the scipy reference.

Input nodes (section 7.3), the observer-copy hold (Remark 3), networks (delay, loss,
reordering, overflow) and measurement noise, alone and together, with output nodes of
one and two outputs: the engine sends the same transmissions as the ``solve_ivp``
reference (an independent integrator on the Python functions), at the same times, and
with a network loses, drops and applies the same packets (the fates are drawn by one
function, :mod:`etobs.model.fates`, in both).
"""

import numpy as np
import pytest

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

TIGHT = SolverOptions(rtol=1e-12, atol=1e-12)
X0 = np.array([[1.0, -0.5, 0.4], [0.3, 0.8, -0.6]])
Z0 = np.zeros(3)
DYN = DynamicRule(gamma=Quadratic(4.0), alpha=Linear(1.0), sigma=2.0, c=0.2, b=0.5, eps=0.004, eta0=0.05)
TWO = [Node((0, 2), DYN, name="y02"), Node((1,), send_on_delta(0.04), name="y1")]

CASES = {
    "input nodes": dict(
        nodes=TWO,
        input_nodes=[
            InputNode((1,), DynamicRule(gamma=Linear(1.0), alpha=Linear(2.0), sigma=1.0, c=0.5, eps=0.05)),
            InputNode((0,), RelativeRule(rho=0.1, eps=0.05)),
        ],
    ),
    "copy hold": dict(
        nodes=[Node((0, 2), DYN), Node((1,), RelativeRule(rho=0.05, eps=0.01))],
        hold="innovation",
        m=Sinusoid(amplitude=[0.001, 0.0, 0.002], omega=7.0),
    ),
    "network": dict(
        nodes=[Node((0, 2), PeriodicRule(0.05)), Node((1,), send_on_delta(0.04))],
        network=Network(
            [
                Link(delay=UniformDelay(0.0, 0.12), loss=GilbertElliottLoss(p_gb=0.2, p_bg=0.4), capacity=2),
                Link(delay=0.01, loss=0.3),
            ],
            seed=9,
        ),
    ),
    "network and input node": dict(
        nodes=TWO,
        input_nodes=[InputNode((0, 1), StaticRule(gamma=Linear(1.0), eps=0.1))],
        network=Network([Link(delay=0.02, loss=0.2), None, Link(delay=UniformDelay(0.0, 0.05))], seed=3),
        m=Sinusoid(amplitude=[0.001, 0.001, 0.0], omega=5.0),
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_the_engine_runs_the_extension_as_the_reference_and_numpy_do(case):
    pb = chain(**CASES[case])
    grid = np.linspace(0.0, 3.0, 31)
    save = SaveAt(steps=False, grid=grid)
    ours = simulate(pb, X0, 3.0, z0=Z0, save=save)
    assert ours.backend == "engine" and ours.backend_reason == "auto: the engine models this problem"
    sci = simulate(pb, X0, 3.0, z0=Z0, save=save, backend="scipy", options=TIGHT)
    assert ours.ok and sci.ok
    counts = transmission_counts(ours)
    assert np.all(counts >= 3), counts
    np.testing.assert_array_equal(counts, transmission_counts(sci))
    assert ours.solution.jumps.rule.tolist() == sci.solution.jumps.rule.tolist()
    np.testing.assert_allclose(ours.solution.jumps.t, sci.solution.jumps.t, rtol=0, atol=1e-6)
    np.testing.assert_allclose(ours.solution.grid.x, sci.solution.grid.x, rtol=0, atol=1e-5)
    if pb.network is not None:
        ours_st, ref_st = ours.network_stats(), sci.network_stats()
        for key in ours_st:
            np.testing.assert_array_equal(ours_st[key], ref_st[key], err_msg=key)


def test_network_case_exercises_every_packet_fate():
    """The network case loses, reorders (stale), overflows and applies packets."""
    res = simulate(chain(**CASES["network"]), X0, 3.0, z0=Z0)
    st = res.network_stats()
    for key in ("lost", "stale", "overflow", "applied"):
        assert st[key][:, 0].min() > 0, key
    np.testing.assert_array_equal(
        st["sent"], st["lost"] + st["overflow"] + st["stale"] + st["in_flight"] + st["applied"]
    )


def test_the_engine_draws_the_packets_the_stream_replays():
    from etobs.model.network import PacketStream

    pb = chain(**CASES["network"])
    res = simulate(pb, X0, 3.0, z0=Z0, run_ids=[5, 11])
    st = res.network_stats()
    for b, run in enumerate((5, 11)):
        for c, link in enumerate(pb.network.links):
            stream = PacketStream(link, pb.network.seed, run, c)
            lost = sum(stream.fate(k)[0] for k in range(1, st["sent"][b, c] + 1))
            assert st["lost"][b, c] == lost


def test_a_run_on_the_engine_does_not_depend_on_its_batch_or_threads():
    import numba

    pb = chain(**CASES["network and input node"])
    both = simulate(pb, X0, 2.0, z0=Z0)
    alone = simulate(pb, X0[1:], 2.0, z0=Z0, run_ids=[1])
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        serial = simulate(pb, X0, 2.0, z0=Z0)
    finally:
        numba.set_num_threads(before)
    np.testing.assert_array_equal(both.solution.jumps.t[both.solution.jumps.run == 1], alone.solution.jumps.t)
    np.testing.assert_array_equal(both.solution.jumps.t, serial.solution.jumps.t)
    np.testing.assert_array_equal(both.solution.x_final, serial.solution.x_final)
