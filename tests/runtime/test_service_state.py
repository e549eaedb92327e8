"""The service's state (issue 23): a status that says what it waits for and whom it refuses,
the observer checkpointed with the marks and resumed after a restart, the newest sequence
number winning over time stamps, the sequence-jump bound on both sides, files that are not
regular refused without blocking, and sequence numbers never reused across restarts."""

import itertools
import json
import math
import os
import threading
from collections import deque

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from etobs.errors import InputError
from etobs.examples import robot_arm
from etobs.runtime.marks import HighWaterMarks
from etobs.runtime.packet import Packet, decode, encode, node_keys, record_of, resync_record
from etobs.runtime.sampled_rule import SampledRule
from etobs.runtime.sensor import RESYNC_MIN_GAP, RESYNC_WINDOW, SensorNode, SequenceStore
from etobs.runtime.service import MAX_SEQ_JUMP, REFUSED_IN_A_ROW, RESYNC_RETRY, RESYNC_TRIES, ObserverCore

KEYS = node_keys(b"deployment secret", [0, 1])
SESSION = 7.0


def _pkt(node, seq, t, value, *, initial=False, session=SESSION):
    return encode(Packet(node, seq, t, (value,), initial, session), KEYS[node])


def _core(**kw):
    return ObserverCore(robot_arm(), KEYS, session=SESSION, **kw)


def test_the_status_waits_until_every_node_is_heard():
    """It said "ok" having received nothing."""
    core = _core()
    snap = core.snapshot()
    assert snap["status"] == "waiting" and snap["waiting"] == [0, 1] and snap["xhat"] is not None
    assert core.receive(_pkt(0, 1, 0.0, 0.0, initial=True), now=0.0) == "initial"
    assert core.snapshot()["status"] == "waiting" and core.snapshot()["waiting"] == [1]
    assert core.receive(_pkt(1, 1, 0.0, 0.0, initial=True), now=0.0) == "initial"
    snap = core.snapshot()
    assert snap["status"] == "ok" and snap["waiting"] == [] and snap["refused"] == []


@pytest.mark.parametrize("verdict", ["stale", "wrong_session"])
def test_a_node_whose_packets_are_refused_in_a_row_is_named(verdict):
    """After the sensors' sequence files were deleted, their packets were refused as stale
    while the status said ok. The bound on both sides: REFUSED_IN_A_ROW - 1 refusals are a
    replay or an overtaken packet (not named), REFUSED_IN_A_ROW name the node."""
    core = _core()
    for i in range(2):
        assert core.receive(_pkt(i, 5000, 0.0, 0.0, initial=True), now=0.0) == "initial"

    def refused(k):  # a node restarted without its sequence file (numbers from 1), or on another epoch
        seq = k + 1 if verdict == "stale" else 6000 + k
        return _pkt(1, seq, 0.1, 1.0, session=SESSION if verdict == "stale" else 8.0)

    for k in range(REFUSED_IN_A_ROW - 1):
        assert core.receive(refused(k), now=0.1) == verdict
    assert core.snapshot()["status"] == "ok" and core.snapshot()["refused"] == []
    assert core.receive(refused(REFUSED_IN_A_ROW), now=0.1) == verdict
    snap = core.snapshot()
    assert snap["status"] == "refusing"
    assert snap["refused"] == [{"node": 1, "verdict": verdict, "in_a_row": REFUSED_IN_A_ROW}]
    assert core.receive(_pkt(1, 5001, 0.2, 1.0), now=0.2) == "applied"  # a packet in: named no more
    assert core.snapshot()["status"] == "ok" and core.snapshot()["refused"] == []


