"""A sensor node: sample, decide with the rule, send an authenticated packet (standard library only).

::

    node = SensorNode(node=0, key=key, rule=SampledRule(spec, period=0.01),
                      send=udp_sender("127.0.0.1", 47000), seq=SequenceStore("node0.seq"),
                      session=epoch)
    run(node, read=lambda t: [read_adc()], period=0.01, duration=60.0, epoch=epoch)

At its first sample the node sends its value flagged *initial* (the observer's starting
``ybar``; not counted as a transmission), then at every sample ``t_k = k T`` it computes
``e_k = ybar - y(t_k)`` against the value it last sent and sends when the rule fires.
Sequence numbers never repeat, even across restarts: :class:`SequenceStore` reserves
blocks of them in a file before using them. Every packet carries the deployment's session
(its epoch), which binds it to the run it was measured in.

**Resync.** A service restarted mid-run resumes its observer from its checkpoint, but
what the nodes sent while it was down is lost, and each node believes the observer holds
its last value. The service then asks each node, at the address its packets came from,
to resend what it sent after the service's record (the last sequence number of the node
it holds; :meth:`etobs.runtime.service.ObserverCore.resync_requests`), and holds its
observer until each has answered. A node given ``listen`` reads such requests at each
sample (at most ``MAX_READS``) and takes one only if it is authentic (its own key), of
its session, stamped within ``RESYNC_WINDOW`` of its own time, later than the last one
it took, and at least ``RESYNC_MIN_GAP`` after its last answer. It then resends, as they
were sent (same bytes), the packets of its log (the last ``RESEND_LOG``) numbered above
the record, and an *answer*: the value it last sent and the time it sent it. The rule's
state is not touched (no transmission is made), so the run goes on as if the service had
never been down, and the restarted observer, integrating the resent packets at their
sample times, gets the undisturbed estimate back. What it refused is counted in
``resync_refused`` by reason.
"""

from __future__ import annotations

import math
import os
import socket
import time
from collections import deque
from collections.abc import Callable, Sequence
from pathlib import Path

from etobs.errors import InputError
from etobs.runtime.files import open_regular
from etobs.runtime.packet import Packet, PacketError, decode, encode, record_of
from etobs.runtime.sampled_rule import SampledRule

#: How far ahead of the clock an epoch may lie: a start further away is a typing mistake,
#: and the run would wait until then.
MAX_EPOCH_LEAD = 3600.0
#: Seconds between two hellos of a sensor waiting for the service's answer (a datagram
#: may be lost), and how long it waits in all by default.
HELLO_RETRY = 0.5
HANDSHAKE_TIMEOUT = 3600.0
#: Largest block of sequence numbers reserved at once: a restart skips at most a block, and
#: the service refuses a jump of 2^32 (``service.MAX_SEQ_JUMP``) as a node gone wrong.
MAX_BLOCK = 2**20
#: A resync request is taken only if stamped within this many seconds (node time) of the
#: node's own time, and later than the last one taken: an old one replayed is refused.
RESYNC_WINDOW = 1.0
#: Node seconds between two answers to resync requests, at least: however many arrive, a
#: node answers (resends its log above the record) at most once per this time (a flood is counted).
RESYNC_MIN_GAP = 0.5
#: Datagrams a node reads at most per sample (the rest wait, or the socket drops them).
MAX_READS = 8
#: Packets a node keeps to resend after a service's restart (about 100 kB at 8 values):
#: a downtime in which it sent more loses the oldest, and the service counts them in ``gaps``.
RESEND_LOG = 1024


