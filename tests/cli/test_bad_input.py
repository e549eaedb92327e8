"""Every CLI mistake is one line on stderr naming the file, key or argument, and exit 2.

The audit of issue 14 found 23 tracebacks for ordinary mistakes (a non-UTF-8 spec, a
directory as spec, integers beyond float range, deep nesting, unknown factory
parameters, ...), ``etobs sweep /dev/zero`` reading until memory ran out, and
``factory = "subprocess:run"`` running a command. Each spec mistake is tried here on
every command that reads a spec (``sweep``, ``compare``, ``check``, ``serve`` and
``sensor``, all through :func:`etobs.cli.main.main`), and the argument mistakes on every
command.
"""

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from etobs._spec import MAX_DEPTH, MAX_SPEC_BYTES
from etobs.cli.main import main

LINEAR = '"tests.estimation.linear:factory"'


@pytest.fixture(autouse=True)
def _in_tmp_path(tmp_path, monkeypatch):
    """Run every command here in its temporary folder: a default output folder (``sweep``
    without ``--out`` writes ``sweep-NAME``) lands there, never in the checkout."""
    monkeypatch.chdir(tmp_path)


def sweep_spec(factory=LINEAR, params="{}", number="1.0", top=""):
    return (
        f'{top}name = "bad"\n[system]\nfactory = {factory}\nfixed = {params}\n'
        "[initial_states]\nlow = [-1.0, -1.0]\nhigh = [1.0, 1.0]\nruns = 1\nseed = 0\n"
        f"[horizon]\nt_end = {number}\n"
    )


def compare_spec(factory=LINEAR, params="{}", number="1.0", top=""):
    return (
        f'{top}name = "bad"\n[system]\nfactory = {factory}\nparams = {params}\n'
        "[initial_states]\nlow = [-1.0, -1.0]\nhigh = [1.0, 1.0]\nruns = 1\nseed = 0\n"
        f'[horizon]\nt_end = {number}\n[[rules]]\nname = "base"\nkind = "base"\n'
    )


def check_spec(factory=LINEAR, params="{}", number="1.0", top=""):
    # guarantees.E: a number that needs no [observer] (disturbance and a_U do)
    return f"{top}[system]\nfactory = {factory}\nparams = {params}\n[guarantees]\nE = {number}\n"


def tune_spec(factory=LINEAR, params="{}", number="1.0", top=""):
    return (
        f'{top}name = "bad"\n[system]\nfactory = {factory}\nfixed = {params}\n'
        '[parameters]\neps = { low = 0.001, high = 0.1, log = true, per = "scalar" }\n'
        '[budget]\nkind = "simulated"\nerror = 1.0\n'
        "[initial_states]\nlow = [-1.0, -1.0]\nhigh = [1.0, 1.0]\nruns = 1\nseed = 0\n"
        f"[horizon]\nt_end = {number}\n"
    )


def deployment_spec(factory=LINEAR, params="{}", number="1.0", top=""):
    return (
        f'{top}name = "bad"\n[system]\nfactory = {factory}\nparams = {params}\n'
        f'[runtime]\nperiod = 0.01\nduration = {number}\nport = 0\nsecret_file = "secret.key"\n'
        "[plant]\nx0 = [1.0, 0.0]\n"
    )


#: Each command that reads a spec: its spec writer, extra arguments, the numeric key.
COMMANDS = {
    "sweep": (sweep_spec, ["--executor", "serial"], "horizon.t_end"),
    "compare": (compare_spec, ["--executor", "serial", "--no-plot"], "horizon.t_end"),
    "check": (check_spec, [], "guarantees.E"),
    "tune": (tune_spec, ["--executor", "serial", "--no-plot", "--trials", "1"], "horizon.t_end"),
    "serve": (deployment_spec, ["--epoch", "1000.0"], "runtime.duration"),
    "sensor": (deployment_spec, ["--node", "0", "--epoch", "1000.0"], "runtime.duration"),
}

