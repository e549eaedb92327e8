"""A spec names code: only functions marked with ``@etobs.factory`` may be called, and a
module whose source does not mark the function is refused without being imported."""

import re
import sys

import pytest

import etobs
from etobs import EstimationProblem
from etobs._spec import SpecError, is_factory
from etobs.examples.registry import REGISTRY, make_problem, resolve_factory

from .conftest import FACTORY

SIDE_EFFECT = """
from pathlib import Path
Path({marker!r}).write_text("imported")  # what a module may do at import time

def problem(**kwargs):
    from etobs.examples import robot_arm
    return robot_arm(**kwargs)
"""

MARKED = """
import etobs
from etobs.examples import robot_arm

@etobs.factory
def problem(**kwargs):
    return robot_arm(**kwargs)

def helper():
    return robot_arm()

also_marked = etobs.factory(helper)
"""


def test_the_packaged_and_test_factories_are_marked():
    assert all(is_factory(fn) for fn in REGISTRY.values())
    assert is_factory(resolve_factory(FACTORY))
    assert is_factory(resolve_factory("tests.estimation.linear:factory"))
    assert is_factory(resolve_factory("etobs.examples.robot_arm:robot_arm_network"))


@pytest.mark.parametrize("name", ["subprocess:run", "os:system", "builtins:eval", "shutil:rmtree"])
def test_an_unmarked_function_is_refused_not_called(name):
    with pytest.raises(
        SpecError, match=rf"`system.factory` = '{name}'.* is not marked as a factory; mark it"
    ):
        make_problem(name, {"args": ["false"]}, "system.params")


def test_a_module_that_does_not_mark_the_function_is_not_imported(tmp_path, monkeypatch):
    marker = tmp_path / "imported"
    (tmp_path / "sideeffect_mod.py").write_text(SIDE_EFFECT.format(marker=str(marker)))
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(SpecError, match=r"'problem' in '.*sideeffect_mod.py' is not marked as a factory, so"):
        resolve_factory("sideeffect_mod:problem")
    with pytest.raises(SpecError, match=r"'problem' in '.*sideeffect_mod.py' is not marked as a factory, so"):
        resolve_factory(f"{tmp_path / 'sideeffect_mod.py'}:problem")
    assert not marker.exists() and "sideeffect_mod" not in sys.modules
    # nor are its packages: the source is found without importing them
    pkg = tmp_path / "sideeffect_pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text(SIDE_EFFECT.format(marker=str(marker)))
    (pkg / "models.py").write_text("def problem():\n    pass\n")
    with pytest.raises(SpecError, match=r"'problem' in '.*models.py' is not marked as a factory"):
        resolve_factory("sideeffect_pkg.models:problem")
    assert not marker.exists() and "sideeffect_pkg" not in sys.modules


@pytest.mark.parametrize(
    ("name", "match"),
    [
        ("_testcapi:f", r"'_testcapi' has no Python source in which to look for the mark, so it is not"),
        ("no.such.module:f", r"cannot import 'no.such.module': no module named 'no'"),
        ("json..x:f", r"cannot import 'json..x': not a module name"),
        ("json:", r"is neither a registered example"),
        # importing antigravity opens a web browser, importing this prints a poem: neither is imported
        ("antigravity:geohash", r"'geohash' in '.*antigravity.py' is not marked as a factory, so its"),
        ("this:nothing_here", r"'.*this.py' has no callable 'nothing_here'"),
    ],
)
def test_what_cannot_be_checked_without_importing_is_refused(name, match):
    with pytest.raises(SpecError, match=match):
        resolve_factory(name)
    assert "antigravity" not in sys.modules and "this" not in sys.modules


def test_a_marked_factory_in_a_file_builds_its_problem(tmp_path):
    path = tmp_path / "mine.py"
    path.write_text(MARKED)
    # read, not run: its source does not mark `helper` (which `also_marked = etobs.factory(helper)` marks
    # once it has run: the mark is on the function itself)
    with pytest.raises(SpecError, match=r"'helper' in '.*mine.py' is not marked as a factory"):
        resolve_factory(f"{path}:helper")
    problem = make_problem(f"{path}:problem", {"noise": False}, "system.params")
    assert isinstance(problem, EstimationProblem) and problem.n_nodes == 2
    assert is_factory(resolve_factory(f"{path}:also_marked"))


