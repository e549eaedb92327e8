"""A deployment spec: the problem, the sampling, the endpoints and the secret (validated, frozen).

A TOML file (the packaged ``robot_arm`` is ``runtime/data/robot_arm_live.toml``): every
key of ``[system]``, ``[runtime]`` and ``[plant]``, its type, default and limits, and a
minimal and a full example are in ``docs/specs.md`` ("Deployment"), which a test keeps in
step with :func:`parse_deployment`.
"""

from __future__ import annotations

import os
import secrets
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from etobs._spec import FACTORY, TABLE, SpecError, check_tree, spec_path
from etobs._spec import keys as _keys
from etobs._spec import name as _name
from etobs._spec import number as _number
from etobs._validate import shown
from etobs.errors import InputError
from etobs.estimation.problem import EstimationProblem
from etobs.examples.registry import locate_factory, make_problem
from etobs.model.sampled import Sampled
from etobs.runtime.files import open_regular
from etobs.runtime.server import is_loopback

#: Largest secret or token read: they are 32 and 43 bytes.
MAX_SECRET_BYTES = 4096


def read_secret(path: Path, key: str, *, create: bytes | None = None) -> bytes:
    """The bytes of the secret file ``path`` (named ``key`` in errors), refused if others can read it.

    With ``create`` a missing file is written with those bytes, mode 600. A file that the
    group or others may read is refused, naming its mode and the fix: its holder could
    forge packets (the deployment secret) or read the estimate (the HTTP token). It is
    opened without blocking and refused unless it is a regular file (a FIFO hung
    ``etobs serve`` in ``open()``): :func:`~etobs.runtime.files.open_regular`.
    """
    if not path.exists() and not path.is_symlink():
        if create is None:
            raise SpecError(f"`{key}` {str(path)!r} does not exist; `etobs serve` creates it")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
            with os.fdopen(fd, "wb") as fh:
                fh.write(create)
        except OSError as exc:
            raise SpecError(f"`{key}` {str(path)!r} cannot be created: {exc.strerror or exc}") from exc
    try:
        with open_regular(path, f"`{key}`") as fh:  # the mode of the file that is read (no window to swap it)
            mode = stat.S_IMODE(os.fstat(fh.fileno()).st_mode)
            if os.name == "posix" and mode & 0o077:
                raise SpecError(
                    f"`{key}` {str(path)!r} has mode {mode:04o}: the group or others may read it; "
                    f"run `chmod 600 {path}`"
                )
            data = fh.read(MAX_SECRET_BYTES + 1)
    except InputError as exc:  # not a regular file, or it cannot be opened
        raise SpecError(str(exc)) from exc
    except OSError as exc:
        raise SpecError(f"`{key}` {str(path)!r} cannot be read: {exc}") from exc
    if len(data) > MAX_SECRET_BYTES:
        raise SpecError(
            f"`{key}` {str(path)!r} holds more than {MAX_SECRET_BYTES} bytes; is it the right file?"
        )
    return data


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
    http_host: str = "127.0.0.1"
    http_token_file: Path | None = None
    state_file: Path | None = None
    max_value: float = 1e12

    def problem(self) -> EstimationProblem:
        """The estimation problem of ``[system]`` (a factory marked with :func:`etobs.factory`)."""
        return make_problem(self.factory, self.params, "system.params")

    def node_rule(self, problem: EstimationProblem, node: int) -> tuple[dict[str, Any], float]:
        """Node ``node``'s rule as a sensor runs it and its sampling period: ``runtime.period``.

        A node whose rule is sampled already (:class:`~etobs.model.Sampled`) must be sampled
        at ``runtime.period`` with phase 0 (a node samples at ``k T``): else what runs would
        not be what was simulated.

        Raises
        ------
        InputError
            A node out of range, a rule a sensor node does not run (named), a sampled rule
            at another period.

        """
        if isinstance(node, bool) or not isinstance(node, int) or not 0 <= node < problem.n_nodes:
            raise InputError(f"--node must be in 0..{problem.n_nodes - 1}; got {node!r}")
        rule = problem.nodes[node].rule
        if isinstance(rule, Sampled) and (rule.period != self.period or rule.phase != 0.0):
            raise SpecError(
                f"node {node}'s rule is sampled at period {rule.period!r} s, phase {rule.phase!r} s in the "
                f"model, but a node samples at k * `runtime.period` = k * {self.period!r} s: make them equal "
                "(what runs must be what was simulated)"
            )
        return rule.sensor_spec(), self.period

    def secret(self, *, create: bool = False) -> bytes:
        """The deployment secret; with ``create`` a new one is written (mode 600) if missing."""
        data = read_secret(
            self.secret_file, "runtime.secret_file", create=secrets.token_bytes(32) if create else None
        )
        if len(data) < 16:
            raise SpecError(
                f"`runtime.secret_file` {str(self.secret_file)!r} holds {len(data)} bytes; "
                "at least 16 are needed"
            )
        return data

    @property
    def marks_file(self) -> Path:
        """The service's high-water marks: ``state_file``, or the secret's name with ``.state``."""
        return self.state_file or self.secret_file.with_suffix(".state")

    @property
    def token_file(self) -> Path | None:
        """Where the HTTP token is, if ``GET /estimate`` needs one (set, or off loopback)."""
        if self.http_port is None:
            return None
        if self.http_token_file is not None:
            return self.http_token_file
        if is_loopback(self.http_host):
            return None
        return self.secret_file.with_name(self.secret_file.stem + ".http-token")

    def token(self) -> bytes | None:
        """The bearer token of ``GET /estimate`` (created, mode 600, if missing), or None."""
        path = self.token_file
        if path is None:
            return None
        token = read_secret(
            path, "runtime.http_token_file", create=secrets.token_urlsafe(32).encode()
        ).strip()
        if len(token) < 16 or not all(33 <= b < 127 for b in token):
            raise SpecError(
                f"`runtime.http_token_file` {str(path)!r} must hold at least 16 printable ASCII "
                f"characters (no spaces); it holds {len(token)} bytes"
            )
        return token


