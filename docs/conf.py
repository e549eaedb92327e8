"""Sphinx configuration of etobs' documentation site: ``make docs`` (docs/_build/html).

The source is the repository's root: ``README.md`` is the front page, ``docs/*.md`` the
pages (MyST Markdown), ``CHANGES.md`` the changes; nothing else is read. The API
reference (``docs/api.rst``) is written here, at every build, from ``etobs.__all__``
(the names of ``etobs/__init__.pyi``), so that it lists every public name and no other;
``tests/test_docs_site.py`` compares the built site's index with ``etobs.__all__``.

The gallery (``docs/gallery/``, generated) is ``examples/*.py``, each run at build time by
sphinx-gallery with its figures (``docs/gallery_scraper.py``). The examples run in a copy
(``docs/_gallery_src/``, generated), so that the files they write stay out of the
repository; an example that raises fails the build.
"""

from __future__ import annotations

import importlib
import shutil
import sys
from pathlib import Path
from typing import Any

import etobs

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))  # the gallery's scraper, named by its module below

project = "etobs"
author = "the etobs developers"
release = etobs.__version__
extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
    "sphinx.ext.viewcode",
]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "README"
include_patterns = [
    "README.md",
    "CHANGES.md",
    "docs/*.md",
    "docs/api.rst",
    "docs/generated/*.rst",
    "docs/gallery/*.rst",
]
exclude_patterns = ["docs/_build"]
html_theme = "furo"
html_title = f"etobs {release}"
myst_heading_anchors = 3
autosummary_generate = True
templates_path = [str(HERE / "_templates")]  # a class's page documents its members in place
# every cross-reference must resolve (make docs runs with -n); the references to other
# projects' objects (numpy, the standard library, matplotlib, pandas...) cannot: their
# inventories would come over the network, which a build must not use
nitpicky = True
nitpick_ignore_regex = [
    (
        r"py:.*",
        r"(numpy|np|collections\.abc|abc|typing|pathlib|os|matplotlib|pandas|pd|xarray|xr|scipy"
        r"|optuna|dask|distributed|control|cvxpy|concurrent\.futures|datetime|enum|socket|asyncio)(\..*)?",
    ),
    (r"py:class", r"etobs\._spec\._F"),  # the type variable of the @factory decorator's signature
]
numpydoc_show_class_members = False
suppress_warnings = ["myst.header"]  # pages start at their own level: a README's sections


GALLERY_SRC = HERE / "_gallery_src"
GALLERY_HEADER = """Gallery
=======

The examples, each run when the site is built: what they print and the figures they draw
are the build's. Download any of them (below each page) and run it with ``python``.
"""


def _gallery_sources() -> None:
    """``examples/*.py`` and the gallery's header, copied where sphinx-gallery runs them.

    The copy keeps each file's time stamp, so an unchanged example is not run again.
    """
    GALLERY_SRC.mkdir(exist_ok=True)
    wanted = {p.name: p for p in sorted((ROOT / "examples").glob("*.py"))}
    for old in GALLERY_SRC.iterdir():
        if old.is_file() and old.name not in wanted and old.name != "GALLERY_HEADER.rst":
            old.unlink()  # what an example wrote, or an example since removed
    for name, src in wanted.items():
        dst = GALLERY_SRC / name
        if not dst.exists() or dst.read_bytes() != src.read_bytes():
            shutil.copy2(src, dst)
    header = GALLERY_SRC / "GALLERY_HEADER.rst"
    if not header.exists() or header.read_text() != GALLERY_HEADER:
        header.write_text(GALLERY_HEADER)


_gallery_sources()
sphinx_gallery_conf = {
    "examples_dirs": str(GALLERY_SRC),
    "gallery_dirs": str(HERE / "gallery"),
    "filename_pattern": r".*",  # run every example, not only plot_*.py
    "image_scrapers": ("gallery_scraper.scrape",),
    "abort_on_example_error": True,
    "download_all_examples": False,
    "remove_config_comments": True,
    "show_memory": False,
    "matplotlib_animations": False,
    "write_computation_times": False,
    # every build runs every example, so that a library change that breaks one fails the
    # build (sphinx-gallery would skip an example whose own text is unchanged)
    "run_stale_examples": True,
}


#: Objects the public names' documentation refers to, defined in etobs' modules: documented
#: on the API page under "Supporting objects", so that every cross-reference resolves.
SUPPORTING = (
    "etobs.model.GeneralizedRule",
    "etobs.model.rules.KindRule",
    "etobs.model.rules.EngineForm",
    "etobs.model.rules.engine_form_of",
    "etobs.model.signals.Signal",
    "etobs.model.functions.Builtin",
    "etobs.model.quantities.Quantity",
    "etobs.model.network.Loss",
    "etobs.model.network.Delay",
    "etobs.model.fates.fate",
    "etobs.model.fates.LINK_WIDTH",
    "etobs.formulas.KKind",
    "etobs.formulas.sample_decision",
    "etobs.formulas.norm",
    "etobs.formulas.eta_period",
    "etobs.hybrid.system.BatchedSystem",
    "etobs.hybrid.compiled.CompiledSystem",
    "etobs.hybrid.solution.HybridSolution",
    "etobs.hybrid.solution.JumpLog",
    "etobs.estimation.calls.ModelCalls",
    "etobs.runtime.sensor.run",
    "etobs.runtime.sampled_rule.SampledRule",
    "etobs.tuning.result.TuningResult",
    "etobs.experiments.compare.Comparison",
)
#: Modules the documentation refers to: their docstrings, on the API page.
MODULES = (
    "etobs.estimation",
    "etobs.estimation.compiled",
    "etobs.hybrid.zeno",
    "etobs.model.network",
    "etobs.runtime",
    "etobs.runtime.sensor",
)


