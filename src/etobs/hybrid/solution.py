"""Results of a hybrid solve: hybrid arcs, the jump log and per-run status."""

from __future__ import annotations

import html
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, NamedTuple, overload

import numpy as np
from numpy.typing import NDArray

from etobs._validate import shown
from etobs.errors import InputError, InputTypeError
from etobs.hybrid.status import Status, status_message

if TYPE_CHECKING:
    import pandas as pd


@dataclass(frozen=True, repr=False)
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
        return int(self.t.shape[0])

    def __repr__(self) -> str:
        if not len(self):
            return f"HybridArc: 0 points, n = {self.x.shape[-1]}"
        return (
            f"HybridArc: {len(self)} points, n = {self.x.shape[1]}, "
            f"t in [{self.t[0]:.6g}, {self.t[-1]:.6g}], j in [{self.j[0]}, {self.j[-1]}]"
        )


class JumpRow(NamedTuple):
    """One row of a :class:`JumpLog`: rule ``rule`` of run ``run`` jumped at ``(t, j)``.

    ``x`` holds the logged state entries just after the jump (``log_columns``).
    """

    run: int
    rule: int
    t: float
    j: int
    x: np.ndarray


#: Rows a JumpLog's repr shows (its HTML repr: twice as many).
_REPR_ROWS = 5
#: Rules whose jump counts a HybridSolution's repr names.
_REPR_RULES = 8
_KEYS = ("run", "rule", "t", "j")


