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
        ("disturbance = 0.0", "disturbance = [1]"),
        r"`guarantees.disturbance` must be a number; got \[1\]",
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
        ("disturbance = 0.0", "disturbance = 0.0\ncolour = 1"),
        r"unknown key `guarantees.colour`; allowed",
    ),
    ("serve", ("[plant]", "[plant]\nx1 = 2"), r"unknown key `plant.x1`; allowed keys of `plant`: x0"),
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
    spec.write_text(writer() + "E = 1.0\nE_estimate = { low = [0.0, 0.0], high = [1.0, 1.0] }\n")
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
