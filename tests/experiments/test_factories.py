"""A spec names code: only functions marked with ``@etobs.factory`` may be called, and a
module whose source does not mark the function is refused without being imported."""

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
    problem = make_problem(f"{path}:problem", {"noise": False}, "system.params")
    assert isinstance(problem, EstimationProblem) and problem.n_nodes == 2
    assert is_factory(resolve_factory(f"{path}:also_marked"))
    with pytest.raises(SpecError, match=r"'helper' in '.*mine.py' is not marked as a factory"):
        resolve_factory(f"{path}:helper")


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
        make_problem(FACTORY, {"fail": True}, "row 1")