@dataclass(frozen=True, repr=False)
class JumpLog:
    """Every jump of every run, sorted by run then ``j``: a table with one row per jump.

    A row ``(run, rule, t, j, x)`` says that rule ``rule`` of run ``run`` jumped at time
    ``t`` from hybrid time ``(t, j)`` to ``(t, j + 1)``; ``x`` holds the state entries
    the system logs (its ``log_columns``) just after that jump, in columns named
    ``names``.

    Read it as arrays (``log.t``, ``log.x``, ``log.to_dict()``), row by row
    (``log[k]`` and iteration give :class:`JumpRow`), or as a table
    (:meth:`to_pandas`). ``log[mask]``, ``log[slice]`` and ``log[indices]`` are
    JumpLogs of the rows chosen.

    Attributes
    ----------
    run, rule, j : ndarray of int, shape (L,)
    t : ndarray, shape (L,)
    x : ndarray, shape (L, c)
        The post-jump values of the ``c`` logged state entries (``c = 0``: none logged).
    names : tuple of str
        Names of the columns of ``x`` (default ``x_i`` for state entry ``i``; see
        :func:`log_names`).

    Examples
    --------
    >>> log = JumpLog(np.array([0, 0, 1]), np.array([0, 1, 0]), np.array([0.5, 0.7, 0.2]),
    ...               np.array([0, 1, 0]), x=np.array([[1.0], [2.0], [3.0]]), names=("x_1",))
    >>> log[1]
    JumpRow(run=0, rule=1, t=0.7, j=1, x=array([2.]))
    >>> len(log[log.run == 0]), [row.t for row in log[1:]]
    (2, [0.7, 0.2])

    """

    run: np.ndarray
    rule: np.ndarray
    t: np.ndarray
    j: np.ndarray
    x: np.ndarray | None = None
    names: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        L = np.shape(self.run)[0]
        for key in _KEYS[1:]:
            if np.shape(getattr(self, key)) != (L,):
                raise InputError(
                    f"JumpLog `{key}` must have shape ({L},) like `run`; got {np.shape(getattr(self, key))}"
                )
        names = tuple(self.names)
        if self.x is None and names:  # names without values would label uninitialised memory
            raise InputError(f"JumpLog `names` {list(names)} given without `x`: give the logged values too")
        x = np.empty((L, 0)) if self.x is None else np.asarray(self.x, dtype=float)
        if not names and x.ndim == 2:
            names = log_names(range(x.shape[1]))
        if x.shape != (L, len(names)):
            raise InputError(f"JumpLog `x` must have shape ({L}, {len(names)}) (rows, names); got {x.shape}")
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "names", names)

    def __len__(self) -> int:
        return int(self.run.shape[0])

    @overload
    def __getitem__(self, key: int | np.integer) -> JumpRow: ...

    @overload
    def __getitem__(self, key: slice | np.ndarray | list[Any]) -> JumpLog: ...

    def __getitem__(self, key: Any) -> JumpRow | JumpLog:
        """Row ``k`` (a :class:`JumpRow`), or the JumpLog of a slice, boolean mask or indices."""
        L = len(self)
        if isinstance(key, int | np.integer) and not isinstance(key, bool | np.bool_):
            k = int(key)
            if not -L <= k < L:
                raise IndexError(f"JumpLog row {k} is out of range: the log has {L} rows")
            k %= L
            assert self.x is not None
            return JumpRow(
                int(self.run[k]), int(self.rule[k]), float(self.t[k]), int(self.j[k]), self.x[k].copy()
            )
        if not isinstance(key, slice):
            given, key = key, np.asarray(key)
            if key.dtype == bool:
                if key.shape != (L,):
                    raise IndexError(
                        f"a boolean mask of a JumpLog must have shape ({L},) (one per row); got {key.shape}"
                    )
            elif key.ndim != 1 or not (np.issubdtype(key.dtype, np.integer) or key.size == 0):
                raise InputTypeError(
                    "a JumpLog is indexed by an int, a slice, a boolean mask or a 1-D array of ints "
                    f"(its columns are attributes: log.t, log.x); got {type(given).__name__} "
                    f"{shown(given)} (dtype {key.dtype}, shape {key.shape})"
                )
            else:
                key = key.astype(np.int64)
                if key.size and not (np.all(key < L) and np.all(key >= -L)):
                    raise IndexError(f"JumpLog rows {key.tolist()} are out of range: the log has {L} rows")
        assert self.x is not None
        return replace(
            self, run=self.run[key], rule=self.rule[key], t=self.t[key], j=self.j[key], x=self.x[key]
        )

    def __iter__(self) -> Iterator[JumpRow]:
        assert self.x is not None
        for run, rule, t, j, x in zip(
            self.run.tolist(), self.rule.tolist(), self.t.tolist(), self.j.tolist(), self.x, strict=True
        ):
            yield JumpRow(run, rule, t, j, x.copy())

    def select(self, run: int | None = None, rule: int | None = None) -> JumpLog:
        """Return the rows of one run and/or one rule."""
        keep = np.ones(len(self), dtype=bool)
        if run is not None:
            keep &= self.run == run
        if rule is not None:
            keep &= self.rule == rule
        return self[keep]

    def times(self, run: int, rule: int) -> np.ndarray:
        """Jump times of ``rule`` in ``run``, increasing."""
        keep: NDArray[np.bool_] = (self.run == run) & (self.rule == rule)
        return self.t[keep]

    def counts(self, n_runs: int, n_rules: int) -> np.ndarray:
        """Number of jumps per run and rule, shape ``(n_runs, n_rules)``."""
        out = np.zeros((n_runs, n_rules), dtype=np.int64)
        np.add.at(out, (self.run, self.rule), 1)
        return out

    def to_dict(self, names: Sequence[str] | None = None) -> dict[str, np.ndarray]:
        """The log's columns by name: ``run, rule, t, j``, then one per logged state entry.

        ``names`` renames the logged entries (default :attr:`names`). The arrays are the
        log's own (not copies).
        """
        assert self.x is not None
        names = self._column_names(names)
        return {**{k: getattr(self, k) for k in _KEYS}, **{n: self.x[:, c] for c, n in enumerate(names)}}

    def to_pandas(self, names: Sequence[str] | None = None) -> pd.DataFrame:
        """The log as a :class:`pandas.DataFrame`, one row per jump.

        Columns ``run, rule, t, j`` and one per logged state entry, named ``names``
        (default :attr:`names`: ``x_i`` for state entry ``i``).

        Examples
        --------
        >>> log = JumpLog(np.array([0]), np.array([1]), np.array([0.5]), np.array([0]))
        >>> log.to_pandas().columns.tolist()
        ['run', 'rule', 't', 'j']

        """
        import pandas as pd  # only here: the numerics never import pandas

        return pd.DataFrame(self.to_dict(names))

    def _column_names(self, names: Sequence[str] | None) -> tuple[str, ...]:
        if names is None:
            return self.names
        if isinstance(names, str):
            raise InputTypeError(f"`names` must be a sequence of column names; got the string {names!r}")
        if not isinstance(names, Sequence):
            raise InputTypeError(f"`names` must be a sequence of column names; got {type(names).__name__}")
        out = tuple(names)
        if len(out) != len(self.names):
            raise InputError(
                f"`names` must give {len(self.names)} names (one per logged state entry); got {len(out)}"
            )
        if not all(isinstance(n, str) for n in out) or len(set(out + _KEYS)) != len(out) + len(_KEYS):
            raise InputError(
                f"`names` must be distinct strings other than {', '.join(_KEYS)}; got {list(out)}"
            )
        return out

    def _summary(self) -> str:
        rules = [f"{r}: {c}" for r, c in zip(*np.unique(self.rule, return_counts=True), strict=True)]
        if len(rules) > _REPR_RULES:
            rules = [*rules[:_REPR_RULES], "..."]
        runs = np.unique(self.run).size
        cols = f"; logged {', '.join(self.names)}" if self.names else ""
        return (
            f"JumpLog: {len(self)} jumps in {runs} run{'' if runs == 1 else 's'}"
            f" (jumps per rule: {', '.join(rules) or 'none'}){cols}"
        )

    def _head(self, rows: int) -> tuple[list[str], list[list[str]]]:
        assert self.x is not None
        header = [*_KEYS, *self.names]
        cells = [
            [str(r.run), str(r.rule), f"{r.t:.6g}", str(r.j), *(f"{v:.6g}" for v in r.x)] for r in self[:rows]
        ]
        return header, cells

    def __repr__(self) -> str:
        header, cells = self._head(_REPR_ROWS)
        if not cells:
            return self._summary()
        widths = [max(len(c) for c in col) for col in zip(header, *cells, strict=True)]
        lines = [" ".join(c.rjust(w) for c, w in zip(row, widths, strict=True)) for row in [header, *cells]]
        more = [f"... {len(self) - len(cells)} more rows"] if len(self) > len(cells) else []
        return "\n".join([self._summary(), *("  " + line for line in lines), *more])

    def _repr_html_(self) -> str:
        header, cells = self._head(2 * _REPR_ROWS)
        more = len(self) - len(cells)
        head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
        body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>" for row in cells)
        tail = f"<p>... {more} more rows</p>" if more > 0 else ""
        return (
            f"<p>{html.escape(self._summary())}</p>"
            f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>{tail}"
        )


