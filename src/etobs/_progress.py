"""Progress bars for long work (simulate runs and batches, sweeps, comparisons, rate estimates).

One place decides how progress is shown: a `tqdm <https://tqdm.github.io>`_ bar on
stderr, on by default only when stderr is a terminal, and drawn only after the work has
taken :data:`DELAY` seconds (a short call prints nothing). Callers pass ``enabled``:
``None`` for that default, ``True`` or ``False`` to force it. :func:`progress_bar` counts
units of work (runs, grid points); :func:`horizon_bar` counts simulated time, so that a
single long run shows how far it got and how long the rest would take.
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, NoReturn

if TYPE_CHECKING:
    from tqdm import tqdm

#: Seconds before a bar first appears: work shorter than this shows nothing.
DELAY = 1.0


def progress_shown(enabled: bool | None) -> bool:
    """Whether a bar asked for with ``enabled`` is shown (``None``: stderr is a terminal).

    Callers that would pay for a bar (tqdm's import, a solver reporting in chunks) ask
    this first and skip the bar when it is ``False``.
    """
    return sys.stderr.isatty() if enabled is None else bool(enabled)


def progress_write(line: str) -> None:
    """Print ``line`` on stderr above any progress bar (drawing it again below, not cut)."""
    from tqdm import tqdm

    tqdm.write(line, file=sys.stderr)


def progress_bar(
    total: int, desc: str, *, enabled: bool | None = None, unit: str = "run", initial: int = 0
) -> tqdm[NoReturn]:
    """A tqdm bar on stderr counting ``total`` units of work.

    Parameters
    ----------
    total : int
        Units of work (runs, grid points, samples).
    desc : str
        What the work is, shown before the bar.
    enabled : bool or None
        ``None``: shown when stderr is a terminal; ``True``/``False``: forced.
    unit : str
        Name of one unit.
    initial : int
        Units already done before this call (resumed work): counted in the bar, not in
        its rate.

    Returns
    -------
    tqdm.tqdm
        Use ``bar.update(n)`` and ``bar.close()`` (or ``with``). When disabled every call
        is a no-op.

    Examples
    --------
    >>> with progress_bar(3, "runs", enabled=False) as bar:
    ...     bar.update(3)
    >>> bar.disable
    True

    """
    from tqdm import tqdm

    show = progress_shown(enabled)
    return tqdm(
        total=total,
        desc=desc,
        unit=unit,
        file=sys.stderr,
        disable=not show,
        delay=0.0 if enabled else DELAY,
        dynamic_ncols=True,
        leave=True,
        initial=initial,
    )


#: Seconds of work left beyond which :func:`horizon_bar` writes years (tqdm's own ETA
#: would print every digit of e.g. 1e290 hours).
_LONG = 1e6
_YEAR = 365.25 * 86400.0


class _HorizonBar:
    """A tqdm bar over runs whose postfix says the simulated time and the time left."""

    def __init__(self, bar: tqdm[NoReturn], t0: float, t_end: float, runs: int) -> None:
        self.bar, self.t0, self.span, self.runs = bar, t0, t_end - t0, runs
        self.t_end = t_end

    def update(self, runs_done: float) -> None:
        """Add ``runs_done`` runs (fractions of a run's horizon count) to the bar."""
        bar = self.bar
        if bar.disable:
            return
        frac = min(float(bar.n) + float(runs_done), self.runs) / self.runs
        elapsed = bar.format_dict["elapsed"]
        left = elapsed * (1.0 - frac) / frac if frac > 0 else float("inf")
        mean = " (mean of the runs)" if self.runs > 1 else ""
        bar.set_postfix_str(
            f"t = {self.t0 + frac * self.span:.4g} of {self.t_end:.4g} s simulated{mean}, {_left(left)} left",
            refresh=False,
        )
        bar.update(runs_done)

    def close(self) -> None:
        self.bar.close()

    def __enter__(self) -> _HorizonBar:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _left(seconds: float) -> str:
    if seconds != seconds or seconds == float("inf"):
        return "? s"
    if seconds > _LONG:
        return f"about {seconds / _YEAR:.2g} years"
    from tqdm import tqdm

    return str(tqdm.format_interval(seconds))


def horizon_bar(runs: int, t0: float, t_end: float, desc: str, *, enabled: bool | None = None) -> _HorizonBar:
    """A bar for ``runs`` runs over ``[t0, t_end]``, advanced by the simulated time of each run.

    ``update(k)`` adds ``k`` runs, fractions included: a run that has simulated to ``t``
    counts ``(t - t0) / (t_end - t0)``. The bar shows the mean simulated time of the runs
    and the wall time left at the pace so far (in years when it is more than
    :data:`_LONG` seconds), so a run that would take too long is seen a second after it
    starts. Shown as :func:`progress_bar` is (``enabled``, :data:`DELAY`).

    Examples
    --------
    >>> with horizon_bar(2, 0.0, 10.0, "simulate", enabled=False) as bar:
    ...     bar.update(0.5)
    >>> bar.bar.disable
    True

    """
    from tqdm import tqdm

    show = progress_shown(enabled)
    bar = tqdm(
        total=runs,
        desc=desc,
        file=sys.stderr,
        disable=not show,
        delay=0.0 if enabled else DELAY,
        dynamic_ncols=True,
        leave=True,
        bar_format="{desc}: {percentage:3.0f}%|{bar}| {postfix}",
    )
    return _HorizonBar(bar, t0, t_end, runs)
