"""A small progress line on stderr for long experiments (sweeps, comparisons)."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    """``NAME: 1200/2600 runs (46%), 0 failed, 12 s, ETA 14 s`` on one line."""

    def __init__(self, total: int, name: str, *, enabled: bool = True, stream: TextIO | None = None) -> None:
        self.total, self.name, self.enabled = total, name, enabled
        self.stream = stream or sys.stderr
        self.done = self.failed = 0
        self.start = time.monotonic()

    def update(self, done: int = 0, failed: int = 0) -> None:
        """Count finished and failed runs, and redraw."""
        self.done += done
        self.failed += failed
        if not self.enabled:
            return
        elapsed = time.monotonic() - self.start
        finished = self.done + self.failed
        eta = f"{elapsed / finished * (self.total - finished):.0f} s" if finished else "unknown"
        pct = 100.0 * finished / self.total if self.total else 100.0
        self.stream.write(
            f"\r{self.name}: {self.done}/{self.total} runs ({pct:.0f}%), {self.failed} failed, "
            f"{elapsed:.0f} s, ETA {eta} "
        )
        self.stream.flush()

    def close(self) -> None:
        """End the progress line."""
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()
