"""Benchmarks check the agreement they print: a disagreement between solvers fails the run.

``expect(ok, what)`` records a failed check (and says so on stderr); a benchmark ends
with ``raise SystemExit(status())``, so ``make test`` fails when the engine and the
scipy reference disagree where they must agree.
"""

from __future__ import annotations

import sys

_FAILED: list[str] = []


def expect(ok: bool, what: str) -> bool:
    """Record the check ``what``; ``ok`` is returned unchanged."""
    if not ok:
        _FAILED.append(what)
        print(f"DISAGREEMENT: {what}", file=sys.stderr)
    return bool(ok)


def status() -> int:
    """The exit status: 1 when a check failed."""
    return 1 if _FAILED else 0
