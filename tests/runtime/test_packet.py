"""Packets: round trip, authentication, every malformed shape rejected by kind."""

import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from etobs.runtime.packet import HEADER, TAG_BYTES, Packet, PacketError, decode, derive_key, encode, node_keys

KEYS = node_keys(b"deployment secret", [0, 1, 2])


@given(
    node=st.integers(0, 2),
    seq=st.integers(0, 2**64 - 1),
    t=st.floats(allow_nan=False, allow_infinity=False),
    values=st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=1, max_size=64),
    initial=st.booleans(),
)
def test_round_trip(node, seq, t, values, initial):
    p = Packet(node, seq, t, tuple(values), initial)
    assert decode(encode(p, KEYS[node]), KEYS) == p


def test_layout_is_the_documented_one():
    data = encode(Packet(1, 7, 0.5, (1.0, -2.0)), KEYS[1])
    assert len(data) == 24 + 16 + TAG_BYTES and HEADER.size == 24
    assert data[:4] == b"ET\x01\x00" and struct.unpack(">HHQd", data[4:24]) == (1, 2, 7, 0.5)


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
        (b"XX" + bytes(46), r"magic b'XX' version 0"),
        (encode(Packet(0, 1, 0.0, (1.0, 2.0)), KEYS[0])[:-1], r"do not fit"),
        (encode(Packet(0, 1, 0.0, (1.0,)), KEYS[0]) + b"\0", r"do not fit"),
    ],
)
def test_malformed_packets_are_rejected(data, message):
    with pytest.raises(PacketError, match=rf"malformed packet: .*{message}") as e:
        decode(data, KEYS)
    assert e.value.kind == "malformed"


def test_non_finite_values_are_malformed_even_when_authentic():
    data = encode(Packet(0, 1, 0.0, (float("nan"),)), KEYS[0])
    with pytest.raises(PacketError, match=r"malformed packet: non-finite"):
        decode(data, KEYS)


def test_encode_refuses_what_the_format_cannot_carry():
    with pytest.raises(ValueError, match=r"a packet carries 1..64 values; got 0"):
        encode(Packet(0, 1, 0.0, ()), KEYS[0])
    with pytest.raises(ValueError, match=r"node id must fit in 16 bits"):
        encode(Packet(2**16, 1, 0.0, (1.0,)), KEYS[0])


def test_observer_core_queues_packets_in_time_order_and_refuses_the_future():
    from etobs.examples import robot_arm
    from etobs.runtime.service import ObserverCore

    core = ObserverCore(robot_arm(), KEYS)
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
    assert core.ybar[1] == 5.0 and core.late == 1
    # an authentic packet stamped far ahead is refused at once (no long integration)
    assert core.receive(encode(Packet(0, 4, 1e12, (4.0,)), KEYS[0]), now=1.0) == "future"
    assert core.t == 1.0 and core.counts["future"] == 1
