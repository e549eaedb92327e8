"""The observer service over asyncio: UDP packets in, a JSON endpoint and a trace out.

Service time is ``(time.time() - epoch) * time_scale`` (``time_scale > 1`` runs faster
than real time, for tests and demos). The epoch is also the session every packet must
carry (:mod:`etobs.runtime.packet`). The observer is advanced to ``now - hold_back``, so
a packet that arrives within ``hold_back`` of its sample time is applied at that sample
time (see :class:`~etobs.runtime.service.ObserverCore`). Endpoints:

* UDP on ``host``: the packets of :mod:`~etobs.runtime.packet`;
* HTTP ``GET /estimate`` on ``http_host`` (127.0.0.1 unless set; bound apart from the
  UDP socket, so a service that takes packets from remote sensors does not also show
  its estimate to them): the current estimate and counters as JSON. With a ``token`` the
  request must carry ``Authorization: Bearer <token>`` (compared in constant time); a
  non-loopback ``http_host`` requires one. A request must be read whole within
  ``read_timeout``; idle connections cannot deny the endpoint: beyond
  ``HTTP_MAX_CLIENTS`` (or ``HTTP_MAX_PER_ADDRESS`` from one address) connections still
  being read, a new one evicts the oldest of them.

**Start-up handshake** (``handshake=True``, what ``etobs serve`` does without
``--epoch``): the service has no epoch until every node has said hello. A sensor that is
ready (its samples computed) sends a *hello* packet (authenticated, a fresh sequence
number, so a captured one gets no answer) every ``HELLO_RETRY`` seconds; once every node
has, the epoch is set ``START_LEAD`` wall seconds ahead and each hello is answered with a
*start* packet (the hello's number echoed, the epoch as its session, and the first sample
time to take: 0 for a node not yet heard in this run, the current time for a sensor
restarted mid-run). Sensors started one after another by hand, however late, all begin
at t = 0. A hello after the start is answered at once.

The trace is JSON lines, one object per ``tick`` of service time on the grid
``t = 0, tick, 2 tick, ...`` and one at the end (``t``, ``status``, ``xhat``, ``ybar``,
``transmissions``, ``gaps``, ``counts``, ...), read back by :func:`read_trace`. The grid
does not depend on how often the event loop runs, so a loaded machine writes the same
lines, later.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import ipaddress
import json
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from etobs.errors import InputError
from etobs.runtime.files import open_regular
from etobs.runtime.packet import MAX_BYTES, Packet, encode
from etobs.runtime.sensor import check_epoch
from etobs.runtime.service import ObserverCore

#: Read deadline: a client whose request is not read whole within this many seconds is
#: dropped (the default of ``read_timeout``).
HTTP_TIMEOUT = 2.0
#: Connections whose request is still being read, at most, in all and from one address. A
#: new connection beyond either cap evicts the *oldest* such one (of that address), never
#: itself: 32 idle connections, with the cap taken before the request was read, denied
#: ``GET /estimate`` to everyone. 256 file descriptors stay well under the usual limit of 1024.
HTTP_MAX_CLIENTS = 256
HTTP_MAX_PER_ADDRESS = 64
HTTP_MAX_HEADERS = 32
#: Most observer steps per wall second (``time_scale / dt``). A step of the robot arm's
#: observer takes about 70 us in Python, so this is several times more than a service
#: keeps up with; ``runtime.dt = 1e-9`` (1e9 steps per second) blocked the service for
#: eleven minutes in every 10-ms tick.
MAX_STEP_RATE = 1e5
#: Trace lines at most written for the time before a run starts (1000 s at the 10-ms tick):
#: a service started on an old epoch does not write every line since it first.
MAX_BACKFILL_LINES = 100_000
#: Wall seconds between the last hello and the epoch: every sensor gets its answer before
#: t = 0 (a sensor that does not still begins at t = 0, catching up).
START_LEAD = 0.5
#: Turns of the event loop spent reading waiting datagrams at the end of a run (a socket
#: buffer holds a few thousand packets).
DRAIN_TURNS = 100_000


def is_loopback(host: str) -> bool:
    """Whether ``host`` names this machine only (``localhost`` or a loopback address)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:  # a host name: it may resolve to anything
        return False


def to_json(snapshot: dict[str, Any]) -> str:
    """``snapshot`` as strict JSON (no NaN or infinity: other readers reject them)."""
    return json.dumps(snapshot, allow_nan=False)


class _Datagrams(asyncio.DatagramProtocol):
    def __init__(self, server: ObserverServer) -> None:
        self.server = server

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self.server.receive(data, addr)


