"""Network effects between the nodes and the observer: delay and packet loss (not in the paper).

The paper assumes that a transmitted value reaches the observer at once and never gets
lost. A :class:`Network` puts a :class:`Link` between each node and the observer:

* every packet is delayed by a draw of the link's :class:`Delay`
  (:class:`ConstantDelay`, :class:`UniformDelay`, :class:`ExponentialDelay`);
* every packet may be lost (:class:`BernoulliLoss`, or bursts with
  :class:`GilbertElliottLoss`);
* a link holds at most ``capacity`` packets in flight; one more is dropped (overflow);
* the observer applies a packet only if it is newer (by sequence number) than the last
  one applied; an older one arriving late (reordered by random delays) is stale and
  dropped. Between packets it keeps the last value applied.

The node does not learn of losses: its rule acts on the gap to the value it last
*sent*. The fate of packet ``k`` (lost or not, its delay) of node ``i`` in run ``b``
depends only on ``(seed, b, i, k)``, so results do not depend on batching and a
result can be replayed (:meth:`PacketStream.fate`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from etobs import _validate as v
from etobs.errors import InputError, InputTypeError
from etobs.model import fates
from etobs.model.fates import MAX_DELAY

#: Seeds, run indices and sequence numbers stay below this (64-bit integers in the engine).
MAX_SEED = 2**63 - 1


class Delay(ABC):
    """Distribution of a packet's transmission delay (seconds)."""

    @abstractmethod
    def form(self) -> tuple[int, float, float]:
        """The delay kind and its two numbers (:func:`etobs.model.fates.delay_quantile`)."""

    @property
    @abstractmethod
    def mean(self) -> float:
        """Mean delay."""


@dataclass(frozen=True)
class ConstantDelay(Delay):
    """Every packet takes ``d >= 0`` seconds."""

    d: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "d", v.real("d", self.d, lower=0.0, upper=MAX_DELAY))

    def form(self) -> tuple[int, float, float]:
        return fates.CONSTANT, self.d, 0.0

    @property
    def mean(self) -> float:
        return self.d


@dataclass(frozen=True)
class UniformDelay(Delay):
    """Delays uniform on ``[low, high]``."""

    low: float
    high: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "low", v.real("low", self.low, lower=0.0))
        object.__setattr__(self, "high", v.real("high", self.high, lower=self.low, upper=MAX_DELAY))

    def form(self) -> tuple[int, float, float]:
        return fates.UNIFORM, self.low, self.high

    @property
    def mean(self) -> float:
        return 0.5 * (self.low + self.high)


@dataclass(frozen=True)
class ExponentialDelay(Delay):
    """Delays ``minimum + Exp(scale)``: a fixed part plus an exponential queueing part."""

    scale: float
    minimum: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "scale", v.real("scale", self.scale, lower=0.0, lower_open=True, upper=MAX_DELAY / 100)
        )
        object.__setattr__(self, "minimum", v.real("minimum", self.minimum, lower=0.0, upper=MAX_DELAY))

    def form(self) -> tuple[int, float, float]:
        return fates.EXPONENTIAL, self.scale, self.minimum

    @property
    def mean(self) -> float:
        return self.minimum + self.scale


class Loss(ABC):
    """Packet-loss process of a link."""

    @abstractmethod
    def form(self) -> tuple[int, float, float, float, float]:
        """The loss kind and its four numbers (:func:`etobs.model.fates.fate`)."""

    @property
    @abstractmethod
    def rate(self) -> float:
        """Long-run fraction of packets lost."""


@dataclass(frozen=True)
class BernoulliLoss(Loss):
    """Each packet is lost with probability ``p``, independently."""

    p: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "p", v.real("p", self.p, lower=0.0, upper=1.0))

    def form(self) -> tuple[int, float, float, float, float]:
        return fates.BERNOULLI, self.p, 0.0, 0.0, 0.0

    @property
    def rate(self) -> float:
        return self.p


@dataclass(frozen=True)
class GilbertElliottLoss(Loss):
    """Bursty loss: a two-state Markov chain (good, bad) advanced once per packet.

    Before each packet the channel moves from good to bad with probability ``p_gb``
    and from bad to good with probability ``p_bg``; the packet is then lost with
    probability ``loss_good`` or ``loss_bad``. The channel starts good. The mean burst
    length in the bad state is ``1 / p_bg`` packets and the long-run loss rate is
    ``(p_bg loss_good + p_gb loss_bad) / (p_gb + p_bg)``.
    """

    p_gb: float
    p_bg: float
    loss_good: float = 0.0
    loss_bad: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "p_gb", v.real("p_gb", self.p_gb, lower=0.0, upper=1.0))
        object.__setattr__(self, "p_bg", v.real("p_bg", self.p_bg, lower=0.0, upper=1.0, lower_open=True))
        object.__setattr__(self, "loss_good", v.real("loss_good", self.loss_good, lower=0.0, upper=1.0))
        object.__setattr__(self, "loss_bad", v.real("loss_bad", self.loss_bad, lower=0.0, upper=1.0))

    def form(self) -> tuple[int, float, float, float, float]:
        return fates.GILBERT_ELLIOTT, self.p_gb, self.p_bg, self.loss_good, self.loss_bad

    @property
    def rate(self) -> float:
        return (self.p_bg * self.loss_good + self.p_gb * self.loss_bad) / (self.p_gb + self.p_bg)


