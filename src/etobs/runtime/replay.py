"""The reference for a deployment: the same sensor nodes and observer, run offline.

:func:`sample_outputs` simulates the plant and reads its measured outputs at the
sampling instants ``t_k = k T``. :func:`replay` feeds those samples through the very
:class:`~etobs.runtime.sensor.SensorNode` and :class:`~etobs.runtime.service.ObserverCore`
a deployment runs, with no network in between. A live run on loopback should give the
same transmissions and, up to the packets' lateness, the same estimate.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from etobs.errors import InputError
from etobs.estimation.problem import EstimationProblem
from etobs.estimation.simulate import simulate
from etobs.hybrid.options import SaveAt
from etobs.runtime.sampled_rule import SampledRule
from etobs.runtime.sensor import SensorNode
from etobs.runtime.service import ObserverCore


def sample_outputs(
    problem: EstimationProblem, x0: Any, t_end: float, period: float
) -> tuple[np.ndarray, np.ndarray]:
    """Sample times ``t_k = k period <= t_end`` and the measured outputs there, ``(K,)`` and ``(K, n_y)``."""
    if period <= 0:
        raise InputError(f"`period` must be > 0; got {period}")
    t = period * np.arange(int(np.floor(t_end / period + 1e-9)) + 1)
    res = simulate(problem, x0, float(t[-1]), save=SaveAt(steps=False, grid=t))
    if not res.ok:
        raise InputError(f"the plant simulation failed: {res.messages()[0]}")
    x = res.solution.grid.x[0][:, problem.layout.x]
    return t, problem.ytilde(t, x)


@dataclass(frozen=True)
class Replay:
    """Transmissions per node, the observer's estimate at every sample, and the plant's state."""

    t: np.ndarray
    xhat: np.ndarray
    transmissions: tuple[int, ...]
    packets: tuple[tuple[int, int, float], ...]  # (node, seq, t) of every transmission


def replay(
    problem: EstimationProblem,
    keys: Mapping[int, bytes],
    t: np.ndarray,
    y: np.ndarray,
    period: float,
    *,
    z0: Any = None,
    dt: float = 1e-3,
) -> Replay:
    """Run the nodes on the samples ``(t, y)`` and the observer on their packets, no network.

    It is also the reference of a live run whose service was restarted: a resync
    changes no node's rule state (:mod:`etobs.runtime.sensor`).
    """
    core = ObserverCore(problem, keys, z0=z0, t0=float(t[0]), dt=dt)
    inbox: list[bytes] = []
    nodes = [
        SensorNode(i, keys[i], SampledRule(nd.rule.sensor_spec(), period), inbox.append)
        for i, nd in enumerate(problem.nodes)
    ]
    xhat, packets = [], []
    for k, tk in enumerate(t):
        for i, (node, nd) in enumerate(zip(nodes, problem.nodes, strict=True)):
            p = node.sample(float(tk), y[k, list(nd.outputs)])
            if p is not None and not p.initial:
                packets.append((i, p.seq, float(tk)))
        for data in inbox:
            core.receive(data)
        inbox.clear()
        core.advance(float(tk))
        xhat.append(core.xhat())
    return Replay(
        t=np.asarray(t),
        xhat=np.array(xhat),
        transmissions=tuple(n.transmissions for n in nodes),
        packets=tuple(packets),
    )
