"""Network effects (not in the paper): delay, loss, reordering, overflow; seeded and replayable."""

import numpy as np
import pytest

from etobs import Link, Network, PeriodicRule, SaveAt, simulate
from etobs.errors import InputError, InputTypeError
from etobs.model import (
    BernoulliLoss,
    ExponentialDelay,
    GilbertElliottLoss,
    InputNode,
    StaticRule,
    UniformDelay,
)
from etobs.model.functions import Linear
from etobs.model.network import PacketStream
from tests.estimation import linear

X0 = np.array([[1.0, -0.5], [-2.0, 1.0]])
PERIOD = 0.02


def _periodic(network, t_end=20.0, x0=X0):
    pb = linear.problem(PeriodicRule(PERIOD), network=network)
    return pb, simulate(pb, x0, t_end, z0=np.zeros(2))


def test_twenty_percent_loss_and_10ms_delay_give_the_asked_statistics():
    net = Network(Link(delay=0.01, loss=0.2), seed=7)
    _, res = _periodic(net)
    assert res.ok
    st = res.network_stats()
    sent = st["sent"]
    assert np.all((sent >= 999) & (sent <= 1000))  # every 20 ms for 20 s (the last one at t_end or not)
    # counts add up, and nothing overflowed or arrived out of order
    np.testing.assert_array_equal(
        sent, st["lost"] + st["overflow"] + st["stale"] + st["in_flight"] + st["applied"]
    )
    assert st["overflow"].sum() == 0 and st["stale"].sum() == 0
    # loss fraction: 2000 Bernoulli(0.2) draws, within 4 standard deviations
    n, k = sent.sum(), st["lost"].sum()
    assert abs(k / n - 0.2) < 4 * np.sqrt(0.2 * 0.8 / n)
    # the lost packets are exactly those the seeded streams say (replayed independently)
    for run in range(2):
        stream = PacketStream(net.links[0], net.seed, run, 0)
        assert st["lost"][run, 0] == sum(stream.fate(s)[0] for s in range(1, sent[run, 0] + 1))
    # every delivery comes 10 ms after a send of the same run
    d, s = res.deliveries, res.transmissions
    assert len(d) == st["applied"].sum() + st["stale"].sum()
    for run in range(2):
        sends = s.times(run, 0)
        arrivals = d.times(run, 0)
        gap = arrivals[:, None] - sends[None, :]
        assert np.all(np.min(np.abs(gap - 0.01), axis=1) < 1e-9)


def test_results_are_reproducible_with_the_seed_and_change_with_it():
    def log(seed):
        _, res = _periodic(Network(Link(delay=0.01, loss=0.2), seed=seed), t_end=4.0)
        return res.deliveries.t, res.network_stats()["lost"]

    t1, l1 = log(3)
    t2, l2 = log(3)
    t3, l3 = log(4)
    assert l3.shape == l1.shape
    np.testing.assert_array_equal(t1, t2)
    np.testing.assert_array_equal(l1, l2)
    assert t1.shape != t3.shape or not np.array_equal(t1, t3)


def test_the_fate_of_a_run_does_not_depend_on_its_batch():
    """Run 1 of a batch, solved alone at batch position 0 with run_ids=[1], has the same
    packets; solved alone without run_ids it draws run 0's packets instead. (Times agree
    to rounding, not bit for bit: the model's matrix products round differently for
    batches of other shapes, with or without a network.)"""
    net = Network(Link(delay=UniformDelay(0.0, 0.03), loss=0.3), seed=1)
    pb, both = _periodic(net, t_end=3.0)
    alone = simulate(pb, X0[1:], 3.0, z0=np.zeros(2), run_ids=[1])
    np.testing.assert_allclose(both.deliveries.select(run=1).t, alone.deliveries.t, rtol=0, atol=1e-9)
    for key, counts in both.network_stats().items():
        np.testing.assert_array_equal(counts[1], alone.network_stats()[key][0])
    other = simulate(pb, X0[1:], 3.0, z0=np.zeros(2))
    t_other, t_alone = other.deliveries.t, alone.deliveries.t
    assert t_other.shape != t_alone.shape or not np.allclose(t_other, t_alone)


def test_observer_keeps_the_last_value_received():
    """ybar at the observer changes only at deliveries; the node's sent value at sends."""
    net = Network(Link(delay=0.05, loss=0.5), seed=2)
    pb = linear.problem(PeriodicRule(PERIOD), network=net)
    res = simulate(pb, X0[:1], 2.0, z0=np.zeros(2), save=SaveAt(steps=True))
    a = res.solution.arcs[0]
    ch = pb.layout.channels[0]
    held = a.x[:, ch.held][:, 0]
    changed = np.flatnonzero(np.diff(held) != 0)
    deliver_j = set(res.deliveries.j.tolist())
    assert changed.size > 0
    assert all(a.j[k] in deliver_j and a.j[k + 1] == a.j[k] + 1 for k in changed)
    # with half the packets lost, the observer applied fewer than it was sent
    st = res.network_stats()
    assert st["applied"][0, 0] < st["sent"][0, 0]


