"""The event-triggered estimation problem and its hybrid model, eq. (16)--(22).

The hybrid state is ``q = (x, z, ybar, s_0, ..., s_{N-1})`` where ``s_i`` is the
internal state of node ``i``'s rule (``eta_i`` for the dynamic rule). We carry the held
value ``ybar`` rather than the paper's ``e``: ``e_i = ybar_i - ytilde_i(t)`` is then
exact at every instant and ``ybar`` is constant along flows (eq. (4)), so the paper's
``e``-dynamics (eq. (9)) follow without being integrated.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from etobs.errors import InputError, InputTypeError, ModelError
from etobs.hybrid.system import HybridSystem
from etobs.model.node import Node
from etobs.model.observer import Observer
from etobs.model.plant import Plant
from etobs.model.signals import Signal, Sinusoid, as_signal


@dataclass(frozen=True)
class StateLayout:
    """Where each part of the hybrid state ``q`` lives."""

    x: slice
    z: slice
    ybar: slice
    rule: tuple[slice, ...]
    outputs: tuple[np.ndarray, ...]
    n: int


@dataclass(frozen=True)
class EstimationProblem:
    """Plant, observer, sensor nodes and signals of one event-triggered estimator.

    Parameters
    ----------
    plant : Plant
    observer : Observer
    nodes : sequence of Node
        Their output sets must partition ``0 .. n_y - 1``.
    u : Signal, callable, array_like or None
        Known input ``u(t)`` (dimension ``n_u``); ``None`` is zero.
    v : Signal, callable, array_like or None
        Unknown disturbance ``v(t)`` (dimension ``n_v``).
    m : Signal, callable, array_like or None
        Measurement noise ``m(t)`` (dimension ``n_y``), eq. (46): ``ytilde = h(x) + m``.

    """

    plant: Plant
    observer: Observer
    nodes: tuple[Node, ...]
    u: Any = None
    v: Any = None
    m: Any = None
    layout: StateLayout = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.plant, Plant):
            raise InputTypeError(f"`plant` must be a Plant; got {type(self.plant).__name__}")
        if not isinstance(self.observer, Observer):
            raise InputTypeError(f"`observer` must be an Observer; got {type(self.observer).__name__}")
        nodes = tuple(self.nodes)
        if not nodes or not all(isinstance(nd, Node) for nd in nodes):
            raise InputTypeError("`nodes` must be a non-empty sequence of Node objects")
        object.__setattr__(self, "nodes", nodes)
        p = self.plant
        if self.observer.n_z < p.n_x:
            raise InputError(
                f"observer `n_z` = {self.observer.n_z} is smaller than the plant's n_x = {p.n_x}"
            )
        _check_partition(nodes, p.n_y)
        object.__setattr__(self, "u", as_signal("u", self.u, p.n_u))
        object.__setattr__(self, "v", as_signal("v", self.v, p.n_v))
        object.__setattr__(self, "m", as_signal("m", self.m, p.n_y))
        object.__setattr__(self, "layout", _layout(p, self.observer, nodes))
        _check_shapes(self)
        _check_noise(self)

    @property
    def n_nodes(self) -> int:
        """Number of sensor nodes ``N``."""
        return len(self.nodes)

    def psi(self, z: np.ndarray) -> np.ndarray:
        """State estimate ``xhat = psi(z)``."""
        if self.observer.psi is None:
            return z[..., : self.plant.n_x]
        return self.observer.psi(z)

    def ytilde(self, t: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Measured output ``ytilde = h(x) + m(t)`` (eq. (46))."""
        m: Signal = self.m
        return self.plant.h(x) + m(t)

    def initial_state(self, x0: np.ndarray, z0: np.ndarray, e0: np.ndarray, t0: float) -> np.ndarray:
        """Hybrid state at ``t0``: ``ybar = ytilde(t0) + e0`` and each rule's own start."""
        b = x0.shape[0]
        lay = self.layout
        q = np.empty((b, lay.n))
        q[:, lay.x] = x0
        q[:, lay.z] = z0
        q[:, lay.ybar] = self.ytilde(np.full(b, t0), x0) + e0
        for nd, sl in zip(self.nodes, lay.rule, strict=True):
            q[:, sl] = nd.rule.initial_state()
        return q

    def hybrid_system(self) -> HybridSystem:
        """The hybrid model (16)--(22) as a :class:`~etobs.hybrid.HybridSystem`."""
        lay, plant, obs = self.layout, self.plant, self.observer
        nodes = self.nodes
        u_sig: Signal = self.u
        v_sig: Signal = self.v

        def flow(t: np.ndarray, q: np.ndarray) -> np.ndarray:
            x, z, ybar = q[:, lay.x], q[:, lay.z], q[:, lay.ybar]
            u = u_sig(t)
            out = np.zeros_like(q)
            out[:, lay.x] = plant.f_p(t, x, u, v_sig(t))  # eq. (2)
            yhat = plant.h(self.psi(z))
            out[:, lay.z] = obs.f_o(t, z, u, ybar, yhat)  # eq. (7): the observer runs on ybar
            e = ybar - self.ytilde(t, x)
            for nd, sl, idx in zip(nodes, lay.rule, lay.outputs, strict=True):
                if sl.stop > sl.start:
                    out[:, sl] = nd.rule.derivative(t, e[:, idx], q[:, sl])  # eq. (14)
            return out

        def guard(t: np.ndarray, q: np.ndarray) -> np.ndarray:
            e = q[:, lay.ybar] - self.ytilde(t, q[:, lay.x])
            g = np.empty((q.shape[0], len(nodes)))
            for i, (nd, sl, idx) in enumerate(zip(nodes, lay.rule, lay.outputs, strict=True)):
                g[:, i] = nd.rule.trigger(t, e[:, idx], q[:, sl])  # eq. (18), (20)
            return g

        def jump(i: int, t: np.ndarray, q: np.ndarray) -> np.ndarray:
            # eq. (22): node i sends ytilde_i (e_i+ = 0) and resets its own rule state;
            # every other node is untouched.
            qn = q.copy()
            idx = lay.outputs[i]
            ybar_idx = lay.ybar.start + idx
            qn[:, ybar_idx] = self.ytilde(t, q[:, lay.x])[:, idx]
            sl = lay.rule[i]
            qn[:, sl] = nodes[i].rule.reset(t, q[:, sl])
            return qn

        names = tuple(nd.name or f"node{i}" for i, nd in enumerate(nodes))
        return HybridSystem(n=lay.n, n_rules=len(nodes), flow=flow, guard=guard, jump=jump, rule_names=names)


