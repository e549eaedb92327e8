"""Packets: round trip, authentication, every malformed shape rejected by kind; the core's
verdicts, bounds, gap counter and high-water marks, on generated packets too."""

import json
import math
import struct

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from etobs.errors import InputError
from etobs.runtime.marks import HighWaterMarks
from etobs.runtime.packet import (
    HEADER,
    MAX_BYTES,
    TAG_BYTES,
    Packet,
    PacketError,
    decode,
    derive_key,
    encode,
    node_keys,
)

KEYS = node_keys(b"deployment secret", [0, 1, 2])


@given(
    node=st.integers(0, 2),
    seq=st.integers(0, 2**64 - 1),
    t=st.floats(allow_nan=False, allow_infinity=False),
    values=st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=1, max_size=64),
    initial=st.booleans(),
    session=st.floats(allow_nan=False),
)
def test_round_trip(node, seq, t, values, initial, session):
    p = Packet(node, seq, t, tuple(values), initial, session)
    assert decode(encode(p, KEYS[node]), KEYS) == p


def test_layout_is_the_documented_one():
    data = encode(Packet(1, 7, 0.5, (1.0, -2.0), session=1.5e9), KEYS[1])
    assert len(data) == 32 + 16 + TAG_BYTES and HEADER.size == 32
    assert data[:4] == b"ET\x02\x00" and struct.unpack(">HHQdd", data[4:32]) == (1, 2, 7, 0.5, 1.5e9)


def test_forged_packets_are_rejected():
    good = encode(Packet(0, 1, 0.0, (1.0,)), KEYS[0])
    with pytest.raises(PacketError, match=r"forged packet: authentication failed for node 0") as e:
        decode(encode(Packet(0, 1, 0.0, (1.0,)), derive_key(b"wrong", 0)), KEYS)
    assert e.value.kind == "forged"
    flipped = bytearray(good)
    flipped[30] ^= 1  # a changed value
    with pytest.raises(PacketError, match="forged"):
        decode(bytes(flipped), KEYS)
    renamed = bytearray(good)
    renamed[5] = 1  # claims to be node 1
    with pytest.raises(PacketError, match="forged"):
        decode(bytes(renamed), KEYS)
    with pytest.raises(PacketError, match=r"forged packet: authentication failed for node 9"):
        decode(encode(Packet(9, 1, 0.0, (1.0,)), derive_key(b"deployment secret", 9)), KEYS)


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"", r"0 bytes is shorter than the smallest packet"),
        (b"XX" + bytes(54), r"magic b'XX' version 0"),
        (b"ET\x02" + bytes(MAX_BYTES), r"longer than the largest packet"),
        (encode(Packet(0, 1, 0.0, (1.0, 2.0)), KEYS[0])[:-1], r"do not fit"),
        (encode(Packet(0, 1, 0.0, (1.0,)), KEYS[0]) + b"\0", r"do not fit"),
    ],
)
def test_malformed_packets_are_rejected(data, message):
    with pytest.raises(PacketError, match=rf"malformed packet: .*{message}") as e:
        decode(data, KEYS)
    assert e.value.kind == "malformed"


def test_version_1_packets_are_refused():
    """A version 1 packet (no session) names the version expected."""
    v1 = b"ET\x01\x00" + struct.pack(">HHQd", 0, 1, 1, 0.0) + struct.pack(">d", 1.0) + bytes(TAG_BYTES)
    with pytest.raises(
        PacketError, match=r"malformed packet: magic b'ET' version 1; expected b'ET' version 2"
    ):
        decode(v1, KEYS)


def test_encode_refuses_what_the_format_cannot_carry():
    with pytest.raises(ValueError, match=r"a packet carries 1..64 values; got 0"):
        encode(Packet(0, 1, 0.0, ()), KEYS[0])
    with pytest.raises(ValueError, match=r"node id must fit in 16 bits"):
        encode(Packet(2**16, 1, 0.0, (1.0,)), KEYS[0])