def test_random_delays_reorder_and_stale_packets_are_dropped():
    net = Network(Link(delay=UniformDelay(0.0, 0.1)), seed=5)
    pb, res = _periodic(net, t_end=5.0)
    st = res.network_stats()
    assert st["stale"].sum() > 0
    np.testing.assert_array_equal(
        st["sent"], st["lost"] + st["overflow"] + st["stale"] + st["in_flight"] + st["applied"]
    )
    # the observer's applied sequence number never decreases
    res2 = simulate(pb, X0[:1], 5.0, z0=np.zeros(2), save=SaveAt(steps=True))
    applied = res2.solution.arcs[0].x[:, pb.layout.channels[0].net.start + 1]
    assert np.all(np.diff(applied) >= 0)


def test_a_full_link_drops_packets_as_overflow():
    net = Network(Link(delay=0.1, capacity=2), seed=0)
    _, res = _periodic(net, t_end=2.0)
    st = res.network_stats()
    assert st["overflow"].min() > 0 and st["lost"].sum() == 0


def test_gilbert_elliott_rate_and_burst_length():
    loss = GilbertElliottLoss(p_gb=0.05, p_bg=0.25)
    stream = PacketStream(Link(loss=loss), seed=11, run=0, channel=0)
    lost = np.array([stream.fate(k)[0] for k in range(1, 40001)])
    assert loss.rate == pytest.approx(0.05 / 0.3)
    assert abs(lost.mean() - loss.rate) < 0.02
    # bursts of consecutive losses: mean length 1 / p_bg = 4
    edges = np.flatnonzero(np.diff(np.concatenate([[0], lost.astype(int), [0]])))
    bursts = edges[1::2] - edges[::2]
    assert 3.5 < bursts.mean() < 4.5


def _delays(delay, n=20000):
    stream = PacketStream(Link(delay=delay), seed=3, run=0, channel=0)
    return np.array([stream.fate(k)[1] for k in range(1, n + 1)])


def test_delay_distributions_have_their_means_and_quantiles():
    d = _delays(UniformDelay(0.01, 0.03))
    assert d.min() >= 0.01 and d.max() <= 0.03
    assert d.mean() == pytest.approx(0.02, rel=0.01)
    np.testing.assert_allclose(np.quantile(d, [0.25, 0.75]), [0.015, 0.025], atol=5e-4)
    d = _delays(ExponentialDelay(scale=0.01, minimum=0.005))
    assert d.min() >= 0.005 and d.mean() == pytest.approx(0.015, rel=0.03)
    # Exp(0.01) has median 0.01 ln 2
    assert np.median(d) - 0.005 == pytest.approx(0.01 * np.log(2), rel=0.03)
    assert ExponentialDelay(scale=0.01, minimum=0.005).mean == pytest.approx(0.015)


def test_packet_fates_are_independent_draws():
    """The counter-based draws (etobs.model.fates): no correlation between successive
    packets, between nodes or between runs, and a uniform histogram."""
    from etobs.model.fates import uniform

    u = np.array([[uniform(5, run, ch, k, 2) for k in range(1, 4001)] for run in range(2) for ch in range(2)])
    assert np.all((u >= 0) & (u < 1))
    counts = np.histogram(u.ravel(), bins=20, range=(0, 1))[0]
    expected = u.size / 20
    assert np.sum((counts - expected) ** 2 / expected) < 50  # chi2(19): p < 1e-4 above 43.8
    for a in range(4):
        assert abs(np.corrcoef(u[a, :-1], u[a, 1:])[0, 1]) < 0.06
        for b in range(a):
            assert abs(np.corrcoef(u[a], u[b])[0, 1]) < 0.06


def test_input_nodes_can_have_their_own_link():
    rule = StaticRule(gamma=Linear(1.0), eps=0.05)
    net = Network([Link(), Link(loss=1.0)], seed=0)
    pb = linear.problem(rule, input_nodes=[InputNode((0,), rule)], network=net)
    res = simulate(pb, X0[:1], 3.0, z0=np.zeros(2))
    st = res.network_stats()
    assert st["lost"][0, 0] == 0 and st["applied"][0, 0] == st["sent"][0, 0]
    assert st["lost"][0, 1] == st["sent"][0, 1] > 0


