"""Sphinx configuration of etobs' documentation site: ``make docs`` (docs/_build/html).

The source is the repository's root: ``README.md`` is the front page, ``docs/*.md`` the
pages (MyST Markdown), ``CHANGES.md`` the changes; nothing else is read. The API
reference (``docs/api.rst``) is written here, at every build, from ``etobs.__all__``
(the names of ``etobs/__init__.pyi``), so that it lists every public name and no other;
``tests/test_docs_site.py`` compares the built site's index with ``etobs.__all__``.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import etobs

HERE = Path(__file__).resolve().parent

project = "etobs"
author = "the etobs developers"
release = etobs.__version__
extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.autosummary", "numpydoc"]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "README"
include_patterns = ["README.md", "CHANGES.md", "docs/*.md", "docs/api.rst", "docs/generated/*.rst"]
exclude_patterns = ["docs/_build"]
html_theme = "furo"
html_title = f"etobs {release}"
myst_heading_anchors = 3
autosummary_generate = True
numpydoc_show_class_members = False
suppress_warnings = ["myst.header"]  # pages start at their own level: a README's sections


def _api_page() -> str:
    names = sorted(etobs.__all__)
    rows = "".join(f"   etobs.{n}\n" for n in names)
    return (
        "API reference\n=============\n\n"
        f"Every public name of ``etobs`` ({len(names)}), from ``etobs.__all__``; the modules below\n"
        "them are described in the pages.\n\n"
        ".. autosummary::\n   :toctree: generated\n\n" + rows
    )


_api = HERE / "api.rst"
if not _api.exists() or _api.read_text() != _api_page():
    _api.write_text(_api_page())


def _front_page(app: Any, exception: BaseException | None) -> None:
    """``index.html`` is the front page (README.html), so that the site's folder opens on it."""
    out = Path(app.outdir)
    if exception is None and app.builder.name == "html" and (out / "README.html").exists():
        shutil.copyfile(out / "README.html", out / "index.html")


def setup(app: Any) -> None:
    """Sphinx extension hook of this configuration: the front page after the build."""
    app.connect("build-finished", _front_page)
