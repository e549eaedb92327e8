"""Each spec format's errors name the file, the key path, what was expected and what was received.

For each command that reads a spec (``sweep``, ``compare``, ``check``, ``serve``) a wrong
type, a missing required key and an unknown key, at the top and in a nested table, through
:func:`etobs.cli.main.main` as the installed command runs it. Before issue 15 a missing key
said only its name (``missing key `horizon.t_end```), a deployment's ``name = 3`` was
taken as ``"3"``, and ``load_spec(path)`` did not name the file.
"""

import re

import pytest

from etobs._spec import SpecError
from etobs.cli.main import main
from etobs.experiments import load_spec

from .test_bad_input import COMMANDS, one_clear_line, run

#: (command, (old, new) edit of the command's spec, what the line must say after the file name).
CASES = [
    # wrong type
    ("sweep", ("runs = 1", 'runs = "1"'), r"`initial_states.runs` must be an integer; got '1'"),
    ("sweep", ("fixed = {}", "fixed = 3"), r"`system.fixed` must be a table of keyword arguments; got 3"),
    (
        "compare",
        ('kind = "base"', 'kind = "static"\neps = "x"'),
        r"`rules\[0\].eps` must be a number; got 'x'",
    ),
    (
        "check",
        ("E = 1.0", 'E = "1"'),
        r"`guarantees.E` must be a number; got '1'",
    ),
    ("serve", ("period = 0.01", 'period = "0.01"'), r"`runtime.period` must be a number; got '0.01'"),
    (
        "serve",
        ('name = "bad"', "name = 3"),
        r"`name` must be a non-empty name of letters, digits, '_' or '-'; got 3",
    ),
    (
        "serve",
        ("params = {}", "params = [1]"),
        r"`system.params` must be a table of keyword arguments; got \[1\]",
    ),
    (
        "serve",
        ("port = 0", "port = 0\nbroker = 1883"),
        r"`runtime.broker` must be a string 'host:port' .*; got 1883",
    ),
    ("check", ("[system]\n", "observer = 3\n[system]\n"), r"`observer` must be a table; got 3 \(int\)"),
    # a missing required key: what it expects, and what the table has
    (
        "sweep",
        ("t_end = 1.0", ""),
        r"missing key `horizon.t_end`: expected a number > 0; `horizon` has no keys",
    ),
    (
        "sweep",
        ("seed = 0\n", ""),
        r"missing key `initial_states.seed`: expected an integer >= 0; `initial_states` has keys high, low, runs",
    ),
    (
        "compare",
        ('kind = "base"', 'kind = "periodic"'),
        r"missing key `rules\[0\].period`: expected a number \(every node\) or a list of numbers \(one per node\); "
        r"`rules\[0\]` has keys kind, name",
    ),
    (
        "compare",
        ('name = "base"\n', ""),
        r"missing key `rules\[0\].name`: expected a non-empty string; `rules\[0\]` has keys kind",
    ),
    (
        "check",
        ('factory = "tests.estimation.linear:factory"\n', ""),
        r"missing key `system.factory`: expected a string: a registered example, 'package.module:function' or "
        r"'path/file.py:function'; `system` has keys params",
    ),
    (
        "serve",
        ("period = 0.01\n", ""),
        r"missing key `runtime.period`: expected a number > 0 \(s\); `runtime` has keys duration, port, secret_file",
    ),
    # an unknown key: the allowed ones are listed
    ("sweep", ("seed = 0", "seed = 0\ncolour = 1"), r"unknown key `initial_states.colour`; allowed keys of "),
    (
        "compare",
        ('kind = "base"', 'kind = "base"\nsigma = 1'),
        r"unknown key `rules\[0\].sigma`; allowed keys of ",
    ),
    (
        "check",
        ("E = 1.0", "E = 1.0\ncolour = 1"),
        r"unknown key `guarantees.colour`; allowed",
    ),
    ("serve", ("[plant]", "[plant]\nx1 = 2"), r"unknown key `plant.x1`; allowed keys of `plant`: x0"),
    # the top level is called as on docs/specs.md: its keys bare (it said `spec.horizn`)
    (
        "sweep",
        ("[horizon]", "[horizn]"),
        r"unknown key `horizn`; allowed top-level keys: execution, grid, horizon",
    ),
    (
        "compare",
        ("[horizon]\nt_end = 1.0\n", ""),
        r"missing key `horizon`: expected a table; the spec has keys ",
    ),
    ("check", ("[system]", "[systems]"), r"unknown key `systems`; allowed top-level keys: guarantees, name"),
    (
        "serve",
        ('name = "bad"\n', "colour = 1\n"),
        r"unknown key `colour`; allowed top-level keys: name, plant",
    ),
    # a network's value names its spec key, not the argument of the class built from it (`p`)
    (
        "compare",
        ('kind = "base"\n', 'kind = "base"\n[[networks]]\nname = "lossy"\nloss = 1.2\n'),
        r"`networks\[0\].loss` must be <= 1; got 1.2$",
    ),
    (
        "compare",
        (
            'kind = "base"\n',
            'kind = "base"\n[[networks]]\nname = "ge"\nloss = { gilbert_elliott = [0.1, 0.0, 0.0, 1.0] }\n',
        ),
        r"`networks\[0\].loss.gilbert_elliott\[1\]` must be > 0; got 0$",
    ),
    (
        "compare",
        ('kind = "base"\n', 'kind = "base"\n[[networks]]\nname = "slow"\ndelay = { uniform = [0.2, 0.1] }\n'),
        r"`networks\[0\].delay.uniform\[1\]` must be >= 0.2; got 0.1$",
    ),
    (
        "compare",
        ('kind = "base"\n', 'kind = "base"\n[[networks]]\nname = "late"\ndelay = -1.0\n'),
        r"`networks\[0\].delay` must be >= 0; got -1$",
    ),
    # a rule is named by position, as every other error names it (it said `rules['base'].delta`)
    (
        "compare",
        ('kind = "base"', 'kind = "send_on_delta"\ndelta = [0.1, 0.2, 0.3]'),
        r"`rules\[0\].delta` has 3 values but the problem has 1 nodes",
    ),
]


