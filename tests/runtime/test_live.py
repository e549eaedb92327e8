"""Live runs on 127.0.0.1: the deployment matches its offline reference; faults and attacks are survived.

Every run is bounded in packets and ends when the senders are done and every datagram
has been judged (:func:`tests.runtime.loopback.live`), not after some wall time; the
observer holds packets back for the whole run, so a loaded machine delays the run but
does not change its result.
"""

import itertools
import json
import math
import random
import struct

import numpy as np
import pytest

from etobs.errors import InputError
from etobs.examples import robot_arm
from etobs.runtime.marks import HighWaterMarks
from etobs.runtime.packet import MAX_BYTES, Packet, decode, derive_key, encode
from etobs.runtime.server import read_trace
from etobs.runtime.service import VERDICTS, ObserverCore
from tests.estimation import linear
from tests.runtime.loopback import KEYS, final_gap, live, reference

X0 = [3.0, 2.0, 3.0, -2.0]


def test_robot_arm_live_matches_the_offline_reference(tmp_path):
    """The paper's arm sampled at 2 ms for 3 s, run 3x faster than real time: the same
    transmissions per node, and the final estimate within 1e-6 (relative) of the reference."""
    pb = robot_arm()
    t, y, ref = reference(pb, X0, 3.0, 0.002)
    snap, _, extra = live(pb, y, 0.002, 3.0, time_scale=3.0, trace=tmp_path / "trace.jsonl")
    assert tuple(snap["transmissions"]) == ref.transmissions
    assert tuple(n.transmissions for n in extra["nodes"]) == ref.transmissions
    assert snap["counts"]["applied"] == sum(ref.transmissions) and snap["counts"]["initial"] == 2
    assert sum(snap["counts"].values()) == len(extra["sent"])  # every datagram judged, all used
    assert snap["late"] == 0 and snap["gaps"] == [0, 0] and snap["status"] == "ok"
    assert final_gap(snap, ref) < 1e-6 * np.max(np.abs(ref.xhat[-1]))
    status, body = extra["estimate"]
    assert status == "HTTP/1.0 200 OK" and json.loads(body)["transmissions"] == snap["transmissions"]
    tr = read_trace(tmp_path / "trace.jsonl")
    # one line per 10 ms of service time on the grid 0, 0.01, ..., 3.0, however loaded the machine
    assert len(tr["t"]) == 301 and tr["t"][-1] == 3.0 and tr["xhat"].shape == (301, 4)
    np.testing.assert_allclose(tr["t"][:-1], 0.01 * np.arange(300), rtol=0, atol=1e-12)
    # the trace follows the reference along the way, not only at the end
    k = np.searchsorted(t, tr["t"][150])
    assert np.max(np.abs(tr["xhat"][150] - ref.xhat[k])) < 0.05 * np.max(np.abs(ref.xhat[k])) + 0.1


def _hostile(epoch_of, n):
    """A client on the network, and a node that went wrong (its key, wrong contents):
    ``n`` datagrams of each kind, every one with the verdict it must get."""

    def attack(port, sent, send):
        rng = random.Random(0)
        key, epoch = KEYS[0], epoch_of(sent[0])
        wrong = derive_key(b"not the secret", 0)
        for k in range(n):
            send(encode(Packet(0, 10**9 + k, 0.1, (99.0,), session=epoch), wrong))  # forged
            send(sent[0][: rng.randrange(1, len(sent[0]))])  # malformed: truncated
            send(rng.randbytes(rng.randrange(0, 80)))  # malformed: noise
            send(bytes(MAX_BYTES + 1 + k))  # malformed: oversized
            send(sent[0])  # replayed: the initial packet, again
            # authentic, but wrong: what a broken or misconfigured node would send
            send(encode(Packet(0, 2**64 - 1 - k, 0.1, (1.0,), session=epoch), key))  # seq_jump
            bad = (math.nan, math.inf, -math.inf, 1.7e308)[k % 4]
            send(encode(Packet(0, 10**6 + k, 0.1, (bad,), session=epoch), key))  # out_of_range
            send(encode(Packet(0, 10**6 + k, 0.1, (1.0,), session=epoch + 1.0), key))  # wrong_session
            send(encode(Packet(0, 10**6 + k, 1e6, (1.0,), session=epoch), key))  # future
            send(encode(Packet(0, 10**6 + k, 0.1, (1.0, 2.0), session=epoch), key))  # wrong_size

    return attack


def hostile_verdicts(n, applied):
    """The service's counts after :func:`_hostile`'s ``n`` datagrams of each kind around one node."""
    bad = {"forged": n, "malformed": 3 * n, "replayed": n, "seq_jump": n, "out_of_range": n}
    bad |= {"wrong_session": n, "future": n, "wrong_size": n}
    return dict.fromkeys(VERDICTS, 0) | bad | {"initial": 1, "applied": applied}


