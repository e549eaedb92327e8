"""Results of a hybrid solve: hybrid arcs, the jump log and per-run status."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from etobs.hybrid.status import Status, status_message


@dataclass(frozen=True)
class HybridArc:
    """One run's solution on its hybrid time domain.

    ``t[k], j[k], x[k]`` is the state at hybrid time ``(t[k], j[k])``. A jump appears as
    two consecutive rows with the same ``t`` and ``j`` increasing by one.

    Attributes
    ----------
    t : ndarray, shape (K,)
    j : ndarray of int, shape (K,)
    x : ndarray, shape (K, n)

    """

    t: np.ndarray
    j: np.ndarray
    x: np.ndarray

    def __len__(self) -> int:
        return self.t.shape[0]


@dataclass(frozen=True)
class JumpLog:
    """Every jump of every run, sorted by run then ``j``.

    A row ``(run, rule, t, j)`` says that rule ``rule`` of run ``run`` jumped at time
    ``t`` from hybrid time ``(t, j)`` to ``(t, j + 1)``.
    """

    run: np.ndarray
    rule: np.ndarray
    t: np.ndarray
    j: np.ndarray

    def __len__(self) -> int:
        return self.run.shape[0]

    def select(self, run: int | None = None, rule: int | None = None) -> JumpLog:
        """Return the rows of one run and/or one rule."""
        keep = np.ones(len(self), dtype=bool)
        if run is not None:
            keep &= self.run == run
        if rule is not None:
            keep &= self.rule == rule
        return JumpLog(self.run[keep], self.rule[keep], self.t[keep], self.j[keep])

    def times(self, run: int, rule: int) -> np.ndarray:
        """Jump times of ``rule`` in ``run``, increasing."""
        keep = (self.run == run) & (self.rule == rule)
        return self.t[keep]

    def counts(self, n_runs: int, n_rules: int) -> np.ndarray:
        """Number of jumps per run and rule, shape ``(n_runs, n_rules)``."""
        out = np.zeros((n_runs, n_rules), dtype=np.int64)
        np.add.at(out, (self.run, self.rule), 1)
        return out


@dataclass(frozen=True)
class SavedGrid:
    """States kept on a common time grid: ``x[b, g]`` is run ``b`` at ``t[g]``, ``j[b, g]``."""

    t: np.ndarray
    j: np.ndarray
    x: np.ndarray


@dataclass(frozen=True)
class GridMax:
    """Each run's largest distance over the save grid (``SaveAt(max_distance=...)``).

    ``value[b]`` is the maximum over the points ``t`` of run ``b``; NaN when a value was
    not finite or the run stopped before the last point.
    """

    t: np.ndarray
    value: np.ndarray


def max_over_grid(distance: np.ndarray) -> np.ndarray:
    """Per run (axis 0), the maximum over the grid (axis 1); NaN unless every value is finite.

    (NaN too for a grid of no point.) The compiled engine folds the same maximum point
    by point (``_grid_keep`` in :mod:`etobs.hybrid._kernel_body`).
    """
    if distance.shape[1] == 0:
        return np.full(distance.shape[0], np.nan)
    finite = np.all(np.isfinite(distance), axis=1)
    return np.where(finite, np.max(np.nan_to_num(distance, nan=-np.inf), axis=1), np.nan)


@dataclass(frozen=True)
class HybridSolution:
    """Solution of a batch of runs of one hybrid system.

    Attributes
    ----------
    t_span : tuple of float
    status : ndarray of int, shape (B,)
        :class:`Status` code of each run.
    t_final, j_final, x_final : ndarray
        Hybrid time and state where each run stopped.
    jumps : JumpLog
    arcs : tuple of HybridArc or None
        Full arcs (``SaveAt(steps=True)``).
    grid : SavedGrid or None
        States on the save grid (``SaveAt(grid=...)``), unless only their distance's
        maximum was kept (``SaveAt(max_distance=...)``): then ``grid_max``.
    n_steps, n_rejected : ndarray of int, shape (B,)
        Accepted and rejected steps of each run.
    rule_names : tuple of str
    backend : str
    failures : tuple of str
        Per run, which model function failed and how (runs with status
        ``model_error``), else ``""``.
    grid_max : GridMax or None
        With ``SaveAt(max_distance=...)``.

    """

    t_span: tuple[float, float]
    status: np.ndarray
    t_final: np.ndarray
    j_final: np.ndarray
    x_final: np.ndarray
    jumps: JumpLog
    arcs: tuple[HybridArc, ...] | None
    grid: SavedGrid | None
    n_steps: np.ndarray
    n_rejected: np.ndarray
    rule_names: tuple[str, ...]
    backend: str
    failures: tuple[str, ...] = ()
    grid_max: GridMax | None = None

    @property
    def n_runs(self) -> int:
        """Number of runs ``B``."""
        return self.status.shape[0]

    @property
    def ok(self) -> bool:
        """Whether every run completed."""
        return bool(np.all(self.status == Status.COMPLETED))

    def messages(self) -> list[str]:
        """One sentence per run saying how it ended and, on failure, how to fix it."""
        details = self.failures or ("",) * self.n_runs
        return [
            status_message(Status(s), float(t), d)
            for s, t, d in zip(self.status, self.t_final, details, strict=True)
        ]

    def status_labels(self) -> list[str]:
        """Status of each run as a lower-case label (``"completed"``, ``"max_jumps"``...)."""
        return [Status(s).label for s in self.status]
