"""Validators of the solvers' arguments, shared by the front door and both solvers.

:func:`etobs.hybrid.solve` (the front door), the engine (:mod:`etobs.hybrid.compiled`),
the reference (:mod:`etobs.hybrid.reference`) and the systems (:mod:`etobs.hybrid.system`)
check their arguments here, below all of them, so that none imports the front door.
"""

from __future__ import annotations

import os
import sys
import warnings
from collections.abc import Callable
from types import FrameType
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.errors import InputError, InputTypeError

#: The solvers of :func:`~etobs.hybrid.solve` (and of :func:`etobs.simulate`).
BACKENDS = ("auto", "engine", "scipy")
#: Earlier names: ``"numba"`` is the engine; the batched numpy solver is retired.
RETIRED = ("numpy", "fast")


def check_backend(backend: Any, name: str = "backend") -> str:
    """``backend`` validated (``"numba"`` read as ``"engine"``); the retired numpy solver is named.

    ``name`` is how the error message names the argument (``"execution.backend"`` in a spec).

    Examples
    --------
    >>> check_backend("numba")
    'engine'

    """
    if backend == "numba":
        return "engine"
    if backend in RETIRED:
        raise InputError(
            f"`{name}` {backend!r} (the batched numpy solver) was retired: the compiled engine "
            "runs every feature; use 'engine' (the default, 'auto') or 'scipy' (the solve_ivp reference)"
        )
    if backend not in BACKENDS:
        raise InputError(f"`{name}` must be one of {BACKENDS} (or 'numba' for 'engine'); got {backend!r}")
    return str(backend)


def span(t_span: Any) -> tuple[float, float]:
    """Validate a time span ``(t0, t_end)`` with ``t0 <= t_end``."""
    try:
        t0, t_end = t_span
    except (TypeError, ValueError) as exc:
        raise InputError(f"`t_span` must be a pair (t0, t_end); got {t_span!r}") from exc
    t0 = v.real("t_span[0]", t0)
    t_end = v.real("t_span[1]", t_end)
    if t_end < t0:
        raise InputError(f"`t_span` must satisfy t0 <= t_end; got ({t0:g}, {t_end:g})")
    return t0, t_end


def warn_unreached_grid(grid: Any, t0: float, t_end: float) -> None:
    """Say, with a ``RuntimeWarning``, when points of a ``SaveAt`` grid lie outside ``[t0, t_end]``.

    A run never reaches them, so their states are NaN and a ``max_distance`` over the
    grid is NaN: said rather than left to be found in the results. The usual cause is
    ``np.arange``, whose last point can lie a rounding error past its end.
    """
    if grid is None or len(grid) == 0:
        return
    g = np.asarray(grid, dtype=float)
    after, before = int(np.sum(g > t_end)), int(np.sum(g < t0))
    if after:
        warnings.warn(
            f"`save.grid`: {after} of {g.size} points lie after t_end = {t_end!r} (the last at "
            f"{float(g[-1])!r}, t_end + {float(g[-1]) - t_end:.3g}): no run reaches them, so their values "
            "(and a max_distance over the grid) are NaN; end the grid at t_end, e.g. "
            "np.linspace(start, t_end, n) rather than np.arange",
            RuntimeWarning,
            stacklevel=_callers_level(),
        )
    if before:
        warnings.warn(
            f"`save.grid`: {before} of {g.size} points lie before t0 = {t0!r} (the first at "
            f"{float(g[0])!r}): no run reaches them, so their values (and a max_distance over the "
            "grid) are NaN",
            RuntimeWarning,
            stacklevel=_callers_level(),
        )


def _callers_level() -> int:
    """``stacklevel`` of the first frame outside etobs, for a warning the caller can filter by module.

    ``warn_unreached_grid`` is reached through ``solve``, ``simulate``, sweeps and the design
    tools, each at its own depth below the user's call.
    """
    package = os.path.dirname(os.path.dirname(os.path.abspath(__file__))) + os.sep
    frame: FrameType | None = sys._getframe(1)  # the frame that calls warnings.warn: level 1
    level = 1
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(package):
        frame, level = frame.f_back, level + 1
    return level


def check_progress(progress: object) -> Callable[[float], object] | None:
    """``progress`` validated: a callable ``progress(n_runs_finished)``, or ``None``."""
    if progress is not None and not callable(progress):
        raise InputTypeError(
            "`progress` must be a callable progress(n_runs_finished) (a tqdm bar's update, say) "
            f"or None; got {type(progress).__name__}"
        )
    return progress


def check_sizes(n: int, n_rules: int, n_flow: int | None) -> None:
    """Validate a system's state size ``n``, rule count ``n_rules`` and ``n_flow <= n``."""
    v.integer("n", n, lower=1)
    v.integer("n_rules", n_rules, lower=0)
    if n_flow is not None:
        v.integer("n_flow", n_flow, lower=1)
        if n_flow > n:
            raise InputError(f"`n_flow` must be <= n = {n}; got {n_flow}")


def check_log_columns(log_columns: Any, n: int) -> tuple[int, ...]:
    """``log_columns`` validated: distinct state indices in ``0 .. n-1`` (empty: none)."""
    if isinstance(log_columns, tuple | list | range | np.ndarray) and len(log_columns) == 0:
        return ()
    cols = v.index_tuple("log_columns", log_columns, "state")
    beyond = [c for c in cols if c >= n]
    if beyond:
        raise InputError(
            f"`log_columns` must be state indices 0..{n - 1} (n = {n}); got {list(cols)} ({beyond[0]} >= n)"
        )
    return cols
