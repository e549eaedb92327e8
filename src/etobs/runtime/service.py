"""The observer service's state machine: packets in, estimate out (no I/O here).

:class:`ObserverCore` holds the observer state ``z``, the held outputs ``ybar`` and, per
node, the last sequence number accepted, a window of recent ones and a count of the
sequence numbers it never saw. It integrates ``z' = f_o(t, z, u, ybar, yhat)`` (eq. (7))
with classical Runge--Kutta steps of at most ``dt`` between events. A packet is checked
(:func:`~etobs.runtime.packet.decode`: ``malformed``, ``forged``), then, in this order:

* ``wrong_session`` if it is authentic but carries another session (epoch) than the
  service's: a packet of an earlier run, or a sensor given the wrong ``--epoch``;
* ``wrong_size`` if it carries another number of values than the node has outputs;
* ``out_of_range`` if a value is non-finite or larger than ``max_value`` in magnitude,
  or the sample time is non-finite or beyond ``MAX_TIME``;
* ``replayed`` if its sequence number was already accepted (a copy); ``resent`` if it is
  such a copy resent by its node in a resync (below);
* ``stale`` if it is older than the last one accepted (overtaken, or a replay older than
  the window of recent numbers or than a restart), except a packet its node resends in a
  resync: numbered above the record the service asked from and not seen since;
* ``seq_jump`` if it is ``MAX_SEQ_JUMP`` or more above the last one accepted (a node
  never skips that many: accepting it would refuse the node's next packets as stale);
* ``hello`` for a sensor's hello (any session: it asks the server for the epoch, see
  :mod:`etobs.runtime.server`), if its sequence number is fresh (else ``replayed``,
  ``stale`` or ``seq_jump`` as above); a ``start`` packet (the server's answer) sent
  back to the service is ``malformed``;
* ``future`` if its sample time is more than ``max_lead`` ahead of the service clock
  (a wrong clock or epoch; accepting it would stall the observer);
* otherwise accepted (``initial``, ``applied``, or ``answer`` for a node's answer to a
  resync, which holds the value the node last sent from the time it sent it and is not
  a transmission). It waits in a queue and is applied
  when the observer reaches its sample time, in time order across nodes (so it acts from
  when it was measured); one whose time the observer has passed is applied at the next
  :meth:`ObserverCore.advance` and counted in ``late``.

The newest sequence number of a node wins over time stamps: a packet stamped earlier than
one of its node accepted before (the sensor's clock went back) is applied at that later
time, after it, and counted in the node's ``clock_back``; an older measurement never
overrides a newer one.

``status`` is ``nonfinite`` (below), else ``resyncing`` while a restarted service holds
its observer for its nodes' resends (below), else ``refusing`` when some node's last
``REFUSED_IN_A_ROW`` authentic packets or more were all refused as ``stale`` or
``wrong_session`` (its sequence file was reset, or it runs another epoch: the snapshot's
``refused`` names it), else ``waiting`` while some node has not been heard in this
session (``waiting`` lists them), else ``ok``.

When a packet is accepted, the high-water marks are written to their file
(:class:`~etobs.runtime.marks.HighWaterMarks`) before it can be applied, so a packet that
acted on the estimate is refused after any restart. The observer state (``t``, ``z``, ``ybar``, the packets
accepted but not yet applied) is written with them, and at least every
``CHECKPOINT_EVERY`` of service time: a service restarted on the same session resumes
from it (integrating from the checkpoint's time reproduces the run it left). What the
nodes sent while it was down is lost, so the checkpoint also keeps the address each
node's packets came from, and a resumed service *resyncs*: it asks each node it had heard
to resend what it sent after the service's record (:meth:`ObserverCore.resync_requests`,
the sensor's side in :mod:`etobs.runtime.sensor`) and holds its observer at the
checkpoint's time (``status`` ``resyncing``, :attr:`ObserverCore.holding`) until each has
answered, or has been asked ``RESYNC_TRIES`` times in vain (then named in
``resync_gave_up``). The resent packets are applied at their own sample times, so the
observer then catches up to the estimate of the run that was never interrupted. A resync
request sent to the service is ``malformed``.
Every rejection is counted by kind; nothing raises. If the observer's state stops being
finite (an unstable observer, a too-large ``dt``), it stays at its last finite value and
``status`` says ``nonfinite``. The asyncio transports
(:mod:`etobs.runtime.server`) feed it.
"""

