"""The Pareto front of (transmissions, error): the points no other point beats in both."""

from __future__ import annotations

from collections.abc import Sequence


def dominates(a: Sequence[float], b: Sequence[float]) -> bool:
    """Whether ``a`` is at least as good as ``b`` in every objective and better in one (both minimized)."""
    return all(x <= y for x, y in zip(a, b, strict=True)) and any(x < y for x, y in zip(a, b, strict=True))


def pareto(points: Sequence[Sequence[float]]) -> list[int]:
    """Indices of the non-dominated points, in their order; of equal points the first is kept.

    >>> pareto([(3, 1), (1, 3), (2, 2), (3, 3), (1, 3)])
    [0, 1, 2]
    """
    out: list[int] = []
    for i, p in enumerate(points):
        if any(dominates(q, p) for q in points):
            continue
        if any(tuple(points[j]) == tuple(p) for j in out):
            continue
        out.append(i)
    return out