def test_hostile_client_is_rejected_and_the_estimate_is_unharmed(tmp_path):
    """Ten kinds of bad datagram, 30 of each, during a live run: each gets its verdict,
    the genuine packets are all applied, and the estimate is the reference's. Then the
    service restarts, on the same high-water marks, and every captured packet is replayed:
    none is accepted; a new run (another epoch) refuses them as another session's."""
    pb = linear.factory()
    _, y, ref = reference(pb, [1.0, -0.5], 4.0, 0.005)
    n = 30
    marks = HighWaterMarks(tmp_path / "service.state")
    snap, srv, extra = live(
        pb, y, 0.005, 4.0, time_scale=4.0, hostile=_hostile(lambda d: decode(d, KEYS).session, n), marks=marks
    )
    c = snap["counts"]
    assert c == hostile_verdicts(n, sum(ref.transmissions)) and set(c) == set(VERDICTS)
    assert tuple(snap["transmissions"]) == ref.transmissions and snap["gaps"] == [0]
    assert final_gap(snap, ref) < 1e-6
    json.dumps(snap, allow_nan=False)
    # the service restarts with its marks: every genuine packet of the run is refused
    genuine = extra["sent"]
    again = ObserverCore(pb, KEYS, session=srv.epoch, marks=marks)
    assert {again.receive(d) for d in genuine} == {"stale"}
    assert again.counts["stale"] == len(genuine) == 1 + sum(ref.transmissions)
    # a new run has another epoch: the old run's packets are another session's
    fresh = ObserverCore(pb, KEYS, session=srv.epoch + 10.0, marks=marks)
    assert {fresh.receive(d) for d in genuine} == {"wrong_session"}
    # what the marks protect: without them the same session would take every packet again
    forgetful = ObserverCore(pb, KEYS, session=srv.epoch)
    assert {forgetful.receive(d) for d in genuine} == {"initial", "applied"}


def test_loss_duplication_and_reordering_are_survived():
    """A relay drops 20 %, duplicates 25 % and delays by up to 10 ms of wall time (so
    reorders) the first 150 datagrams of a node sending every 10 ms of plant time
    (2.5 ms of wall time), then passes the rest: duplicates are counted as replays,
    overtaken packets as stale, every missing sequence number as a gap, and the estimate
    is back on the reference by the end."""
    from etobs import PeriodicRule

    pb = linear.problem(PeriodicRule(0.01))
    _, y, ref = reference(pb, [1.0, -0.5], 6.0, 0.005)
    link = {"loss": 0.2, "duplicate": 0.25, "max_delay": 0.01, "seed": 3, "until": 150}
    snap, _, extra = live(pb, y, 0.005, 6.0, time_scale=4.0, link=link)
    c, st = snap["counts"], extra["link"]
    assert st["dropped"] > 10 and st["duplicated"] > 10 and st["delayed"] > 100
    assert c["forged"] == c["malformed"] == c["future"] == 0
    assert c["replayed"] >= 1 and c["stale"] >= 1
    assert (
        c["applied"] + c["initial"] + c["replayed"] + c["stale"]
        == st["in"] - st["dropped"] + st["duplicated"]
    )
    # every sequence number from the first accepted to the last is applied or counted
    # missing (dropped or overtaken); the numbers before the first accepted are not known
    assert c["initial"] + c["applied"] + snap["gaps"][0] <= snap["last_seq"][0]
    assert snap["gaps"][0] >= st["dropped"] - 2  # but a drop before the first or after the last
    # the node sent what the reference sent; the observer received less
    assert tuple(n.transmissions for n in extra["nodes"]) == ref.transmissions
    assert final_gap(snap, ref) < 1e-3


def test_the_token_guards_the_estimate_and_idle_clients_do_not_stop_a_clean_close(caplog):
    """GET /estimate with a token forced on (on 127.0.0.1): refused without it or with a
    wrong one, answered with it; clients left idle at the end are dropped without a
    traceback (131 lines of asyncio tracebacks before)."""
    import asyncio
    import logging

    from etobs.errors import InputError
    from etobs.runtime.server import ObserverServer
    from tests.runtime.loopback import _get

    token = b"t" * 32

    async def main():
        srv = ObserverServer(ObserverCore(linear.factory(), KEYS), token=token)
        _, web = await srv.start(http_port=0)
        answers = [await _get(web), await _get(web, b"x" * 32), await _get(web, token)]
        idle = [await asyncio.open_connection("127.0.0.1", web) for _ in range(5)]
        await asyncio.sleep(0)
        await srv.close()
        for _, writer in idle:
            writer.close()
        return answers

    with caplog.at_level(logging.DEBUG, logger="asyncio"):
        (no, wrong, yes) = asyncio.run(main())
    assert no[0] == wrong[0] == "HTTP/1.0 401 Unauthorized"
    assert yes[0] == "HTTP/1.0 200 OK" and json.loads(yes[1])["counts"]["applied"] == 0
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]

    async def exposed():
        srv = ObserverServer(ObserverCore(linear.factory(), KEYS))
        await srv.start(http_port=0, http_host="0.0.0.0")  # refused before anything is bound

    with pytest.raises(
        InputError, match=r"GET /estimate on '0.0.0.0', not a loopback address, needs a token"
    ):
        asyncio.run(exposed())