from __future__ import annotations

import heapq
import math
import secrets
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from etobs.errors import InputError
from etobs.estimation.assembly import observer_flow
from etobs.estimation.calls import ModelCalls
from etobs.estimation.problem import EstimationProblem
from etobs.formulas import rk4_step
from etobs.runtime.marks import HighWaterMarks
from etobs.runtime.packet import Packet, PacketError, decode, encode, key_id, resync_record

VERDICTS = (
    "applied",
    "initial",
    "replayed",
    "stale",
    "seq_jump",
    "future",
    "wrong_session",
    "out_of_range",
    "malformed",
    "forged",
    "wrong_size",
    "hello",
    "answer",
    "resent",
)
#: A node's sequence numbers never jump by more: a restart skips at most one reserved block
#: (1024 by default), so 2^32 is four million restarts between two packets the service saw.
MAX_SEQ_JUMP = 2**32
#: Sample times beyond this many seconds (31,700 years) are no clock's.
MAX_TIME = 1e12
#: Authentic packets of a node refused in a row as ``stale`` or ``wrong_session`` before the
#: status names it: one or two are a replay or a packet overtaken in the network.
REFUSED_IN_A_ROW = 3
#: Service time between two checkpoints of the observer state when no packet is accepted
#: (a restart integrates at most this much again).
CHECKPOINT_EVERY = 1.0
#: Service seconds between two resync requests to a node that has not answered yet, and the
#: most requests sent to it after a restart (a datagram may be lost; a node gone stays gone).
RESYNC_RETRY = 0.1
RESYNC_TRIES = 20


