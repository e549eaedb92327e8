"""Where each part of the hybrid state ``q`` of an estimation problem lives, eq. (16)--(22).

The hybrid state is ``q = (x, z, ybar, ubar, s_0, ..., s_{C-1}, [network], [run])``
where ``s_c`` is the internal state of node ``c``'s rule (``eta`` for the dynamic rule),
``ubar`` the held inputs of the input nodes (section 7.3, empty without them), and the
network part (only with a :class:`~etobs.model.network.Network`) the values the nodes
last sent, their packets in flight and counters, and the run's index. We carry the held
value ``ybar`` rather than the paper's ``e``: ``e_i = ybar_i - ytilde_i(t)`` is then
exact at every instant and ``ybar`` is constant along flows (eq. (4)), so the paper's
``e``-dynamics (eq. (9)) follow without being integrated.

A *channel* is what one node sends: the output node ``i`` sends ``ytilde_i`` (or, in
the observer-copy variant of Remark 3, the output estimation error
``ytilde_i - yhat_i``), an input node sends ``u_k`` (section 7.3). Every channel has

* a *sent* value: the value the node last sent; its rule acts on
  ``e = sent - (current value)``;
* a *held* value: what the observer holds and runs on (``ybar_i`` or ``ubar_k``).

On an ideal network both are the same entries of the state. With a network they are
separate, and each channel also carries its packets in flight and its counters
(:mod:`etobs.estimation._network_jumps`).

This module is the layout's one definition: the problem (:mod:`etobs.estimation.problem`)
builds it, the reference model (:mod:`etobs.estimation.assembly`), the engine's model
source and the results read it.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from etobs.estimation._network_jumps import N_META
from etobs.model.network import Link, Network
from etobs.model.node import InputNode, Node
from etobs.model.observer import Observer
from etobs.model.plant import Plant
from etobs.model.rules import TriggerRule


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


@dataclass(frozen=True)
class StateLayout:
    """Where each part of the hybrid state ``q`` lives."""

    x: slice
    z: slice
    ybar: slice
    ubar: slice
    rule: tuple[slice, ...]
    outputs: tuple[np.ndarray, ...]
    channels: tuple[Channel, ...]
    run: int | None
    n: int
    n_flow: int | None = None  # entries from here on are constant along flows (the network's)

    @property
    def sent_columns(self) -> tuple[int, ...]:
        """Entries of ``q`` holding what each node last sent, node after node, in index order.

        The solvers log them after every jump (``log_columns``): after a node's
        transmission they hold the value it sent (eq. (22)), which the transmissions table
        of :meth:`EstimationResult.to_pandas` reads.
        """
        return tuple(int(c) for ch in self.channels for c in ch.sent)

    @property
    def sent_names(self) -> tuple[str, ...]:
        """Names of :attr:`sent_columns`: ``sent_y<k>`` for output ``k``, ``sent_u<k>`` for input ``k``."""
        return tuple(f"sent_{ch.kind}{int(k)}" for ch in self.channels for k in ch.index)


def state_layout(
    plant: Plant,
    obs: Observer,
    nodes: tuple[Node, ...],
    inputs: tuple[InputNode, ...],
    network: Network | None,
) -> StateLayout:
    """Where each part of ``q`` lives for this plant, observer, nodes and network (module docstring)."""
    k = 0

    def take(size: int) -> slice:
        nonlocal k
        sl = slice(k, k + size)
        k += size
        return sl

    n_ubar = sum(len(nd.inputs) for nd in inputs)
    x, z, ybar, ubar = take(plant.n_x), take(obs.n_z), take(plant.n_y), take(n_ubar)
    everyone: list[Node | InputNode] = [*nodes, *inputs]
    rule = tuple(take(nd.rule.n_state) for nd in everyone)
    outputs = tuple(np.array(nd.outputs, dtype=np.intp) for nd in nodes)
    index = [*outputs, *(np.array(nd.inputs, dtype=np.intp) for nd in inputs)]
    held: list[np.ndarray] = [ybar.start + idx for idx in outputs]
    offsets = np.cumsum([0] + [len(nd.inputs) for nd in inputs])
    held += [ubar.start + np.arange(a, b) for a, b in itertools.pairwise(offsets)]
    n_ch = len(everyone)
    sent, nets, links = list(held), [None] * n_ch, [None] * n_ch
    n_flow = None
    if network is not None:
        sent_block = take(plant.n_y + n_ubar)
        n_flow = sent_block.start
        sent = [h - ybar.start + sent_block.start for h in held]
        for c, idx in enumerate(index):
            link = network.link(c, n_ch)
            links[c] = link  # type: ignore[call-overload]
            nets[c] = take(N_META + link.capacity * (2 + idx.shape[0]))  # type: ignore[call-overload]
    run = take(1).start if network is not None else None
    names = [nd.name or f"node{i}" for i, nd in enumerate(nodes)]
    names += [nd.name or f"input{i}" for i, nd in enumerate(inputs)]
    channels = tuple(
        Channel(
            name=names[c],
            rule=everyone[c].rule,
            kind="y" if c < len(nodes) else "u",
            index=index[c],
            held=held[c],
            sent=sent[c],
            rule_state=rule[c],
            net=nets[c],
            link=links[c],
        )
        for c in range(n_ch)
    )
    return StateLayout(
        x=x,
        z=z,
        ybar=ybar,
        ubar=ubar,
        rule=rule,
        outputs=outputs,
        channels=channels,
        run=run,
        n=k,
        n_flow=n_flow,
    )
