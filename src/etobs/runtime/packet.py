"""The packet format between sensor nodes and the observer (standard library only).

Version 1, big-endian, 24-byte header, then the values, then the tag::

    offset  size  field
    0       2     magic b"ET"
    2       1     version (1)
    3       1     flags: bit 0 = initial value (sent at start-up, not a transmission)
    4       2     node id (uint16)
    6       2     number of values n (uint16, 1..64)
    8       8     sequence number (uint64, increasing per node, never reused)
    16      8     sample time (float64, seconds on the node's clock)
    24      8n    values (float64 each)
    24+8n   16    tag: HMAC-SHA256 over bytes 0..24+8n with the node's key, first 16 bytes

The observer checks the tag in constant time (:func:`hmac.compare_digest`) with the key
of the node the header names, and rejects anything else as malformed or forged.
"""

from __future__ import annotations

import hashlib
import hmac
import math
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

MAGIC = b"ET"
VERSION = 1
TAG_BYTES = 16
MAX_VALUES = 64
FLAG_INITIAL = 0x01
HEADER = struct.Struct(">2sBBHHQd")


class PacketError(ValueError):
    """A packet was rejected; ``kind`` is ``"malformed"`` or ``"forged"``."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(f"{kind} packet: {message}")
        self.kind = kind


@dataclass(frozen=True)
class Packet:
    """One node's measurement as sent: ``values`` taken at time ``t``."""

    node: int
    seq: int
    t: float
    values: tuple[float, ...]
    initial: bool = False


def _tag(key: bytes, body: bytes) -> bytes:
    return hmac.new(key, body, hashlib.sha256).digest()[:TAG_BYTES]


def encode(packet: Packet, key: bytes) -> bytes:
    """The bytes of ``packet``, authenticated with the node's ``key``."""
    n = len(packet.values)
    if not 1 <= n <= MAX_VALUES:
        raise ValueError(f"a packet carries 1..{MAX_VALUES} values; got {n}")
    if not 0 <= packet.node < 2**16 or not 0 <= packet.seq < 2**64:
        raise ValueError(f"node id must fit in 16 bits and seq in 64; got {packet.node}, {packet.seq}")
    flags = FLAG_INITIAL if packet.initial else 0
    body = HEADER.pack(MAGIC, VERSION, flags, packet.node, n, packet.seq, packet.t)
    body += struct.pack(f">{n}d", *packet.values)
    return body + _tag(key, body)


def decode(data: bytes, keys: Mapping[int, bytes]) -> Packet:
    """Parse and authenticate ``data``; raise :class:`PacketError` on anything wrong."""
    if len(data) < HEADER.size + 8 + TAG_BYTES:
        raise PacketError("malformed", f"{len(data)} bytes is shorter than the smallest packet")
    magic, version, flags, node, n, seq, t = HEADER.unpack_from(data)
    if magic != MAGIC or version != VERSION:
        raise PacketError(
            "malformed", f"magic {magic!r} version {version}; expected {MAGIC!r} version {VERSION}"
        )
    if not 1 <= n <= MAX_VALUES or len(data) != HEADER.size + 8 * n + TAG_BYTES or flags & ~FLAG_INITIAL:
        raise PacketError("malformed", f"{len(data)} bytes and n = {n} values, flags {flags:#x}, do not fit")
    key = keys.get(node)
    body, tag = data[:-TAG_BYTES], data[-TAG_BYTES:]
    # unknown nodes are checked against a dummy key, so the time taken does not tell them apart
    expected = _tag(key if key is not None else b"\0" * 32, body)
    if not hmac.compare_digest(tag, expected) or key is None:
        raise PacketError("forged", f"authentication failed for node {node}")
    values = struct.unpack_from(f">{n}d", data, HEADER.size)
    if not all(math.isfinite(x) for x in (t, *values)):
        raise PacketError("malformed", "non-finite time or value")
    return Packet(node=node, seq=seq, t=t, values=tuple(values), initial=bool(flags & FLAG_INITIAL))


def derive_key(secret: bytes, node: int) -> bytes:
    """A per-node key from one deployment secret: ``HMAC-SHA256(secret, "etobs-node-<id>")``."""
    return hmac.new(secret, f"etobs-node-{node}".encode(), hashlib.sha256).digest()


def node_keys(secret: bytes, nodes: Sequence[int]) -> dict[int, bytes]:
    """The keys of ``nodes`` derived from ``secret``."""
    return {i: derive_key(secret, i) for i in nodes}