@dataclass
class NodeState:
    """What the observer knows of one node."""

    outputs: np.ndarray
    key_id: str
    last_seq: int = 0
    recent: deque[int] = field(default_factory=lambda: deque(maxlen=256))
    transmissions: int = 0
    gaps: int = 0
    heard: bool = False  # a packet accepted in this session
    last_t: float = -math.inf  # the latest time a packet of this node is applied at
    clock_back: int = 0  # packets stamped before one accepted earlier (applied after it)
    refused: str = ""  # the verdict of the authentic packets refused in a row
    refused_in_a_row: int = 0
    address: list[Any] | None = None  # [host, port] its packets came from (the reverse channel)
    resync_asked: int = 0  # resync requests sent since the restart
    resync_next: float = -math.inf  # service time of the next request, while it is owed one
    record: int = 0  # the last sequence number on record at the restart: resends are above it
    resync_seen: dict[int, float] = field(default_factory=dict)  # since the restart: seq -> time applied
    recovered: int = 0  # packets accepted in the resync stamped before its first request
    resync_since: float = math.inf  # service time of the first resync request
    resync_answered: float | None = None  # service time its answer was accepted
    resync_gave_up: bool = False  # asked RESYNC_TRIES times, never answered


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
    session : float
        The session packets must carry (the deployment's epoch; the server sets it).
    marks : HighWaterMarks, optional
        Where the high-water marks are kept across restarts (default: in memory only).
    max_value : float
        Values larger than this in magnitude are refused as ``out_of_range``.

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
        session: float = 0.0,
        marks: HighWaterMarks | None = None,
        max_value: float = 1e12,
    ) -> None:
        if not isinstance(problem, EstimationProblem):
            raise InputError(f"`problem` must be an EstimationProblem; got {type(problem).__name__}")
        if problem.extended:
            raise InputError(
                "the observer service runs the base setting: no input nodes, hold='output', no network"
            )
        for name, value in (("dt", dt), ("max_value", max_value), ("max_lead", max_lead)):
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise InputError(f"`{name}` must be a finite number > 0; got {value!r}")
        missing = [i for i in range(problem.n_nodes) if i not in keys]
        if missing:
            raise InputError(f"`keys` has no key for nodes {missing}")
        self.problem, self.keys, self.dt = problem, dict(keys), float(dt)
        self._calls = ModelCalls(problem, compiled=False)
        n_z = problem.observer.n_z
        self.z = np.zeros(n_z) if z0 is None else np.asarray(z0, dtype=float).reshape(n_z)
        self.t = float(t0)
        self.ybar = np.full(problem.plant.n_y, np.nan)
        self.nodes = {
            i: NodeState(outputs=np.array(nd.outputs), key_id=key_id(self.keys[i]))
            for i, nd in enumerate(problem.nodes)
        }
        self.marks = marks
        self._checkpoint: dict[str, Any] | None = None  # the observer state on file, if any
        if marks is not None:
            stored = marks.load({i: nd.key_id for i, nd in self.nodes.items()})
            for i, seq in stored.items():
                if i in self.nodes:
                    self.nodes[i].last_seq = seq
            self._checkpoint = marks.observer
        self._dirty = False  # marks accepted but not yet written
        self._saved_t = self.t  # service time of the last checkpoint
        self.counts = dict.fromkeys(VERDICTS, 0)
        self.max_lead, self.max_value = float(max_lead), float(max_value)
        self._queue: list[tuple[float, int, int, Packet]] = []  # (time applied, node, seq, packet)
        self.late = 0
        self.max_lateness = 0.0
        self.nonfinite = False
        self.resumed = False  # whether the observer state was restored from the checkpoint
        self.last_hello: tuple[int, int] | None = None  # (node, seq) of the last hello accepted
        self.last_node: int | None = None  # the node of the last packet accepted (or hello)
        #: Nodes asked to transmit afresh: after a restart, what they sent while the service
        #: was down is lost, and each believes the observer holds its last value.
        self.resync_pending: set[int] = set()
        self.session = float(session)

    @property
    def session(self) -> float:
        """The session (epoch) packets must carry; setting it restores a checkpoint of that session."""
        return self._session

    @session.setter
    def session(self, value: float) -> None:
        self._session = float(value)
        cp = self._checkpoint
        if cp is not None and cp["session"] == self._session and not self.resumed:
            self._restore(cp)

    def _restore(self, cp: dict[str, Any]) -> None:
        """The observer state of checkpoint ``cp`` (same session), before any packet of this run."""
        n_z, n_y = self.z.size, self.ybar.size
        if len(cp["z"]) != n_z or len(cp["ybar"]) != n_y or any(i not in self.nodes for i in cp["heard"]):
            raise InputError(
                f"the observer state in {str(self.marks.path) if self.marks else '?'!r} has "
                f"{len(cp['z'])} states and {len(cp['ybar'])} outputs; this problem's observer has {n_z} "
                f"and {n_y}: it is another deployment's; start a new epoch (omit --epoch)"
            )
        self.t, self._saved_t = cp["t"], cp["t"]
        self.z = np.array(cp["z"], dtype=float)
        self.ybar = np.array([np.nan if v is None else v for v in cp["ybar"]], dtype=float)
        self.nonfinite = cp["nonfinite"]
        for i in cp["heard"]:
            self.nodes[i].heard = True
        for key in ("transmissions", "gaps"):  # the counters go on (version-2 files have them)
            if len(cp.get(key, ())) == len(self.nodes):
                for i, value in zip(sorted(self.nodes), cp[key], strict=True):
                    setattr(self.nodes[i], key, value)
        for i, addr in zip(sorted(self.nodes), cp.get("addresses", ()), strict=False):
            self.nodes[i].address = addr
        # a node whose address is unknown cannot be asked: the observer does not wait for it
        self.resync_pending = {i for i in cp["heard"] if self.nodes[i].address is not None}
        for i in self.resync_pending:
            self.nodes[i].record = self.nodes[i].last_seq
        for t_apply, node, seq, t, values, initial in cp["queue"]:
            p = Packet(node, seq, t, tuple(values), initial, self._session)
            heapq.heappush(self._queue, (t_apply, node, seq, p))
            self.nodes[node].last_t = max(self.nodes[node].last_t, t_apply)
        self.resumed = True

    @property
    def status(self) -> str:
        """``nonfinite``, ``resyncing``, ``refusing``, ``waiting`` or ``ok`` (see the module docstring)."""
        if self.nonfinite:
            return "nonfinite"
        if self.holding:
            return "resyncing"
        if self.refused():
            return "refusing"
        return "waiting" if self.waiting() else "ok"

    def waiting(self) -> list[int]:
        """The nodes not heard in this session."""
        return [i for i in sorted(self.nodes) if not self.nodes[i].heard]

    def refused(self) -> list[dict[str, Any]]:
        """The nodes whose last ``REFUSED_IN_A_ROW`` or more authentic packets were all refused."""
        return [
            {"node": i, "verdict": nd.refused, "in_a_row": nd.refused_in_a_row}
            for i, nd in sorted(self.nodes.items())
            if nd.refused_in_a_row >= REFUSED_IN_A_ROW
        ]

    @property
    def holding(self) -> bool:
        """Whether the observer waits at the checkpoint's time for its nodes' resends (a restart)."""
        return bool(self.resync_pending)

    @property
    def ready(self) -> bool:
        """Whether every node's initial value has arrived (the observer runs only then)."""
        return bool(np.all(np.isfinite(self.ybar)))

    def xhat(self) -> np.ndarray:
        """The estimate ``psi(z)``."""
        with np.errstate(all="ignore"):
            return np.asarray(self.problem.observer.call_psi(self.z, self.problem.plant.n_x), dtype=float)

    def _f(self, t: float, z: np.ndarray) -> np.ndarray:
        """The observer's flow (eq. (7)) of the one run the service observes: the simulator's."""
        pb, at = self.problem, np.array([t])
        return observer_flow(pb, self._calls, at, z[None, :], pb.u(at), self.ybar[None, :])[0]

    def advance(self, t: float) -> None:
        """Integrate the observer to time ``t``, applying the queued packets on the way.

        The high-water marks of every packet accepted so far are written first, so no
        packet acts on the estimate before its sequence number is on record. While
        :attr:`holding`, the observer stays where it is and the packets wait.
        """
        if not math.isfinite(t):
            raise InputError(f"`t` must be a finite time; got {t!r}")
        if self.t - self._saved_t >= CHECKPOINT_EVERY:
            self._dirty = True
        self.flush()
        if self.holding:
            return
        while self._queue and self._queue[0][0] <= t:
            tk, _, _, p = heapq.heappop(self._queue)
            if tk < self.t:  # arrived after the observer passed its time: acts from now
                self.late += 1
                self.max_lateness = max(self.max_lateness, self.t - tk)
            self._integrate(tk)
            self._hold(p)
        self._integrate(t)

    def _integrate(self, t: float) -> None:
        if t <= self.t:
            return
        if not self.ready or self.nonfinite:  # nothing (sound) to run on: the state waits
            self.t = t
            return
        n = max(1, math.ceil((t - self.t) / self.dt - 1e-9))
        h = (t - self.t) / n
        z = self.z
        with np.errstate(all="ignore"):  # an overflow is a status below, not a warning
            for k in range(n):
                step = rk4_step(self._f, self.t + k * h, z, h)
                if not np.all(np.isfinite(step)) or not np.all(np.isfinite(self._psi(step))):
                    self.nonfinite = True  # keep the last finite state; say so
                    self.z, self.t = z, t
                    return
                z = step
        self.z, self.t = z, t

    def _psi(self, z: np.ndarray) -> np.ndarray:
        return np.asarray(self.problem.observer.call_psi(z, self.problem.plant.n_x), dtype=float)

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
        if p.start or p.resync:  # the service's own packets, sent back to it
            return self._count("malformed")
        if p.hello:
            return self._hello(node, p)
        if p.session != self.session:
            return self._refuse(node, "wrong_session")
        if len(p.values) != node.outputs.size:
            return self._count("wrong_size")
        if not all(math.isfinite(v) and abs(v) <= self.max_value for v in p.values) or not (
            math.isfinite(p.t) and abs(p.t) <= MAX_TIME
        ):
            return self._count("out_of_range")
        resync = p.node in self.resync_pending
        if p.seq in node.recent or p.seq in node.resync_seen:
            return self._count("resent" if resync and p.seq > node.record else "replayed")
        # a resend of the node's resync may arrive after a newer packet: it fills its gap
        older = resync and node.record < p.seq < node.last_seq and not p.answer
        if p.seq <= node.last_seq and not older:
            return self._refuse(node, "stale")
        if p.seq - node.last_seq >= MAX_SEQ_JUMP:  # a jump of MAX_SEQ_JUMP itself is refused
            return self._count("seq_jump")
        if now is not None and p.t > now + self.max_lead:
            return self._count("future")
        if older:
            node.gaps = max(0, node.gaps - 1)
            # acts at its own time, before every newer packet of the node: never overrides one
            t_apply = min([p.t, *(ta for seq, ta in node.resync_seen.items() if seq > p.seq)])
        else:
            if not p.initial and node.last_seq > 0:  # a restarted node skips numbers and says so
                node.gaps += p.seq - node.last_seq - 1
            node.last_seq = p.seq
            if p.t < node.last_t:  # the sensor's clock went back: the newer number still wins
                node.clock_back += 1
            node.last_t = t_apply = max(node.last_t, p.t)
        node.recent.append(p.seq)
        node.heard, node.refused, node.refused_in_a_row = True, "", 0
        self._dirty = True
        self.last_node = p.node
        if resync:
            node.resync_seen[p.seq] = t_apply
            if p.answer:  # the node has resent what it had: the observer may go on
                self.resync_pending.discard(p.node)
                node.resync_answered = now
                node.resync_seen.clear()
            elif not p.initial and p.t < node.resync_since:  # sent while the service was down
                node.recovered += 1
        if not (p.initial or p.answer):
            node.transmissions += 1
        heapq.heappush(self._queue, (t_apply, p.node, p.seq, p))
        verdict = self._count("initial" if p.initial else "answer" if p.answer else "applied")
        # on record at once, in the checkpoint's queue: a service killed before its next
        # advance lost the packet (the sensor sends it once) and its estimate diverged
        self.flush()
        return verdict

    def _hello(self, node: NodeState, p: Packet) -> str:
        """A sensor ready to start (any session: it asks for the epoch); fresh numbers only."""
        if p.seq in node.recent:
            return self._count("replayed")
        if p.seq <= node.last_seq:  # a captured hello gets no answer, in any run
            return self._refuse(node, "stale")
        if p.seq - node.last_seq >= MAX_SEQ_JUMP:
            return self._count("seq_jump")
        node.last_seq = p.seq
        node.recent.append(p.seq)
        self._dirty = True
        self.last_hello = (p.node, p.seq)
        self.last_node = p.node
        return self._count("hello")

    def note_address(self, node: int, address: Any) -> None:
        """Where ``node``'s last accepted packet came from: the resync requests go there."""
        if isinstance(address, tuple | list) and len(address) >= 2:
            addr = [str(address[0]), int(address[1])]
            if addr != self.nodes[node].address:
                self.nodes[node].address = addr
                self._dirty = True

    def resync_requests(self, now: float) -> list[tuple[int, tuple[str, int], bytes]]:
        """The resync requests due at service time ``now``: ``(node, address, datagram)``.

        A node heard before a restart is asked, every ``RESYNC_RETRY`` and at most
        ``RESYNC_TRIES`` times, until its answer is accepted; each request carries the
        session, ``now``, a random nonce and the node's record (the last sequence number
        of it the checkpoint had), authenticated with the node's key. The node resends
        what it sent after the record, then answers (:mod:`etobs.runtime.sensor`). A node
        not answered ``RESYNC_RETRY`` after its last request is given up
        (``resync_gave_up``): the observer goes on without what it sent while down.
        """
        out = []
        for i in sorted(self.resync_pending):
            nd = self.nodes[i]
            if now < nd.resync_next:
                continue
            if nd.resync_asked >= RESYNC_TRIES:
                self.resync_pending.discard(i)
                nd.resync_gave_up, nd.resync_seen = True, {}
                continue
            if nd.resync_asked == 0:
                nd.resync_since = now
            nd.resync_asked += 1
            nd.resync_next = now + RESYNC_RETRY
            p = Packet(
                i, secrets.randbits(63), now, resync_record(nd.record), session=self.session, resync=True
            )
            out.append((i, (nd.address[0], nd.address[1]), encode(p, self.keys[i])))
        return out

    def flush(self) -> None:
        """Write the marks (and the observer state) now if a packet was accepted since the last write."""
        if self._dirty and self.marks is not None:
            self.marks.save({i: (nd.key_id, nd.last_seq) for i, nd in self.nodes.items()}, self.checkpoint())
            self._saved_t = self.t
        self._dirty = False

    def _refuse(self, node: NodeState, verdict: str) -> str:
        """Count an authentic packet refused as ``stale`` or ``wrong_session`` against its node."""
        node.refused_in_a_row = node.refused_in_a_row + 1 if node.refused == verdict else 1
        node.refused = verdict
        return self._count(verdict)

    def _hold(self, p: Packet) -> None:
        self.ybar[self.nodes[p.node].outputs] = p.values  # eq. (5): ybar_i+ = y_i(t_k)

    def _count(self, verdict: str) -> str:
        self.counts[verdict] += 1
        return verdict

    def snapshot(self) -> dict[str, Any]:
        """The estimate and counters, JSON-ready (finite numbers or ``null``, never NaN)."""
        nodes = [self.nodes[i] for i in sorted(self.nodes)]
        return {
            "t": self.t,
            "status": self.status,
            "waiting": self.waiting(),
            "refused": self.refused(),
            "xhat": [_finite(v) for v in self.xhat()],
            "ybar": [_finite(v) for v in self.ybar],
            "transmissions": [nd.transmissions for nd in nodes],
            "last_seq": [nd.last_seq for nd in nodes],
            "gaps": [nd.gaps for nd in nodes],
            "clock_back": [nd.clock_back for nd in nodes],
            "counts": dict(self.counts),
            "late": self.late,
            "resumed": self.resumed,
            "resync_asked": [nd.resync_asked for nd in nodes],
            "recovered": [nd.recovered for nd in nodes],
            "resync_since": [_finite(nd.resync_since) for nd in nodes],
            "resync_answered": [nd.resync_answered for nd in nodes],
            "resync_gave_up": [i for i, nd in sorted(self.nodes.items()) if nd.resync_gave_up],
        }

    def checkpoint(self) -> dict[str, Any]:
        """The observer state written with the marks: what a restart on this session resumes from."""
        return {
            "session": self.session,
            "t": self.t,
            "z": [float(v) for v in self.z],
            "ybar": [_finite(v) for v in self.ybar],
            "nonfinite": self.nonfinite,
            "heard": [i for i in sorted(self.nodes) if self.nodes[i].heard],
            "queue": [[ta, i, s, p.t, list(p.values), p.initial] for ta, i, s, p in sorted(self._queue)],
            "transmissions": [self.nodes[i].transmissions for i in sorted(self.nodes)],
            "gaps": [self.nodes[i].gaps for i in sorted(self.nodes)],
            "addresses": [self.nodes[i].address for i in sorted(self.nodes)],
        }


def _finite(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None
