"""A node's packet entering and leaving its link, on one run's hybrid state, as scalar Python.

Written once: the reference model (:mod:`etobs.estimation.assembly`) calls these on each
run's row of ``q``, and the engine's generated model (:mod:`etobs.estimation._model_source`)
has numba compile them into itself. ``q`` is one run's state; a channel's network block
starts at ``meta``: the counters (:data:`SEQ` ...), then ``capacity`` packet slots of
``2 + n`` numbers each (arrival time, sequence number, values). ``sent`` and ``held`` are
the indices in ``q`` of what the node last sent and of what the observer holds.
"""

from __future__ import annotations

from typing import Any

from etobs.model.fates import fate

#: Arrival time of an empty packet slot (finite: the solvers reject non-finite states).
EMPTY = 1e30
#: Entries of a channel's network block before its packet slots.
SEQ, APPLIED, LOST, OVERFLOW, STALE, N_APPLIED, LOSS_STATE = range(7)
N_META = 7


def arrival_gap(q: Any, t: float, meta: int, n: int, capacity: int) -> float:
    """``t`` minus the earliest arrival time in flight, at least ``-1``: the delivery's guard."""
    first = EMPTY
    for s in range(capacity):
        a = q[meta + N_META + s * (2 + n)]
        if a < first:
            first = a
    return max(t - first, -1.0)


def send(
    q: Any, t: float, seed: int, run: int, channel: int, meta: int, sent: Any, held: Any, n: int,
    capacity: int, link: Any,
) -> None:  # fmt: skip
    """The node's new packet (its values already in ``q[sent]``) enters the link.

    It is numbered, then lost, applied at once (no delay), or put in a free slot, or
    dropped when the link is full (overflow).
    """
    seq = q[meta + SEQ] + 1.0
    q[meta + SEQ] = seq
    lost, delay, state = fate(seed, run, channel, int(seq), int(q[meta + LOSS_STATE]), link)
    q[meta + LOSS_STATE] = state
    if lost:
        q[meta + LOST] += 1.0
        return
    if delay == 0.0:
        for o in range(n):
            q[held[o]] = q[sent[o]]
        q[meta + APPLIED] = seq
        q[meta + N_APPLIED] += 1.0
        return
    w = 2 + n
    for s in range(capacity):
        base = meta + N_META + s * w
        if q[base] >= EMPTY:
            q[base] = t + delay
            q[base + 1] = seq
            for o in range(n):
                q[base + 2 + o] = q[sent[o]]
            return
    q[meta + OVERFLOW] += 1.0


def deliver(q: Any, meta: int, held: Any, n: int, capacity: int) -> None:
    """The packet with the earliest arrival reaches the observer.

    It is applied only if newer than the last one applied (a late, reordered packet is
    stale and dropped).
    """
    w = 2 + n
    best = -1
    first = EMPTY
    for s in range(capacity):
        a = q[meta + N_META + s * w]
        if a < first:
            first = a
            best = s
    if best < 0:
        return
    base = meta + N_META + best * w
    q[base] = EMPTY
    if q[base + 1] > q[meta + APPLIED]:
        for o in range(n):
            q[held[o]] = q[base + 2 + o]
        q[meta + APPLIED] = q[base + 1]
        q[meta + N_APPLIED] += 1.0
    else:
        q[meta + STALE] += 1.0