@pytest.mark.parametrize(("command", "edit", "says"), CASES, ids=[f"{c}: {s[:40]}" for c, _, s in CASES])
def test_spec_errors_name_the_file_the_key_the_expected_and_the_received(
    command, edit, says, tmp_path, capsys
):
    writer, extra, _ = COMMANDS[command]
    text = writer()
    assert edit[0] in text
    spec = tmp_path / "spec.toml"
    spec.write_text(text.replace(edit[0], edit[1], 1))
    line = one_clear_line(*run([command, str(spec), *extra], capsys))
    assert re.search(rf"^etobs: error: {re.escape(str(spec))}: {says}", line), line


def test_load_spec_names_the_file(tmp_path):
    # only the CLI named it: load_spec(path) from Python said "`initial_states.runs` must be ..."
    writer, _, _ = COMMANDS["sweep"]
    spec = tmp_path / "spec.toml"
    spec.write_text(writer().replace("runs = 1", "runs = 2.5"))
    with pytest.raises(
        SpecError, match=rf"^{re.escape(str(spec))}: `initial_states.runs` must be an integer; got 2.5"
    ):
        load_spec(spec)


def test_a_wrong_factory_argument_of_a_sweep_names_the_spec_key():
    # it said "row 1, scenario 'default': `sigma` must be ...", not which spec key gave sigma
    from etobs.experiments import parse_spec

    from ..experiments.conftest import raw_spec

    system = {"factory": "tests.estimation.linear:factory", "fixed": {}}
    box = {"low": [-1.0, -1.0], "high": [1.0, 1.0], "runs": 1, "seed": 0}
    rows = [{"sigma": 1.0}, {"sigma": "big"}]
    scenarios = [{"name": "a"}, {"name": "b", "eps": "tiny"}]
    spec = parse_spec(raw_spec(system=system, initial_states=box, rows=rows, scenarios=scenarios))
    with pytest.raises(
        SpecError, match=r"^`rows\[1\].sigma` \(row 1, scenario 'a'\): `sigma` must be a real"
    ):
        spec.problem(2)
    with pytest.raises(
        SpecError, match=r"^`scenarios\[1\].eps` \(row 0, scenario 'b'\): `eps` must be a real"
    ):
        spec.problem(1)
    fixed = {**system, "fixed": {"sigma": "big"}}
    spec = parse_spec(raw_spec(system=fixed, initial_states=box, rows=[{}], scenarios=[{"name": "a"}]))
    with pytest.raises(SpecError, match=r"^`system.fixed.sigma` \(row 0, scenario 'a'\): `sigma` must be"):
        spec.problem(0)
    raw = raw_spec(system=system, initial_states=box, scenarios=[{"name": "a"}], grid={"sigma": [1.0, "big"]})
    del raw["rows"]
    with pytest.raises(SpecError, match=r"^`grid.sigma` \(row 1, scenario 'a'\): `sigma` must be"):
        parse_spec(raw).problem(1)


def test_check_refuses_both_e_and_its_estimate(tmp_path, capsys):
    # E_estimate was used and E ignored without a word
    writer, _, _ = COMMANDS["check"]
    spec = tmp_path / "spec.toml"
    spec.write_text(writer() + "E_estimate = { low = [0.0, 0.0], high = [1.0, 1.0] }\n")
    line = one_clear_line(*run(["check", str(spec)], capsys))
    assert line.endswith("give either `guarantees.E` or `guarantees.E_estimate`, not both")