def test_observer_core_queues_packets_in_time_order_and_refuses_the_future():
    from etobs.examples import robot_arm
    from etobs.runtime.service import ObserverCore

    core = ObserverCore(robot_arm(), KEYS)
    assert core.session == 0.0  # the packets below carry the default session too
    for i in range(2):
        assert core.receive(encode(Packet(i, 1, 0.0, (0.0,), initial=True), KEYS[i]), now=0.0) == "initial"
    core.advance(0.5)
    # node 0's packet of t = 1.0 arrives before node 1's of t = 0.99: both wait, and are
    # applied in time order when the observer gets there (none late)
    assert core.receive(encode(Packet(0, 2, 1.0, (3.0,)), KEYS[0]), now=1.0) == "applied"
    assert core.receive(encode(Packet(1, 2, 0.99, (2.0,)), KEYS[1]), now=1.0) == "applied"
    core.advance(0.995)
    assert core.ybar.tolist() == [0.0, 2.0]
    core.advance(1.0)
    assert core.ybar.tolist() == [3.0, 2.0] and core.late == 0
    # an older sequence number of the same node is stale; a late packet is applied at once
    assert core.receive(encode(Packet(0, 1, 0.2, (9.0,)), KEYS[0]), now=1.0) in ("replayed", "stale")
    assert core.receive(encode(Packet(1, 3, 0.9, (5.0,)), KEYS[1]), now=1.0) == "applied"
    core.advance(1.0)  # applied at the next advance, after its mark is on record
    assert core.ybar[1] == 5.0 and core.late == 1
    # an authentic packet stamped far ahead is refused at once (no long integration)
    assert core.receive(encode(Packet(0, 4, 1e12, (4.0,)), KEYS[0]), now=1.0) == "future"
    assert core.t == 1.0 and core.counts["future"] == 1


def _core(**kw):
    from etobs.examples import robot_arm
    from etobs.runtime.service import ObserverCore

    core = ObserverCore(robot_arm(), KEYS, session=7.0, **kw)
    for i in range(2):
        assert core.receive(_pkt(i, 1, 0.0, 0.0, initial=True), now=0.0) == "initial"
    return core


def _pkt(node, seq, t, value, *, initial=False, session=7.0, key=None):
    return encode(Packet(node, seq, t, (value,), initial, session), key or KEYS[node])


def test_an_authentic_huge_sequence_number_does_not_lock_the_node_out():
    """seq 2^64 - 1 from the node's own key was accepted and every later packet was stale;
    then a jump of exactly 2^32 still was (the bound was on the wrong side)."""
    from etobs.runtime.service import MAX_SEQ_JUMP

    core = _core()
    assert core.receive(_pkt(0, 2**64 - 1, 0.1, 1.0), now=0.1) == "seq_jump"
    assert core.receive(_pkt(0, 1 + MAX_SEQ_JUMP, 0.1, 1.0), now=0.1) == "seq_jump"  # the bound itself
    assert core.receive(_pkt(0, MAX_SEQ_JUMP, 0.1, 1.0), now=0.1) == "applied"  # just below it
    assert core.receive(_pkt(1, 2, 0.1, 1.0), now=0.1) == "applied"
    assert core.snapshot()["last_seq"] == [MAX_SEQ_JUMP, 2]


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, 1.7e308, -1.0000001e12])
def test_non_finite_or_huge_values_are_refused_and_the_estimate_stays_valid_json(value):
    """1.7e308 from an authentic node turned the estimate into NaN for good, and the
    trace and /estimate then wrote invalid JSON."""
    core = _core()
    assert core.receive(_pkt(0, 2, 0.1, value), now=0.1) == "out_of_range"
    assert core.receive(_pkt(0, 3, math.nan, 1.0), now=0.1) == "out_of_range"  # a sample time too
    core.advance(0.5)
    snap = core.snapshot()
    assert snap["status"] == "ok" and all(math.isfinite(v) for v in snap["xhat"])
    assert snap["counts"]["out_of_range"] == 2 and snap["gaps"] == [0, 0]
    json.dumps(snap, allow_nan=False)
    assert core.receive(_pkt(0, 4, 0.6, 2.0), now=0.6) == "applied"
    assert core.snapshot()["gaps"] == [2, 0]  # the two refused samples are missing


def test_an_observer_that_stops_being_finite_says_so_and_keeps_its_last_state():
    core = _core(max_value=1.7976931348623157e308)  # the bound turned off
    assert core.receive(_pkt(0, 2, 0.1, 1.7e308), now=0.1) == "applied"
    core.advance(2.0)
    snap = core.snapshot()
    assert snap["status"] == "nonfinite" and snap["t"] == 2.0
    assert all(v is None or math.isfinite(v) for v in snap["xhat"])
    json.dumps(snap, allow_nan=False)


def test_the_gap_counter_counts_missing_sequence_numbers_but_not_a_restart():
    core = _core()
    for seq in (2, 3, 7, 8):  # 4, 5, 6 lost
        assert core.receive(_pkt(0, seq, 0.01 * seq, 1.0), now=1.0) == "applied"
    assert core.receive(_pkt(0, 5000, 0.2, 1.0, initial=True), now=1.0) == "initial"  # a restart
    assert core.receive(_pkt(0, 5002, 0.3, 1.0), now=1.0) == "applied"
    assert core.snapshot()["gaps"] == [3 + 1, 0]


