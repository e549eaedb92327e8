"""The documentation site: ``make docs`` builds with no warning, and its API index is ``etobs.__all__``.

The site is built here as ``make docs`` builds it (Sphinx, warnings as errors), into a
temporary folder; the test then reads the built site's inventory (``objects.inv``, what
the search and the cross-references use) and its pages.
"""

from __future__ import annotations

import enum
import inspect
import io
import re
import subprocess
import sys
from pathlib import Path

import pytest

import etobs

ROOT = Path(__file__).resolve().parents[1]

pytest.importorskip("sphinx", reason="the docs extra is not installed")


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("site")
    cmd = [
        sys.executable,
        "-m",
        "sphinx",
        "-W",
        "--keep-going",
        "-q",
        "-c",
        "docs",
        "-b",
        "html",
        ".",
        str(out),
    ]
    cmd += ["-d", str(out / ".doctrees")]
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-4000:]
    assert done.stderr.strip() == "", done.stderr  # no warning at all
    return out


def test_the_api_reference_lists_every_public_name_and_no_other(site: Path) -> None:
    from sphinx.util.inventory import InventoryFile

    with (site / "objects.inv").open("rb") as fh:
        inv = InventoryFile.load(io.BytesIO(fh.read()), "", lambda a, b: b)
    documented = {
        name.removeprefix("etobs.")
        for role, entries in inv.items()
        if role.startswith("py:") and role != "py:module"
        for name in entries
        if re.fullmatch(r"etobs\.\w+", name)
    }
    assert documented == set(etobs.__all__), sorted(documented ^ set(etobs.__all__))
    assert {"simulate", "Sampled", "DynamicRule", "EstimationResult"} <= documented


def test_the_front_page_is_the_readme_and_every_page_is_built(site: Path) -> None:
    front = (site / "index.html").read_text()
    assert "decentralized event-triggered state estimation" in front
    assert (site / "README.html").read_text() == front
    pages = sorted(p.stem for p in (ROOT / "docs").glob("*.md"))
    assert [p for p in pages if not (site / "docs" / f"{p}.html").exists()] == []
    assert (site / "CHANGES.html").exists() and (site / "docs" / "api.html").exists()
    # the README's links reach the pages, the changes and the example, in the site
    for href in ("docs/models.html", "CHANGES.html", "first_hour.py"):
        assert href in front, href


@pytest.mark.parametrize("name", sorted(etobs.__all__))
def test_every_public_name_has_a_numpydoc_docstring_with_an_example(name: str) -> None:
    """Examples everywhere (the doctests of ``src`` run them); Parameters and Returns where they apply.

    A function has Parameters and Returns; a class that takes arguments has Parameters
    (or, a record of values, Attributes). Exceptions, enums and interfaces without
    arguments of their own have no Parameters.
    """
    from numpydoc.docscrape import NumpyDocString

    obj = getattr(etobs, name)
    if not callable(obj):
        assert name == "__version__" and re.fullmatch(r"\d+\.\d+\.\d+.*", obj)
        return
    doc = NumpyDocString(inspect.getdoc(obj) or "")
    assert doc["Summary"], f"{name}: no summary line"
    assert doc["Examples"], f"{name}: no Examples section"
    if inspect.isclass(obj):
        exempt = issubclass(obj, BaseException | enum.Enum) or not inspect.signature(obj).parameters
        assert exempt or doc["Parameters"] or doc["Attributes"], f"{name}: no Parameters section"
    else:
        assert doc["Parameters"] and doc["Returns"], f"{name}: Parameters {bool(doc['Parameters'])}, Returns"