def test_a_sensor_whose_sequence_file_was_deleted_is_named(tmp_path):
    """The case of the trial: a real node whose file is gone starts again at 1 and is stale."""
    pb = robot_arm()
    core = ObserverCore(pb, KEYS, marks=HighWaterMarks(tmp_path / "s.state"))
    inbox = []
    spec = {"kind": "periodic", "period": 0.01}
    for i in range(2):
        core.receive(encode(Packet(i, 2000, 0.0, (0.0,), True), KEYS[i]))
    core.advance(0.0)
    node = SensorNode(1, KEYS[1], SampledRule(spec, 0.01), inbox.append, SequenceStore(tmp_path / "n1.seq"))
    for k in range(REFUSED_IN_A_ROW + 1):
        node.sample(0.01 * k, [1.0 + k])
    assert [core.receive(d) for d in inbox][:2] == ["stale", "stale"]
    assert core.snapshot()["status"] == "refusing" and core.snapshot()["refused"][0]["node"] == 1


def test_the_newest_sequence_number_wins_over_time_stamps():
    """A sensor clock going back made an older measurement override the newest one: packets
    were applied in time-stamp order. Now the newer number is applied after the older one."""
    core = _core()
    for i in range(2):
        core.receive(_pkt(i, 1, 0.0, 0.0, initial=True), now=0.0)
    assert core.receive(_pkt(0, 2, 0.50, 5.0), now=0.5) == "applied"
    assert core.receive(_pkt(0, 3, 0.45, 6.0), now=0.5) == "applied"  # newer, stamped earlier
    assert core.receive(_pkt(1, 2, 0.47, 7.0), now=0.5) == "applied"  # another node: its own time
    core.advance(0.48)
    assert core.ybar.tolist() == [0.0, 7.0]  # node 0's newest waits for its older one
    core.advance(0.6)
    assert core.ybar.tolist() == [6.0, 7.0] and core.snapshot()["clock_back"] == [1, 0]
    # once the older one was applied, a newer one stamped before it acts at once (late)
    assert core.receive(_pkt(0, 4, 0.1, 8.0), now=0.6) == "applied"
    core.advance(0.6)
    assert core.ybar[0] == 8.0 and core.late == 1 and core.snapshot()["clock_back"] == [2, 0]


@pytest.mark.parametrize(("jump", "verdict"), [(MAX_SEQ_JUMP - 1, "applied"), (MAX_SEQ_JUMP, "seq_jump")])
def test_the_sequence_jump_bound_on_both_sides_and_across_a_restart(tmp_path, jump, verdict):
    """One authentic packet with seq = last + 2^32 was accepted, its mark written, and the
    node's next packets stale, across restarts too."""
    marks = HighWaterMarks(tmp_path / "s.state")
    core = _core(marks=marks)
    for i in range(2):
        core.receive(_pkt(i, 10, 0.0, 0.0, initial=True), now=0.0)
    assert core.receive(_pkt(0, 10 + jump, 0.1, 1.0), now=0.1) == verdict
    core.advance(0.2)  # the marks are written
    restarted = _core(marks=marks)
    expected = 10 + jump if verdict == "applied" else 10
    assert restarted.snapshot()["last_seq"] == [expected, 10]
    if verdict == "seq_jump":  # the node was not locked out: its next packet is applied
        assert restarted.receive(_pkt(0, 11, 0.3, 2.0), now=0.3) == "applied"


def _packets(pb, t_end, period):
    """Packets of both nodes of the arm on smooth made-up outputs: [(t_k, [datagrams])]."""
    inbox, out = [], []
    nodes = [
        SensorNode(i, KEYS[i], SampledRule(nd.rule.sensor_spec(), period), inbox.append, session=SESSION)
        for i, nd in enumerate(pb.nodes)
    ]
    for k in range(round(t_end / period) + 1):
        t = k * period
        for i, node in enumerate(nodes):
            node.sample(t, [30.0 * math.cos(4.0 * t + i) + 5.0 * t])
        out.append((t, list(inbox)))
        inbox.clear()
    return out


def _feed(core, packets, t_from=-1.0, t_to=math.inf):
    xhat = {}
    for t, data in packets:
        if t_from < t <= t_to:
            for d in data:
                core.receive(d, now=t)
            core.advance(t)
            xhat[round(t, 9)] = core.xhat()
    return xhat


