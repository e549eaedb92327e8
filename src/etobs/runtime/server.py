"""The observer service over asyncio: UDP packets in, a JSON endpoint and a trace out.

Service time is ``(time.time() - epoch) * time_scale`` (``time_scale > 1`` runs faster
than real time, for tests and demos). Every ``tick`` of service time the observer is
advanced to ``now - hold_back`` and a line is appended to the trace, so a packet that
arrives within ``hold_back`` of its sample time is applied at that sample time (see
:class:`~etobs.runtime.service.ObserverCore`). Endpoints listen on the host given (the
tests use 127.0.0.1 only):

* UDP: the packets of :mod:`~etobs.runtime.packet`;
* HTTP ``GET /estimate``: the current estimate and counters as JSON.

The trace is JSON lines (one object per tick: ``t``, ``xhat``, ``ybar``,
``transmissions``, ``counts``), read back by :func:`read_trace`.
"""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from etobs.runtime.service import ObserverCore


class _Datagrams(asyncio.DatagramProtocol):
    def __init__(self, server: ObserverServer) -> None:
        self.server = server

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self.server.core.receive(data, self.server.now())


class ObserverServer:
    """Run an :class:`ObserverCore` behind UDP and HTTP endpoints.

    Parameters
    ----------
    core : ObserverCore
    epoch : float, optional
        ``time.time()`` at service time 0 (default: when :meth:`start` runs).
    time_scale : float
    tick : float
        Service time between trace lines and observer updates.
    hold_back : float
        How far behind the clock the observer runs, in service time.
    trace : path, optional
        Where to write the trace.

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
    ) -> None:
        self.core, self.epoch, self.time_scale = core, epoch, time_scale
        self.tick, self.hold_back = tick, hold_back
        self.trace_path = None if trace is None else Path(trace)
        self._transport: asyncio.DatagramTransport | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._http: asyncio.Server | None = None

    def feed(self, data: bytes) -> None:
        """Hand a datagram to the observer from another thread (e.g. the MQTT client's)."""
        assert self._loop is not None, "start() first"
        self._loop.call_soon_threadsafe(lambda: self.core.receive(data, self.now()))

    def now(self) -> float:
        """Service time."""
        assert self.epoch is not None
        return (time.time() - self.epoch) * self.time_scale

    async def start(
        self, host: str = "127.0.0.1", port: int = 0, http_port: int | None = None
    ) -> tuple[int, int | None]:
        """Open the endpoints; return the UDP and HTTP ports (0 picks free ones)."""
        if self.epoch is None:
            self.epoch = time.time()
        loop = self._loop = asyncio.get_running_loop()
        self._transport, _ = await loop.create_datagram_endpoint(
            lambda: _Datagrams(self), local_addr=(host, port)
        )
        udp = self._transport.get_extra_info("sockname")[1]
        web = None
        if http_port is not None:
            self._http = await asyncio.start_server(self._serve_http, host, http_port)
            web = self._http.sockets[0].getsockname()[1]
        return udp, web

    async def run_until(
        self, t_end: float, *, finished: Callable[[], bool] | None = None, linger: float = 30.0
    ) -> dict[str, Any]:
        """Tick until service time ``t_end``; return the final snapshot.

        With ``finished`` (e.g. "every sensor process has exited"), the observer stays
        ``hold_back`` short of ``t_end`` until it returns True, so that the senders' last
        packets are applied at their sample times; after ``linger`` wall seconds past
        ``t_end`` it stops anyway.
        """
        assert self.epoch is not None, "start() first"
        fh = open(self.trace_path, "w") if self.trace_path is not None else None
        give_up = self.epoch + t_end / self.time_scale + linger
        try:
            next_tick = 0.0
            while True:
                done = finished is None or finished() or time.time() > give_up
                target = min(self.now() - self.hold_back, t_end if done else t_end - self.hold_back)
                if done and self.now() >= t_end:
                    target = t_end
                self.core.advance(target)
                if fh is not None and (target >= next_tick or target >= t_end):  # the end always
                    fh.write(json.dumps(self.core.snapshot()) + "\n")
                    next_tick = target + self.tick
                if target >= t_end:
                    break
                await asyncio.sleep(self.tick / self.time_scale / 2)
            return self.core.snapshot()
        finally:
            if fh is not None:
                fh.close()

    async def close(self) -> None:
        """Close the endpoints."""
        if self._transport is not None:
            self._transport.close()
        if self._http is not None:
            self._http.close()
            await self._http.wait_closed()

    async def _serve_http(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            line = await asyncio.wait_for(reader.readline(), timeout=2.0)
            parts = line.decode("latin-1").split()
            if len(parts) >= 2 and parts[0] == "GET" and parts[1] == "/estimate":
                body, status = json.dumps(self.core.snapshot()).encode(), "200 OK"
            else:
                body, status = b'{"error": "only GET /estimate"}', "404 Not Found"
            head = (
                f"HTTP/1.0 {status}\r\nContent-Type: application/json\r\nContent-Length: {len(body)}\r\n\r\n"
            )
            writer.write(head.encode() + body)
            await writer.drain()
        except (TimeoutError, ConnectionError, UnicodeDecodeError, ValueError):  # ValueError: line too long
            pass
        finally:
            writer.close()


def read_trace(path: str | Path) -> dict[str, np.ndarray]:
    """A trace as arrays: ``t`` (K,), ``xhat`` (K, n_x), ``ybar`` (K, n_y), ``transmissions`` (K, N)."""
    rows = [json.loads(line) for line in Path(path).read_text().splitlines() if line.strip()]
    return {
        "t": np.array([r["t"] for r in rows]),
        "xhat": np.array([r["xhat"] for r in rows], dtype=float),
        "ybar": np.array([[np.nan if v is None else v for v in r["ybar"]] for r in rows], dtype=float),
        "transmissions": np.array([r["transmissions"] for r in rows], dtype=np.int64),
    }
