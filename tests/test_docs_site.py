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
    plots = {
        name.removeprefix("etobs.plot.")
        for role, entries in inv.items()
        if role.startswith("py:")
        for name in entries
        if re.fullmatch(r"etobs\.plot\.\w+", name)
    }
    from etobs import plot

    assert plots == set(plot.__all__), sorted(plots ^ set(plot.__all__))


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


def _plot_names() -> list[str]:
    try:
        import etobs.plot
    except ImportError:  # pragma: no cover - the plot extra is in the test extra
        return []
    return [f"plot.{n}" for n in sorted(etobs.plot.__all__)]


@pytest.mark.parametrize("name", sorted(etobs.__all__) + _plot_names())
def test_every_public_name_has_a_numpydoc_docstring_with_an_example(name: str) -> None:
    """Examples everywhere (the doctests of ``src`` run them); Parameters and Returns where they apply.

    A function has Parameters and Returns; a class that takes arguments has Parameters
    (or, a record of values, Attributes). Exceptions, enums and interfaces without
    arguments of their own have no Parameters.
    """
    from numpydoc.docscrape import NumpyDocString

    import etobs.plot

    obj = getattr(etobs.plot, name[5:]) if name.startswith("plot.") else getattr(etobs, name)
    if name in ("plot.COLUMN_WIDTH", "plot.PAPER_RC"):  # settings: documented where they are defined
        return
    if not callable(obj):
        assert name == "__version__" and re.fullmatch(r"\d+\.\d+\.\d+.*", obj)
        return
    doc = NumpyDocString(inspect.getdoc(obj) or "")
    assert doc["Summary"], f"{name}: no summary line"
    assert doc["Examples"], f"{name}: no Examples section"
    if inspect.isclass(obj):
        exempt = issubclass(obj, BaseException | enum.Enum) or not inspect.signature(obj).parameters
        assert exempt or doc["Parameters"] or doc["Attributes"], f"{name}: no Parameters section"
    elif not inspect.signature(obj).parameters:  # paper_style(): nothing to take, what it yields
        assert doc["Returns"] or doc["Yields"], f"{name}: no Returns or Yields section"
    else:
        assert doc["Parameters"] and doc["Returns"], f"{name}: Parameters {bool(doc['Parameters'])}, Returns"


def test_the_gallery_runs_every_example_with_its_figures_and_the_two_panel_pdf(site: Path) -> None:
    examples = sorted(p.stem for p in (ROOT / "examples").glob("*.py"))
    assert {"robot_arm", "first_hour"} <= set(examples)
    index = (site / "docs" / "gallery" / "index.html").read_text()
    for name in examples:
        page = (site / "docs" / "gallery" / f"{name}.html").read_text()
        assert f"{name}.html" in index
        shown = re.findall(rf'src="([./]*_images/sphx_glr_{name}_\d+\.png)"', page)
        assert shown, f"{name}: no figure"  # drawn when the site was built
        for src in shown:
            assert (site / "docs" / "gallery" / src).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the robot arm's two-panel figure, written as PDF, offered for download
    page = (site / "docs" / "gallery" / "robot_arm.html").read_text()
    (href,) = set(re.findall(r'href="([^"]*robot-arm\.pdf)"', page))
    pdf = (site / "docs" / "gallery" / href).read_bytes()
    assert pdf.startswith(b"%PDF") and b"/Subtype /Image" not in pdf
    assert b"motor angle" in pdf or b"/FontFile2" in pdf


def test_every_cross_reference_is_checked() -> None:
    """nitpicky: the -W build fails on a reference that resolves to nothing (docs/conf.py)."""
    conf: dict = {"__file__": str(ROOT / "docs" / "conf.py")}
    exec(compile((ROOT / "docs" / "conf.py").read_text(), "conf.py", "exec"), conf)
    assert conf["nitpicky"] is True
    # only other projects' objects are exempt (their inventories would need the network)
    for _, pattern in conf["nitpick_ignore_regex"]:
        assert not re.fullmatch(pattern, "etobs.simulate"), pattern