def _as_delay(value: Any) -> Delay:
    if isinstance(value, Delay):
        return value
    if isinstance(value, int | float) and not isinstance(value, bool):
        return ConstantDelay(float(value))
    raise InputTypeError(
        f"`delay` must be a number of seconds or a Delay (ConstantDelay, UniformDelay, ExponentialDelay); "
        f"got {type(value).__name__}"
    )


def _as_loss(value: Any) -> Loss | None:
    if value is None or isinstance(value, Loss):
        return value
    if isinstance(value, int | float) and not isinstance(value, bool):
        return BernoulliLoss(float(value))
    raise InputTypeError(
        f"`loss` must be None, a probability or a Loss (BernoulliLoss, GilbertElliottLoss); "
        f"got {type(value).__name__}"
    )


@dataclass(frozen=True)
class Link:
    """The channel from one node to the observer.

    Parameters
    ----------
    delay : float or Delay
        Seconds (a constant) or a delay distribution. Default: none.
    loss : None, float or Loss
        A probability (Bernoulli loss) or a loss process. Default: none.
    capacity : int
        Packets in flight at most; a packet sent while the link is full is dropped.

    Examples
    --------
    20 % of the packets lost, the others 10 ms late:

    >>> from etobs import Link
    >>> link = Link(delay=0.01, loss=0.2)
    >>> link.instant, link.capacity
    (False, 16)

    """

    delay: Delay | float = 0.0
    loss: Loss | float | None = None
    capacity: int = 16

    def __post_init__(self) -> None:
        object.__setattr__(self, "delay", _as_delay(self.delay))
        object.__setattr__(self, "loss", _as_loss(self.loss))
        object.__setattr__(self, "capacity", v.integer("capacity", self.capacity, lower=1))

    @property
    def instant(self) -> bool:
        """Whether every packet arrives at once (a constant zero delay)."""
        return isinstance(self.delay, ConstantDelay) and self.delay.d == 0.0

    def form(self) -> tuple[float, ...]:
        """The link's :data:`~etobs.model.fates.LINK_WIDTH` numbers for :func:`~etobs.model.fates.fate`."""
        loss = (fates.NO_LOSS, 0.0, 0.0, 0.0, 0.0) if self.loss is None else self.loss.form()  # type: ignore[union-attr]
        return tuple(float(a) for a in (*loss, *self.delay.form()))  # type: ignore[union-attr]


@dataclass(frozen=True)
class Network:
    """The links of a problem's nodes, in node order (output nodes, then input nodes).

    Parameters
    ----------
    links : Link or sequence of (Link or None)
        One link for every node, or one per node (``None``: an ideal link).
    seed : int
        Seed of every packet's fate (``>= 0``).

    Examples
    --------
    20 % Bernoulli loss and 10 ms delay on every node:

    >>> Network(Link(delay=0.01, loss=0.2), seed=1).links[0].loss
    BernoulliLoss(p=0.2)

    """

    links: Link | Sequence[Link | None] = field(default_factory=Link)
    seed: int = 0

    def __post_init__(self) -> None:
        links = self.links
        if isinstance(links, Link):
            links = (links,)
        elif isinstance(links, Sequence) and not isinstance(links, str):
            links = tuple(Link() if lk is None else lk for lk in links)
        else:
            raise InputTypeError(f"`links` must be a Link or a sequence of Link; got {type(links).__name__}")
        for k, lk in enumerate(links):
            if not isinstance(lk, Link):
                raise InputTypeError(f"`links[{k}]` must be a Link or None; got {type(lk).__name__}")
        if not links:
            raise InputError("`links` must hold at least one Link")
        object.__setattr__(self, "links", links)
        object.__setattr__(self, "seed", v.integer("seed", self.seed, lower=0, upper=MAX_SEED))

    def link(self, channel: int, n_channels: int) -> Link:
        """The link of node ``channel`` out of ``n_channels``."""
        links: tuple[Link, ...] = self.links  # type: ignore[assignment]
        if len(links) == 1:
            return links[0]
        if len(links) != n_channels:
            raise InputError(
                f"`network.links` has {len(links)} links but the problem has {n_channels} nodes "
                "(output nodes, then input nodes); give one link or one per node"
            )
        return links[channel]


class PacketStream:
    """The fates of the packets of one node in one run: ``fate(k)`` for ``k = 1, 2, ...``.

    Deterministic in ``(seed, run, channel)`` (:mod:`etobs.model.fates`); the engine
    draws the same fates in its compiled model.
    """

    def __init__(self, link: Link, seed: int, run: int, channel: int) -> None:
        self._link = link.form()
        self._key = (int(seed), int(run), int(channel))
        self._fates: list[tuple[bool, float]] = []
        self._state = 0  # the loss chain's state after the fates drawn so far

    def fate(self, k: int) -> tuple[bool, float]:
        """Whether packet ``k`` (1-based sequence number) is lost, and its delay."""
        seed, run, channel = self._key
        while k > len(self._fates):
            lost, delay, self._state = fates.fate(
                seed, run, channel, len(self._fates) + 1, self._state, self._link
            )
            self._fates.append((lost, delay))
        return self._fates[k - 1]