def test_a_restarted_service_resumes_its_observer_from_the_checkpoint(tmp_path):
    """A service killed and restarted kept its marks but not its observer: no estimate until
    every node had sent again (4.9 s in the trial). Now it resumes at once from the state
    written with the marks, and goes on exactly as the run that was not interrupted."""
    pb = robot_arm()
    packets = _packets(pb, 2.0, 0.01)
    whole = _core()
    undisturbed = _feed(whole, packets)
    killed = _core(marks=HighWaterMarks(tmp_path / "s.state"))
    _feed(killed, packets, t_to=1.0)
    # the packets of the next sample are received, and the service is killed before it applies
    # them (they were lost with it before: the sensors send each once)
    t_kill = next(t for t, data in packets if t > 1.0 and data)
    for t, data in packets:
        if 1.0 < t <= t_kill:
            for d in data:
                killed.receive(d, now=t)
    saved = json.loads((tmp_path / "s.state").read_text())
    assert saved["version"] == 2 and saved["observer"]["session"] == SESSION
    restarted = _core(marks=HighWaterMarks(tmp_path / "s.state"))
    snap = restarted.snapshot()
    assert restarted.resumed and snap["status"] == "ok" and None not in snap["xhat"]
    assert saved["observer"]["t"] <= restarted.t <= 1.0 and len(saved["observer"]["queue"]) > 0
    after = _feed(restarted, packets, t_from=t_kill)
    assert restarted.counts["stale"] == restarted.counts["replayed"] == 0
    assert restarted.snapshot()["transmissions"] == whole.snapshot()["transmissions"]  # counters go on
    gap = max(np.max(np.abs(after[t] - undisturbed[t])) for t in after)
    assert gap < 1e-9 * max(np.max(np.abs(undisturbed[t])) for t in after)
    # another session (a new epoch) starts afresh: the state belongs to the run it was written in
    fresh = ObserverCore(pb, KEYS, session=SESSION + 1, marks=HighWaterMarks(tmp_path / "s.state"))
    assert not fresh.resumed and fresh.t == 0.0 and fresh.snapshot()["status"] == "waiting"


def test_a_checkpoint_of_another_problem_is_refused(tmp_path):
    from tests.estimation import linear

    marks = HighWaterMarks(tmp_path / "s.state")
    core = ObserverCore(linear.factory(), KEYS, session=SESSION, marks=marks)
    core.receive(_pkt(0, 1, 0.0, 0.0, initial=True), now=0.0)
    core.advance(0.1)
    with pytest.raises(
        InputError, match=r"observer state in .*s.state' has 2 states and 1 outputs; .* has 4"
    ):
        _core(marks=marks)
    saved = json.loads((tmp_path / "s.state").read_text())
    saved["observer"]["z"] = ["x", 1.0]
    (tmp_path / "s.state").write_text(json.dumps(saved))
    with pytest.raises(
        InputError, match=r"high-water marks .* are damaged \(the observer state is not one\)"
    ):
        _core(marks=marks)


def _in_thread(fn, fifo):
    """``fn()`` in a thread; a call that blocks on the FIFO is released and reported."""
    box = {}

    def call():
        try:
            box["value"] = fn()
        except Exception as exc:  # the test looks at it
            box["error"] = exc

    thread = threading.Thread(target=call, daemon=True)
    thread.start()
    thread.join(30)
    if thread.is_alive():  # release the open() that blocks, then fail
        os.close(os.open(fifo, os.O_RDWR | os.O_NONBLOCK))
        thread.join(30)
        pytest.fail(f"{fn} blocked on the FIFO {fifo}")
    return box


