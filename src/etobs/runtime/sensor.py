"""A sensor node: sample, decide with the rule, send an authenticated packet (standard library only).

::

    node = SensorNode(node=0, key=key, rule=SampledRule(spec, period=0.01),
                      send=udp_sender("127.0.0.1", 47000), seq=SequenceStore("node0.seq"))
    run(node, read=lambda t: [read_adc()], period=0.01, duration=60.0)

At its first sample the node sends its value flagged *initial* (the observer's starting
``ybar``; not counted as a transmission), then at every sample ``t_k = k T`` it computes
``e_k = ybar - y(t_k)`` against the value it last sent and sends when the rule fires.
Sequence numbers never repeat, even across restarts: :class:`SequenceStore` reserves
blocks of them in a file before using them.
"""

from __future__ import annotations

import math
import os
import socket
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from etobs.runtime.packet import Packet, encode
from etobs.runtime.sampled_rule import SampledRule


class SequenceStore:
    """Increasing sequence numbers that survive a restart of the node.

    The file holds an upper bound on every number handed out; a restarted node starts
    from it. Numbers are reserved ``block`` at a time, written atomically before use, so a
    crash skips at most a block and never reuses a number. ``path=None`` keeps them in
    memory (starting at 1).
    """

    def __init__(self, path: str | os.PathLike[str] | None = None, block: int = 1024) -> None:
        self.path = None if path is None else Path(path)
        self.block = block
        self._next = 1
        if self.path is not None and self.path.exists():
            text = self.path.read_text().strip()
            if not text.isdigit():
                raise ValueError(
                    f"sequence file {self.path} is damaged: {text[:40]!r}; remove it only if the key changes"
                )
            self._next = int(text)
        self._limit = self._next
        self._reserve()

    def _reserve(self) -> None:
        self._limit = self._next + self.block
        if self.path is not None:
            tmp = self.path.with_name(f".{self.path.name}.tmp")
            with open(tmp, "w") as fh:
                fh.write(str(self._limit))
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, self.path)

    def next(self) -> int:
        """The next sequence number."""
        if self._next >= self._limit:
            self._reserve()
        n = self._next
        self._next += 1
        return n


class SensorNode:
    """One node: its id, key, rule and a way to send bytes.

    Attributes
    ----------
    transmissions : int
        Packets sent because the rule fired (the initial value not counted).
    sent : list of float or None
        The value last sent (the node's ``ybar``).

    """

    def __init__(
        self,
        node: int,
        key: bytes,
        rule: SampledRule,
        send: Callable[[bytes], object],
        seq: SequenceStore | None = None,
    ) -> None:
        self.node, self.key, self.rule, self._send = node, key, rule, send
        self.seq = seq if seq is not None else SequenceStore()
        self.sent: list[float] | None = None
        self.transmissions = 0

    def sample(self, t: float, y: Sequence[float]) -> Packet | None:
        """Take the sample ``y`` at time ``t``; return the packet sent, if any."""
        y = [float(v) for v in y]
        packet = None
        if self.sent is None:
            packet = Packet(self.node, self.seq.next(), t, tuple(y), initial=True)
            self._emit(packet, y)
        e = [s - v for s, v in zip(self.sent or y, y, strict=True)]
        if self.rule.decide(e, y):
            packet = Packet(self.node, self.seq.next(), t, tuple(y))
            self._emit(packet, y)
            self.transmissions += 1
        return packet

    def _emit(self, packet: Packet, y: list[float]) -> None:
        self._send(encode(packet, self.key))
        self.sent = y


class UdpSender:
    """Send each packet as one UDP datagram to ``(host, port)``; close when done.

    On loopback the socket is bound to 127.0.0.1, so nothing listens beyond the machine.
    """

    def __init__(self, host: str, port: int) -> None:
        self.address = (host, port)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        if host in ("127.0.0.1", "localhost"):
            self.sock.bind(("127.0.0.1", 0))

    def __call__(self, data: bytes) -> None:
        self.sock.sendto(data, self.address)

    def close(self) -> None:
        self.sock.close()

    def __enter__(self) -> UdpSender:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def udp_sender(host: str, port: int) -> UdpSender:
    """A :class:`UdpSender` to ``(host, port)``."""
    return UdpSender(host, port)


def run(
    node: SensorNode,
    read: Callable[[float], Sequence[float]],
    period: float,
    duration: float,
    *,
    epoch: float | None = None,
    time_scale: float = 1.0,
) -> int:
    """Sample at ``t_k = k period`` for ``t_k <= duration``; return the samples taken.

    Node time runs ``time_scale`` times faster than the wall clock from ``epoch`` (a
    ``time.time()`` value shared with the service; default now), so a test can run a
    minute of plant time in a second. A node started after the epoch (e.g. restarted)
    begins at the first sample not yet due; a sample that then falls behind the clock is
    taken at once (never skipped).
    """
    start = time.time() if epoch is None else epoch
    k = max(0, math.ceil((time.time() - start) * time_scale / period - 1e-9))
    while k * period <= duration + 1e-12:
        t = k * period
        wait = start + t / time_scale - time.time()
        if wait > 0:
            time.sleep(wait)
        node.sample(t, read(t))
        k += 1
    return k
