"""The hybrid model (16)--(22) of an :class:`~etobs.estimation.EstimationProblem`.

A *channel* is what one node sends: the output node ``i`` sends ``ytilde_i`` (or, in
the observer-copy variant of Remark 3, the output estimation error
``ytilde_i - yhat_i``), an input node sends ``u_k`` (section 6.3). Every channel has

* a *sent* value: the value the node last sent; its rule acts on
  ``e = sent - (current value)``;
* a *held* value: what the observer holds and runs on (``ybar_i`` or ``ubar_k``).

On an ideal network both are the same entries of the state. With a
:class:`~etobs.model.network.Network` they are separate, and each channel also carries
its packets in flight and its counters; a second jump rule per channel delivers the
packet whose arrival time has come (see :mod:`etobs.model.network`).

Jump rules: ``0 .. C-1`` are the channels' transmissions. With a network the
deliveries come first, ``0 .. C-1``, and the transmissions are ``C .. 2C-1``: at one
instant the solver jumps in rule order, so a packet arriving when its node sends again
leaves the link before the new one enters it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from etobs.hybrid.system import BatchedSystem
from etobs.model.network import Link, PacketStream
from etobs.model.rules import TriggerRule

if TYPE_CHECKING:
    from etobs.estimation.calls import ModelCalls
    from etobs.estimation.problem import EstimationProblem

#: Arrival time of an empty packet slot (finite: the solver rejects non-finite states).
EMPTY = 1e30
#: Entries of a channel's network block before its packet slots.
SEQ, APPLIED, LOST, OVERFLOW, STALE, N_APPLIED = range(6)
N_META = 6


@dataclass(frozen=True)
class Channel:
    """One node as the hybrid model sees it (indices into the hybrid state ``q``)."""

    name: str
    rule: TriggerRule
    kind: str  # "y" or "u"
    index: np.ndarray  # into y or u
    held: np.ndarray  # into q: what the observer holds
    sent: np.ndarray  # into q: what the node last sent
    rule_state: slice
    net: slice | None  # the network block (meta, then slots), or None
    link: Link | None

    @property
    def size(self) -> int:
        return int(self.index.shape[0])

    @property
    def slot_width(self) -> int:
        """Arrival time, sequence number, values."""
        return 2 + self.size


def slot_columns(ch: Channel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Columns of ``q`` of the arrival times, sequence numbers and values of every slot."""
    assert ch.net is not None and ch.link is not None
    w, start = ch.slot_width, ch.net.start + N_META
    base = start + w * np.arange(ch.link.capacity)
    return base, base + 1, base[:, None] + 2 + np.arange(ch.size)[None, :]


def build_system(pb: EstimationProblem, calls: ModelCalls) -> BatchedSystem:
    """The problem as a :class:`~etobs.hybrid.BatchedSystem` (eq. (16)--(22))."""
    return _Assembly(pb, calls).system()