class ObserverServer:
    """Run an :class:`ObserverCore` behind UDP and HTTP endpoints.

    Parameters
    ----------
    core : ObserverCore
    epoch : float, optional
        ``time.time()`` at service time 0 (default: when :meth:`start` runs); also the
        session packets must carry.
    time_scale : float
    tick : float
        Service time between trace lines.
    hold_back : float
        How far behind the clock the observer runs, in service time.
    trace : path, optional
        Where to write the trace.
    token : bytes, optional
        The bearer token ``GET /estimate`` requires (required on a non-loopback host).
    read_timeout : float
        Seconds a client has to send its whole request (and to take the answer).
    handshake : bool
        Without ``epoch``: set the epoch once every node has said hello (module docstring),
        not when :meth:`start` runs.

    """

    def __init__(
        self,
        core: ObserverCore,
        *,
        epoch: float | None = None,
        time_scale: float = 1.0,
        tick: float = 0.01,
        hold_back: float = 0.05,
        trace: str | Path | None = None,
        token: bytes | None = None,
        read_timeout: float = HTTP_TIMEOUT,
        handshake: bool = False,
    ) -> None:
        for name, value in (("time_scale", time_scale), ("tick", tick), ("read_timeout", read_timeout)):
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise InputError(f"`{name}` must be a finite number > 0; got {value!r}")
        if not (isinstance(hold_back, int | float) and math.isfinite(hold_back) and hold_back >= 0):
            raise InputError(f"`hold_back` must be a finite number >= 0; got {hold_back!r}")
        if time_scale / core.dt > MAX_STEP_RATE:
            raise InputError(
                f"the observer would take time_scale / dt = {time_scale:g} / {core.dt:g} = "
                f"{time_scale / core.dt:.3g} steps per wall second; at most {MAX_STEP_RATE:.0e}: use a "
                "larger `runtime.dt` or a smaller `runtime.time_scale`"
            )
        if token is not None and not isinstance(token, bytes):
            raise InputError(f"`token` must be bytes; got {type(token).__name__}")
        if token is not None and len(token) < 16:
            raise InputError(f"`token` must have at least 16 bytes; got {len(token)}")
        self.core, self.time_scale = core, time_scale
        self.handshake = handshake and epoch is None
        self._hellos: dict[int, tuple[Any, int]] = {}  # node: (address, seq) of its last hello
        self._started: asyncio.Event | None = None
        if self.handshake:
            core.session = -1.0  # no epoch yet: no packet's session (an epoch is > 0)
        self.epoch = epoch
        self.tick, self.hold_back, self.token = tick, hold_back, token
        self.trace_path = None if trace is None else Path(trace)
        self._transport: asyncio.DatagramTransport | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._http: asyncio.Server | None = None
        self._clients: set[asyncio.Task[None]] = set()
        self.read_timeout = float(read_timeout)
        #: Connections whose request is being read, oldest first, with their peer's address.
        self._reading: dict[asyncio.Task[None], str] = {}
        self.received = 0  # datagrams handed to the core

    @property
    def epoch(self) -> float | None:
        """``time.time()`` at service time 0, and the session of this run's packets."""
        return self._epoch

    @epoch.setter
    def epoch(self, value: float | None) -> None:
        self._epoch = value
        if value is not None:
            self.core.session = float(value)

    def feed(self, data: bytes) -> None:
        """Hand a datagram to the observer from another thread (e.g. the MQTT client's).

        What is longer than any packet is cut to one byte more than the largest (it is
        still judged ``malformed``) before it waits for the event loop: an MQTT message
        may be 256 MiB, and a flood of them would otherwise wait whole.
        """
        assert self._loop is not None, "start() first"
        with contextlib.suppress(RuntimeError):  # the loop has closed: the service is done
            self._loop.call_soon_threadsafe(self.receive, data[: MAX_BYTES + 1])

    def receive(self, data: bytes, addr: Any = None) -> str:
        """Judge one datagram now (on the event loop); return its verdict.

        A hello from ``addr`` is answered there once the epoch is set (module docstring).
        """
        self.received += 1
        verdict = self.core.receive(data, None if self.epoch is None else self.now())
        if (
            verdict in ("applied", "initial", "hello")
            and addr is not None
            and self.core.last_node is not None
        ):
            self.core.note_address(self.core.last_node, addr)
        if verdict == "hello" and addr is not None and self.core.last_hello is not None:
            node, seq = self.core.last_hello
            self._hellos[node] = (addr, seq)
            if self.epoch is None and set(self._hellos) >= set(self.core.nodes):
                self.epoch = time.time() + START_LEAD
                if self._started is not None:
                    self._started.set()
                for i in sorted(self._hellos):
                    self._answer_hello(i)
            elif self.epoch is not None:
                self._answer_hello(node)
        return verdict

    def waiting_for(self) -> list[int]:
        """The nodes whose hello the handshake still waits for."""
        return [i for i in sorted(self.core.nodes) if i not in self._hellos]

    def _answer_hello(self, node: int) -> None:
        """The start packet for ``node``'s last hello: epoch, and the first sample to take."""
        assert self.epoch is not None and self._transport is not None
        self.core.flush()  # the hello's number on record before it is acted on
        addr, seq = self._hellos[node]
        first = max(0.0, self.now()) if self.core.nodes[node].heard else 0.0
        packet = Packet(node, seq, first, (0.0,), session=self.epoch, start=True)
        self._transport.sendto(encode(packet, self.core.keys[node]), addr)

    async def wait_start(self, timeout: float) -> None:
        """Wait until the handshake has set the epoch; after ``timeout`` s raise naming the nodes missing."""
        if self.epoch is not None:
            return
        assert self._started is not None, "start() first"
        try:
            await asyncio.wait_for(self._started.wait(), timeout)
        except TimeoutError:
            raise InputError(
                f"no hello from nodes {self.waiting_for()} after {timeout:g} s: start each with "
                "`etobs sensor SPEC --node i` (or give every process the same --epoch)"
            ) from None

    def now(self) -> float:
        """Service time."""
        assert self.epoch is not None
        return (time.time() - self.epoch) * self.time_scale

    async def start(
        self,
        host: str = "127.0.0.1",
        port: int = 0,
        http_port: int | None = None,
        http_host: str = "127.0.0.1",
    ) -> tuple[int, int | None]:
        """Open the endpoints; return the UDP and HTTP ports (0 picks free ones)."""
        if http_port is not None and self.token is None and not is_loopback(http_host):
            raise InputError(
                f"GET /estimate on {http_host!r}, not a loopback address, needs a token "
                "(`runtime.http_token_file`); without one it would show the estimate to anyone"
            )
        if self.epoch is None and not self.handshake:
            self.epoch = time.time()
        self._started = asyncio.Event()
        loop = self._loop = asyncio.get_running_loop()
        try:
            self._transport, _ = await loop.create_datagram_endpoint(
                lambda: _Datagrams(self), local_addr=(host, port)
            )
        except (OSError, UnicodeError, OverflowError) as exc:  # in use, unknown host, not ours
            raise InputError(f"cannot receive packets on UDP {host}:{port} (`host`, `port`): {exc}") from exc
        udp = self._transport.get_extra_info("sockname")[1]
        web = None
        if http_port is not None:
            try:
                self._http = await asyncio.start_server(self._serve_http, http_host, http_port, limit=8192)
            except (OSError, UnicodeError, OverflowError) as exc:
                self._transport.close()
                raise InputError(
                    f"cannot serve GET /estimate on {http_host}:{http_port} (`http_host`, `http_port`): {exc}"
                ) from exc
            web = self._http.sockets[0].getsockname()[1]
        return udp, web

    async def run_until(
        self, t_end: float, *, finished: Callable[[], bool] | None = None, linger: float = 30.0
    ) -> dict[str, Any]:
        """Run until service time ``t_end``; return the final snapshot.

        With ``finished`` (e.g. "every sensor process has exited"), the observer stays
        ``hold_back`` short of ``t_end`` until it returns True, so that the senders' last
        packets are applied at their sample times; after ``linger`` wall seconds past
        ``t_end`` it stops anyway. The epoch is checked first
        (:func:`~etobs.runtime.sensor.check_epoch`): one far ahead would wait for years.
        """
        assert self.epoch is not None, "start() first"
        check_epoch(self.epoch, t_end, self.time_scale, time.time())
        fh = open_regular(self.trace_path, "the trace", write=True) if self.trace_path is not None else None
        give_up = self.epoch + t_end / self.time_scale + linger
        # the next trace line is at k * tick: from 0, or at most MAX_BACKFILL_LINES before now for
        # a service started long after its epoch (`serve --epoch 1` wrote every line since 1970 first)
        k = max(0, math.floor((self.now() - self.hold_back) / self.tick) - MAX_BACKFILL_LINES)
        # an observer resumed from its checkpoint starts there: no lines before its time
        k = max(k, math.ceil(self.core.t / self.tick - 1e-9))
        try:
            while True:
                done = finished is None or finished() or time.time() > give_up
                if done and self.now() >= t_end:  # the last turn: read what has arrived first
                    await self._drain()
                target = min(self.now() - self.hold_back, t_end if done else t_end - self.hold_back)
                if done and self.now() >= t_end:
                    target = t_end
                # a restarted observer waits for its nodes' resends (bounded: RESYNC_TRIES each);
                # the trace has no line for a time the observer has not reached
                while k * self.tick <= target and not self.core.holding:  # (target - last) / tick lines
                    self.core.advance(min(k * self.tick, t_end))
                    if fh is not None:
                        fh.write(to_json(self.core.snapshot()).encode() + b"\n")
                    k += 1
                self.core.advance(target)
                self._resync()
                if target >= t_end and not self.core.holding:
                    if fh is not None and (k - 1) * self.tick < t_end:  # the end is always a line
                        fh.write(to_json(self.core.snapshot()).encode() + b"\n")
                    break
                await asyncio.sleep(self.tick / self.time_scale / 2)
            return self.core.snapshot()
        finally:
            if fh is not None:
                fh.close()

    def _resync(self) -> None:
        """Send the resync requests due (a restarted service's nodes, :mod:`etobs.runtime.service`)."""
        if self._transport is None:
            return
        for _, addr, data in self.core.resync_requests(self.now()):
            self._transport.sendto(data, addr)

    async def _drain(self) -> None:
        """Read the datagrams already waiting, one per turn of the loop (bounded).

        Packets sent before the senders finished are then counted and applied.
        """
        for _ in range(DRAIN_TURNS):
            before = self.received
            # a turn's reads run after this task resumes: the second turn sees the first's
            await asyncio.sleep(0)
            await asyncio.sleep(0)
            if self.received == before:
                return

    async def close(self) -> None:
        """Close the endpoints; HTTP clients still connected are dropped quietly."""
        if self._transport is not None:
            self._transport.close()
        if self._http is not None:
            self._http.close()
            for task in list(self._clients):
                task.cancel()
            await asyncio.gather(*self._clients, return_exceptions=True)
            await self._http.wait_closed()

    def _make_room(self, host: str) -> None:
        """Evict the oldest connection still being read, if a cap would be passed by one more."""
        same = [t for t, h in self._reading.items() if h == host]
        if len(same) >= HTTP_MAX_PER_ADDRESS:
            victim = same[0]
        elif len(self._reading) >= HTTP_MAX_CLIENTS:
            victim = next(iter(self._reading))
        else:
            return
        del self._reading[victim]
        victim.cancel()  # its handler closes the connection

    async def _serve_http(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        peer = writer.get_extra_info("peername")
        host = str(peer[0]) if peer else ""
        self._make_room(host)
        self._clients.add(task)
        self._reading[task] = host
        try:
            status, body, extra = await asyncio.wait_for(self._answer(reader), timeout=self.read_timeout)
            self._reading.pop(task, None)
            head = (
                f"HTTP/1.0 {status}\r\nContent-Type: application/json\r\n{extra}"
                f"Content-Length: {len(body)}\r\n\r\n"
            )
            writer.write(head.encode() + body)
            await asyncio.wait_for(writer.drain(), timeout=self.read_timeout)  # a client that reads nothing
        # a client that is slow, disconnects, sends junk or too long a line; evicted for a newer
        # one, or the service closing (CancelledError): the connection ends without a traceback
        except (TimeoutError, ConnectionError, UnicodeDecodeError, ValueError, asyncio.CancelledError):
            pass
        finally:
            self._reading.pop(task, None)
            self._clients.discard(task)
            writer.close()

    async def _answer(self, reader: asyncio.StreamReader) -> tuple[str, bytes, str]:
        parts = (await reader.readline()).decode("latin-1").split()
        headers = {}
        for _ in range(HTTP_MAX_HEADERS):
            line = (await reader.readline()).decode("latin-1")
            if not line.strip():
                break
            name, _, value = line.partition(":")
            headers[name.strip().lower()] = value.strip()
        if self.token is not None:
            scheme, _, given = headers.get("authorization", "").partition(" ")
            ok = hmac.compare_digest(given.strip().encode("latin-1"), self.token)
            if scheme.lower() != "bearer" or not ok:
                return (
                    "401 Unauthorized",
                    b'{"error": "a bearer token is required"}',
                    ("WWW-Authenticate: Bearer\r\n"),
                )
        if len(parts) >= 2 and parts[0] == "GET" and parts[1] == "/estimate":
            return "200 OK", to_json(self.core.snapshot()).encode(), ""
        return "404 Not Found", b'{"error": "only GET /estimate"}', ""


def read_trace(path: str | Path) -> dict[str, np.ndarray]:
    """A trace as arrays: ``t`` (K,), ``xhat`` (K, n_x), ``ybar`` (K, n_y), ``transmissions`` (K, N).

    ``null`` entries (an output not yet received, an estimate that stopped being finite)
    are NaN.
    """
    rows = [json.loads(line) for line in Path(path).read_text().splitlines() if line.strip()]

    def floats(key: str) -> np.ndarray:
        return np.array([[np.nan if v is None else v for v in r[key]] for r in rows], dtype=float)

    return {
        "t": np.array([r["t"] for r in rows]),
        "xhat": floats("xhat"),
        "ybar": floats("ybar"),
        "transmissions": np.array([r["transmissions"] for r in rows], dtype=np.int64),
    }