def test_high_water_marks_survive_a_restart_and_are_written_before_use(tmp_path):
    """Captured packets replayed into a restarted service were all accepted."""
    marks = HighWaterMarks(tmp_path / "service.state")
    core = _core(marks=marks)
    packets = [_pkt(0, seq, 0.01 * seq, 1.0) for seq in range(2, 10)]
    assert {core.receive(d, now=1.0) for d in packets} == {"applied"}
    # on record as soon as accepted, before any packet acts (a service killed before its next
    # advance lost the accepted packets, and with them the estimate); still queued, none applied
    saved = json.loads((tmp_path / "service.state").read_text())
    assert len(saved["observer"]["queue"]) == 2 + 8 and np.all(np.isnan(core.ybar))  # none applied
    core.advance(0.05)
    assert saved["nodes"]["0"]["seq"] == 9 and saved["nodes"]["1"]["seq"] == 1
    from etobs.examples import robot_arm
    from etobs.runtime.service import ObserverCore

    restarted = ObserverCore(robot_arm(), KEYS, session=7.0, marks=marks)
    again = [restarted.receive(d, now=1.0) for d in [_pkt(0, 1, 0.0, 0.0, initial=True), *packets]]
    assert set(again) == {"stale"}
    assert restarted.receive(_pkt(0, 10, 0.2, 1.0), now=1.0) == "applied"
    # another secret: the marks of the old keys mean nothing for the new ones

    other = ObserverCore(robot_arm(), node_keys(b"new secret", [0, 1]), marks=marks)
    assert other.snapshot()["last_seq"] == [0, 0]
    (tmp_path / "service.state").write_text('{"format": "etobs-high-water-marks", "version": 1, "nodes": 3}')
    with pytest.raises(InputError, match=r"high-water marks .*service.state' are damaged"):
        _core(marks=marks)


def test_a_packet_of_another_session_is_refused():
    core = _core()
    assert core.receive(_pkt(0, 2, 0.1, 1.0, session=8.0), now=0.1) == "wrong_session"
    assert core.receive(_pkt(0, 2, 0.1, 1.0), now=0.1) == "applied"


_FLOATS = st.floats(allow_nan=True, allow_infinity=True)


@given(data=st.binary(max_size=2 * MAX_BYTES))
def test_random_bytes_never_raise(data):
    core = _core()
    verdict = core.receive(data, now=0.5)
    assert verdict in ("malformed", "forged")
    core.advance(1.0)
    json.dumps(core.snapshot(), allow_nan=False)


