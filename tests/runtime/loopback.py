"""Run sensors (threads) and the observer server (asyncio) on 127.0.0.1, bounded in time."""

import asyncio
import random
import socket
import threading
import time

import numpy as np

from etobs.runtime.packet import node_keys
from etobs.runtime.replay import replay, sample_outputs
from etobs.runtime.sampled_rule import SampledRule
from etobs.runtime.sensor import SensorNode, run, udp_sender
from etobs.runtime.server import ObserverServer
from etobs.runtime.service import ObserverCore

KEYS = node_keys(b"loopback test secret", range(8))


def reference(problem, x0, duration, period):
    t, y = sample_outputs(problem, x0, duration, period)
    return t, y, replay(problem, KEYS, t, y, period)


class LossyLink:
    """A UDP relay on 127.0.0.1 that drops, duplicates and delays datagrams (seeded)."""

    def __init__(self, target_port, *, loss=0.0, duplicate=0.0, max_delay=0.0, seed=0, until=None):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.port = self.sock.getsockname()[1]
        self.target = ("127.0.0.1", target_port)
        self.loss, self.duplicate, self.max_delay = loss, duplicate, max_delay
        self.rng = random.Random(seed)
        self.until = until  # stop disturbing after this many datagrams
        self.stats = {"in": 0, "dropped": 0, "duplicated": 0, "delayed": 0, "out": 0}
        self._lock = threading.Lock()
        self._pending = 0  # delayed datagrams not yet sent
        self._stop = threading.Event()
        self._out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.thread = threading.Thread(target=self._relay, daemon=True)
        self.thread.start()

    def _relay(self):
        while not self._stop.is_set():
            try:
                data, _ = self.sock.recvfrom(4096)
            except TimeoutError:
                continue
            self.stats["in"] += 1
            disturb = self.until is None or self.stats["in"] <= self.until
            if disturb and self.rng.random() < self.loss:
                self.stats["dropped"] += 1
                continue
            copies = 2 if disturb and self.rng.random() < self.duplicate else 1
            self.stats["duplicated"] += copies - 1
            delay = self.rng.uniform(0, self.max_delay) if disturb and self.max_delay else 0.0
            if delay:
                self.stats["delayed"] += 1
                with self._lock:
                    self._pending += 1
                threading.Timer(delay, self._send, (data, copies, True)).start()
            else:
                self._send(data, copies)

    def _send(self, data, copies, delayed=False):
        for _ in range(copies):
            self._out.sendto(data, self.target)
        with self._lock:
            self.stats["out"] += copies
            self._pending -= delayed

    def drained(self, sent, received):
        """Whether the ``sent`` datagrams all reached the relay and all it sent on were ``received``.

        On loopback nothing is lost, so a loaded machine delays this but cannot make it false
        for good; the server stops waiting after its ``linger`` anyway.
        """
        with self._lock:
            return self.stats["in"] == sent and self._pending == 0 and self.stats["out"] == received

    def close(self):
        self._stop.set()
        self.thread.join(timeout=2)
        time.sleep(0.05)  # let delayed copies go out
        self.sock.close()
        self._out.close()


def live(
    problem,
    y,
    period,
    duration,
    *,
    time_scale,
    link=None,
    hostile=None,
    hold_back=0.05,
    trace=None,
    broker=None,
):
    """Run the server and one sensor thread per node on loopback; return (snapshot, server, extras).

    With ``broker = (host, port)`` the packets go through MQTT instead of UDP.
    """

    async def main():
        core = ObserverCore(problem, KEYS)
        srv = ObserverServer(core, time_scale=time_scale, hold_back=hold_back, trace=trace)
        srv.epoch = time.time() + 0.3
        port, web = await srv.start(port=0, http_port=0)
        relay = LossyLink(port, **link) if link else None
        target = relay.port if relay else port
        sent, sockets = [], []
        receiver = None
        if broker is not None:
            from etobs.runtime.mqtt import MqttReceiver, MqttSender

            receiver = MqttReceiver(*broker, "etobs/test", srv.feed)
            time.sleep(0.2)  # let the subscription settle before the first packet

        def sender(i=0):
            udp = MqttSender(*broker, "etobs/test", i) if broker else udp_sender("127.0.0.1", target)
            sockets.append(udp)

            def send(data):
                sent.append(data)
                udp(data)

            return send

        nodes = [
            SensorNode(i, KEYS[i], SampledRule(nd.rule.sensor_spec(), period), sender(i))
            for i, nd in enumerate(problem.nodes)
        ]
        srv.epoch = time.time() + 0.3  # once every sender is connected
        threads = [
            threading.Thread(
                target=run,
                args=(
                    node,
                    lambda t, i=i: y[round(t / period), list(problem.nodes[i].outputs)],
                    period,
                    duration,
                ),
                kwargs={"epoch": srv.epoch, "time_scale": time_scale},
                daemon=True,
            )
            for i, node in enumerate(nodes)
        ]
        for th in threads:
            th.start()
        extra = {}
        if hostile is not None:
            extra["hostile"] = threading.Thread(target=hostile, args=(port, sent, srv.epoch), daemon=True)
            extra["hostile"].start()

        def finished():
            # the senders are done and, behind a relay, everything it sent on has arrived:
            # stopping earlier would leave datagrams unread and the counts short
            if any(th.is_alive() for th in threads):
                return False
            return relay is None or relay.drained(len(sent), sum(core.counts.values()))

        snap = await asyncio.wait_for(
            srv.run_until(duration, finished=finished), timeout=60 + duration / time_scale
        )
        for th in threads:
            th.join(timeout=5)
        for udp in sockets:
            udp.close()
        if receiver is not None:
            receiver.close()
        if "hostile" in extra:
            extra["hostile"].join(timeout=5)
        extra["estimate"] = await _get(web)
        await srv.close()
        if relay:
            relay.close()
            extra["link"] = relay.stats
        extra["nodes"] = nodes
        return snap, srv, extra

    return asyncio.run(main())


async def _get(port):
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(b"GET /estimate HTTP/1.0\r\n\r\n")
    await writer.drain()
    data = await asyncio.wait_for(reader.read(), timeout=5)
    writer.close()
    head, _, body = data.partition(b"\r\n\r\n")
    return head.split(b"\r\n")[0].decode(), body


def final_gap(snap, ref):
    return float(np.max(np.abs(np.array(snap["xhat"]) - ref.xhat[-1])))
