"""Figures and axes for the plot functions: their own, the caller's (``ax=``), and a paper's sizes.

Every plot function draws into the axes it is given (``ax=``: one ``Axes``, or one per
panel) or, without them, into a new :class:`matplotlib.figure.Figure`; it returns a
:class:`Drawn`, which unpacks as ``fig, axes`` and names the artists it drew.
:func:`paper_figure` makes a figure one or two columns of a journal wide, :func:`paper_style`
sets fonts and lines for it, and :func:`save_figure` writes PDF, SVG or PNG.
``pyplot`` is never imported, so all of this works headless.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.errors import InputError, InputTypeError

#: Text widths in inches of a two-column journal page (IEEE Transactions: 3.5 in a column,
#: 7.16 in the page); ``paper_figure(columns=...)`` makes figures this wide.
COLUMN_WIDTH = {1: 3.5, 2: 7.16}
#: The formats :func:`save_figure` writes, by suffix: vector (pdf, svg) or raster (png).
FORMATS = ("pdf", "svg", "png")


class Drawn(tuple):  # type: ignore[type-arg]
    """What a plot function drew: unpacks as ``fig, axes``, and names its artists.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure drawn on (the caller's when ``ax=`` was given).
    axes : Axes or ndarray of Axes
        The axes drawn on, as the function documents.
    artists : mapping of str to list
        The artists drawn, by role (``"x"``, ``"xhat"``, ``"held"``, ...), in drawing
        order; each function's docstring lists its roles. Equality is the tuple's
        (``fig`` and ``axes``).

    Examples
    --------
    >>> from etobs.plot.layout import Drawn
    >>> drawn = Drawn("fig", "axes", {"x": ["line"]})
    >>> fig, axes = drawn
    >>> drawn.artists["x"]
    ('line',)

    """

    def __new__(cls, fig: Any, axes: Any, artists: Mapping[str, Sequence[Any]]) -> Drawn:
        self = super().__new__(cls, (fig, axes))
        self._artists = MappingProxyType({k: tuple(a) for k, a in artists.items()})
        return self

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled and copied with its artists (a figure pickles with them)."""
        return (Drawn, (self[0], self[1], dict(self._artists)))

    @property
    def fig(self) -> Any:
        """The figure."""
        return self[0]

    @property
    def axes(self) -> Any:
        """The axes (one, or an array of them)."""
        return self[1]

    @property
    def artists(self) -> Mapping[str, tuple[Any, ...]]:
        """The artists drawn, by role."""
        return self._artists

    def __repr__(self) -> str:
        roles = ", ".join(f"{k}: {len(a)}" for k, a in self._artists.items())
        return f"Drawn(fig, axes; artists {{{roles}}})"


def _matplotlib() -> Any:
    try:
        import matplotlib
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("plotting needs matplotlib: pip install 'etobs[plot]'") from exc
    return matplotlib


def canvas(
    ax: Any, nrows: int, height: float, *, height_ratios: list[float] | None = None, width: float = 7.0
) -> tuple[Any, np.ndarray, bool]:
    """The figure and ``nrows`` axes to draw in: the caller's ``ax``, or a new figure.

    Returns ``(fig, axes, own)``; ``own`` says the figure is new (a function then titles
    it; on the caller's figure it leaves the title to the caller). The caller gives one
    Axes per panel, or one Axes for all of them: ``axes`` then holds it ``nrows`` times,
    and the function overlays its panels there (:func:`shared`).
    """
    _matplotlib()
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    if ax is None:
        fig = Figure(figsize=(width, height), layout="constrained")
        grid = {"height_ratios": height_ratios} if height_ratios is not None else None
        axes = fig.subplots(nrows, 1, sharex=True, squeeze=False, gridspec_kw=grid)[:, 0]
        return fig, axes, True
    given = [ax] if isinstance(ax, Axes) else list(np.ravel(np.asarray(ax, dtype=object)))
    if not all(isinstance(a, Axes) for a in given):
        bad = next(a for a in given if not isinstance(a, Axes))
        raise InputTypeError(
            f"`ax` must be a matplotlib Axes or a sequence of {nrows}; got {type(bad).__name__}"
        )
    if len(given) == 1 and nrows > 1:  # every panel overlaid in the one Axes given
        given = given * nrows
    if len(given) != nrows:
        raise InputError(
            f"`ax` must be one Axes (all panels overlaid) or {nrows} Axes (one per panel); got {len(given)}"
        )
    return given[0].figure, np.asarray(given, dtype=object), False


def shared(axes: np.ndarray) -> bool:
    """Whether the panels share one Axes (``ax=`` one Axes for several panels)."""
    return len(axes) > 1 and all(a is axes[0] for a in axes)


def components(name: str, value: Any, size: int) -> tuple[int, ...]:
    """``value`` checked as indices into a vector of ``size`` entries; all of them when ``None``."""
    if value is None:
        return tuple(range(size))
    chosen = v.index_tuple(name, value, what="component")
    for k in chosen:
        if k >= size:
            raise InputError(f"`{name}` must be in 0..{size - 1}; got {k}")
    return chosen


def time_label(ax: Any, label: str = "t [s]") -> None:
    """Label ``ax``'s time axis, unless a panel below shares it (a grid's inner rows stay bare)."""
    spec = ax.get_subplotspec()
    if spec is None or spec.is_last_row() or not ax.get_shared_x_axes().get_siblings(ax)[1:]:
        ax.set_xlabel(label)


def window(value: Any) -> tuple[float, float] | None:
    """``window`` checked: ``None`` or a pair ``(t0, t1)`` with ``t0 < t1``."""
    if value is None:
        return None
    if isinstance(value, str) or np.ndim(value) != 1 or np.size(value) != 2:
        raise InputError(f"`window` must be a pair (t0, t1) of times; got {v.shown(value)}")
    lo = v.real("window[0]", value[0])
    hi = v.real("window[1]", value[1])
    if not lo < hi:
        raise InputError(f"`window` must have t0 < t1; got ({lo:g}, {hi:g})")
    return lo, hi


def in_window(t: np.ndarray, span: tuple[float, float] | None, *, reach: bool = False) -> np.ndarray:
    """Boolean mask of the times ``t`` inside ``span`` (ends included); all of them without one.

    ``reach``: also the point just before and just after (``t`` in order) where no point
    lies on the edge, so that a line drawn through the points reaches the window's edges
    (the axis limits clip it there).
    """
    t = np.asarray(t, dtype=float)
    if span is None:
        return np.ones(t.shape, dtype=bool)
    inside = (t >= span[0]) & (t <= span[1])
    if reach and t.size:
        extra = []
        if not np.any(t == span[0]):
            extra.append(np.searchsorted(t, span[0], side="left") - 1)  # the last point before
        if not np.any(t == span[1]):
            extra.append(np.searchsorted(t, span[1], side="right"))  # the first point after
        inside[[k for k in extra if 0 <= k < t.size]] = True
    return inside


def time_axes(axes: np.ndarray, span: tuple[float, float] | None, label: str = "t [s]") -> None:
    """Label the time axis (once, on the bottom panel) and set it to ``span`` when given."""
    time_label(axes[-1], label)
    if span is not None:
        for a in axes:
            a.set_xlim(*span)


def runs(n_runs: int, run: Any) -> tuple[int, ...]:
    """``run`` (one index or a sequence of them) checked against a batch of ``n_runs`` runs."""
    if isinstance(run, int | np.integer) and not isinstance(run, bool):
        chosen: tuple[int, ...] = (int(run),)
    elif isinstance(run, bool) or isinstance(run, str) or not isinstance(run, Sequence | np.ndarray):
        raise InputTypeError(
            f"`run` must be an integer or a sequence of integers; got {v.shown(run)} ({type(run).__name__})"
        )
    else:
        chosen = v.index_tuple("run", run, what="run")
    for r in chosen:
        if not 0 <= r < n_runs:
            raise InputError(f"`run` must be in 0..{n_runs - 1}; got {r}")
    return chosen


def run_color(k: int, n: int, default: str) -> str:
    """Colour of the ``k``-th of ``n`` overlaid runs: ``default`` for one run, else one per run."""
    return default if n == 1 else f"C{k % 10}"


def paper_figure(
    columns: int = 1, nrows: int = 1, ncols: int = 1, *, height: float | None = None, sharex: bool = True
) -> tuple[Any, np.ndarray]:
    """A figure one or two journal columns wide, with ``nrows x ncols`` axes, to pass as ``ax=``.

    Parameters
    ----------
    columns : {1, 2}
        Width: one column (3.5 in) or the page (7.16 in), as :data:`COLUMN_WIDTH`.
    nrows, ncols : int
        The grid of axes.
    height : float, optional
        Height in inches; default 1.3 in per row plus 0.4 in (room for the x label).
    sharex : bool
        The axes share their time axis.

    Returns
    -------
    fig : matplotlib.figure.Figure
        Constrained layout, so labels do not overlap.
    axes : ndarray of Axes, shape (nrows, ncols) squeezed to 1-D when either is 1

    Examples
    --------
    >>> fig, axes = paper_figure(columns=2, nrows=2)
    >>> fig.get_size_inches().tolist(), axes.shape
    ([7.16, 3.0], (2,))

    """
    if columns not in COLUMN_WIDTH:
        raise InputError(f"`columns` must be 1 or 2 (one column or the page); got {v.shown(columns)}")
    nrows = v.integer("nrows", nrows, lower=1)
    ncols = v.integer("ncols", ncols, lower=1)
    h = 1.3 * nrows + 0.4 if height is None else v.real("height", height, lower=0.5)
    _matplotlib()
    from matplotlib.figure import Figure

    fig = Figure(figsize=(COLUMN_WIDTH[columns], h), layout="constrained")
    axes = fig.subplots(nrows, ncols, sharex=sharex, squeeze=False)
    return fig, axes.ravel() if nrows == 1 or ncols == 1 else axes


#: The settings of :func:`paper_style`: 8-point text (a journal's figure text), thin lines,
#: fonts embedded as text in PDF and SVG (editable, searchable), no PDF creation date.
PAPER_RC = {
    "font.size": 8.0,
    "axes.labelsize": 8.0,
    "axes.titlesize": 8.0,
    "legend.fontsize": 7.0,
    "xtick.labelsize": 7.0,
    "ytick.labelsize": 7.0,
    "figure.titlesize": 8.0,
    "lines.linewidth": 1.0,
    "lines.markersize": 4.0,
    "axes.linewidth": 0.6,
    "grid.linewidth": 0.5,
    "pdf.fonttype": 42,
    "svg.fonttype": "none",
    "savefig.dpi": 300,
}


@contextmanager
def paper_style() -> Iterator[dict[str, Any]]:
    """Fonts and lines for a paper's figure, while the block runs (:data:`PAPER_RC`).

    Draw inside the block: matplotlib reads font sizes when text is created.

    Yields
    ------
    dict
        The settings in force.

    Examples
    --------
    >>> with paper_style() as rc:
    ...     rc["font.size"]
    8.0

    """
    matplotlib = _matplotlib()
    with matplotlib.rc_context(PAPER_RC):
        yield dict(PAPER_RC)


def save_figure(fig: Any, path: str | os.PathLike[str], *, dpi: float = 300.0) -> Path:
    """Write ``fig`` as PDF, SVG (vector) or PNG, by the path's suffix.

    Vector files keep text as text (fonts embedded, ``pdf.fonttype 42``) and carry no
    creation date, so the same figure writes the same bytes; ``dpi`` applies to PNG.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    path : str or path-like
        Ends in ``.pdf``, ``.svg`` or ``.png``.
    dpi : float
        Resolution of a PNG.

    Returns
    -------
    pathlib.Path
        The file written.

    Examples
    --------
    >>> fig, (ax,) = paper_figure()
    >>> save_figure(fig, tmp_path / "empty.pdf").read_bytes()[:5]
    b'%PDF-'

    """
    target = Path(path)
    fmt = target.suffix.lower().lstrip(".")
    if fmt not in FORMATS:
        raise InputError(
            f"`path` must end in one of {', '.join('.' + f for f in FORMATS)}; got {str(path)!r}"
        )
    dpi = v.real("dpi", dpi, lower=1.0)
    metadata = {"pdf": {"CreationDate": None}, "svg": {"Date": None}}.get(fmt)
    rc = {"pdf.fonttype": 42, "svg.fonttype": "none", "svg.hashsalt": "etobs"}
    subset = logging.getLogger("fontTools")  # embedding a font logs every table at INFO
    level = subset.level
    subset.setLevel(max(level, logging.WARNING))
    try:
        with _matplotlib().rc_context(rc):
            fig.savefig(target, format=fmt, dpi=dpi, metadata=metadata)
    finally:
        subset.setLevel(level)
    return target