@pytest.mark.parametrize("which", ["secret", "token", "state", "sequence", "trace"])
def test_a_file_that_is_a_fifo_is_refused_without_blocking(tmp_path, which):
    """A secret, state or token file that was a FIFO hung `etobs serve` in open(); a
    sequence file hung the sensor."""
    import tomllib
    from dataclasses import replace

    from etobs.runtime.deployment import parse_deployment
    from etobs.runtime.files import open_regular

    fifo = tmp_path / f"{which}.fifo"
    os.mkfifo(fifo)
    text = '[system]\nfactory = "robot_arm"\n[runtime]\nperiod = 0.01\nduration = 1.0\nhttp_port = 0\n'
    dep = parse_deployment(tomllib.loads(text), tmp_path)
    calls = {
        "secret": lambda: replace(dep, secret_file=fifo).secret(create=True),
        "token": lambda: replace(dep, http_token_file=fifo).token(),
        "state": lambda: HighWaterMarks(fifo).load({0: "k"}),
        "sequence": lambda: SequenceStore(fifo),
        "trace": lambda: open_regular(fifo, "--trace", write=True),
    }
    box = _in_thread(calls[which], fifo)
    assert isinstance(box.get("error"), InputError), box
    message = str(box["error"])
    assert len(message.splitlines()) == 1 and str(fifo) in message, message
    assert "is a FIFO, not a regular file" in message or "cannot be opened: No such device" in message


def test_a_folder_or_a_device_is_refused_naming_it(tmp_path):
    from etobs.runtime.files import open_regular

    with pytest.raises(InputError, match=r"`runtime.secret_file` '.*' is a folder, not a regular file"):
        open_regular(tmp_path, "`runtime.secret_file`")
    with pytest.raises(InputError, match=r"--trace '/dev/null' is a character device, not a regular file"):
        open_regular("/dev/null", "--trace", write=True)
    link = tmp_path / "link"
    link.symlink_to(tmp_path / "target")
    (tmp_path / "target").write_text("x")
    with pytest.raises(InputError, match=r"the high-water marks '.*link' cannot be opened"):
        open_regular(link, "the high-water marks", follow=False)
    with open_regular(link, "`runtime.secret_file`") as fh:  # a secret may be a link (a mounted one)
        assert fh.read() == b"x"


@settings(max_examples=60, deadline=None)
@given(
    block=st.integers(1, 9),
    takes=st.lists(st.integers(0, 25), min_size=1, max_size=8),
)
def test_sequence_numbers_strictly_increase_across_restarts(tmp_path_factory, block, takes):
    """A restarted SequenceStore must never reuse a number, at a block boundary or anywhere:
    the node takes ``takes[r]`` numbers in run ``r`` and is killed (no clean shutdown)."""
    path = tmp_path_factory.mktemp("seq") / "node.seq"
    got = []
    for n in takes:
        store = SequenceStore(path, block=block)
        got += [store.next() for _ in range(n)]
    assert all(b > a for a, b in itertools.pairwise(got)), got
    assert got == [] or got[0] >= 1


@pytest.mark.parametrize("block", [0, -1, 1.5, True, 2**20 + 1])
def test_a_block_that_would_reuse_numbers_is_refused(block):
    """``block = 0`` wrote the number about to be handed out as the bound: a restart reused it."""
    with pytest.raises(InputError, match=r"`block` must be an integer in 1..1048576; got"):
        SequenceStore(None, block=block)


def test_hellos_need_fresh_numbers_and_a_start_packet_is_not_for_the_service():
    """The handshake's packets: a captured hello gets no answer (replayed, or stale after
    its number), and a start packet sent to the service is refused."""
    core = _core()
    hello = encode(Packet(0, 5, 0.0, (0.0,), session=0.0, hello=True), KEYS[0])
    assert core.receive(hello) == "hello" and core.last_hello == (0, 5)
    assert core.receive(hello) == "replayed"
    assert core.receive(encode(Packet(0, 4, 0.0, (0.0,), session=0.0, hello=True), KEYS[0])) == "stale"
    start = encode(Packet(0, 6, 0.0, (0.0,), session=SESSION, start=True), KEYS[0])
    assert core.receive(start) == "malformed"
    resync = encode(Packet(0, 7, 0.0, (0.0,), session=SESSION, resync=True), KEYS[0])
    assert core.receive(resync) == "malformed"  # a resync request is the service's too
    assert core.snapshot()["waiting"] == [0, 1]  # a hello is not a measurement
    with pytest.raises(ValueError, match=r"at most one of initial, hello, start, resync and answer"):
        encode(Packet(0, 1, 0.0, (0.0,), initial=True, hello=True), KEYS[0])


