"""MQTT transport (optional extra ``mqtt``: paho-mqtt), for deployments with a broker.

Node ``i`` publishes each packet, unchanged (the packet carries its own authentication),
on ``<topic>/node/<i>`` with QoS 0; the observer subscribes to ``<topic>/node/+``. The
broker is not trusted: a packet it alters, replays or invents is rejected by the
observer like any other (:mod:`etobs.runtime.packet`). The sensor core stays on the
standard library; only this transport needs paho-mqtt.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any


def _paho() -> Any:
    try:
        import paho.mqtt.client as mqtt
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("the MQTT transport needs paho-mqtt: pip install 'etobs[mqtt]'") from exc
    return mqtt


def _client_id(role: str) -> str:
    import uuid

    return f"etobs-{role}-{uuid.uuid4().hex[:12]}"  # unique: a duplicate id would knock us off


def _connect(
    client: Any, host: str, port: int, timeout: float, on_connect: Callable[[], object] = lambda: None
) -> None:
    import threading

    ready = threading.Event()

    def connected(c: Any, u: Any, flags: Any, reason: Any, props: Any) -> None:
        on_connect()  # also after an automatic reconnect
        ready.set()

    client.on_connect = connected
    try:
        client.connect(host, port, keepalive=30)
    except (OSError, ValueError, UnicodeError) as exc:  # refused, unknown host, bad port
        raise ConnectionError(f"cannot reach the MQTT broker at {host}:{port}: {exc}") from exc
    client.loop_start()
    if not ready.wait(timeout):
        client.loop_stop()
        raise ConnectionError(f"no answer from the MQTT broker at {host}:{port} within {timeout:g} s")


class MqttSender:
    """Publish node ``node``'s packets on ``<topic>/node/<node>``; ``close()`` when done."""

    def __init__(self, host: str, port: int, topic: str, node: int, *, timeout: float = 10.0) -> None:
        mqtt = _paho()
        self.topic = f"{topic}/node/{node}"
        self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=_client_id(f"node{node}"))
        _connect(self.client, host, port, timeout)

    def __call__(self, data: bytes) -> None:
        self.client.publish(self.topic, data, qos=0)

    def close(self) -> None:
        self.client.loop_stop()
        self.client.disconnect()

    def __enter__(self) -> MqttSender:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class MqttReceiver:
    """Subscribe to every node's topic and hand each payload to ``deliver`` (from paho's thread)."""

    def __init__(
        self, host: str, port: int, topic: str, deliver: Callable[[bytes], object], *, timeout: float = 10.0
    ) -> None:
        mqtt = _paho()
        import threading

        self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=_client_id("observer"))
        self.client.on_message = lambda c, u, msg: deliver(msg.payload)  # bytes; deliver cuts it short
        acked = threading.Event()
        self.client.on_subscribe = lambda c, u, mid, codes, props: acked.set()
        # subscribe on every (re)connect: a broker does not keep a clean session's subscriptions
        _connect(self.client, host, port, timeout, lambda: self.client.subscribe(f"{topic}/node/+", qos=0))
        if not acked.wait(timeout):  # packets published before the broker's answer would be lost
            self.close()
            raise ConnectionError(f"the MQTT broker at {host}:{port} did not confirm the subscription")

    def close(self) -> None:
        self.client.loop_stop()
        self.client.disconnect()