def parse_deployment(raw: dict[str, Any], base: Path = Path(".")) -> Deployment:
    """Validate a deployment spec (the parsed TOML); relative paths are taken from ``base``."""
    check_tree(raw)
    top = _keys("spec", raw, {"system": TABLE, "runtime": TABLE}, {"name", "plant"})
    system = _keys("system", top["system"], {"factory": FACTORY}, {"params"})
    params = system.get("params", {})
    if not isinstance(params, dict):
        raise SpecError(f"`system.params` must be a table of keyword arguments; got {shown(params)}")
    rt = _keys(
        "runtime",
        top["runtime"],
        {"period": "a number > 0 (s)", "duration": "a number > 0 (s)"},
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
            "http_host",
            "http_token_file",
            "state_file",
            "max_value",
        },
    )
    transport = rt.get("transport", "udp")
    if transport not in ("udp", "mqtt"):
        raise SpecError(f"`runtime.transport` must be 'udp' or 'mqtt'; got {shown(transport)}")
    broker = rt.get("broker", "127.0.0.1:1883")
    b_host, _, b_port = broker.rpartition(":") if isinstance(broker, str) else ("", "", "")
    if not b_host or not b_port.isdigit() or not 0 < int(b_port) <= 65535:
        raise SpecError(
            f"`runtime.broker` must be a string 'host:port' (port 1 to 65535); got {shown(broker)}"
        )
    name = _name("name", top.get("name", "deployment"))
    topic = rt.get("topic", f"etobs/{name}")
    if not isinstance(topic, str) or not topic or any(c in topic for c in "+#"):
        raise SpecError(
            f"`runtime.topic` must be a non-empty string without wildcards (+, #); got {shown(topic)}"
        )
    host = rt.get("host", "127.0.0.1")
    if not isinstance(host, str) or not host:
        raise SpecError(f"`runtime.host` must be a host name or address (a string); got {shown(host)}")

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
            raise SpecError(f"`plant.x0` must be a non-empty list of numbers; got {shown(x0)}")
        x0 = tuple(float(_number(f"plant.x0[{i}]", v)) for i, v in enumerate(x0))
    http_host = rt.get("http_host", "127.0.0.1")
    if not isinstance(http_host, str) or not http_host:
        raise SpecError(
            f"`runtime.http_host` must be a host name or address (a string); got {shown(http_host)}"
        )

    def path(key: str, default: str | None) -> Path | None:
        value = rt.get(key, default)
        if value is None:
            return None
        if not isinstance(value, str) or not value:
            raise SpecError(f"`runtime.{key}` must be a file name; got {shown(value)}")
        return spec_path(value, base)

    secret_file = path("secret_file", None) or base / "etobs.secret"
    return Deployment(
        name=name,
        factory=locate_factory(system["factory"], base),  # a relative file: from base, as the files
        params=dict(params),
        period=float(_number("runtime.period", rt["period"], lower=0.0, strict=True)),
        duration=float(_number("runtime.duration", rt["duration"], lower=0.0, strict=True)),
        time_scale=float(_number("runtime.time_scale", rt.get("time_scale", 1.0), lower=0.0, strict=True)),
        host=host,
        port=int(port("port", 47100) or 0),
        http_port=port("http_port", None),
        dt=float(_number("runtime.dt", rt.get("dt", 1e-3), lower=0.0, strict=True)),
        hold_back=float(_number("runtime.hold_back", rt.get("hold_back", 0.05), lower=0.0)),
        secret_file=secret_file,
        x0=x0,
        transport=transport,
        broker=(b_host, int(b_port)),
        topic=topic,
        http_host=http_host,
        http_token_file=path("http_token_file", None),
        state_file=path("state_file", None),
        max_value=float(_number("runtime.max_value", rt.get("max_value", 1e12), lower=0.0, strict=True)),
    )
