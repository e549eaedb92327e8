"""The gallery's image scraper: what each example block drew, and the files it wrote.

etobs never imports ``pyplot``, so sphinx-gallery's matplotlib scraper (which reads
pyplot's figure list) sees nothing. This one finds the figures in the example's
variables (a :class:`matplotlib.figure.Figure`, or the ``fig`` of a ``Drawn``), saves
each new one as PNG where sphinx-gallery asks, and offers the vector files (PDF, SVG)
the block wrote for download. ``docs/conf.py`` names it in ``sphinx_gallery_conf``.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

#: Per example, the figures (by id) already shown, so each appears once.
_SHOWN: dict[str, set[int]] = {}
#: The files already offered for download (the examples run in one folder, one after another).
_LINKED: set[str] = set()
#: Files an example writes that the page offers for download, by suffix.
DOWNLOADS = (".pdf", ".svg")


def _figures(values: Any) -> list[Any]:
    from matplotlib.figure import Figure

    out = []
    for value in values:
        if isinstance(value, tuple) and value and isinstance(value[0], Figure):
            value = value[0]  # a Drawn (fig, axes)
        if isinstance(value, Figure) and all(value is not f for f in out):
            out.append(value)
    return out


def scrape(block: Any, block_vars: dict[str, Any], gallery_conf: dict[str, Any], **kwargs: Any) -> str:
    """Save the block's new figures (PNG) and link its new PDF/SVG files; return their reST."""
    from sphinx_gallery.scrapers import figure_rst

    src = str(block_vars["src_file"])
    shown = _SHOWN.setdefault(src, set())
    images = []
    for fig, path in zip(
        [f for f in _figures(block_vars["example_globals"].values()) if id(f) not in shown],
        block_vars["image_path_iterator"],
        strict=False,
    ):
        fig.savefig(path, dpi=96)
        shown.add(id(fig))
        images.append(path)
    rst = figure_rst(images, gallery_conf["src_dir"]) if images else ""
    here = Path(src).parent
    links = []
    for written in sorted(p for p in here.iterdir() if p.suffix in DOWNLOADS and p.name not in _LINKED):
        target = Path(block_vars["target_file"]).parent / "images" / written.name
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(written, target)
        _LINKED.add(written.name)
        links.append(f"* :download:`{written.name} <images/{written.name}>`")
    if links:
        rst += "\n\nFiles this block wrote:\n\n" + "\n".join(links) + "\n"
    return rst