def _api_page() -> str:
    import etobs.plot

    names = sorted(etobs.__all__)

    def table(items: list[str], template: str = "") -> str:
        option = f"   :template: {template}\n" if template else ""
        rows = "".join(f"   {n}\n" for n in items)
        return f".. autosummary::\n   :toctree: generated\n{option}\n{rows}\n"

    modules = "".join(f".. automodule:: {m}\n   :no-members:\n\n" for m in MODULES)
    return (
        "API reference\n=============\n\n"
        f"Every public name of ``etobs`` ({len(names)}), from ``etobs.__all__``; the modules below\n"
        "them are described in the pages.\n\n"
        + table([f"etobs.{n}" for n in names])
        + "Plots: ``etobs.plot``\n---------------------\n\n"
        f"Every name of ``etobs.plot.__all__`` ({len(etobs.plot.__all__)}); see :doc:`plots`.\n\n"
        + table([f"etobs.plot.{n}" for n in sorted(etobs.plot.__all__)])
        + "Supporting objects\n------------------\n\n"
        "Defined in etobs' modules and named by the documentation of the public names.\n\n"
        + table(list(SUPPORTING), "brief.rst")  # their own docstrings, not their members'
        + "Modules\n-------\n\n"
        + modules
    )


_api = HERE / "api.rst"
if not _api.exists() or _api.read_text() != _api_page():
    _api.write_text(_api_page())


def _front_page(app: Any, exception: BaseException | None) -> None:
    """``index.html`` is the front page (README.html), so that the site's folder opens on it."""
    out = Path(app.outdir)
    if exception is None and app.builder.name == "html" and (out / "README.html").exists():
        shutil.copyfile(out / "README.html", out / "index.html")


def _public_alias(app: Any, env: Any, node: Any, contnode: Any) -> Any:
    """Resolve ``etobs.model.rules.DynamicRule`` (where a name is defined) to ``etobs.DynamicRule``.

    Docstrings name a class by the module that defines it; the reference documents it
    under its public name. Any other unresolved reference stays unresolved (a warning,
    an error under ``-W``).
    """
    target = node.get("reftarget", "")
    if node.get("refdomain") != "py":
        return None
    domain = env.get_domain("py")
    if "." not in target:  # a name in an annotation (CompiledSystem): the one object of that name
        found = [name for name in domain.objects if name.rsplit(".", 1)[-1] == target]
        if len(found) == 1:
            return domain.resolve_xref(
                env, node["refdoc"], app.builder, node["reftype"], found[0], node, contnode
            )
    if target.startswith("etobs."):
        parts = target.split(".")
        for k in range(1, len(parts)):
            if parts[k] in etobs.__all__:
                alias = node.deepcopy()
                alias["reftarget"] = ref = ".".join(["etobs", *parts[k:]])
                found = domain.resolve_xref(
                    env, node["refdoc"], app.builder, node["reftype"], ref, alias, contnode
                )
                if found is not None:
                    return found
                break  # etobs.simulate.simulate is no public name: the object's source, below
    return _source_link(app, env, node, contnode)


def _locate(target: str, module: str | None, cls: str | None) -> tuple[str, str] | None:
    """``(module, qualname)`` of the etobs object ``target`` names (from ``module``, in ``cls``), if any."""
    candidates = [target]
    if module:
        candidates += [f"{module}.{target}"] + ([f"{module}.{cls}.{target}"] if cls else [])
    for name in reversed(candidates):  # the closest scope first
        if not name.startswith("etobs"):
            continue
        parts = name.split(".")
        for k in range(len(parts), 0, -1):
            try:
                obj: Any = importlib.import_module(".".join(parts[:k]))
            except ImportError:
                continue
            try:
                for part in parts[k:]:
                    obj = getattr(obj, part)
            except AttributeError:
                break
            home = getattr(obj, "__module__", None) if parts[k:] else None
            qual = getattr(obj, "__qualname__", None) if parts[k:] else None
            if isinstance(home, str) and home.startswith("etobs") and isinstance(qual, str):
                return home, qual
            return ".".join(parts[:k]), ".".join(parts[k:])
    return None


def _source_link(app: Any, env: Any, node: Any, contnode: Any) -> Any:
    """A reference to an etobs object the site does not document: a link to its source (viewcode).

    Only objects that exist are linked; a reference to anything else stays unresolved.
    """
    from sphinx.pycode import ModuleAnalyzer
    from sphinx.util.nodes import make_refnode

    found = _locate(node.get("reftarget", ""), node.get("py:module"), node.get("py:class"))
    if found is None:
        return None
    module, qualname = found
    pages = env.__dict__.setdefault("_viewcode_modules", {})
    if module not in pages:  # not yet shown by viewcode: analyse it, so its page is written
        try:
            analyzer = ModuleAnalyzer.for_module(module)
            analyzer.find_tags()
        except Exception:
            return None
        pages[module] = (analyzer.code, analyzer.tags, {}, module)
    entry = pages[module]
    if not entry:
        return None
    if qualname in entry[1]:
        entry[2].setdefault(qualname, node["refdoc"])  # viewcode anchors the object's lines
    page = "_modules/" + module.replace(".", "/")
    return make_refnode(app.builder, node["refdoc"], page, qualname if qualname in entry[1] else "", contnode)


def setup(app: Any) -> None:
    """Sphinx extension hook of this configuration: the front page after the build, public aliases."""
    app.connect("build-finished", _front_page)
    app.connect("missing-reference", _public_alias)
