"""Live runs on 127.0.0.1: the deployment matches its offline reference; faults are survived.

Every run is bounded: a few seconds of wall time, a fixed number of packets.
"""

import itertools
import json
import os
import random
import socket
import struct
import time

import numpy as np
import pytest

from etobs.examples import robot_arm
from etobs.runtime.packet import Packet, derive_key, encode
from etobs.runtime.server import read_trace
from tests.estimation import linear
from tests.runtime.loopback import KEYS, final_gap, live, reference

X0 = [3.0, 2.0, 3.0, -2.0]


def test_robot_arm_live_matches_the_offline_reference(tmp_path):
    """The paper's arm sampled at 2 ms for 3 s, run 3x faster than real time: the same
    transmissions per node, and the final estimate within 1e-4 of the reference."""
    pb = robot_arm()
    t, y, ref = reference(pb, X0, 3.0, 0.002)
    snap, _, extra = live(pb, y, 0.002, 3.0, time_scale=3.0, trace=tmp_path / "trace.jsonl")
    assert tuple(snap["transmissions"]) == ref.transmissions
    assert tuple(n.transmissions for n in extra["nodes"]) == ref.transmissions
    assert snap["counts"]["applied"] == sum(ref.transmissions) and snap["counts"]["initial"] == 2
    assert sum(snap["counts"][k] for k in ("replayed", "stale", "malformed", "forged")) == 0
    assert snap["late"] == 0  # every packet applied at its sample time
    assert final_gap(snap, ref) < 1e-4 * np.max(np.abs(ref.xhat[-1]))
    status, body = extra["estimate"]
    assert status == "HTTP/1.0 200 OK" and json.loads(body)["transmissions"] == snap["transmissions"]
    tr = read_trace(tmp_path / "trace.jsonl")
    assert tr["t"][-1] == pytest.approx(3.0) and tr["xhat"].shape[1] == 4 and len(tr["t"]) > 100
    # the trace follows the reference along the way, not only at the end
    k = np.searchsorted(t, tr["t"][len(tr["t"]) // 2])
    assert (
        np.max(np.abs(tr["xhat"][len(tr["t"]) // 2] - ref.xhat[k])) < 0.05 * np.max(np.abs(ref.xhat[k])) + 0.1
    )


def _hostile(count):
    def attack(port, sent, epoch):
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        rng = random.Random(0)
        while time.time() < epoch + 0.3:  # wait for some genuine traffic to capture
            time.sleep(0.01)
        wrong = derive_key(b"not the secret", 0)
        for k in range(count):
            sock.sendto(encode(Packet(0, 10**9 + k, 0.1, (99.0,)), wrong), ("127.0.0.1", port))  # forged
            junk = os.urandom(rng.randrange(0, 80)) if k % 2 else sent[0][: rng.randrange(1, len(sent[0]))]
            sock.sendto(junk, ("127.0.0.1", port))  # malformed: random bytes or a truncated packet
            sock.sendto(sent[k % 2], ("127.0.0.1", port))  # replayed: the initial packets, again
            time.sleep(0.002)
        sock.close()

    return attack


def test_hostile_client_is_rejected_and_the_estimate_is_unharmed():
    pb = linear.factory()
    _, y, ref = reference(pb, [1.0, -0.5], 4.0, 0.005)
    n = 30
    snap, _, _ = live(pb, y, 0.005, 4.0, time_scale=4.0, hostile=_hostile(n))
    c = snap["counts"]
    assert c["forged"] == n and c["malformed"] == n and c["replayed"] == n
    assert c["applied"] == sum(ref.transmissions) and c["stale"] == 0
    assert tuple(snap["transmissions"]) == ref.transmissions
    assert final_gap(snap, ref) < 1e-6


def test_loss_duplication_and_reordering_are_survived():
    """A relay drops 20 %, duplicates 25 % and delays by up to 10 ms of wall time (so
    reorders) the first 150 datagrams of a node sending every 10 ms of plant time
    (2.5 ms of wall time), then passes the rest: duplicates are counted as replays,
    overtaken packets as stale, and the estimate is back on the reference by the end."""
    from etobs import PeriodicRule

    pb = linear.problem(PeriodicRule(0.01))
    _, y, ref = reference(pb, [1.0, -0.5], 6.0, 0.005)
    link = {"loss": 0.2, "duplicate": 0.25, "max_delay": 0.01, "seed": 3, "until": 150}
    # hold back 0.4 s of service time (0.1 s of wall time): on a loaded machine a packet
    # later than the hold-back is applied late (counted in "late") and the estimate
    # drifts from the reference, which is the service working, not this test's subject
    snap, _, extra = live(pb, y, 0.005, 6.0, time_scale=4.0, link=link, hold_back=0.4)
    c, st = snap["counts"], extra["link"]
    assert st["dropped"] > 10 and st["duplicated"] > 10 and st["delayed"] > 100
    assert c["forged"] == c["malformed"] == c["future"] == 0
    assert c["replayed"] >= 1 and c["stale"] >= 1
    assert (
        c["applied"] + c["initial"] + c["replayed"] + c["stale"]
        == st["in"] - st["dropped"] + st["duplicated"]
    )
    # the node sent what the reference sent; the observer received less
    assert tuple(n.transmissions for n in extra["nodes"]) == ref.transmissions
    assert final_gap(snap, ref) < 1e-3, f"late packets: {snap['late']}"


def test_a_restarted_sensor_resumes_above_its_old_sequence_numbers(tmp_path):
    from etobs.runtime.sampled_rule import SampledRule
    from etobs.runtime.sensor import SensorNode, SequenceStore
    from etobs.runtime.service import ObserverCore

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
    seqs = [struct.unpack(">Q", d[8:16])[0] for d in out]
    assert all(b > a for a, b in itertools.pairwise(seqs))
    with pytest.raises(ValueError, match=r"sequence file .* is damaged"):
        (tmp_path / "bad.seq").write_text("garbage")
        SequenceStore(tmp_path / "bad.seq")
