"""Progress bars for long work (simulate batches, sweeps, comparisons, rate estimates).

One place decides how progress is shown: a `tqdm <https://tqdm.github.io>`_ bar on
stderr, on by default only when stderr is a terminal, and drawn only after the work has
taken :data:`DELAY` seconds (a short call prints nothing). Callers pass ``enabled``:
``None`` for that default, ``True`` or ``False`` to force it.
"""

from __future__ import annotations

import sys
from typing import Any

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
) -> Any:
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