def test_a_sensor_takes_only_the_answer_to_its_own_hello():
    """A captured start packet (another hello's number, another node's, or forged) is
    ignored; the answer that echoes this hello is taken; no answer ends with one line."""
    from etobs.runtime.sensor import handshake

    class Link:
        address = ("127.0.0.1", 9)

        def __init__(self, replies):
            self.sent, self.replies = [], replies

        def __call__(self, data):
            self.sent.append(data)

        def recv(self, timeout):
            return self.replies.pop(0)(self.sent[-1]) if self.replies else None

    def answer(node, key, *, seq=None, first=0.0):
        def reply(hello):
            n = seq if seq is not None else int.from_bytes(hello[8:16], "big")
            return encode(Packet(node, n, first, (0.0,), session=1.7e9, start=True), key)

        return reply

    forged = node_keys(b"not the secret", [0])[0]
    link = Link(
        [answer(0, KEYS[0], seq=1), answer(1, KEYS[1]), answer(0, forged), answer(0, KEYS[0], first=2.5)]
    )
    store = SequenceStore()
    store.next()  # number 1 was an earlier hello's: its captured answer must not be taken
    assert handshake(link, 0, KEYS[0], store, timeout=60) == (1.7e9, 2.5)
    ticks = iter(range(100))
    with pytest.raises(
        InputError, match=r"no answer from the service at 127.0.0.1:9 after 2 s; is `etobs serve"
    ):
        handshake(Link([]), 0, KEYS[0], SequenceStore(), timeout=2, clock=lambda: next(ticks) * 0.25)


def _cosim(pb, t, y, marks, *, down=None, listen=True, sent_hook=None):
    """Sensors and service on one virtual clock; ``down = (t_kill, t_up)`` kills the service.

    While it is down the sensors' datagrams are lost; at ``t_up`` a new service is started on
    the same state file, and its resync requests reach the sensors' inboxes. ``sent_hook``
    may reorder or drop the datagrams of a sample. Returns the estimate and the status at
    each sample, the sensors, the last core, the datagrams lost and the verdicts after the
    restart (sample time, verdict, datagram).
    """
    inbox = {i: deque() for i in range(pb.n_nodes)}
    sent = []
    nodes = [
        SensorNode(
            i,
            KEYS[i],
            SampledRule(nd.rule.sensor_spec(), t[1] - t[0]),
            sent.append,
            session=SESSION,
            listen=(lambda q=inbox[i]: q.popleft() if q else None) if listen else None,
        )
        for i, nd in enumerate(pb.nodes)
    ]
    core, xhat, status, lost, after = _core(marks=HighWaterMarks(marks)), [], [], [], []
    core.in_sync = in_sync = []  # whether the held outputs are the sensors' sent values, per sample
    for k, tk in enumerate(t):
        if down is not None and down[0] <= tk < down[1]:
            core = None
        elif core is None:
            core = _core(marks=HighWaterMarks(marks))
            core.in_sync = in_sync
            assert core.resumed
        for i, nd in enumerate(pb.nodes):
            nodes[i].sample(tk, y[k, list(nd.outputs)])
        for d in sent_hook(tk, sent) if sent_hook else sent:
            if core is None:
                lost.append(d)
                continue
            verdict = core.receive(d, now=tk)
            if down is not None and tk >= down[1]:
                after.append((tk, verdict, d))
            if verdict in ("initial", "applied", "answer"):
                core.note_address(core.last_node, ("127.0.0.1", 47000 + core.last_node))
        sent.clear()
        if core is None:
            xhat.append(np.full(pb.plant.n_x, np.nan))
            status.append("down")
            in_sync.append(False)
            continue
        core.advance(tk)
        core.in_sync.append(core.ybar.tolist() == [v for n in nodes for v in n.sent])
        for i, addr, d in core.resync_requests(tk):
            assert addr == ("127.0.0.1", 47000 + i)
            inbox[i].append(d)
        xhat.append(core.xhat())
        status.append(core.status)
    return np.array(xhat), status, nodes, core, lost, after