def _check_partition(nodes: tuple[Node, ...], n_y: int) -> None:
    owner: dict[int, list[int]] = {}
    for i, nd in enumerate(nodes):
        for k in nd.outputs:
            owner.setdefault(k, []).append(i)
    outside = sorted(k for k in owner if k >= n_y)
    twice = {k: o for k, o in owner.items() if len(o) > 1}
    missing = [k for k in range(n_y) if k not in owner]
    problems = []
    if outside:
        problems.append(f"outputs {outside} do not exist (n_y = {n_y})")
    for k, o in sorted(twice.items()):
        problems.append(f"output {k} is claimed by nodes {o}")
    if missing:
        problems.append(f"outputs {missing} belong to no node")
    if problems:
        raise InputError(
            f"the nodes' output sets must partition the outputs 0..{n_y - 1}: " + "; ".join(problems)
        )


def _layout(plant: Plant, obs: Observer, nodes: tuple[Node, ...]) -> StateLayout:
    k = 0

    def take(size: int) -> slice:
        nonlocal k
        sl = slice(k, k + size)
        k += size
        return sl

    x, z, ybar = take(plant.n_x), take(obs.n_z), take(plant.n_y)
    rule = tuple(take(nd.rule.n_state) for nd in nodes)
    outputs = tuple(np.array(nd.outputs, dtype=np.intp) for nd in nodes)
    return StateLayout(x=x, z=z, ybar=ybar, rule=rule, outputs=outputs, n=k)


def _check_shapes(pb: EstimationProblem) -> None:
    """Call every model function once on a batch of two runs and check the shapes."""
    p, o = pb.plant, pb.observer
    b = 2
    t = np.zeros(b)
    x, z = np.zeros((b, p.n_x)), np.zeros((b, o.n_z))
    u, v = pb.u(t), pb.v(t)

    def check(name: str, out: Any, shape: tuple[int, int], what: str) -> np.ndarray:
        arr = np.asarray(out)
        if arr.shape != shape:
            raise ModelError(f"`{name}` returned shape {arr.shape} for a batch of {b} runs; expected {what}")
        return arr

    check("f_p", p.f_p(t, x, u, v), (b, p.n_x), f"({b}, n_x={p.n_x})")
    y = check("h", p.h(x), (b, p.n_y), f"({b}, n_y={p.n_y})")
    xhat = check("psi", pb.psi(z), (b, p.n_x), f"({b}, n_x={p.n_x})")
    check("f_o", o.f_o(t, z, u, y, p.h(xhat)), (b, o.n_z), f"({b}, n_z={o.n_z})")


def _check_noise(pb: EstimationProblem) -> None:
    """Warn when a node's ``eps_i <= gamma_i(2 m_i)`` (section 6.2) for sinusoidal noise.

    The rule sees ``e~_i = e_i + m_i(t_k) - m_i(t)``; a sinusoid's offset cancels there,
    so ``m_i`` is the norm of the node's amplitudes. Without the condition the noise
    alone can trigger transmissions, and the minimum inter-event time is lost.
    """
    if not isinstance(pb.m, Sinusoid):
        return
    for i, nd in enumerate(pb.nodes):
        gamma, eps = getattr(nd.rule, "gamma", None), getattr(nd.rule, "eps", None)
        if gamma is None or eps is None:
            continue
        bound = float(np.linalg.norm(pb.m.amplitude[list(nd.outputs)]))
        g2m = float(np.asarray(gamma(np.array([2.0 * bound])))[0])
        if bound > 0 and eps <= g2m:
            warnings.warn(
                f"node {i} ({nd.name!r}): eps = {eps:g} <= gamma(2 m) = {g2m:.6g} with noise bound "
                f"m = {bound:g}: section 6.2's condition fails, so noise alone can trigger transmissions; "
                "raise eps",
                RuntimeWarning,
                stacklevel=3,
            )
