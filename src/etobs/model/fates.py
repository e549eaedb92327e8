"""The fate of one packet (lost or not, its delay), as plain scalar Python.

Written once and run in two ways: as is by :class:`~etobs.model.network.PacketStream`
(the reference solver, replays, tests) and compiled into the engine's model (see
:mod:`etobs.estimation._network_jumps`). It uses only integers below ``2**64`` masked to
32 bits and ``math``, so Python's integers and numba's 64-bit ones give the same bits.

The draws are *counter-based*: uniform number ``lane`` of packet ``k`` of node ``c`` in
run ``b`` is a hash of ``(seed, b, c, k, lane)``, so a packet's fate depends on nothing
else: not on the batch, the thread, the backend or the other packets (Gilbert--Elliott
loss also on its chain's state, which advances once per packet of its node).

A link is described by :data:`LINK_WIDTH` numbers (``Link.form``): the loss kind and
four loss numbers, then the delay kind and two delay numbers.
"""

from __future__ import annotations

import math

M32 = 0xFFFFFFFF
#: Loss kinds and their numbers.
NO_LOSS, BERNOULLI, GILBERT_ELLIOTT = 0, 1, 2  # (p,), (p_gb, p_bg, loss_good, loss_bad)
#: Delay kinds and their numbers.
CONSTANT, UNIFORM, EXPONENTIAL = 0, 1, 2  # (d,), (low, high), (scale, minimum)
LINK_WIDTH = 8
MAX_DELAY = 1e9  # seconds; far below the solver's empty-slot marker


def _mix(x: int) -> int:
    """A bijection of 32-bit integers with good avalanche (Wellons' "lowbias32")."""
    x ^= x >> 16
    x = (x * 0x7FEB352D) & M32
    x ^= x >> 15
    x = (x * 0x846CA68B) & M32
    x ^= x >> 16
    return x


def uniform(seed: int, run: int, channel: int, k: int, lane: int) -> float:
    """Uniform number ``lane`` of packet ``k`` of node ``channel`` in ``run``, in ``[0, 1)``.

    ``seed``, ``run`` and ``k`` are below ``2**63``; ``channel`` and ``lane`` below ``2**32``.
    """
    h = _mix((seed & M32) ^ 0x9E3779B9)
    h = _mix(h ^ ((seed >> 32) & M32))
    h = _mix(h ^ (run & M32))
    h = _mix(h ^ ((run >> 32) & M32))
    h = _mix(h ^ channel)
    h = _mix(h ^ (k & M32))
    h = _mix(h ^ ((k >> 32) & M32))
    a = _mix(h ^ (2 * lane + 1))
    b = _mix(a ^ 0x632BE5AB)
    return ((a >> 5) * 67108864.0 + (b >> 6)) / 9007199254740992.0  # 53 random bits


def delay_quantile(kind: int, d1: float, d2: float, u: float) -> float:
    """The delay whose distribution function is ``u`` (inverse transform), at most MAX_DELAY."""
    if kind == UNIFORM:
        d = d1 + (d2 - d1) * u
    elif kind == EXPONENTIAL:
        d = d2 - d1 * math.log(1.0 - u)  # minimum + Exp(scale); 1 - u is in (0, 1]
    else:
        d = d1
    return min(d, MAX_DELAY)


def fate(
    seed: int, run: int, channel: int, k: int, state: int, link: list[float] | tuple[float, ...]
) -> tuple[bool, float, int]:
    """Whether packet ``k`` (1-based) is lost, its delay, and the loss chain's state after it.

    ``state`` is the Gilbert--Elliott chain's state before the packet (0 good, 1 bad;
    other kinds ignore it); ``link`` the link's :data:`LINK_WIDTH` numbers.
    """
    kind = int(link[0])
    lost = False
    if kind == BERNOULLI:
        lost = uniform(seed, run, channel, k, 0) < link[1]
    elif kind == GILBERT_ELLIOTT:
        # the chain moves before each packet (good -> bad w.p. p_gb, bad -> good w.p. p_bg)
        move = uniform(seed, run, channel, k, 0)
        if state == 0 and move < link[1]:
            state = 1
        elif state == 1 and move < link[2]:
            state = 0
        lost = uniform(seed, run, channel, k, 1) < (link[4] if state == 1 else link[3])
    delay = delay_quantile(int(link[5]), link[6], link[7], uniform(seed, run, channel, k, 2))
    return lost, delay, state