def test_a_restarted_sensor_resumes_above_its_old_sequence_numbers(tmp_path):
    from etobs.runtime.sampled_rule import SampledRule
    from etobs.runtime.sensor import SensorNode, SequenceStore

    pb = linear.factory()
    core = ObserverCore(pb, KEYS)
    spec = {"kind": "static", "gamma": ["linear", 1.0], "eps": 0.01}
    out = []
    node = SensorNode(
        0, KEYS[0], SampledRule(spec, 0.01), out.append, SequenceStore(tmp_path / "n0.seq", block=8)
    )
    for k in range(50):
        node.sample(0.01 * k, [np.sin(0.01 * k)])
    before = len(out)
    # the process dies (no clean shutdown) and starts again with the same state file
    node = SensorNode(
        0, KEYS[0], SampledRule(spec, 0.01), out.append, SequenceStore(tmp_path / "n0.seq", block=8)
    )
    for k in range(50, 100):
        node.sample(0.01 * k, [np.sin(0.01 * k)])
    verdicts = [core.receive(d) for d in out]
    assert before > 5 and len(out) > before
    assert "stale" not in verdicts and "replayed" not in verdicts
    assert core.snapshot()["gaps"] == [0]  # the skipped block comes with an initial packet
    seqs = [struct.unpack(">Q", d[8:16])[0] for d in out]
    assert all(b > a for a, b in itertools.pairwise(seqs))
    with pytest.raises(ValueError, match=r"sequence file .* is damaged"):
        (tmp_path / "bad.seq").write_text("garbage")
        SequenceStore(tmp_path / "bad.seq")
    with pytest.raises(ValueError, match=r"sequence file .* is damaged"):
        (tmp_path / "big.seq").write_text(str(2**64))
        SequenceStore(tmp_path / "big.seq")
    # non-UTF-8 bytes were a UnicodeDecodeError traceback, and a file without end was read whole
    (tmp_path / "binary.seq").write_bytes(b"\xff\xfe12")
    with pytest.raises(InputError, match=r"sequence file .*binary.seq is damaged: '.*12'"):
        SequenceStore(tmp_path / "binary.seq")
    with pytest.raises(InputError, match=r"sequence file '/dev/zero' is a character device, not a regular"):
        SequenceStore("/dev/zero")


def test_a_genuine_packet_lost_in_a_flood_is_counted_as_a_gap():
    """5,000 junk datagrams sent as fast as the machine allows, 100 genuine packets among
    them, one of which never sent (lost): every genuine sequence number is applied or
    counted missing, so a loss (in the flood or on the way) shows; nothing else changes."""
    import asyncio
    import socket
    import threading

    from etobs.runtime.server import ObserverServer

    async def main():
        core = ObserverCore(linear.factory(), KEYS, session=5.0)
        srv = ObserverServer(core, epoch=5.0)
        port, _ = await srv.start()

        def packet(seq):
            return encode(Packet(0, seq, 0.001 * seq, (1.0,), seq == 1, session=5.0), KEYS[0])

        genuine = [packet(s) for s in range(2, 101)]
        lost = genuine.pop(49)  # seq 51 never arrives
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))

        def flood():
            for k in range(5000):
                sock.sendto(b"junk" * (k % 16 + 1), ("127.0.0.1", port))
                if k % 50 == 0 and genuine:
                    sock.sendto(genuine.pop(0), ("127.0.0.1", port))

        try:
            sock.sendto(packet(1), ("127.0.0.1", port))  # the first and last arrive for sure:
            await srv._drain()  # the numbers before and after them are not the subject
            th = threading.Thread(target=flood)
            th.start()
            while th.is_alive():  # the service reads while the flood goes on
                await asyncio.sleep(0.001)
            th.join()
            await srv._drain()
            sock.sendto(packet(101), ("127.0.0.1", port))
            await srv._drain()
        finally:
            sock.close()
            await srv.close()
        return core, lost

    core, lost = asyncio.run(main())
    snap = core.snapshot()
    c = snap["counts"]
    assert decode(lost, KEYS).seq == 51 and snap["last_seq"] == [101]
    assert c["initial"] == 1 and c["applied"] + snap["gaps"][0] == 100  # seq 2..101
    assert snap["gaps"][0] >= 1 and c["malformed"] + c["initial"] + c["applied"] <= 5000 + 100
    assert set(c) == set(VERDICTS) and c["forged"] == c["stale"] == c["replayed"] == 0