NESTED = "[" * (MAX_DEPTH + 4) + "1.0" + "]" * (MAX_DEPTH + 4)
#: (case, how to write the spec file from the command's writer, what the line must say).
SPEC_CASES = [
    ("missing", None, r"does not exist"),
    ("directory", "DIR", r"is a directory; expected a TOML file"),
    ("not UTF-8", lambda w: w().encode() + b'colour = "\xff\xfe"\n', r"is not UTF-8 text: byte \d+ is 0xff"),
    ("over 1 MiB", lambda w: w() + "#" * MAX_SPEC_BYTES + "\n", r"is larger than 1048576 bytes \(1 MiB\)"),
    ("not TOML", lambda w: w() + "[system\n", r"is not valid TOML"),
    (
        "nested past the recursion limit",
        lambda w: w(number="[" * 5000 + "]" * 5000),
        r"deeper than 16 levels",
    ),
    (
        "nested past the limit",
        lambda w: w(number=NESTED),
        r"`{key}\[0\](\[0\])*` .* is nested 17 levels deep",
    ),
    ("5000-digit integer", lambda w: w(number="9" * 5000), r"holds a value Python cannot read"),
    ("400-digit integer", lambda w: w(number="9" * 400), r"`{key}` must lie within \+-1.8e308"),
    ("400-digit factory argument", lambda w: w(params="{ sigma = " + "9" * 400 + " }"), r"params|fixed"),
    ("1e400", lambda w: w(number="1e400"), r"`{key}` must be finite; got inf"),
    ("nan", lambda w: w(number="nan"), r"`{key}` must be finite; got nan"),
    ("a date", lambda w: w(number="1979-05-27"), r"`{key}` .*got a date or time"),
    ("a string for a number", lambda w: w(number='"1.0"'), r"`{key}` must be a number; got '1.0'"),
    (
        "a key with a line break",
        lambda w: w(top='"a\\nb" = 1\n'),
        r"unknown key `a\\nb`; allowed top-level keys",
    ),
    ("a factory that is not a string", lambda w: w(factory="3"), r"`system.factory` must be a string"),
    ("an unknown factory", lambda w: w(factory='"pendulum"'), r"`system.factory` = 'pendulum' is neither"),
    (
        "an unknown factory parameter",
        lambda w: w(params="{ colour = 1 }"),
        r"parameter `colour` \(.*\) is not an argument of the factory 'tests.estimation.linear:factory'",
    ),
    (
        "a factory argument of the wrong type",
        lambda w: w(params='{ sigma = "big" }'),
        r"`sigma` must be a real number; got 'big'",
    ),
]


def run(argv, capsys):
    """Exit status and the stderr lines of ``etobs ARGV`` run in this process."""
    with pytest.raises(SystemExit) as info:
        main(argv)
    err = capsys.readouterr().err
    return info.value.code, [line for line in err.splitlines() if line.strip()]


def one_clear_line(code, lines):
    assert code == 2, lines
    assert len(lines) == 1, lines
    assert "Traceback" not in lines[0]
    assert re.match(r"etobs( [a-z0-9-]+)*: error: ", lines[0]), lines[0]
    return lines[0]


@pytest.mark.parametrize("command", list(COMMANDS))
@pytest.mark.parametrize(("case", "write", "says"), SPEC_CASES, ids=[c[0] for c in SPEC_CASES])
def test_every_spec_mistake_is_one_line_naming_the_file(command, case, write, says, tmp_path, capsys):
    writer, extra, key = COMMANDS[command]
    spec = tmp_path / "spec.toml"
    if write == "DIR":
        spec.mkdir()
    elif write is not None:
        content = write(writer)
        spec.write_bytes(content if isinstance(content, bytes) else content.encode())
    line = one_clear_line(*run([command, str(spec), *extra], capsys))
    assert str(spec) in line
    assert re.search(says.format(key=re.escape(key)), line), line


@pytest.mark.skipif(not Path("/dev/zero").exists(), reason="no /dev/zero")
@pytest.mark.parametrize("command", list(COMMANDS))
def test_an_endless_spec_file_is_read_in_bounded_memory(command, capsys):
    # it read until memory ran out (2.6 GB when a 3 GB limit stopped it)
    _, extra, _ = COMMANDS[command]
    line = one_clear_line(*run([command, "/dev/zero", *extra], capsys))
    assert "spec file '/dev/zero' is larger than 1048576 bytes" in line


@pytest.mark.parametrize("command", list(COMMANDS))
def test_a_named_pipe_as_spec_is_refused_without_waiting_for_a_writer(command, tmp_path, capsys):
    # opening a FIFO with no writer blocked for good
    fifo = tmp_path / "spec.toml"
    os.mkfifo(fifo)
    _, extra, _ = COMMANDS[command]
    line = one_clear_line(*run([command, str(fifo), *extra], capsys))
    assert f"spec file '{fifo}' is a pipe or socket; expected a TOML file" in line