class _Assembly:
    def __init__(self, pb: EstimationProblem, calls: ModelCalls) -> None:
        self.pb = pb
        self.calls = calls
        self.lay = pb.layout
        self.channels: tuple[Channel, ...] = pb.layout.channels
        self.innovation = pb.hold == "innovation"
        self.networked = pb.network is not None
        self.streams: dict[tuple[int, int], PacketStream] = {}
        self.u_held = [ch for ch in self.channels if ch.kind == "u"]

    # -- the signals every channel reads -------------------------------------------
    def _parts(
        self, t: np.ndarray, q: np.ndarray, need_yhat: bool, need_u: bool = True
    ) -> tuple[np.ndarray, ...]:
        pb, lay = self.pb, self.lay
        x = q[:, lay.x]
        yt = self.calls.h(x) + pb.m(t)  # eq. (46)
        u = pb.u(t) if need_u else np.empty((t.shape[0], 0))  # the guard reads u only for input nodes
        yhat = self.calls.h(self.calls.psi(q[:, lay.z])) if need_yhat else yt
        return yt, u, yhat

    def _source(
        self, ch: Channel, yt: np.ndarray, u: np.ndarray, yhat: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """What the channel sends, and the current measurement its rule may read."""
        if ch.kind == "u":
            return u[:, ch.index], u[:, ch.index]
        if self.innovation:  # Remark 3: the node's observer copy gives yhat_i
            return yt[:, ch.index] - yhat[:, ch.index], yt[:, ch.index]
        return yt[:, ch.index], yt[:, ch.index]

    @staticmethod
    def _trigger(ch: Channel, t: np.ndarray, e: np.ndarray, s: np.ndarray, y: np.ndarray) -> np.ndarray:
        if ch.rule.reads_y:
            return ch.rule.trigger(t, e, s, y=y)
        return ch.rule.trigger(t, e, s)

    @staticmethod
    def _derivative(ch: Channel, t: np.ndarray, e: np.ndarray, s: np.ndarray, y: np.ndarray) -> np.ndarray:
        if ch.rule.reads_y:
            return ch.rule.derivative(t, e, s, y=y)
        return ch.rule.derivative(t, e, s)

    # -- flow, guard, jump ---------------------------------------------------------
    def flow(self, t: np.ndarray, q: np.ndarray) -> np.ndarray:
        pb, lay = self.pb, self.lay
        x, z = q[:, lay.x], q[:, lay.z]
        yt, u, yhat = self._parts(t, q, need_yhat=True)
        out = np.zeros_like(q)
        out[:, lay.x] = self.calls.f_p(t, x, u, pb.v(t))  # eq. (2)
        ubar = u
        if self.u_held:  # eq. (50): the observer runs on the held input
            ubar = u.copy()
            for ch in self.u_held:
                ubar[:, ch.index] = q[:, ch.held]
        ybar = q[:, lay.ybar]
        if self.innovation:  # Remark 3: the observer holds ytilde - yhat as sent
            ybar = yhat + ybar
        out[:, lay.z] = self.calls.f_o(t, z, ubar, ybar, yhat)  # eq. (7)
        for ch in self.channels:
            if ch.rule_state.stop > ch.rule_state.start:
                sig, meas = self._source(ch, yt, u, yhat)
                e = q[:, ch.sent] - sig
                out[:, ch.rule_state] = self._derivative(
                    ch, t, e, q[:, ch.rule_state], meas
                )  # eq. (14), (52)
        return out

    def guard(self, t: np.ndarray, q: np.ndarray) -> np.ndarray:
        yt, u, yhat = self._parts(t, q, need_yhat=self.innovation, need_u=bool(self.u_held))
        n_ch = len(self.channels)
        off = n_ch if self.networked else 0  # deliveries first (see the module docstring)
        g = np.empty((q.shape[0], n_ch + off))
        for c, ch in enumerate(self.channels):
            sig, meas = self._source(ch, yt, u, yhat)
            g[:, off + c] = self._trigger(ch, t, q[:, ch.sent] - sig, q[:, ch.rule_state], meas)  # (15), (53)
            if self.networked:
                arrival = q[:, slot_columns(ch)[0]].min(axis=1)
                g[:, c] = np.maximum(t - arrival, -1.0)  # a packet's arrival time has come
        return g

    def jump(self, k: int, t: np.ndarray, q: np.ndarray) -> np.ndarray:
        n_ch = len(self.channels)
        if not self.networked:
            return self._send(self.channels[k], k, t, q)
        if k < n_ch:
            return self._deliver(self.channels[k], t, q)
        return self._send(self.channels[k - n_ch], k - n_ch, t, q)

    def _send(self, ch: Channel, c: int, t: np.ndarray, q: np.ndarray) -> np.ndarray:
        # eq. (22): the node sends its current value (e+ = 0) and resets its own rule
        # state; every other node is untouched.
        yt, u, yhat = self._parts(t, q, need_yhat=self.innovation, need_u=bool(self.u_held))
        sig, _ = self._source(ch, yt, u, yhat)
        qn = q.copy()
        qn[:, ch.sent] = sig
        qn[:, ch.rule_state] = ch.rule.reset(t, q[:, ch.rule_state])
        if ch.net is None:
            return qn
        assert ch.link is not None and self.lay.run is not None
        arrival, seqcol, values = slot_columns(ch)
        meta = ch.net.start
        for r in range(q.shape[0]):
            seq = q[r, meta + SEQ] + 1.0
            qn[r, meta + SEQ] = seq
            lost, delay = self._stream(ch, c, int(q[r, self.lay.run])).fate(int(seq))
            if lost:
                qn[r, meta + LOST] += 1.0
            elif delay == 0.0:
                qn[r, ch.held] = sig[r]
                qn[r, meta + APPLIED] = seq
                qn[r, meta + N_APPLIED] += 1.0
            else:
                free = np.flatnonzero(q[r, arrival] >= EMPTY)
                if not free.size:
                    qn[r, meta + OVERFLOW] += 1.0
                    continue
                s = free[0]
                qn[r, arrival[s]] = t[r] + delay
                qn[r, seqcol[s]] = seq
                qn[r, values[s]] = sig[r]
        return qn

    def _deliver(self, ch: Channel, t: np.ndarray, q: np.ndarray) -> np.ndarray:
        # the packet with the earliest arrival reaches the observer; it is applied only
        # if newer than the last one applied (a late, reordered packet is stale)
        assert ch.net is not None
        arrival, seqcol, values = slot_columns(ch)
        meta = ch.net.start
        qn = q.copy()
        for r in range(q.shape[0]):
            s = int(np.argmin(q[r, arrival]))
            if q[r, arrival[s]] >= EMPTY:
                continue
            qn[r, arrival[s]] = EMPTY
            if q[r, seqcol[s]] > q[r, meta + APPLIED]:
                qn[r, ch.held] = q[r, values[s]]
                qn[r, meta + APPLIED] = q[r, seqcol[s]]
                qn[r, meta + N_APPLIED] += 1.0
            else:
                qn[r, meta + STALE] += 1.0
        return qn

    def _stream(self, ch: Channel, c: int, run: int) -> PacketStream:
        key = (run, c)
        if key not in self.streams:
            assert ch.link is not None and self.pb.network is not None
            self.streams[key] = PacketStream(ch.link, self.pb.network.seed, run, c)
        return self.streams[key]

    def system(self) -> BatchedSystem:
        names = tuple(ch.name for ch in self.channels)
        if self.networked:
            names = tuple(f"deliver {n}" for n in names) + names
        jump: Callable[[int, np.ndarray, np.ndarray], np.ndarray] = self.jump
        return BatchedSystem(
            n=self.lay.n,
            n_rules=len(names),
            flow=self.flow,
            guard=self.guard,
            jump=jump,
            rule_names=names,
            n_flow=self.lay.n_flow,
        )