def test_the_mark_cannot_be_faked():
    def fake():
        pass

    fake.__etobs_factory__ = True
    assert not is_factory(fake)
    assert is_factory(etobs.factory(fake))
    with pytest.raises(etobs.InputError, match=r"@etobs.factory marks a function; got 3"):
        etobs.factory(3)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (
            {"colour": 1},
            r"parameter `colour` \(system.params\) is not an argument of the factory 'robot_arm'",
        ),
        ({"sigma": "x"}, r"^system.params: `sigma` must be a vector of real numbers"),
        ({"sigma": [1.0, 2.0, 3.0]}, r"^system.params: `sigma` must have 2 entries"),
    ],
)
def test_factory_arguments_are_checked_naming_the_key(kwargs, match):
    with pytest.raises(SpecError, match=match):
        make_problem("robot_arm", kwargs, "system.params")


def test_whatever_a_factory_raises_names_the_spec_table(tmp_path):
    with pytest.raises(
        SpecError, match=r"failed on the arguments of row 1: ValueError: this row fails on purpose"
    ):
        make_problem(FACTORY, {"refuse": True}, "row 1")


REEXPORT = """
from pathlib import Path
Path({marker!r}).write_text("imported")  # what a module may do at import time
import webbrowser
from subprocess import run
from {target} import {name} as reexported
"""