def test_network_errors_name_the_argument():
    with pytest.raises(InputError, match=r"`p` must be <= 1; got 1.5"):
        BernoulliLoss(1.5)
    with pytest.raises(InputTypeError, match=r"`delay` must be a number of seconds or a Delay"):
        Link(delay="10ms")
    with pytest.raises(InputTypeError, match=r"`loss` must be None, a probability or a Loss"):
        Link(loss="bursty")
    with pytest.raises(InputError, match=r"`capacity` must be an integer >= 1; got 0"):
        Link(capacity=0)
    with pytest.raises(
        InputError, match=r"`seed` must be an integer <= 9223372036854775807; got 9223372036854775808"
    ):
        Network(Link(), seed=2**63)
    with pytest.raises(InputError, match=r"`high` must be >= 0.2; got 0.1"):
        UniformDelay(0.2, 0.1)
    with pytest.raises(InputError, match=r"`network.links` has 3 links but the problem has 1 nodes"):
        linear.problem(PeriodicRule(0.1), network=Network([Link(), Link(), Link()]))
    with pytest.raises(InputError, match=r"hold='innovation'.*not simulated"):
        linear.problem(PeriodicRule(0.1), network=Network(Link()), hold="innovation")
    with pytest.raises(InputTypeError, match=r"`network` must be a Network or None; got Link"):
        linear.problem(PeriodicRule(0.1), network=Link())
    with pytest.raises(InputError, match=r"this problem has no network"):
        simulate(linear.problem(PeriodicRule(0.1)), X0[:1], 0.1).network_stats()


def test_the_network_does_not_change_when_nodes_send():
    """A node's rule acts on what it sent, never on what arrived, and the plant does not
    depend on the observer: the transmissions are those of the ideal network (up to the
    solver's tolerance, as delivery events split its steps differently)."""
    rule = linear.factory().nodes[0].rule
    ideal = simulate(linear.problem(rule), X0, 6.0, z0=np.zeros(2))
    lossy = simulate(
        linear.problem(rule, network=Network(Link(delay=UniformDelay(0.0, 0.05), loss=0.3), seed=9)),
        X0,
        6.0,
        z0=np.zeros(2),
    )
    a, b = ideal.transmissions, lossy.transmissions
    assert len(a) > 20
    np.testing.assert_array_equal(a.run, b.run)
    np.testing.assert_allclose(a.t, b.t, atol=1e-6)
    assert lossy.network_stats()["lost"].sum() > 0


def test_an_ideal_link_changes_nothing_not_even_the_step_sizes():
    """The network's entries (buffers, counters) are constant along flows and left out of
    the integration and its error norm, so an ideal Link gives the same steps and states
    as no network."""
    rule = linear.factory().nodes[0].rule
    plain = simulate(linear.problem(rule), X0, 5.0, z0=np.zeros(2))
    pb = linear.problem(rule, network=Network(Link()))
    ideal = simulate(pb, X0, 5.0, z0=np.zeros(2))
    assert ideal.backend == plain.backend == "engine"
    np.testing.assert_array_equal(plain.solution.n_steps, ideal.solution.n_steps)
    n = plain.problem.layout.n
    np.testing.assert_allclose(ideal.solution.x_final[:, :n], plain.solution.x_final, rtol=0, atol=1e-13)
    np.testing.assert_array_equal(plain.transmissions.t, ideal.transmissions.t)
    assert pb.layout.n_flow == n and pb.layout.n > 3 * n


def test_a_packet_arriving_as_its_node_sends_again_frees_its_slot_first():
    """delay = 2 periods and capacity 2: at every send one packet arrives at the same
    instant; deliveries jump before sends, so nothing overflows."""
    net = Network(Link(delay=2 * PERIOD, capacity=2), seed=0)
    _, res = _periodic(net, t_end=2.0)
    st = res.network_stats()
    assert st["overflow"].sum() == 0 and st["applied"].min() >= st["sent"].min() - 2


def test_absurd_delays_are_refused():
    with pytest.raises(InputError, match=r"`d` must be <= 1e\+09; got 1e\+31"):
        Link(delay=1e31)


@pytest.mark.parametrize("backend", ["engine", "scipy"])
def test_which_packets_are_lost_and_how_late_each_arrives_follows_its_own_draws(backend):
    # guards against: packet k's fate drawn from another packet's draws (k - 1, or a
    # shared stream). The count of lost packets hardly moves under such a shift; which
    # packets are lost and each one's delay do. Replayed from the seed independently
    # (PacketStream, the documented draw scheme of etobs.model.fates): packet k (1-based
    # sequence number, in sending order) is delivered exactly when fate(k) says it is
    # not lost, at its send time plus its own delay.
    net = Network(Link(delay=UniformDelay(0.001, 0.015), loss=0.3), seed=11)
    pb = linear.problem(PeriodicRule(PERIOD), network=net)
    res = simulate(pb, X0, 2.0, z0=np.zeros(2), backend=backend)
    assert res.ok
    for run in range(2):
        stream = PacketStream(net.links[0], net.seed, run, 0)
        sends = res.transmissions.times(run, 0)
        fate = [stream.fate(k) for k in range(1, sends.size + 1)]
        lost = np.array([f[0] for f in fate])
        due = sends + np.array([f[1] for f in fate])
        # delays < PERIOD: no reordering, so arrivals come in sending order
        expected = due[~lost & (due < 2.0)]
        assert 5 < lost.sum() < sends.size - 5  # both kinds present, so the test can tell
        np.testing.assert_allclose(res.deliveries.times(run, 0), expected, rtol=0, atol=1e-9)