def _moving_then_resting(t):
    # the outputs move while the service is down, then rest: no sensor's rule fires again
    return np.stack([3.0 - i + 4.0 * np.clip(t - 5.5, 0.0, 1.0) * (1 - 2 * i) for i in range(2)], axis=1)


def test_a_restarted_service_gets_back_what_its_sensors_sent_while_it_was_down(tmp_path):
    """SIGKILLed for 2.6 s, the service resumed from its checkpoint but the packets sent
    meanwhile were lost and no sensor resent: its held outputs stayed off the sensors' (the
    estimate 8.1 off the reference at the end; 2.35 with a resync that only asked for the
    current value). Now the restarted service holds its observer and asks each sensor to
    resend what it sent after the service's record; one sampling period after the restart
    the observer has integrated them at their sample times, and its estimate is the
    undisturbed run's."""
    pb, period = robot_arm(), 0.01
    t = period * np.arange(round(12.0 / period) + 1)
    y = _moving_then_resting(t)
    whole, _, whole_nodes, whole_core, _, _ = _cosim(pb, t, y, tmp_path / "a.state")
    down, up = (5.0, 7.6), round(7.6 / period)
    runs = {
        listen: _cosim(pb, t, y, tmp_path / f"{listen}.state", down=down, listen=listen)
        for listen in (False, True)
    }
    # without an answer: 4 packets of the downtime lost, each sensor holding a value the
    # service never got; 20 requests each (RESYNC_TRIES) unanswered, then the observer goes on
    xhat, status, nodes, core, lost, _ = runs[False]
    assert len(lost) == 4 and core.snapshot()["resync_asked"] == [RESYNC_TRIES] * 2
    assert core.snapshot()["resync_gave_up"] == [0, 1] and core.snapshot()["recovered"] == [0, 0]
    held = up + RESYNC_TRIES * round(RESYNC_RETRY / period)  # the last request waits one retry
    assert set(status[up:held]) == {"resyncing"} and status[held:] == ["ok"] * (len(t) - held)
    assert core.ybar.tolist() == [3.0, 2.0] and [n.sent for n in nodes] != [[3.0], [2.0]]
    # now: one request each at t_up; at the next sample each sensor resends exactly the
    # packets that were lost, in order, then answers
    xhat, status, nodes, core, lost, after = runs[True]
    assert core.snapshot()["resync_asked"] == [1, 1] and [n.resyncs for n in nodes] == [1, 1]
    resent = [(v, d) for tk, v, d in after if tk == t[up + 1]]
    by_node = sorted(lost, key=lambda d: d[4:6])  # node by node, each in the order sent
    assert [d for v, d in resent if v == "applied"] == by_node and len(lost) == 4
    assert [v for v, _ in resent].count("answer") == 2 and [n.resent for n in nodes] == [2, 2]
    snap = core.snapshot()
    assert snap["recovered"] == [2, 2] and snap["gaps"] == [0, 0] and snap["resync_gave_up"] == []
    assert snap["transmissions"] == whole_core.snapshot()["transmissions"]  # answers are not transmissions
    assert [n.transmissions for n in nodes] == [n.transmissions for n in whole_nodes]
    assert status[up] == "resyncing" and status[up + 1 :] == ["ok"] * (len(t) - up - 1)
    assert core.ybar.tolist() == [n.sent[0] for n in nodes] == [n.sent[0] for n in whole_nodes]
    assert core.in_sync[up : up + 2] == [False, True] and all(core.in_sync[up + 1 :])
    # the estimate: held at the checkpoint's at t_up, the undisturbed run's one period later
    gap = np.max(np.abs(xhat - whole), axis=1)
    assert gap[up] > 1.0
    assert np.all(gap[up + 1 :] <= 1e-9 * np.max(np.abs(whole[up + 1 :]), axis=1))