def log_names(columns: Iterable[int]) -> tuple[str, ...]:
    """Default names of logged state entries: ``x_i`` for state entry ``i``."""
    return tuple(f"x_{int(c)}" for c in columns)


@dataclass(frozen=True, repr=False)
class SavedGrid:
    """States kept on a common time grid: ``x[b, g]`` is run ``b`` at ``t[g]``, ``j[b, g]``."""

    t: np.ndarray
    j: np.ndarray
    x: np.ndarray

    def __repr__(self) -> str:
        B, G, n = self.x.shape
        return f"SavedGrid: {B} runs x {G} points{_span(self.t)} x n = {n}"


@dataclass(frozen=True)
class GridMax:
    """Each run's largest distance over the save grid (``SaveAt(max_distance=...)``).

    ``value[b]`` is the maximum over the points ``t`` of run ``b``; NaN when a value was
    not finite or the run stopped before the last point.
    """

    t: np.ndarray
    value: np.ndarray

    def __repr__(self) -> str:
        return f"GridMax: {self.value.shape[0]} runs, maximum over {self.t.shape[0]} points{_span(self.t)}"


@dataclass(frozen=True)
class LaneStats:
    """How the engine's lanes were used in a solve (``HybridSolution.lanes``).

    Each thread advances ``width`` runs side by side; a *lane-step* is one lane during one
    step of its thread.

    Attributes
    ----------
    width : int
        Lanes per thread (at most :data:`etobs.hybrid.compiled.LANES`).
    vector : bool
        Whether the system's lane form ran (else its one-run form, lane by lane).
    slots : int
        Lane-steps, over all threads.
    idle : int
        Lane-steps of lanes that held no run (the queue was empty: the batch's tail).
    rejected : int
        Lane-steps whose step was rejected.
    events : int
        Lane-steps whose step was examined lane by lane for an event (an event function
        sampled at or above zero, a peak probe, or a failure).

    """

    width: int
    vector: bool
    slots: int
    idle: int
    rejected: int
    events: int

    def share(self, what: str) -> float:
        """``idle``, ``rejected`` or ``events`` as a fraction of :attr:`slots`."""
        return float(getattr(self, what)) / self.slots if self.slots else 0.0

    def __repr__(self) -> str:
        parts = ", ".join(f"{k} {self.share(k):.1%}" for k in ("idle", "rejected", "events"))
        form = "lane form" if self.vector else "one-run form lane by lane"
        return f"LaneStats: {self.width} lanes ({form}), {self.slots} lane-steps: {parts}"