def check_epoch(epoch: float, duration: float, time_scale: float, now: float, name: str = "`epoch`") -> float:
    """``epoch`` if a run of ``duration`` plant seconds from it is not over at ``now``.

    Raises :class:`~etobs.errors.InputError` naming ``name`` for a non-finite or
    non-positive epoch, one more than :data:`MAX_EPOCH_LEAD` seconds ahead of ``now``, or
    one whose run ended before ``now``: each would make a process wait for hours or do
    nothing at all.
    """
    if not isinstance(epoch, int | float) or not math.isfinite(epoch) or epoch <= 0:
        raise InputError(f"{name} must be a time.time() value (seconds since 1970); got {epoch!r}")
    if epoch > now + MAX_EPOCH_LEAD:
        raise InputError(
            f"{name} {epoch!r} lies {epoch - now:.6g} s ahead of this machine's clock; at most "
            f"{MAX_EPOCH_LEAD:g} s ahead is allowed (use the epoch etobs serve printed)"
        )
    wall = duration / time_scale
    if epoch + wall < now:
        raise InputError(
            f"{name} {epoch!r}: that run ended {now - epoch - wall:.6g} s ago (it lasts {wall:.6g} s "
            "of wall time); use the epoch of the running service"
        )
    return float(epoch)


class SequenceStore:
    """Increasing sequence numbers that survive a restart of the node.

    The file holds an upper bound on every number handed out; a restarted node starts
    from it. Numbers are reserved ``block`` at a time, written atomically before use, so a
    crash skips at most a block and never reuses a number. ``path=None`` keeps them in
    memory (starting at 1). When the 64-bit numbers run out, :meth:`next` raises: the
    node needs a new key (rotate the secret) and a new file. The file is opened without
    blocking and refused unless it is a regular file (a FIFO hung the sensor in ``open()``).

    Invariant (tested over restart points and block sizes): every number handed out is
    below the bound on file when it is handed out, and a restart starts at that bound, so
    numbers strictly increase across restarts and none is reused.
    """

    def __init__(self, path: str | os.PathLike[str] | None = None, block: int = 1024) -> None:
        if isinstance(block, bool) or not isinstance(block, int) or not 1 <= block <= MAX_BLOCK:
            # block = 0 wrote the number about to be handed out as the bound: a restart reused it
            raise InputError(f"`block` must be an integer in 1..{MAX_BLOCK}; got {block!r}")
        self.path = None if path is None else Path(path)
        self.block = block
        self._next = 1
        text = None
        if self.path is not None:
            try:
                with open_regular(self.path, "sequence file") as fh:  # 20 digits at most: not read whole
                    text = fh.read(64).decode("utf-8", errors="replace").strip()
            except FileNotFoundError:
                pass
        if text is not None:
            if not (text.isascii() and text.isdigit()) or int(text) >= 2**64:
                raise InputError(
                    f"sequence file {self.path} is damaged: {text[:40]!r}; remove it only if the key changes"
                )
            self._next = int(text)
        self._limit = self._next
        self._reserve()

    def _reserve(self) -> None:
        self._limit = min(self._next + self.block, 2**64 - 1)
        if self.path is not None:
            tmp = self.path.with_name(f".{self.path.name}.tmp")
            with open_regular(tmp, "sequence file's temporary file", write=True, follow=False) as fh:
                fh.write(str(self._limit).encode())
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, self.path)

    def next(self) -> int:
        """The next sequence number."""
        if self._next >= self._limit:
            if self._next >= 2**64 - 1:
                raise InputError(
                    f"the sequence numbers of {self.path or 'this node'} are used up; rotate the secret "
                    "and start a new sequence file"
                )
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
    session : float
        The deployment's epoch, carried in every packet (the service refuses another).
    resyncs : int
        Resync requests answered (module docstring); not transmissions.
    resent : int
        Packets resent in those answers.
    resync_refused : dict of str to int
        Resync requests refused: ``forged``, ``wrong_session``, ``malformed`` (authentic,
        but its values are not a record), ``out_of_window`` (stamped too far from the
        node's time), ``replayed`` (not later than the last one taken), ``rate_limited``.

    """

    def __init__(
        self,
        node: int,
        key: bytes,
        rule: SampledRule,
        send: Callable[[bytes], object],
        seq: SequenceStore | None = None,
        *,
        session: float = 0.0,
        listen: Callable[[], bytes | None] | None = None,
    ) -> None:
        self.node, self.key, self.rule, self._send = node, key, rule, send
        self.session = float(session)
        self.seq = seq if seq is not None else SequenceStore()
        self.sent: list[float] | None = None
        self.transmissions = 0
        self._listen = listen
        self.resyncs = 0
        self.resent = 0
        self.resync_refused = dict.fromkeys(
            ("forged", "wrong_session", "malformed", "out_of_window", "replayed", "rate_limited"), 0
        )
        self._resync_t = -math.inf  # the stamp of the last request taken
        self._answered = -math.inf  # node time of the last answer
        self._sent_t = -math.inf  # the sample time of the value last sent
        self._log: deque[tuple[int, bytes]] = deque(maxlen=RESEND_LOG)  # (seq, bytes) as sent

    def sample(self, t: float, y: Sequence[float]) -> Packet | None:
        """Take the sample ``y`` at time ``t``; return the packet sent, if any."""
        y = [float(v) for v in y]
        packet = None
        if self.sent is None:
            packet = Packet(self.node, self.seq.next(), t, tuple(y), initial=True, session=self.session)
            self._emit(packet, y)
        record = self._resync_asked(t)
        if record is not None:
            self._answer(record)
        e = [s - v for s, v in zip(self.sent or y, y, strict=True)]
        if self.rule.decide(e, y):
            packet = Packet(self.node, self.seq.next(), t, tuple(y), session=self.session)
            self._emit(packet, y)
            self.transmissions += 1
        return packet

    def _answer(self, record: int) -> None:
        """Resend the packets numbered above ``record``, then the answer (module docstring)."""
        again = [data for seq, data in self._log if seq > record]
        for data in again:
            self._send(data)
        assert self.sent is not None  # the initial value is sent before any request is read
        answer = Packet(
            self.node, self.seq.next(), self._sent_t, tuple(self.sent), session=self.session, answer=True
        )
        self._send(encode(answer, self.key))
        self.resyncs += 1
        self.resent += len(again)

    def _resync_asked(self, t: float) -> int | None:
        """The record of a resync request taken at ``t``, if one is (bounded reads)."""
        taken = None
        for _ in range(MAX_READS if self._listen is not None else 0):
            data = self._listen()
            if data is None:
                break
            try:
                p = decode(data, {self.node: self.key})
            except PacketError:
                self.resync_refused["forged"] += 1
                continue
            record = record_of(p.values)
            if not p.resync or p.node != self.node:
                self.resync_refused["forged"] += 1  # authentic but not a request to this node
            elif p.session != self.session:
                self.resync_refused["wrong_session"] += 1
            elif record is None:
                self.resync_refused["malformed"] += 1
            elif not abs(p.t - t) <= RESYNC_WINDOW:
                self.resync_refused["out_of_window"] += 1
            elif p.t <= self._resync_t:
                self.resync_refused["replayed"] += 1
            elif taken is not None or t - self._answered < RESYNC_MIN_GAP:
                self.resync_refused["rate_limited"] += 1
            else:
                self._resync_t, self._answered, taken = p.t, t, record
        return taken

    def _emit(self, packet: Packet, y: list[float]) -> None:
        data = encode(packet, self.key)
        self._send(data)
        self._log.append((packet.seq, data))
        self.sent, self._sent_t = y, packet.t


class UdpSender:
    """Send each packet as one UDP datagram to ``(host, port)``; close when done.

    On loopback the socket is bound to 127.0.0.1, so nothing listens beyond the machine.
    The host is resolved once, here: a name that does not resolve is an error now, not
    at the first packet.
    """

    def recv_nowait(self) -> bytes | None:
        """One datagram already sent back to this socket, or None (never waits)."""
        # non-blocking mode, not only MSG_DONTWAIT: after recv(timeout) the socket is in
        # timeout mode, where Python waits for the timeout first and raises TimeoutError
        # (every sensor started by the documented recipe failed with "timed out")
        self.sock.settimeout(0.0)
        try:
            return self.sock.recv(4096)
        except (BlockingIOError, ConnectionError):
            return None
        finally:
            self.sock.settimeout(None)  # sends block as they do before any handshake

    def recv(self, timeout: float) -> bytes | None:
        """One datagram sent back to this socket within ``timeout`` seconds, or None."""
        self.sock.settimeout(max(timeout, 1e-3))
        try:
            return self.sock.recv(4096)
        except (TimeoutError, ConnectionError):  # nothing yet; or an ICMP "port unreachable"
            return None

    def __init__(self, host: str, port: int) -> None:
        try:
            info = socket.getaddrinfo(host, port, socket.AF_INET, socket.SOCK_DGRAM)
        except (socket.gaierror, UnicodeError, OverflowError) as exc:
            raise InputError(f"cannot resolve the service's host {host!r} (port {port}): {exc}") from exc
        self.address = info[0][4]
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


def handshake(
    sender: UdpSender,
    node: int,
    key: bytes,
    seq: SequenceStore,
    *,
    timeout: float = HANDSHAKE_TIMEOUT,
    clock: Callable[[], float] = time.monotonic,
) -> tuple[float, float]:
    """Say hello to the service until it answers; return ``(epoch, first sample time)``.

    Each hello carries a fresh sequence number (a captured hello gets no answer), and only
    an authentic start packet echoing one of them is taken (a captured answer is not).
    After ``timeout`` seconds without one, :class:`~etobs.errors.InputError` names the
    service's address. See :mod:`etobs.runtime.server` for the service's side.
    """
    asked: set[int] = set()
    end = clock() + timeout
    while clock() < end:
        n = seq.next()
        asked.add(n)
        sender(encode(Packet(node, n, 0.0, (0.0,), hello=True), key))
        retry = clock() + HELLO_RETRY
        while (left := min(retry, end) - clock()) > 0:
            data = sender.recv(left)
            if data is None:
                continue
            try:
                p = decode(data, {node: key})
            except PacketError:
                continue
            if p.start and p.node == node and p.seq in asked and p.t >= 0:
                return p.session, p.t
    raise InputError(
        f"no answer from the service at {sender.address[0]}:{sender.address[1]} after {timeout:g} s; "
        "is `etobs serve SPEC` running there (without --epoch, or give the sensor its --epoch)?"
    )


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
    clock: Callable[[], float] = time.time,
    sleep: Callable[[float], object] = time.sleep,
    first: float | None = None,
) -> int:
    """Sample at ``t_k = k period`` for ``t_k <= duration``; return the samples taken.

    Node time runs ``time_scale`` times faster than the wall clock ``clock`` from
    ``epoch`` (a ``time.time()`` value shared with the service; default now, checked by
    :func:`check_epoch`), so a test can run a minute of plant time in a second. A node
    started after the epoch (e.g. restarted) begins at the first sample not yet due; a
    sample that then falls behind the clock is taken at once (never skipped). ``first``
    (the service's answer to the hello, :func:`handshake`) is the first sample time to
    take instead. ``clock`` and ``sleep`` let a test run the node on a clock of its own.
    """
    for name, value in (("period", period), ("duration", duration), ("time_scale", time_scale)):
        if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
            raise InputError(f"`{name}` must be a finite number > 0; got {value!r}")
    start = clock() if epoch is None else check_epoch(epoch, duration, time_scale, clock())
    since = (clock() - start) * time_scale if first is None else first
    k = max(0, math.ceil(since / period - 1e-9))
    while k * period <= duration + 1e-12:
        t = k * period
        wait = start + t / time_scale - clock()
        if wait > 0:
            sleep(wait)
        node.sample(t, read(t))
        k += 1
    return k
