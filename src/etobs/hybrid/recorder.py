"""Collects what a solve keeps (steps, jumps, grid values) and builds the results.

Used by the reference backend; the engine fills the same result objects from its buffers.
"""

from __future__ import annotations

import numpy as np

from etobs.hybrid.options import SaveAt
from etobs.hybrid.solution import HybridArc, JumpLog, SavedGrid, log_names


class Recorder:
    """Accumulates arrays chunk by chunk; every call takes the runs it concerns.

    ``log_columns`` are the state entries logged at every jump (the system's).
    """

    def __init__(
        self, n_runs: int, n: int, save: SaveAt, t0: float, log_columns: tuple[int, ...] = ()
    ) -> None:
        self.n_runs, self.n = n_runs, n
        self.keep_steps = save.steps
        self.log_columns = log_columns
        self._steps: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self._jumps: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self.grid_t = save.grid
        if self.grid_t is not None:
            g = self.grid_t.shape[0]
            self.grid_x = np.full((n_runs, g, n), np.nan)
            self.grid_j = np.full((n_runs, g), -1, dtype=np.int64)
            self.grid_next = np.full(n_runs, np.searchsorted(self.grid_t, t0, "left"))

    def steps(self, runs: np.ndarray, t: np.ndarray, j: np.ndarray, x: np.ndarray) -> None:
        """Keep the states ``x`` of ``runs`` at hybrid times ``(t, j)``."""
        if self.keep_steps and runs.size:
            t = np.broadcast_to(t, runs.shape)
            self._steps.append((runs.copy(), t.copy(), j.copy(), x.copy()))

    def jumps(self, runs: np.ndarray, rule: int, t: np.ndarray, j: np.ndarray, x: np.ndarray) -> None:
        """Log one jump of ``rule`` for each of ``runs`` from ``(t, j)``; ``x`` the states after it."""
        if runs.size:
            kept = x[:, list(self.log_columns)]  # a copy (fancy indexing)
            self._jumps.append((runs.copy(), np.full(runs.shape, rule), t.copy(), j.copy(), kept))

    def grid_due(self, runs: np.ndarray, t_stop: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Grid points not yet filled up to and including ``t_stop`` for each run.

        Returns ``(row, g)``: for each due point, the position of its run in ``runs`` and
        its grid index. The points are marked as filled.
        """
        if self.grid_t is None or runs.size == 0:
            empty = np.empty(0, dtype=np.int64)
            return empty, empty
        start = self.grid_next[runs]
        stop = np.searchsorted(self.grid_t, t_stop, "right")
        count = np.maximum(stop - start, 0)
        self.grid_next[runs] = np.maximum(stop, start)
        row = np.repeat(np.arange(runs.size), count)
        offset = np.arange(row.size) - np.repeat(np.cumsum(count) - count, count)
        return row, start[row] + offset

    def grid_fill(self, runs: np.ndarray, g: np.ndarray, j: np.ndarray, x: np.ndarray) -> None:
        """Store grid values for pairs ``(runs[k], g[k])``."""
        if self.grid_t is not None and runs.size:
            self.grid_x[runs, g] = x
            self.grid_j[runs, g] = j

    def arcs(self) -> tuple[HybridArc, ...] | None:
        """Per-run hybrid arcs in chronological order, or ``None`` when steps were not kept."""
        if not self.keep_steps:
            return None
        runs = np.concatenate([c[0] for c in self._steps])
        order = np.argsort(runs, kind="stable")
        t = np.concatenate([c[1] for c in self._steps])[order]
        j = np.concatenate([c[2] for c in self._steps])[order]
        x = np.concatenate([c[3] for c in self._steps])[order]
        cuts = np.searchsorted(runs[order], np.arange(1, self.n_runs))
        return tuple(
            HybridArc(tt, jj, xx)
            for tt, jj, xx in zip(np.split(t, cuts), np.split(j, cuts), np.split(x, cuts), strict=True)
        )

    def jump_log(self) -> JumpLog:
        """All jumps, sorted by run then ``j``."""
        names = log_names(self.log_columns)
        if not self._jumps:
            e = np.empty(0, dtype=np.int64)
            return JumpLog(e, e.copy(), np.empty(0), e.copy(), np.empty((0, len(names))), names)
        run, rule, t, j, x = (np.concatenate([c[k] for c in self._jumps]) for k in range(5))
        order = np.lexsort((j, run))
        return JumpLog(run[order], rule[order].astype(np.int64), t[order], j[order], x[order], names)

    def saved_grid(self) -> SavedGrid | None:
        """The grid values, or ``None`` when no grid was asked for."""
        if self.grid_t is None:
            return None
        return SavedGrid(self.grid_t, self.grid_j, self.grid_x)
