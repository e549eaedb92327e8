"""The observer service's state machine: packets in, estimate out (no I/O here).

:class:`ObserverCore` holds the observer state ``z``, the held outputs ``ybar`` and, per
node, the last sequence number applied and a window of recent ones. It integrates
``z' = f_o(t, z, u, ybar, yhat)`` (eq. (7)) with classical Runge--Kutta steps of at most
``dt`` between events. A packet is checked (:func:`~etobs.runtime.packet.decode`), then:

* ``replayed`` if its sequence number was already accepted (a copy);
* ``stale`` if it is older than the last one accepted (overtaken);
* ``future`` if its sample time is more than ``max_lead`` ahead of the service clock
  (a wrong clock or epoch; accepting it would stall the observer);
* otherwise accepted. A packet whose sample time is still ahead of the observer waits
  in a queue and is applied when the observer reaches that time, in time order across
  nodes (so it acts from when it was measured); one that arrives after the observer
  passed its time is applied at once and counted in ``late``.

Every rejection is counted by kind; nothing raises. The asyncio transports
(:mod:`etobs.runtime.server`) feed it.
"""

from __future__ import annotations

import heapq
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from etobs.errors import InputError
from etobs.estimation.problem import EstimationProblem
from etobs.runtime.packet import Packet, PacketError, decode

VERDICTS = ("applied", "initial", "replayed", "stale", "future", "malformed", "forged", "wrong_size")


@dataclass
class NodeState:
    """What the observer knows of one node."""

    outputs: np.ndarray
    last_seq: int = 0
    recent: deque[int] = field(default_factory=lambda: deque(maxlen=256))
    transmissions: int = 0


class ObserverCore:
    """The observer of ``problem`` run on packets (see the module docstring).

    Parameters
    ----------
    problem : EstimationProblem
        Its plant (``h``), observer and nodes; its rules run on the sensors.
    keys : mapping of int to bytes
        The key of each node id (node ``i`` is ``problem.nodes[i]``).
    z0 : array_like, optional
        Observer initial state (default zero).
    t0 : float
        Start time.
    dt : float
        Largest integration step.
    max_lead : float
        Packets stamped more than this ahead of the clock given to :meth:`receive` are
        rejected as ``future``.

    """

    def __init__(
        self,
        problem: EstimationProblem,
        keys: Mapping[int, bytes],
        *,
        z0: Any = None,
        t0: float = 0.0,
        dt: float = 1e-3,
        max_lead: float = 1.0,
    ) -> None:
        if not isinstance(problem, EstimationProblem):
            raise InputError(f"`problem` must be an EstimationProblem; got {type(problem).__name__}")
        if problem.extended:
            raise InputError(
                "the observer service runs the base setting: no input nodes, hold='output', no network"
            )
        if dt <= 0:
            raise InputError(f"`dt` must be > 0; got {dt}")
        missing = [i for i in range(problem.n_nodes) if i not in keys]
        if missing:
            raise InputError(f"`keys` has no key for nodes {missing}")
        self.problem, self.keys, self.dt = problem, dict(keys), float(dt)
        n_z = problem.observer.n_z
        self.z = np.zeros(n_z) if z0 is None else np.asarray(z0, dtype=float).reshape(n_z)
        self.t = float(t0)
        self.ybar = np.full(problem.plant.n_y, np.nan)
        self.nodes = {i: NodeState(outputs=np.array(nd.outputs)) for i, nd in enumerate(problem.nodes)}
        self.counts = dict.fromkeys(VERDICTS, 0)
        self.max_lead = float(max_lead)
        self._queue: list[tuple[float, int, int, Packet]] = []  # (t, node, seq, packet)
        self.late = 0
        self.max_lateness = 0.0

    @property
    def ready(self) -> bool:
        """Whether every node's initial value has arrived (the observer runs only then)."""
        return bool(np.all(np.isfinite(self.ybar)))

    def xhat(self) -> np.ndarray:
        """The estimate ``psi(z)``."""
        return np.asarray(self.problem.observer.call_psi(self.z, self.problem.plant.n_x), dtype=float)

    def _f(self, t: float, z: np.ndarray) -> np.ndarray:
        """``f_o(t, z, u(t), ybar, h(psi(z)))`` of the one run the service observes."""
        pb = self.problem
        u = pb.u(np.array([t]))[0]
        yhat = np.asarray(pb.plant.call_h(pb.observer.call_psi(z, pb.plant.n_x)), dtype=float)
        return np.asarray(pb.observer.call_f_o(t, z, u, self.ybar.copy(), yhat), dtype=float)

    def advance(self, t: float) -> None:
        """Integrate the observer to time ``t``, applying the queued packets on the way."""
        while self._queue and self._queue[0][0] <= t:
            tk, _, _, p = heapq.heappop(self._queue)
            self._integrate(tk)
            self._hold(p)
        self._integrate(t)

    def _integrate(self, t: float) -> None:
        if t <= self.t:
            return
        if not self.ready:  # nothing to run on yet: the observer waits at its initial state
            self.t = t
            return
        n = max(1, int(np.ceil((t - self.t) / self.dt - 1e-9)))
        h = (t - self.t) / n
        z = self.z
        for k in range(n):
            s = self.t + k * h
            k1 = self._f(s, z)
            k2 = self._f(s + h / 2, z + h / 2 * k1)
            k3 = self._f(s + h / 2, z + h / 2 * k2)
            k4 = self._f(s + h, z + h * k3)
            z = z + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        self.z, self.t = z, t

    def receive(self, data: bytes, now: float | None = None) -> str:
        """Check and accept one datagram; return the verdict (one of :data:`VERDICTS`).

        ``now`` is the service clock (``None``: no clock, as in an offline replay).
        """
        try:
            p = decode(data, self.keys)
        except PacketError as exc:
            return self._count(exc.kind)
        node = self.nodes.get(p.node)
        if node is None:  # a key exists but the problem has no such node
            return self._count("forged")
        if len(p.values) != node.outputs.size:
            return self._count("wrong_size")
        if p.seq in node.recent:
            return self._count("replayed")
        if p.seq <= node.last_seq:
            return self._count("stale")
        if now is not None and p.t > now + self.max_lead:
            return self._count("future")
        node.last_seq = p.seq
        node.recent.append(p.seq)
        if not p.initial:
            node.transmissions += 1
        if p.t > self.t:
            heapq.heappush(self._queue, (p.t, p.node, p.seq, p))
        else:
            if p.t < self.t:
                self.late += 1
                self.max_lateness = max(self.max_lateness, self.t - p.t)
            self._hold(p)
        return self._count("initial" if p.initial else "applied")

    def _hold(self, p: Packet) -> None:
        self.ybar[self.nodes[p.node].outputs] = p.values  # eq. (5): ybar_i+ = y_i(t_k)

    def _count(self, verdict: str) -> str:
        self.counts[verdict] += 1
        return verdict

    def snapshot(self) -> dict[str, Any]:
        """The estimate and counters, JSON-ready."""
        return {
            "t": self.t,
            "xhat": [float(v) for v in self.xhat()],
            "ybar": [None if not np.isfinite(v) else float(v) for v in self.ybar],
            "transmissions": [self.nodes[i].transmissions for i in sorted(self.nodes)],
            "last_seq": [self.nodes[i].last_seq for i in sorted(self.nodes)],
            "counts": dict(self.counts),
            "late": self.late,
        }