def test_a_deployment_given_as_a_dictionary_is_checked_as_a_file_is(tmp_path):
    # parse_deployment skipped etobs._spec.check_tree (parse_spec and the CLI did not): a
    # date reached the factory as an argument
    import datetime

    from etobs.runtime.deployment import parse_deployment

    raw = {
        "system": {"factory": "robot_arm", "params": {"eps": datetime.date(2020, 1, 1)}},
        "runtime": {"period": 0.1, "duration": 1.0},
    }
    with pytest.raises(SpecError, match=r"^`system.params.eps` must be a number, .*; got a date or time"):
        parse_deployment(raw, tmp_path)


#: A marked factory next to the spec (the linear oscillator) and a same-named one in the
#: current folder that says so if it is ever used.
NEXT_TO_SPEC = """
import etobs

@etobs.factory
def problem():
    from tests.estimation.linear import factory
    return factory()
"""
IN_CWD = """
import etobs

@etobs.factory
def problem():
    raise RuntimeError("the models.py of the current folder was used")
"""


@pytest.fixture
def two_folders(tmp_path, monkeypatch):
    """``(spec folder, current folder)``, each with a ``models.py``; the current folder is the second."""
    spec_dir, cwd = tmp_path / "project", tmp_path / "elsewhere"
    spec_dir.mkdir()
    cwd.mkdir()
    (spec_dir / "models.py").write_text(NEXT_TO_SPEC)
    (cwd / "models.py").write_text(IN_CWD)
    monkeypatch.chdir(cwd)
    return spec_dir, cwd


@pytest.mark.parametrize("command", ["sweep", "compare", "check"])
def test_a_relative_factory_file_is_taken_from_the_spec_folder_not_the_current_one(
    command, two_folders, capsys
):
    # `cd /tmp && etobs sweep /tmp/newuser/sweep.toml` said "cannot import 'sweepmodels.py': no
    # such file", and run from a folder holding another sweepmodels.py it used that one
    spec_dir, cwd = two_folders
    writer, extra, _ = COMMANDS[command]
    spec = spec_dir / "spec.toml"
    spec.write_text(writer(factory='"models.py:problem"'))
    out = ["--out", str(cwd / "out")] if command != "check" else []
    code = main([command, str(spec), *extra, *out])  # SystemExit on an error
    err = capsys.readouterr().err
    assert "current folder was used" not in err and "error" not in err, err
    assert code == 0 or (command == "check" and code == 1), err  # check: 1 if a condition fails


def test_a_relative_factory_file_of_a_deployment_is_taken_from_its_folder(two_folders):
    from etobs.cli.runtime import load

    spec_dir, _ = two_folders
    writer, _, _ = COMMANDS["serve"]
    (spec_dir / "deploy.toml").write_text(writer(factory='"models.py:problem"'))
    dep = load(str(spec_dir / "deploy.toml"))
    assert dep.factory == f"{spec_dir / 'models.py'}:problem"
    assert dep.problem().plant.n_x == 2  # the spec folder's file, not the current folder's


@pytest.mark.parametrize("command", ["sweep", "compare", "check", "serve"])
def test_a_missing_factory_file_names_the_absolute_path_tried(command, two_folders, capsys):
    spec_dir, _ = two_folders
    writer, extra, _ = COMMANDS[command]
    spec = spec_dir / "spec.toml"
    spec.write_text(writer(factory='"sub/nothere.py:problem"'))
    line = one_clear_line(*run([command, str(spec), *extra], capsys))
    tried = re.escape(str(spec_dir / "sub" / "nothere.py"))
    assert re.search(rf"`system.factory`: cannot import '{tried}': no such file$", line), line


def test_a_module_not_on_the_path_says_where_it_is_looked_for_and_what_to_write(two_folders, capsys):
    # the installed `etobs` script said only "no module named 'mychain'" (its sys.path[0] is the
    # venv's bin, so a module next to the spec or in the current folder is not found)
    spec_dir, _ = two_folders
    (spec_dir / "mychain.py").write_text(NEXT_TO_SPEC)
    writer, extra, _ = COMMANDS["sweep"]
    spec = spec_dir / "spec.toml"
    spec.write_text(writer(factory='"mychain:problem"'))
    line = one_clear_line(*run(["sweep", str(spec), *extra], capsys))
    assert re.search(
        r"cannot import 'mychain': no module named 'mychain' on Python's path \(the installed `etobs` "
        r"command does not look in the current folder or the spec's; `python -m etobs` looks in the "
        r"current folder\): for a file next to the spec write 'mychain.py:<function>', or install",
        line,
    ), line