@pytest.mark.parametrize(
    ("attr", "match"),
    [
        # an import of the name used to count as a mark: the module was imported (its code ran), then refused
        ("webbrowser", r"'webbrowser' in '.*reexport_mod.py' is not marked as a factory, so its module"),
        ("run", r"'run' in '.*reexport_mod.py' is not marked as a factory, so its module is not"),
        ("reexported", r"'reexported' in '.*reexport_mod.py' is not marked as a factory, so its module"),
    ],
)
def test_an_imported_name_counts_only_if_it_is_marked_where_it_comes_from(tmp_path, monkeypatch, attr, match):
    marker = tmp_path / "imported"
    (tmp_path / "plain_source.py").write_text("def helper():\n    pass\n")
    (tmp_path / "reexport_mod.py").write_text(
        REEXPORT.format(marker=str(marker), target="plain_source", name="helper")
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(SpecError, match=match):
        resolve_factory(f"reexport_mod:{attr}")
    with pytest.raises(SpecError, match=match):
        resolve_factory(f"{tmp_path / 'reexport_mod.py'}:{attr}")
    assert not marker.exists()
    assert "reexport_mod" not in sys.modules and "plain_source" not in sys.modules


def test_antigravity_is_not_imported_through_a_name_it_imports():
    # importing antigravity opens a web browser; it imports webbrowser and hashlib
    for name in ("antigravity:webbrowser", "antigravity:hashlib"):
        with pytest.raises(SpecError, match=r"'.*' in '.*antigravity.py' is not marked as a factory, so"):
            resolve_factory(name)
    assert "antigravity" not in sys.modules


def test_a_marked_factory_may_be_imported_from_where_it_is_marked(tmp_path, monkeypatch):
    # a package that re-exports its factory, absolutely and relatively, a chain of two
    pkg = tmp_path / "reexport_pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text(
        "from .models import problem\nfrom reexport_pkg.models import problem as p2\n"
    )
    (pkg / "models.py").write_text(MARKED)
    (pkg / "outer.py").write_text("from . import problem\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    for name in ("reexport_pkg:problem", "reexport_pkg:p2", "reexport_pkg.outer:problem"):
        assert is_factory(resolve_factory(name))
    # the name an already imported module gives is checked there
    (tmp_path / "from_loaded.py").write_text("from etobs.examples.robot_arm import robot_arm\n")
    assert is_factory(resolve_factory("from_loaded:robot_arm"))


def test_a_file_factory_runs_its_file_once_and_may_hold_dataclasses(tmp_path):
    counter = tmp_path / "runs"
    path = tmp_path / "with_dataclass.py"
    path.write_text(
        "from __future__ import annotations\n"
        "from dataclasses import dataclass\n"
        "from pathlib import Path\n"
        f"_c = Path({str(counter)!r})\n"
        "_c.write_text(_c.read_text() + 'x' if _c.exists() else 'x')\n"
        + MARKED
        + "\n@dataclass\nclass Settings:\n    k: float = 1.0\n"
    )
    # make_problem resolved the factory twice, running the file twice; a dataclass broke it (AttributeError)
    problem = make_problem(f"{path}:problem", {"noise": False}, "system.params")
    assert isinstance(problem, EstimationProblem)
    assert is_factory(resolve_factory(f"{path}:problem"))
    assert counter.read_text() == "x"


def test_a_module_attribute_lookup_that_fails_is_a_spec_error(tmp_path, monkeypatch):
    # a module imported already whose __getattr__ (a lazy import, say) raises: it was a traceback
    (tmp_path / "lazy_mod.py").write_text(
        "def __getattr__(name):\n    raise RuntimeError('lazy import failed')\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    import lazy_mod  # noqa: F401

    try:
        with pytest.raises(
            SpecError, match=r"looking up 'maker' in 'lazy_mod' failed: RuntimeError: lazy import"
        ):
            resolve_factory("lazy_mod:maker")
    finally:
        del sys.modules["lazy_mod"]


SCALAR = """
import etobs
from tests.experiments.factories import scalar


@etobs.factory
def problem(**kwargs):
    return scalar(**kwargs)
"""
UNUSED = """
import etobs


@etobs.factory
def problem(**kwargs):
    raise RuntimeError("the models.py of the current folder was used")
"""


@pytest.fixture
def spec_and_cwd(tmp_path, monkeypatch):
    """A sweep spec file naming ``models.py:problem`` next to it; the current folder holds another."""
    from .conftest import raw_spec

    spec_dir, cwd = tmp_path / "project", tmp_path / "elsewhere"
    spec_dir.mkdir()
    cwd.mkdir()
    (spec_dir / "models.py").write_text(SCALAR)
    (cwd / "models.py").write_text(UNUSED)
    raw = raw_spec(system={"factory": "models.py:problem", "fixed": {}})
    (spec_dir / "spec.toml").write_text(
        'name = "tiny"\n[system]\nfactory = "models.py:problem"\n[[rows]]\nk = 1.0\n[[scenarios]]\nname = "a"\n'
        "[initial_states]\nlow = [-1.0]\nhigh = [1.0]\nruns = 5\nseed = 7\n[horizon]\nt_end = 3.0\n"
    )
    monkeypatch.chdir(cwd)
    return spec_dir / "spec.toml", raw


def test_load_spec_takes_a_relative_factory_file_from_the_spec_folder(spec_and_cwd):
    from etobs.experiments import load_spec

    path, _ = spec_and_cwd
    spec = load_spec(path)
    # made absolute in the spec (and in the raw spec its workers and with_runs read)
    assert spec.factory == f"{path.parent / 'models.py'}:problem"
    assert spec.raw["system"]["factory"] == spec.factory
    for s in (spec, spec.with_runs(2), spec.with_backend("scipy")):
        assert s.problem(0).plant.n_x == 1  # a same-named file in the current folder is not used


def test_a_spec_given_as_a_dictionary_takes_a_relative_factory_file_from_the_current_folder(spec_and_cwd):
    from etobs.experiments import parse_spec
    from etobs.experiments.compare_spec import parse_compare_spec

    path, raw = spec_and_cwd
    with pytest.raises(SpecError, match=r"the models.py of the current folder was used"):
        parse_spec(raw).problem(0)
    assert parse_spec(raw, folder=path.parent).problem(0).plant.n_x == 1
    compare = {k: v for k, v in raw.items() if k not in ("rows", "scenarios")}
    compare["system"] = {"factory": "models.py:problem", "params": {"k": 1.0}}
    compare["rules"] = [{"name": "base", "kind": "base"}]
    assert parse_compare_spec(compare, folder=path.parent).base().plant.n_x == 1
    with pytest.raises(SpecError, match=r"the models.py of the current folder was used"):
        parse_compare_spec(compare).base()
    (path.parent.parent / "elsewhere" / "models.py").unlink()
    tried = re.escape(str(path.parent.parent / "elsewhere" / "models.py"))
    with pytest.raises(
        SpecError,
        match=rf"cannot import '{tried}': no such file \(a spec given as a dictionary: from the current folder\)",
    ):
        parse_spec(raw).problem(0)


def test_locate_factory_changes_only_a_relative_file(tmp_path):
    from etobs.examples.registry import locate_factory

    assert locate_factory("m.py:f", tmp_path) == f"{tmp_path / 'm.py'}:f"
    assert locate_factory("../m.py:f", tmp_path / "a") == f"{tmp_path / 'm.py'}:f"
    assert locate_factory("/abs/m.py:f", tmp_path) == "/abs/m.py:f"
    assert locate_factory("m.py:f", None) == "m.py:f"
    for unchanged in ("robot_arm", "pkg.mod:f", 3, "nonsense"):
        assert locate_factory(unchanged, tmp_path) == unchanged
