"""Conformance vectors: what the Python sensor node does on given samples, for the C node to replay.

:func:`node_vectors` feeds samples through :class:`~etobs.runtime.sensor.SensorNode` with
its :class:`~etobs.runtime.sampled_rule.SampledRule` and records, per sample, the values
read, whether the rule fired, the filter after the sample, the trigger function and the
size of its threshold, and the bytes of every packet sent. :func:`write_vectors` writes
them as text that the generated ``etobs_vectors.c`` reads (with the C library alone)::

    etobs-vectors 1
    node 0 values 1 session 0x1.9537...p+30 key 3f2a...
    sample 0 0x1.8p+1 fire 0 eta 0x1.4p+3 g -0x1.77...p+12 scale 0x1.77...p+12 packets 1 4554...
    ...

Numbers are hexadecimal floats (exact); ``g`` is the trigger function at the sample
(the node sends when it is ``>= 0``), ``scale`` its value at ``|e| = 0`` in magnitude (the
threshold), so that ``|g| / scale`` is the relative distance to the threshold at which a
single-precision node may decide otherwise.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from etobs import formulas as fm
from etobs.errors import InputError
from etobs.runtime.sampled_rule import SampledRule
from etobs.runtime.sensor import SensorNode

HEADER = "etobs-vectors 1"


@dataclass(frozen=True)
class Vectors:
    """One node's samples and what the Python sensor node did at each (module docstring)."""

    node: int
    session: float
    key: bytes
    k: tuple[int, ...]
    y: tuple[tuple[float, ...], ...]
    fire: tuple[bool, ...]
    eta: tuple[float, ...]
    g: tuple[float, ...]
    scale: tuple[float, ...]
    packets: tuple[tuple[bytes, ...], ...]

    @property
    def transmissions(self) -> int:
        return sum(self.fire)


def node_vectors(
    spec: Mapping[str, Any],
    period: float,
    *,
    node: int,
    key: bytes,
    session: float,
    samples: Sequence[Sequence[float]],
    first_k: int = 0,
) -> Vectors:
    """Run the Python sensor node on ``samples`` (sample ``first_k + i`` at ``t = k period``)."""
    if len(key) != 32:
        raise InputError(f"`key` must be the node's 32-byte key; got {len(key)} bytes")
    rule = SampledRule(spec, period)
    kind = rule.kind
    sent: list[bytes] = []
    sensor = SensorNode(node, key, rule, sent.append, session=session)
    trigger = fm.evaluator(kind.trigger, kind.constants)
    ks, ys, fires, etas, gs, scales, packets = [], [], [], [], [], [], []
    for i, row in enumerate(samples):
        y = [float(v) for v in row]
        k = first_k + i
        held = sensor.sent if sensor.sent is not None else y  # e = 0 at the first sample
        if kind.state == "clock":
            g, scale = float(rule.count + 1 - rule.every), 1.0
        else:
            ym = fm.norm(y) if kind.reads_y else None
            g = float(
                trigger(rule._rule, fm.norm([s - v for s, v in zip(held, y, strict=True)]), ym, rule.eta)
            )
            scale = abs(float(trigger(rule._rule, 0.0, ym, rule.eta)))
        before = sensor.transmissions
        sent.clear()
        sensor.sample(k * period, y)
        ks.append(k)
        ys.append(tuple(y))
        fires.append(sensor.transmissions > before)
        etas.append(float(rule.eta) if kind.state == "eta" else 0.0)
        gs.append(g)
        scales.append(scale)
        packets.append(tuple(sent))
    return Vectors(
        node, float(session), key, tuple(ks), tuple(ys), tuple(fires), tuple(etas), tuple(gs), tuple(scales),
        tuple(packets),
    )  # fmt: skip


def write_vectors(vectors: Vectors, path: str | Path) -> Path:
    """Write ``vectors`` as the text ``etobs_vectors.c`` reads (module docstring)."""
    v = vectors
    n = len(v.y[0]) if v.y else 0
    lines = [HEADER, f"node {v.node} values {n} session {v.session.hex()} key {v.key.hex()}"]
    for k, y, fire, eta, g, scale, pk in zip(v.k, v.y, v.fire, v.eta, v.g, v.scale, v.packets, strict=True):
        ys = " ".join(x.hex() for x in y)
        pks = " ".join(p.hex() for p in pk)
        lines.append(
            f"sample {k} {ys} fire {int(fire)} eta {eta.hex()} g {g.hex()} scale {scale.hex()} "
            f"packets {len(pk)}" + (f" {pks}" if pk else "")
        )
    out = Path(path)
    out.write_text("\n".join(lines) + "\n", encoding="ascii")
    return out
