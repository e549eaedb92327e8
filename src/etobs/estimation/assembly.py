"""The hybrid model (16)--(22) of an :class:`~etobs.estimation.EstimationProblem`.

The state ``q`` and its channels (what each node sends, what the observer holds) are
laid out in :mod:`etobs.estimation.layout`. With a
:class:`~etobs.model.network.Network`, a second jump rule per channel delivers the
packet whose arrival time has come (see :mod:`etobs.model.network`).

Jump rules: ``0 .. C-1`` are the channels' transmissions. With a network the
deliveries come first, ``0 .. C-1``, and the transmissions are ``C .. 2C-1``: at one
instant the solver jumps in rule order, so a packet arriving when its node sends again
leaves the link before the new one enters it. The samples of the sampled nodes
(:class:`~etobs.model.Sampled`) come last: a sample that fires marks its node's
transmission due, which the solver then applies at the same instant.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from etobs.estimation import _network_jumps as nj
from etobs.estimation.layout import Channel
from etobs.hybrid.system import BatchedSystem

if TYPE_CHECKING:
    from etobs.estimation.calls import ModelCalls
    from etobs.estimation.problem import EstimationProblem


def observer_flow(
    pb: EstimationProblem,
    calls: ModelCalls,
    t: np.ndarray,
    z: np.ndarray,
    ubar: np.ndarray,
    ybar: np.ndarray,
    yhat: np.ndarray | None = None,
) -> np.ndarray:
    """The observer's flow ``z' = f_o(t, z, ubar, ybar, yhat)``, ``yhat = h(psi(z))`` (eq. (7)), for a batch.

    ``ubar`` is the input the observer runs on (the held one with input nodes, eq. (50));
    ``ybar`` the values held as sent: under the observer copy (Remark 3) the nodes send
    ``ytilde - yhat``, and the observer holds ``yhat + ybar``. ``yhat`` may be given when
    the caller has it. The one implementation of the observer's flow: the simulator's
    reference (:func:`build_system`) and the observer service
    (:mod:`etobs.runtime.service`) call it; the engine's model is generated from the
    same steps (:mod:`etobs.estimation._model_source`).
    """
    if yhat is None:
        yhat = calls.h(calls.psi(z))
    if pb.hold == "innovation":
        ybar = yhat + ybar
    return calls.f_o(t, z, ubar, ybar, yhat)


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
        self.links = tuple(None if ch.link is None else ch.link.form() for ch in self.channels)
        self.u_held = [ch for ch in self.channels if ch.kind == "u"]
        self.sampled = pb.sampled_channels

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
        out[:, lay.z] = observer_flow(pb, self.calls, t, z, ubar, q[:, lay.ybar], yhat)  # eq. (7)
        for ch in self.channels:
            if ch.rule_state.stop > ch.rule_state.start:
                sig, meas = self._source(ch, yt, u, yhat)
                e = q[:, ch.sent] - sig
                out[:, ch.rule_state] = self._derivative(
                    ch, t, e, q[:, ch.rule_state], meas
                )  # eq. (14), (53)
        return out

    def guard(self, t: np.ndarray, q: np.ndarray) -> np.ndarray:
        yt, u, yhat = self._parts(t, q, need_yhat=self.innovation, need_u=bool(self.u_held))
        n_ch = len(self.channels)
        off = n_ch if self.networked else 0  # deliveries first (see the module docstring)
        g = np.empty((q.shape[0], n_ch + off + len(self.sampled)))
        for m, c in enumerate(self.sampled):  # the sampled nodes' samples last
            ch = self.channels[c]
            g[:, off + n_ch + m] = ch.rule.sample_guard(t, q[:, ch.rule_state])  # type: ignore[attr-defined]
        for c, ch in enumerate(self.channels):
            sig, meas = self._source(ch, yt, u, yhat)
            g[:, off + c] = self._trigger(ch, t, q[:, ch.sent] - sig, q[:, ch.rule_state], meas)  # (15), (54)
            if self.networked:  # a packet's arrival time has come
                assert ch.net is not None and ch.link is not None
                for r in range(q.shape[0]):
                    g[r, c] = nj.arrival_gap(q[r], t[r], ch.net.start, ch.size, ch.link.capacity)
        return g

    def jump(self, k: int, t: np.ndarray, q: np.ndarray) -> np.ndarray:
        n_ch = len(self.channels)
        if k >= self.pb.first_sample_rule:
            return self._sample(self.channels[self.sampled[k - self.pb.first_sample_rule]], t, q)
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
        assert ch.link is not None and self.lay.run is not None and self.pb.network is not None
        for r in range(q.shape[0]):
            nj.send(
                qn[r], t[r], self.pb.network.seed, int(q[r, self.lay.run]), c, ch.net.start,
                ch.sent, ch.held, ch.size, ch.link.capacity, self.links[c],
            )  # fmt: skip
        return qn

    def _sample(self, ch: Channel, t: np.ndarray, q: np.ndarray) -> np.ndarray:
        """A sampled node's sample (:class:`~etobs.model.Sampled`): decide, advance the filter."""
        yt, u, yhat = self._parts(t, q, need_yhat=self.innovation, need_u=bool(self.u_held))
        sig, meas = self._source(ch, yt, u, yhat)
        qn = q.copy()
        qn[:, ch.rule_state] = ch.rule.sample(q[:, ch.sent] - sig, q[:, ch.rule_state], meas)  # type: ignore[attr-defined]
        return qn

    def _deliver(self, ch: Channel, t: np.ndarray, q: np.ndarray) -> np.ndarray:
        assert ch.net is not None and ch.link is not None
        qn = q.copy()
        for r in range(q.shape[0]):
            nj.deliver(qn[r], ch.net.start, ch.held, ch.size, ch.link.capacity)
        return qn

    def system(self) -> BatchedSystem:
        names = self.pb.rule_names
        jump: Callable[[int, np.ndarray, np.ndarray], np.ndarray] = self.jump
        return BatchedSystem(
            n=self.lay.n,
            n_rules=len(names),
            flow=self.flow,
            guard=self.guard,
            jump=jump,
            rule_names=names,
            n_flow=self.lay.n_flow,
            log_columns=self.lay.sent_columns,  # the values sent, for the transmissions table
        )
