"""A deployment spec: the problem, the sampling, the endpoints and the secret (validated, frozen).

TOML (the packaged ``robot_arm`` is ``runtime/data/robot_arm_live.toml``)::

    name = "robot_arm_live"
    [system]
    factory = "robot_arm"          # its plant, observer and nodes' rules
    params = {}
    [runtime]
    period = 0.002                 # sensors' sampling period [s]
    duration = 10.0                # plant time to run [s]
    time_scale = 1.0               # > 1: faster than real time (demos, tests)
    host = "127.0.0.1"
    port = 47100                   # UDP, the observer's
    http_port = 47101              # GET /estimate
    dt = 0.001                     # observer integration step
    hold_back = 0.05               # observer runs this far behind the clock [s]
    secret_file = "etobs.secret"   # 32 random bytes; per-node keys derive from it
    transport = "udp"              # or "mqtt" (extra `mqtt`), with:
    broker = "127.0.0.1:1883"      # the MQTT broker
    topic = "etobs/robot_arm_live" # nodes publish on <topic>/node/<i>
    [plant]                        # the simulated plant the sensors read (demo, tests)
    x0 = [3.0, 2.0, 3.0, -2.0]
"""

from __future__ import annotations

import os
import secrets
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from etobs._spec import SpecError
from etobs._spec import keys as _keys
from etobs._spec import number as _number
from etobs.estimation.problem import EstimationProblem
from etobs.examples.registry import resolve_factory


@dataclass(frozen=True)
class Deployment:
    """A validated deployment spec; build it with :func:`parse_deployment`."""

    name: str
    factory: str
    params: dict[str, Any]
    period: float
    duration: float
    time_scale: float
    host: str
    port: int
    http_port: int | None
    dt: float
    hold_back: float
    secret_file: Path
    x0: tuple[float, ...] | None
    transport: str = "udp"
    broker: tuple[str, int] = ("127.0.0.1", 1883)
    topic: str = "etobs/deployment"

    def problem(self) -> EstimationProblem:
        """The estimation problem of ``[system]``."""
        pb = resolve_factory(self.factory)(**self.params)
        if not isinstance(pb, EstimationProblem):
            raise SpecError(
                f"the factory {self.factory!r} returned {type(pb).__name__}, not an EstimationProblem"
            )
        return pb

    def secret(self, *, create: bool = False) -> bytes:
        """The deployment secret; with ``create`` a new one is written (mode 600) if missing."""
        path = self.secret_file
        if not path.exists():
            if not create:
                raise SpecError(
                    f"`runtime.secret_file` {str(path)!r} does not exist; `etobs serve` creates it"
                )
            path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
            with os.fdopen(fd, "wb") as fh:
                fh.write(secrets.token_bytes(32))
        data = path.read_bytes()
        if len(data) < 16:
            raise SpecError(
                f"`runtime.secret_file` {str(path)!r} holds {len(data)} bytes; at least 16 are needed"
            )
        return data


def parse_deployment(raw: dict[str, Any], base: Path = Path(".")) -> Deployment:
    """Validate a deployment spec (the parsed TOML); relative paths are taken from ``base``."""
    top = _keys("spec", raw, {"system", "runtime"}, {"name", "plant"})
    system = _keys("system", top["system"], {"factory"}, {"params"})
    params = system.get("params", {})
    if not isinstance(params, dict):
        raise SpecError("`system.params` must be a table of keyword arguments")
    rt = _keys(
        "runtime",
        top["runtime"],
        {"period", "duration"},
        {
            "time_scale",
            "host",
            "port",
            "http_port",
            "dt",
            "hold_back",
            "secret_file",
            "transport",
            "broker",
            "topic",
        },
    )
    transport = rt.get("transport", "udp")
    if transport not in ("udp", "mqtt"):
        raise SpecError(f"`runtime.transport` must be 'udp' or 'mqtt'; got {transport!r}")
    broker = rt.get("broker", "127.0.0.1:1883")
    b_host, _, b_port = str(broker).rpartition(":")
    if not b_host or not b_port.isdigit() or not 0 < int(b_port) <= 65535:
        raise SpecError(f"`runtime.broker` must be 'host:port'; got {broker!r}")
    name = str(top.get("name", "deployment"))
    topic = rt.get("topic", f"etobs/{name}")
    if not isinstance(topic, str) or not topic or any(c in topic for c in "+#"):
        raise SpecError(f"`runtime.topic` must be a topic without wildcards; got {topic!r}")
    host = rt.get("host", "127.0.0.1")
    if not isinstance(host, str) or not host:
        raise SpecError(f"`runtime.host` must be a host name or address; got {host!r}")

    def port(key: str, default: int | None) -> int | None:
        value = rt.get(key, default)
        if value is None:
            return None
        value = int(_number(f"runtime.{key}", value, lower=0, integer=True))
        if value > 65535:
            raise SpecError(f"`runtime.{key}` must be <= 65535; got {value}")
        return value

    plant = _keys("plant", top.get("plant", {}), set(), {"x0"})
    x0 = plant.get("x0")
    if x0 is not None:
        if not isinstance(x0, list) or not x0:
            raise SpecError(f"`plant.x0` must be a list of numbers; got {x0!r}")
        x0 = tuple(float(_number(f"plant.x0[{i}]", v)) for i, v in enumerate(x0))
    secret_file = Path(rt.get("secret_file", "etobs.secret"))
    return Deployment(
        name=name,
        factory=system["factory"],
        params=dict(params),
        period=float(_number("runtime.period", rt["period"], lower=0.0, strict=True)),
        duration=float(_number("runtime.duration", rt["duration"], lower=0.0, strict=True)),
        time_scale=float(_number("runtime.time_scale", rt.get("time_scale", 1.0), lower=0.0, strict=True)),
        host=host,
        port=int(port("port", 47100) or 0),
        http_port=port("http_port", None),
        dt=float(_number("runtime.dt", rt.get("dt", 1e-3), lower=0.0, strict=True)),
        hold_back=float(_number("runtime.hold_back", rt.get("hold_back", 0.05), lower=0.0)),
        secret_file=secret_file if secret_file.is_absolute() else base / secret_file,
        x0=x0,
        transport=transport,
        broker=(b_host, int(b_port)),
        topic=topic,
    )