def test_a_closed_stdout_pipe_ends_quietly_with_status_141(tmp_path):
    # `etobs check robot_arm --json | head -c 10` printed "etobs: error: Broken pipe", exit 2
    proc = subprocess.Popen(
        [sys.executable, "-m", "etobs", "check", "robot_arm", "--json"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        cwd=tmp_path,
    )
    proc.stdout.close()  # the reader leaves before anything is written
    try:
        err = proc.stderr.read().decode()
        assert proc.wait(timeout=300) == 141
    finally:
        proc.kill()
        proc.stderr.close()
    assert err == ""


@pytest.mark.parametrize("command", list(COMMANDS))
def test_a_spec_cannot_run_a_command(command, tmp_path, capsys):
    # factory = "subprocess:run" ran the shell command in sweep, compare, check and serve
    marker = tmp_path / "ran"
    writer, extra, _ = COMMANDS[command]
    spec = tmp_path / "spec.toml"
    spec.write_text(writer(factory='"subprocess:run"', params=f'{{ args = ["touch", "{marker}"] }}'))
    line = one_clear_line(*run([command, str(spec), *extra], capsys))
    assert not marker.exists()
    assert f"{spec}: `system.factory` = 'subprocess:run' is not marked as a factory" in line
    assert "mark it with @etobs.factory" in line and "docs/specs.md" in line


#: (argv, what the line must say) for mistakes in the arguments of every command.
ARGUMENT_CASES = [
    (["sweep"], r"etobs sweep: error: the following arguments are required: spec"),
    (["sweep", "SPEC", "--runs", "0"], r"argument --runs: must be a positive integer; got '0'"),
    (["sweep", "SPEC", "--executor", "gpu"], r"argument --executor: invalid choice: 'gpu'"),
    (["sweep", "SPEC", "--out", "SPEC"], r"argument --out: must be a folder; '.*spec.toml' is a file"),
    (["sweep", "SPEC", "--backend", "gpu"], r"argument --backend: `--backend` must be one of"),
    (["reproduce", "table1", "--chunk-size", "-3"], r"argument --chunk-size: must be a positive integer"),
    (["compare", "SPEC", "--workers", "many"], r"argument --workers: must be a positive integer; got 'many'"),
    (["compare", "SPEC", "--out", "SPEC"], r"argument --out: must be a folder"),
    (["check"], r"etobs check: error: the following arguments are required: SPEC"),
    (["check", "SPEC", "--colour"], r"unrecognized arguments: --colour"),
    (["tune"], r"etobs tune: error: the following arguments are required: SPEC"),
    (["tune", "SPEC", "--trials", "0"], r"argument --trials: must be a positive integer; got '0'"),
    (["tune", "SPEC", "--out", "SPEC"], r"argument --out: must be a folder"),
    (["tune", "SPEC", "--executor", "gpu"], r"argument --executor: invalid choice: 'gpu'"),
    (["sensor", "SPEC", "--epoch", "1.0"], r"the following arguments are required: --node"),
    (["sensor", "SPEC", "--node", "first", "--epoch", "1.0"], r"argument --node: invalid int value: 'first'"),
    (["demo", "robot-arm", "--t-end", "nan"], r"argument --t-end: must be a finite number > 0; got 'nan'"),
    (["demo", "robot-arm", "--t-end", "-1"], r"argument --t-end: must be a finite number > 0; got '-1'"),
    (["demo", "robot-arm", "--rtol", "0"], r"argument --rtol: must be a finite number > 0; got '0'"),
    (["demo", "robot-arm", "--x0", "1,2"], r"argument --x0: --x0 must be 4 comma-separated finite numbers"),
    (["demo", "robot-arm", "--window", "a,b"], r"argument --window: --window must be 2 comma-separated"),
    (["demo", "robot-arm", "--out", "SPEC"], r"argument --out: must be a folder"),
    (["demo", "pendulum"], r"argument CASE: invalid choice: 'pendulum'"),
    (["colour"], r"argument COMMAND: invalid choice: 'colour'"),
]


@pytest.mark.parametrize(("argv", "says"), ARGUMENT_CASES, ids=[" ".join(a) for a, _ in ARGUMENT_CASES])
def test_every_argument_mistake_is_one_line_naming_the_argument(argv, says, tmp_path, capsys):
    spec = tmp_path / "spec.toml"
    spec.write_text(sweep_spec())
    line = one_clear_line(*run([str(spec) if a == "SPEC" else a for a in argv], capsys))
    assert re.search(says, line), line
    assert line.endswith("--help)")  # the usage is one --help away, not printed


def test_the_installed_command_prints_one_line_and_no_traceback(tmp_path):
    spec = tmp_path / "spec.toml"
    spec.write_bytes(b'name = "\xff"\n')
    out = subprocess.run(
        [sys.executable, "-m", "etobs", "sweep", str(spec)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,  # without --out a sweep writes sweep-NAME in the current folder
    )
    assert out.returncode == 2
    assert out.stderr == f"etobs: error: spec file '{spec}' is not UTF-8 text: byte 8 is 0xff\n"


CHECK = """[system]
factory = "robot_arm"
[observer]
{observer}
[guarantees]
E = [10.0, 20.0]
{guarantees}
"""
PAPER = 'structure = "robot_arm"\nL = "paper"\nc_v = 0.1\nc = [0.1, 0.1]'
OWN = 'A = [[0.0, 1.0], [-1.0, -0.2]]\nC = [[1.0, 0.0]]\nL = "design"\nc_v = 0.1\nc = [0.1, 0.1]'


@pytest.mark.parametrize(
    ("observer", "guarantees", "says"),
    [
        (PAPER.replace('"robot_arm"', "[]"), "", r"`observer.structure` must be one of robot_arm; got \[\]"),
        (PAPER.replace("c = [0.1, 0.1]", "c = 1.5"), "", r"`observer.c` must be a list of numbers"),
        (PAPER.replace("c_v = 0.1", 'c_v = "0.1"'), "", r"`observer.c_v` must be a number; got '0.1'"),
        (
            PAPER.replace('"paper"', '"mine"'),
            "",
            r"`observer.L` must be 'design', 'paper' or a matrix; got 'mine'",
        ),
        (PAPER, "noise = 0.01", r"`guarantees.noise` must be a list of numbers \(one per node\); got 0.01"),
        (PAPER, "d = [1, true]", r"`guarantees.d\[1\]` must be a number; got True"),
        (PAPER, 'a_U = "fast"', r"`guarantees.a_U` must be a number; got 'fast'"),
        (OWN.replace("[[1.0, 0.0]]", '"x"'), "", r"`observer.C` must be a matrix of real numbers; got 'x'"),
        (OWN + "\nG = [[0.0], [1.0]]", "", r"missing key `observer.H` \(G, H and slopes go together\)"),
        (
            OWN + "\nG = [[0.0], [1.0]]\nH = [[1.0, 0.0]]\nslopes = [[1.0]]",
            "",
            r"`observer.slopes` has shape \(1, 1\); expected \('\*', 2\)",
        ),
        (
            PAPER.replace("c = [0.1, 0.1]", "c = [0.1, 0.1, 0.1]"),
            "",
            r"`observer.c` must have one constant per node \(2\); got 3",
        ),
    ],
)
def test_check_values_of_the_wrong_type_name_their_key(observer, guarantees, says, tmp_path, capsys):
    pytest.importorskip("cvxpy")
    # each was a traceback (TypeError, ValueError) from inside the design functions
    spec = tmp_path / "check.toml"
    spec.write_text(CHECK.format(observer=observer, guarantees=guarantees))
    line = one_clear_line(*run(["check", str(spec)], capsys))
    assert re.search(says, line), line


@pytest.mark.parametrize("kind", ["[]", "{}", "3", '"fast"'])
def test_a_rule_kind_of_the_wrong_type_names_the_key(kind, tmp_path, capsys):
    spec = tmp_path / "compare.toml"
    spec.write_text(compare_spec().replace('kind = "base"', f"kind = {kind}"))
    line = one_clear_line(*run(["compare", str(spec)], capsys))
    assert re.search(r"`rules\[0\].kind` must be one of base, dynamic, static, periodic", line), line


def test_ctrl_c_is_one_line_and_exit_130(tmp_path):
    from tests.experiments.conftest import FACTORY

    started = tmp_path / "started"
    spec = tmp_path / "spec.toml"
    spec.write_text(
        f'name = "slow"\n[system]\nfactory = "{FACTORY}"\nfixed = {{ delay = 600.0, started = "{started}" }}\n'
        "[initial_states]\nlow = [-1.0]\nhigh = [1.0]\nruns = 1\nseed = 1\n[horizon]\nt_end = 1.0\n"
    )
    argv = [
        sys.executable,
        "-m",
        "etobs",
        "sweep",
        str(spec),
        "--out",
        str(tmp_path / "o"),
        "--executor",
        "serial",
    ]
    proc = subprocess.Popen(argv, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        for _ in range(1200):  # the factory is called once the sweep is under way (at most 120 s)
            if started.exists() or proc.poll() is not None:
                break
            time.sleep(0.1)
        assert started.exists(), proc.stderr.read() if proc.poll() is not None else "not started"
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130
    assert err == "etobs: interrupted\n"


def test_an_os_error_without_a_message_still_says_what_happened(monkeypatch, capsys):
    # a TimeoutError (an OSError with no strerror and no text) printed "etobs: error: " and nothing else
    import etobs.cli.check as check_cli

    def times_out(args):
        raise TimeoutError

    monkeypatch.setattr(check_cli, "run", times_out)
    line = one_clear_line(*run(["check", "robot_arm"], capsys))
    assert line == "etobs: error: TimeoutError"