def test_a_resend_overtaken_by_a_newer_packet_acts_at_its_own_time(tmp_path):
    """The resends of a node may arrive after a newer packet of it (the network reorders, or
    the node transmitted after the restart before it read the request): each is accepted
    once, acts at its sample time, before the newer packet, and fills its gap; a second copy
    during the resync is ``resent`` (the node answered twice), not counted as an attack."""

    def pkt(node, seq, t, value, **kw):
        return encode(Packet(node, seq, t, (value,), session=SESSION, **kw), KEYS[node])

    def start(core):
        for i in range(2):
            assert core.receive(pkt(i, 1, 0.0, 1.0 + i, initial=True), now=0.0) == "initial"
            core.note_address(i, ("127.0.0.1", 47000 + i))
        assert core.receive(pkt(0, 2, 1.0, 1.5), now=1.0) == "applied"
        core.advance(1.2)

    later = [pkt(0, 3, 2.0, 2.5), pkt(0, 4, 2.5, 3.5), pkt(0, 5, 3.0, 4.5)]
    whole = _core()
    start(whole)
    for d in later:
        whole.receive(d, now=3.0)
    whole.advance(3.5)

    start(_core(marks=HighWaterMarks(tmp_path / "s.state")))  # killed at 1.2; 3, 4, 5 lost
    core = _core(marks=HighWaterMarks(tmp_path / "s.state"))
    assert core.resumed and core.holding and core.status == "resyncing"
    asks = core.resync_requests(3.0)
    assert [(i, addr) for i, addr, _ in asks] == [(0, ("127.0.0.1", 47000)), (1, ("127.0.0.1", 47001))]
    assert [decode(d, KEYS).values for _, _, d in asks] == [(0.0, 2.0), (0.0, 1.0)]  # each node's record
    # node 0 transmitted 5 before it read the request; then resends 3, 4 (and 4 again), answers
    got = [core.receive(d, now=3.0) for d in (later[2], later[0], later[1], later[1])]
    assert got == ["applied", "applied", "applied", "resent"]
    assert core.snapshot()["gaps"] == [0, 0] and core.snapshot()["recovered"] == [2, 0]
    assert core.receive(pkt(0, 6, 3.0, 4.5, answer=True), now=3.0) == "answer"
    assert core.receive(pkt(1, 2, 0.0, 2.0, answer=True), now=3.0) == "answer"
    assert not core.holding
    assert core.snapshot()["transmissions"] == whole.snapshot()["transmissions"] == [4, 0]
    core.advance(3.5)
    assert core.ybar.tolist() == whole.ybar.tolist() == [4.5, 2.0]
    assert np.max(np.abs(core.xhat() - whole.xhat())) <= 1e-12 * np.max(np.abs(whole.xhat()))
    # after the resync, a copy of a resend is a replay again
    assert core.receive(later[0], now=3.5) == "replayed"