@given(
    packets=st.lists(
        st.tuples(
            st.integers(0, 3),  # node (2 and 3 unknown)
            st.one_of(st.integers(0, 40), st.integers(0, 2**64 - 1)),  # seq
            st.one_of(st.floats(0.0, 2.0), _FLOATS),  # t
            st.lists(st.one_of(st.floats(-1e3, 1e3), _FLOATS), min_size=1, max_size=3),  # values
            st.booleans(),  # initial
            st.sampled_from([7.0, 7.5]),  # session: this run's or another's
            st.booleans(),  # the node's key or a wrong one
            st.integers(0, 3),  # damage: none, truncate, flip a bit, append
        ),
        max_size=25,
    ),
    now=st.floats(0.0, 2.0),
)
def test_generated_packets_get_a_verdict_and_the_state_stays_finite(packets, now):
    """Whatever arrives, the core returns one of its verdicts, never raises, accepts only
    authentic packets of this session with finite values in range, and its state and
    snapshot stay finite (strict JSON)."""
    from etobs.runtime.service import VERDICTS

    core = _core()
    for node, seq, t, values, initial, session, right_key, damage in packets:
        key = KEYS.get(node, derive_key(b"deployment secret", node)) if right_key else derive_key(b"x", node)
        data = encode(Packet(node, seq, t, tuple(values), initial, session), key)
        if damage == 1:
            data = data[: len(data) // 2]
        elif damage == 2:
            data = bytes([data[0] ^ 1]) + data[1:] if seq % 2 else data[:-1] + bytes([data[-1] ^ 1])
        elif damage == 3:
            data += b"\0"
        verdict = core.receive(data, now=now)
        assert verdict in VERDICTS
        if verdict in ("applied", "initial"):
            assert right_key and damage == 0 and session == 7.0 and node in (0, 1) and len(values) == 1
            assert all(math.isfinite(v) and abs(v) <= 1e12 for v in values) and math.isfinite(t)
        core.advance(now)
    assert sum(core.counts.values()) == len(packets) + 2
    assert np.all(np.isfinite(core.z)) and core.status == "ok"
    json.dumps(core.snapshot(), allow_nan=False)


def test_a_state_file_others_may_change_is_refused_and_the_service_writes_it_600(tmp_path):
    """Whoever may write the high-water marks can lower them and let captured packets in again."""
    import os

    path = tmp_path / "service.state"
    marks = HighWaterMarks(path)
    core = _core(marks=marks)
    assert core.receive(_pkt(0, 2, 0.01, 1.0), now=1.0) == "applied"
    core.advance(0.05)
    assert oct(path.stat().st_mode & 0o777) == "0o600"  # it was created with the umask's mode (0644)
    from etobs.examples import robot_arm
    from etobs.runtime.service import ObserverCore

    os.chmod(path, 0o620)
    with pytest.raises(
        InputError, match=r"high-water marks '.*service.state' have mode 0620: .*run `chmod 600"
    ):
        ObserverCore(robot_arm(), KEYS, session=7.0, marks=marks)
    os.chmod(path, 0o644)  # readable is fine: the marks are not secret
    assert ObserverCore(robot_arm(), KEYS, session=7.0, marks=marks).snapshot()["last_seq"][0] == 2


def test_the_server_token_must_be_bytes():
    from etobs.runtime.server import ObserverServer

    # a str token passed the length check, then hmac.compare_digest raised TypeError inside every request
    with pytest.raises(InputError, match=r"`token` must be bytes; got str"):
        ObserverServer(_core(), token="a string token of enough length")


@pytest.mark.parametrize(("dt", "scale"), [(1e-9, 1.0), (1e-3, 1e3)])
def test_an_observer_step_the_service_cannot_keep_up_with_is_refused(dt, scale):
    """runtime.dt = 1e-9 took eleven minutes of wall time for every 10-ms tick (the loop was blocked)."""
    from etobs.examples import robot_arm
    from etobs.runtime.server import ObserverServer
    from etobs.runtime.service import ObserverCore

    core = ObserverCore(robot_arm(), KEYS, dt=dt)
    with pytest.raises(
        InputError, match=r"time_scale / dt = .* steps per wall second; at most 1e\+05: use a larger"
    ):
        ObserverServer(core, time_scale=scale)


def test_a_huge_message_from_another_thread_is_cut_before_it_waits_for_the_loop():
    """An MQTT message may be 256 MiB; each waited whole in the event loop's queue."""
    import asyncio

    from etobs.runtime.server import ObserverServer

    seen = []

    async def main():
        srv = ObserverServer(_core())
        await srv.start("127.0.0.1", 0)
        srv.receive = seen.append  # what waits in the loop's queue reaches this
        await asyncio.to_thread(srv.feed, b"E" * 10**7)
        await asyncio.sleep(0)
        await srv.close()
        return srv.core.receive(seen[0])

    assert asyncio.run(main()) == "malformed"
    assert [len(d) for d in seen] == [MAX_BYTES + 1]


def test_a_service_started_long_after_its_epoch_writes_a_bounded_trace(tmp_path, monkeypatch):
    """serve --epoch 1 with a long duration wrote every 10-ms line since 1970 before anything else (hung)."""
    import asyncio
    import time

    from etobs.runtime import server
    from etobs.runtime.server import ObserverServer

    monkeypatch.setattr(server, "MAX_BACKFILL_LINES", 10)
    trace = tmp_path / "trace.jsonl"

    async def main():
        from etobs.examples import robot_arm
        from etobs.runtime.service import ObserverCore

        # no packets: the observer waits (a ready one would integrate the 1000 s)
        core = ObserverCore(robot_arm(), KEYS)
        srv = ObserverServer(core, tick=1.0, time_scale=10.0, hold_back=0.0, trace=trace)
        srv.epoch = time.time() - 100.0  # service time 1000 s, 1000 lines behind
        await srv.start("127.0.0.1", 0)
        try:
            return await srv.run_until(srv.now() + 1.0)  # a tenth of a second of wall time
        finally:
            await srv.close()

    snap = asyncio.run(main())
    t = [json.loads(line)["t"] for line in trace.read_text().splitlines()]
    assert 12 <= len(t) <= 14 and 985.0 <= t[0] <= 991.0 and t[-1] == snap["t"]
