"""The packet format between sensor nodes and the observer (standard library only).

Version 2, big-endian, 32-byte header, then the values, then the tag::

    offset  size  field
    0       2     magic b"ET"
    2       1     version (2)
    3       1     flags (at most one set): bit 0 = initial value (sent at start-up, not a
                  transmission); bit 1 = hello (a sensor ready to start, asking for the
                  epoch); bit 2 = start (the service's answer to a hello: its sequence
                  number echoed, the session = the epoch, t = the first sample to take);
                  bit 3 = resync (the service asking the node to resend what it sent
                  after the service's record: a random nonce as the sequence number, the
                  session, t = the service's time, values = the record, the last
                  sequence number of the node it holds, as (seq >> 32, seq & 0xffffffff));
                  bit 4 = answer (the node's answer to a resync, sent after the packets it
                  resent: the value it holds as sent and the time it sent it, not a
                  transmission; see :mod:`etobs.runtime.sensor`)
    4       2     node id (uint16)
    6       2     number of values n (uint16, 1..64)
    8       8     sequence number (uint64, increasing per node, never reused)
    16      8     sample time (float64, seconds on the deployment's clock)
    24      8     session (float64: the deployment's epoch, the time.time() of time 0)
    32      8n    values (float64 each)
    32+8n   16    tag: HMAC-SHA256 over bytes 0..32+8n with the node's key, first 16 bytes

Version 1 had no session field: a packet of one run could be replayed into a later run
of the service (its sequence numbers were held in memory only). The session binds each
packet to the clock it was measured on, so the tag of a packet of another run does not
cover this run's session, and the observer refuses it (``wrong_session``).

The observer checks the tag in constant time (:func:`hmac.compare_digest`) with the key
of the node the header names, and rejects anything else as malformed or forged. Values
are carried as sent, including non-finite ones: what an authentic packet may carry is
the observer's decision (:mod:`etobs.runtime.service`), not the format's.
"""

from __future__ import annotations

import hashlib
import hmac
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

MAGIC = b"ET"
VERSION = 2
TAG_BYTES = 16
MAX_VALUES = 64
FLAG_INITIAL = 0x01
FLAG_HELLO = 0x02
FLAG_START = 0x04
FLAG_RESYNC = 0x08
FLAG_ANSWER = 0x10
_FLAGS = {
    0: "",
    FLAG_INITIAL: "initial",
    FLAG_HELLO: "hello",
    FLAG_START: "start",
    FLAG_RESYNC: "resync",
    FLAG_ANSWER: "answer",
}
HEADER = struct.Struct(">2sBBHHQdd")
#: The largest datagram the format allows (64 values).
MAX_BYTES = HEADER.size + 8 * MAX_VALUES + TAG_BYTES


class PacketError(ValueError):
    """A packet was rejected; ``kind`` is ``"malformed"`` or ``"forged"``."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(f"{kind} packet: {message}")
        self.kind = kind


@dataclass(frozen=True)
class Packet:
    """One node's measurement as sent: ``values`` taken at time ``t`` of session ``session``."""

    node: int
    seq: int
    t: float
    values: tuple[float, ...]
    initial: bool = False
    session: float = 0.0
    hello: bool = False
    start: bool = False
    resync: bool = False
    answer: bool = False


def resync_record(seq: int) -> tuple[float, float]:
    """The values of a resync request that carries the record ``seq`` (exact: two 32-bit halves)."""
    return (float(seq >> 32), float(seq & 0xFFFFFFFF))


def record_of(values: tuple[float, ...]) -> int | None:
    """The record a resync request carries (:func:`resync_record`), or ``None`` if its values are not one."""
    if len(values) != 2 or not all(v.is_integer() and 0 <= v < 2**32 for v in values):
        return None
    return int(values[0]) << 32 | int(values[1])


def _tag(key: bytes, body: bytes) -> bytes:
    return hmac.new(key, body, hashlib.sha256).digest()[:TAG_BYTES]


def encode(packet: Packet, key: bytes) -> bytes:
    """The bytes of ``packet``, authenticated with the node's ``key``."""
    n = len(packet.values)
    if not 1 <= n <= MAX_VALUES:
        raise ValueError(f"a packet carries 1..{MAX_VALUES} values; got {n}")
    if not 0 <= packet.node < 2**16 or not 0 <= packet.seq < 2**64:
        raise ValueError(f"node id must fit in 16 bits and seq in 64; got {packet.node}, {packet.seq}")
    flags = (
        FLAG_INITIAL * packet.initial
        | FLAG_HELLO * packet.hello
        | FLAG_START * packet.start
        | FLAG_RESYNC * packet.resync
        | FLAG_ANSWER * packet.answer
    )
    if flags not in _FLAGS:
        raise ValueError("a packet is at most one of initial, hello, start, resync and answer")
    body = HEADER.pack(MAGIC, VERSION, flags, packet.node, n, packet.seq, packet.t, packet.session)
    body += struct.pack(f">{n}d", *packet.values)
    return body + _tag(key, body)


def decode(data: bytes, keys: Mapping[int, bytes]) -> Packet:
    """Parse and authenticate ``data``; raise :class:`PacketError` on anything wrong."""
    if len(data) >= 3 and (data[:2] != MAGIC or data[2] != VERSION):  # e.g. a version 1 sensor
        raise PacketError(
            "malformed", f"magic {bytes(data[:2])!r} version {data[2]}; expected {MAGIC!r} version {VERSION}"
        )
    if len(data) < HEADER.size + 8 + TAG_BYTES:
        raise PacketError("malformed", f"{len(data)} bytes is shorter than the smallest packet")
    if len(data) > MAX_BYTES:
        raise PacketError("malformed", f"{len(data)} bytes is longer than the largest packet ({MAX_BYTES})")
    _, _, flags, node, n, seq, t, session = HEADER.unpack_from(data)
    if not 1 <= n <= MAX_VALUES or len(data) != HEADER.size + 8 * n + TAG_BYTES or flags not in _FLAGS:
        raise PacketError("malformed", f"{len(data)} bytes and n = {n} values, flags {flags:#x}, do not fit")
    key = keys.get(node)
    body, tag = data[:-TAG_BYTES], data[-TAG_BYTES:]
    # unknown nodes are checked against a dummy key, so the time taken does not tell them apart
    expected = _tag(key if key is not None else b"\0" * 32, body)
    if not hmac.compare_digest(tag, expected) or key is None:
        raise PacketError("forged", f"authentication failed for node {node}")
    values = struct.unpack_from(f">{n}d", data, HEADER.size)
    return Packet(
        node=node,
        seq=seq,
        t=t,
        values=tuple(values),
        initial=bool(flags & FLAG_INITIAL),
        session=session,
        hello=bool(flags & FLAG_HELLO),
        start=bool(flags & FLAG_START),
        resync=bool(flags & FLAG_RESYNC),
        answer=bool(flags & FLAG_ANSWER),
    )


def derive_key(secret: bytes, node: int) -> bytes:
    """A per-node key from one deployment secret: ``HMAC-SHA256(secret, "etobs-node-<id>")``."""
    return hmac.new(secret, f"etobs-node-{node}".encode(), hashlib.sha256).digest()


def node_keys(secret: bytes, nodes: Sequence[int]) -> dict[int, bytes]:
    """The keys of ``nodes`` derived from ``secret``."""
    return {i: derive_key(secret, i) for i in nodes}


def key_id(key: bytes) -> str:
    """A short public name of ``key`` (SHA-256, 8 bytes in hex): tells keys apart, reveals nothing."""
    return hashlib.sha256(b"etobs-key-id" + key).hexdigest()[:16]