def _span(t: np.ndarray) -> str:
    """`` on t in [a, b]`` for a non-empty time array, else nothing (for reprs)."""
    return f" on t in [{t[0]:.6g}, {t[-1]:.6g}]" if t.size else ""


def max_over_grid(distance: np.ndarray) -> np.ndarray:
    """Per run (axis 0), the maximum over the grid (axis 1); NaN unless every value is finite.

    (NaN too for a grid of no point.) The compiled engine folds the same maximum point
    by point (``_grid_keep`` in :mod:`etobs.hybrid._kernel_body`).
    """
    if distance.shape[1] == 0:
        return np.full(distance.shape[0], np.nan)
    finite = np.all(np.isfinite(distance), axis=1)
    return np.where(finite, np.max(np.nan_to_num(distance, nan=-np.inf), axis=1), np.nan)


@dataclass(frozen=True, repr=False)
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
    lanes : LaneStats or None
        How the engine's lanes were used (``backend == "engine"``).

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
    lanes: LaneStats | None = None

    @property
    def n_runs(self) -> int:
        """Number of runs ``B``."""
        return int(self.status.shape[0])

    @property
    def ok(self) -> bool:
        """Whether every run completed."""
        return bool(np.all(self.status == Status.COMPLETED))

    def messages(self, advice: Mapping[Status, str] | None = None) -> list[str]:
        """One sentence per run saying how it ended and, on failure, how to fix it.

        ``advice`` adds a sentence per status in the terms of the layer that built the
        system (see :func:`~etobs.hybrid.status_message`).
        """
        details = self.failures or ("",) * self.n_runs
        return [
            status_message(Status(s), float(t), d, self.backend, advice)
            for s, t, d in zip(self.status, self.t_final, details, strict=True)
        ]

    def status_labels(self) -> list[str]:
        """Status of each run as a lower-case label (``"completed"``, ``"max_jumps"``...)."""
        return [Status(s).label for s in self.status]

    def __repr__(self) -> str:
        labels, counts = np.unique(self.status_labels(), return_counts=True)
        status = ", ".join(f"{c} {s}" for s, c in zip(labels, counts, strict=True)) or "no run"
        rules = self.jumps.counts(self.n_runs, len(self.rule_names)).sum(axis=0)
        per_rule = [f"{n}: {c}" for n, c in zip(self.rule_names, rules, strict=True)]
        if len(per_rule) > _REPR_RULES:  # an estimation problem has a rule per node and link
            per_rule = [*per_rule[:_REPR_RULES], "..."]
        kept = [f"arcs ({sum(len(a) for a in self.arcs)} points)"] if self.arcs is not None else []
        kept += [repr(g) for g in (self.grid, self.grid_max) if g is not None]
        t0, t1 = self.t_span
        steps = f"{int(self.n_steps.sum())} accepted, {int(self.n_rejected.sum())} rejected"
        return "\n".join(
            [
                f"HybridSolution ({self.backend}): {self.n_runs} run{'' if self.n_runs == 1 else 's'} "
                f"on t in [{t0:g}, {t1:g}]; {status}",
                f"  jumps: {len(self.jumps)} ({', '.join(per_rule) or 'no rule'}); steps: {steps}",
                f"  kept: {'; '.join(kept) or 'final states only'}",
            ]
        )