def test_a_resync_request_forged_replayed_or_flooded_is_refused():
    """A sensor answers only an authentic, fresh request of its session, at most once per
    RESYNC_MIN_GAP: which requests were refused, by reason, counted. An answer resends what
    the node sent above the request's record, as sent, and then says what it holds; it
    never changes the rule's state."""
    inbox, sent = deque(), []
    rule = SampledRule(robot_arm().nodes[0].rule.sensor_spec(), 0.01)
    node = SensorNode(
        0, KEYS[0], rule, sent.append, session=SESSION, listen=lambda: inbox.popleft() if inbox else None
    )
    twin_rule = SampledRule(robot_arm().nodes[0].rule.sensor_spec(), 0.01)
    twin = SensorNode(0, KEYS[0], twin_rule, lambda d: None, session=SESSION)  # never asked

    def sample(t, y):
        twin.sample(t, y)
        return node.sample(t, y)

    def ask(t, *, key=KEYS[0], node_id=0, session=SESSION, resync=True, record=(0.0, 1.0)):
        p = Packet(node_id, 12345, t, record, session=session, resync=resync, start=not resync)
        return encode(p, key)

    sample(0.0, [1.0])  # the initial value, number 1
    t_sent = next(0.01 * k for k in range(1, 50) if sample(0.01 * k, [40.0]) is not None)
    assert len(sent) == 2 and node.transmissions == 1  # a transmission, number 2
    first = ask(1.0)
    inbox.extend(
        [
            ask(1.0, key=KEYS[1]),  # forged: not this node's key
            ask(1.0, node_id=1, key=KEYS[1]),  # another node's request (read with our key: forged)
            ask(1.0, resync=False),  # authentic, but a start packet, not a request
            ask(1.0, session=SESSION + 1),  # a request of another run
            ask(1.0, record=(0.0,)),  # authentic, but no record: malformed
            ask(1.0, record=(0.5, 1.0)),  # not an integer
            ask(1.0 + RESYNC_WINDOW + 0.01),  # just outside the window ahead
            ask(1.0 - RESYNC_WINDOW - 0.01),  # just outside the window behind
        ]
    )
    assert sample(1.0, [40.0]) is None and node.resyncs == 0
    inbox.extend([first, first])  # the same request twice: a copy
    assert sample(1.01, [40.0]) is None and node.resyncs == 1 and node.transmissions == 1
    assert node.resync_refused == {
        "forged": 3,
        "wrong_session": 1,
        "malformed": 2,
        "out_of_window": 2,
        "replayed": 1,
        "rate_limited": 0,
    }
    # above record 1: number 2 resent byte for byte, then the answer: the value sent at t_sent
    assert len(sent) == 4 and sent[2] == sent[1]
    answer = decode(sent[3], KEYS)
    assert answer.answer and answer.seq == 3 and (answer.t, answer.values) == (t_sent, (40.0,))
    assert rule.eta == twin_rule.eta  # the rule went on as at any sample: no jump of eta
    # a record of every packet sent: nothing to resend, only the answer
    inbox.append(ask(1.6, record=(0.0, 2.0)))
    sample(1.6, [40.0])
    assert len(sent) == 5 and decode(sent[4], KEYS).answer and node.resent == 1
    # a record beyond 2^32 is carried exactly
    assert record_of(resync_record(2**40 + 5)) == 2**40 + 5
    # a flood of fresh requests: one answer per RESYNC_MIN_GAP, the rest counted
    answered = 0
    for k in range(1, 201):  # 2 s of samples, 8 requests each (MAX_READS), each newer
        tk = 1.6 + 0.01 * k
        inbox.extend(ask(tk - 0.001 * j) for j in range(8, 0, -1))
        before = node.resyncs
        sample(tk, [40.0])
        answered += node.resyncs - before
    assert answered == round(2.0 / RESYNC_MIN_GAP) == 4 and node.resyncs == 6  # at 2.1, 2.6, 3.1, 3.6
    assert node.resync_refused["rate_limited"] == 200 * 8 - 4 and node.transmissions == 1
    # the window's boundary is inside
    inbox.extend([ask(4.2 + RESYNC_WINDOW)])
    sample(4.2, [40.0])
    assert node.resyncs == 7
    assert (rule.eta, node.transmissions, node.sent) == (twin_rule.eta, twin.transmissions, twin.sent)


def test_a_udp_sender_polls_without_waiting_after_a_handshake_read():
    # the handshake reads with a timeout (recv), then every sample polls for resync
    # requests (recv_nowait): in timeout mode the poll waited out the timeout and raised
    # TimeoutError, and every sensor of the documented recipe ended "etobs: error: timed out"
    import socket

    from etobs.runtime.sensor import UdpSender

    peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    peer.bind(("127.0.0.1", 0))
    try:
        sender = UdpSender("127.0.0.1", peer.getsockname()[1])
        try:
            assert sender.recv(0.01) is None
            assert sender.recv_nowait() is None  # raised TimeoutError before
            sender(b"x")
            data, addr = peer.recvfrom(16)
            assert data == b"x"
            peer.sendto(b"back", addr)
            assert sender.recv(5.0) == b"back"
            peer.sendto(b"again", addr)
            for _ in range(1000):  # bounded: the datagram is on loopback already or soon
                got = sender.recv_nowait()
                if got is not None:
                    break
            else:
                got = sender.recv(5.0)
            assert got == b"again"
        finally:
            sender.close()
    finally:
        peer.close()
