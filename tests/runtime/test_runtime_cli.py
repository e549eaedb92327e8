"""``etobs demo live``, ``etobs sensor`` as a process that is killed and restarted, and every
mistake of ``serve``/``sensor`` as one line and exit 2."""

import json
import os
import re
import signal
import socket
import struct
import subprocess
import sys
import time

import numpy as np
import pytest

from etobs.cli.main import main
from etobs.runtime.packet import node_keys
from etobs.runtime.service import ObserverCore
from tests.estimation import linear

SPEC = """
name = "oscillator"
[system]
factory = "tests.estimation.linear:factory"
[runtime]
period = 0.005
duration = {duration}
time_scale = {scale}
host = "127.0.0.1"
port = {port}
secret_file = "secret.key"
[plant]
x0 = [1.0, -0.5]
"""


def _secret(folder):
    """A deployment secret, mode 600 as a secret file must be."""
    path = folder / "secret.key"
    path.write_bytes(os.urandom(32))
    path.chmod(0o600)
    return path


def test_demo_live_matches_its_reference(tmp_path, capsys):
    """The robot arm with its observer holding packets back for the whole run: live,
    sensors and reference agree on every transmission, and the estimates to 1e-6,
    however loaded the machine."""
    spec = tmp_path / "arm.toml"
    spec.write_text(
        '[system]\nfactory = "robot_arm"\n[runtime]\nperiod = 0.002\nduration = 2.0\n'
        "time_scale = 4.0\nhold_back = 2.0\n[plant]\nx0 = [3.0, 2.0, 3.0, -2.0]\n"
    )
    out = tmp_path / "out"
    assert main(["demo", "live", "--spec", str(spec), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    s = json.loads((out / "summary.json").read_text())
    assert s["transmissions_live"] == s["transmissions_reference"] == s["transmissions_sensors"]
    assert s["final_gap"] < 1e-6 * max(map(abs, s["final_xhat_reference"])) and s["late"] == 0
    assert s["gaps"] == [0, 0] and s["status"] == "ok"
    assert "transmissions per node: live" in printed and (out / "trace.jsonl").is_file()
    assert (out / "trace.png").stat().st_size > 10_000
    assert oct((out / "etobs.secret").stat().st_mode & 0o777) == "0o600"
    marks = json.loads((out / "etobs.state").read_text())["nodes"]  # the service's high-water marks
    assert [marks[str(i)]["seq"] for i in range(2)] == [n + 1 for n in s["transmissions_live"]]


def test_killed_sensor_process_resumes_its_sequence_numbers(tmp_path):
    """A sensor process is killed (SIGKILL) after it has sent packets and started again
    with the same state file and epoch: it joins at the current time, every packet of
    both runs is accepted, none is stale or replayed, sequence numbers keep increasing.

    It rested on a wall-clock window (a minute of wall time for both runs), and with both
    cores busy the restarted sensor refused its epoch ("that run ended 3.98 s ago"). Each
    process now runs on a virtual clock (:mod:`tests.runtime.virtual_clock`): the time it
    slept, not the time it computed, and the restart is at a clock time the test chooses
    (one plant second after the first run's last packet)."""
    spec = tmp_path / "deploy.toml"
    secret = _secret(tmp_path)
    epoch, scale = 1.7e9, 10.0
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as rx:
        rx.bind(("127.0.0.1", 0))
        rx.settimeout(1.0)
        spec.write_text(SPEC.format(duration=600.0, scale=scale, port=rx.getsockname()[1]))
        args = [
            "sensor",
            str(spec),
            "--node",
            "0",
            "--epoch",
            repr(epoch),
            "--state",
            str(tmp_path / "n0.seq"),
        ]
        got, start = [], epoch
        for run in range(2):
            before = len(got)
            cmd = [sys.executable, "-m", "tests.runtime.virtual_clock", repr(start), *args]
            proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
            try:
                for _ in range(600):  # at most 600 s: only a broken run gets near it
                    try:
                        got.append(rx.recv(4096))
                    except TimeoutError:
                        assert proc.poll() is None, f"run {run}: the sensor exited ({proc.returncode})"
                    if len(got) >= before + 6:
                        break
            finally:
                proc.send_signal(signal.SIGKILL)
                proc.communicate(timeout=60)
            assert len(got) >= before + 6, f"run {run}: only {len(got) - before} packets"
            start = epoch + (struct.unpack(">d", got[-1][16:24])[0] + 1.0) / scale
    core = ObserverCore(linear.factory(), node_keys(secret.read_bytes(), [0]), session=epoch)
    verdicts = [core.receive(d) for d in got]
    assert verdicts.count("initial") == 2 and set(verdicts) <= {"initial", "applied"}
    seqs = [struct.unpack(">Q", d[8:16])[0] for d in got]
    times = [struct.unpack(">d", d[16:24])[0] for d in got]
    assert seqs == sorted(set(seqs))
    second = verdicts.index("initial", 1)
    assert times[second] > times[second - 1] + 1.0 - 1e-9  # the restarted node joined at its clock's time
    assert core.snapshot()["gaps"] == [0]


def _one_line_error(capsys, argv, match):
    """``etobs argv`` ends with exit 2 and one line naming the mistake (no traceback)."""
    with pytest.raises(SystemExit) as e:
        main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("etobs: error:") and "Traceback" not in err, err
    assert re.search(match, lines[0]), lines[0]


LINEAR = 'factory = "tests.estimation.linear:factory"'


@pytest.mark.parametrize(
    ("old", "new", "argv", "match"),
    [
        ("", "", ["--epoch", "nan"], r"--epoch must be a time.time\(\) value .*; got nan"),
        ("", "", ["--epoch", "inf"], r"--epoch must be a time.time\(\) value .*; got inf"),
        ("", "", ["--epoch", "soon"], r"--epoch must be a time.time\(\) value .*; got 'soon'"),
        ("", "", ["--epoch", "99999999999"], r"--epoch 99999999999.0 lies .* s ahead .* at most 3600 s"),
        ("", "", ["--epoch", "1000"], r"--epoch 1000.0: that run ended .* s ago"),
        # after the endpoints opened and the epoch was printed: three lines
        (
            "",
            "",
            ["--trace", "/nonexistent-etobs/t.jsonl"],
            r"--trace '/nonexistent-etobs/t.jsonl' cannot be",
        ),
        (
            '"127.0.0.1"',
            '"no.such.host.invalid"',
            [],
            r"cannot receive packets on UDP no.such.host.invalid:0",
        ),
        (
            LINEAR,
            'factory = "robot_arm"\nparams = {bogus = 1}',
            [],
            r"`bogus` \(system.params\) is not an arg",
        ),
        ("[plant]", 'transport = "mqtt"\nbroker = "127.0.0.1:{closed}"\n[plant]', [], r"`runtime.broker`"),
    ],
)
def test_serve_mistakes_are_one_line(tmp_path, capsys, old, new, argv, match):
    """Each of these printed a traceback (or hung, for the far epoch) before."""
    _secret(tmp_path)
    with socket.socket() as closed:  # bound, never listening: a broker that refuses
        closed.bind(("127.0.0.1", 0))
        text = SPEC.format(duration=1.0, scale=1.0, port=0)
        text = text.replace(old, new.replace("{closed}", str(closed.getsockname()[1]))) if old else text
        (tmp_path / "deploy.toml").write_text(text)
        _one_line_error(capsys, ["serve", str(tmp_path / "deploy.toml"), *argv], match)


def test_a_port_in_use_and_a_readable_secret_are_one_line(tmp_path, capsys):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        spec = tmp_path / "deploy.toml"
        spec.write_text(SPEC.format(duration=1.0, scale=1.0, port=taken.getsockname()[1]))
        secret = _secret(tmp_path)
        _one_line_error(capsys, ["serve", str(spec)], r"cannot receive packets on UDP 127.0.0.1:\d+ .*in use")
    secret.chmod(0o640)
    _one_line_error(
        capsys,
        ["serve", str(spec)],
        rf"`runtime.secret_file` '.*secret.key' has mode 0640: the group or others may read it; run "
        rf"`chmod 600 {secret}`",
    )
    _one_line_error(capsys, ["sensor", str(spec), "--node", "0", "--epoch", repr(time.time())], r"mode 0640")


def test_runtime_spec_errors(tmp_path, capsys):
    spec = tmp_path / "deploy.toml"
    spec.write_text(SPEC.format(duration=1.0, scale=1.0, port=70000))
    _one_line_error(capsys, ["serve", str(spec)], r"`runtime.port` must be <= 65535; got 70000")
    spec.write_text(SPEC.format(duration=1.0, scale=1.0, port=0))
    _secret(tmp_path)  # so that the epoch is what is checked
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as nobody:  # bound, never answering
        nobody.bind(("127.0.0.1", 0))
        quiet = nobody.getsockname()[1]
        spec.write_text(SPEC.format(duration=1.0, scale=1.0, port=quiet))
        _one_line_error(  # no --epoch: the sensor asks the service, which does not answer
            capsys,
            ["sensor", str(spec), "--node", "0", "--wait", "0.3"],
            rf"no answer from the service at 127.0.0.1:{quiet} after 0.3 s; is `etobs serve SPEC` running",
        )
    spec.write_text(SPEC.format(duration=1.0, scale=1.0, port=0))
    _one_line_error(
        capsys, ["sensor", str(spec), "--node", "0", "--epoch", "nan"], r"--epoch must be .* got nan"
    )
    spec.write_text(
        SPEC.format(duration=1.0, scale=1.0, port=0).replace(
            'host = "127.0.0.1"', 'host = "no.such.host.invalid"'
        )
    )
    _one_line_error(
        capsys,
        ["sensor", str(spec), "--node", "0", "--epoch", repr(time.time())],
        r"cannot resolve the service's host 'no.such.host.invalid'",
    )


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ("port = 0", None),
        ("port = 70000", r"`runtime.port` must be <= 65535; got 70000"),
        ("period = 0.005\nbogus = 1", r"unknown key `runtime.bogus`"),
        ("period = 0.005\nmax_value = -1", r"`runtime.max_value`"),
        ("period = 0.005\nstate_file = 3", r"`runtime.state_file` must be a file name; got 3"),
    ],
)
def test_deployment_parsing(tmp_path, change, message):
    import tomllib

    from etobs.experiments.spec import SpecError
    from etobs.runtime.deployment import parse_deployment

    text = SPEC.format(duration=1.0, scale=1.0, port=0)
    text = (
        text.replace("port = 0", change)
        if change.startswith("port")
        else text.replace("period = 0.005", change)
    )
    raw = tomllib.loads(text)
    if message is None:
        dep = parse_deployment(raw, tmp_path)
        assert dep.secret_file == tmp_path / "secret.key" and dep.x0 == (1.0, -0.5)
        assert dep.marks_file == tmp_path / "secret.state" and dep.token_file is None
        with pytest.raises(SpecError, match=r"does not exist; `etobs serve` creates it"):
            dep.secret()
        assert len(dep.secret(create=True)) == 32
    else:
        with pytest.raises(SpecError, match=message):
            parse_deployment(raw, tmp_path)


def test_the_http_token_file(tmp_path):
    """Off loopback the token is created (mode 600) next to the secret; a token file given
    is read, and refused when others may read it."""
    import tomllib
    from dataclasses import replace

    from etobs.experiments.spec import SpecError
    from etobs.runtime.deployment import parse_deployment

    text = SPEC.format(duration=1.0, scale=1.0, port=0).replace("[plant]", "http_port = 0\n[plant]")
    dep = parse_deployment(tomllib.loads(text), tmp_path)
    assert dep.token() is None  # loopback: no token unless asked for
    exposed = replace(dep, http_host="192.0.2.1")
    token = exposed.token()
    assert len(token) >= 32 and exposed.token_file == tmp_path / "secret.http-token"
    assert oct(exposed.token_file.stat().st_mode & 0o777) == "0o600" and exposed.token() == token
    given = tmp_path / "my.token"
    given.write_text("short")
    given.chmod(0o600)
    with pytest.raises(SpecError, match=r"`runtime.http_token_file` .* at least 16 printable"):
        replace(dep, http_token_file=given).token()
    given.chmod(0o604)
    with pytest.raises(SpecError, match=r"has mode 0604: .* run `chmod 600"):
        replace(dep, http_token_file=given).token()


@pytest.mark.parametrize("command", ["serve", "sensor"])
def test_ctrl_c_ends_a_process_with_its_state_and_no_traceback(tmp_path, command):
    _secret(tmp_path)
    spec = tmp_path / "deploy.toml"
    spec.write_text(SPEC.format(duration=600.0, scale=1.0, port=0).replace("port = 0", "port = 9"))
    argv = [sys.executable, "-m", "etobs", command, str(spec), "--epoch", "-"]
    argv += ["--node", "0"] if command == "sensor" else []
    proc = subprocess.Popen(
        argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        if command == "sensor":
            assert proc.stdout.readline().strip() == "ready"
        else:
            assert proc.stderr.readline().startswith("etobs serve: UDP")
        proc.stdin.write(f"{time.time()!r}\n")
        proc.stdin.flush()
        if command == "serve":
            assert proc.stderr.readline().startswith("etobs serve: epoch")
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130 and "Traceback" not in err and f"etobs {command}: interrupted" in err
    assert "transmissions" in json.loads(out.strip().splitlines()[-1])


def test_a_secret_that_cannot_be_created_names_its_key(tmp_path, capsys):
    spec = tmp_path / "deploy.toml"
    (tmp_path / "afile").write_text("not a folder")
    spec.write_text(SPEC.format(duration=1.0, scale=1.0, port=0).replace("secret.key", "afile/secret.key"))
    # it printed 'etobs: error: .../afile: Not a directory', naming no key
    _one_line_error(
        capsys, ["serve", str(spec)], r"`runtime.secret_file` '.*afile/secret.key' cannot be created"
    )


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--duration", "-1"], r"argument --duration: must be a finite number > 0; got '-1'"),
        (["--time-scale", "0"], r"argument --time-scale: must be a finite number > 0; got '0'"),
        (["--duration", "1e308"], r"--duration / `runtime.period` = .* samples; a simulated sensor"),
    ],
)
def test_demo_live_arguments_are_checked_before_any_process_starts(tmp_path, capsys, argv, match):
    """Each started the sensor processes first: three lines (theirs and the demo's), or an unnamed key."""
    with pytest.raises(SystemExit) as info:
        main(["demo", "live", "--out", str(tmp_path / "out"), *argv])
    err = capsys.readouterr().err
    assert info.value.code == 2 and len(err.strip().splitlines()) == 1, err
    assert re.search(match, err), err
    assert not (tmp_path / "out" / "deployment.toml").exists()


def test_serve_refuses_an_observer_step_it_cannot_keep_up_with(tmp_path, capsys):
    _secret(tmp_path)
    spec = tmp_path / "deploy.toml"
    spec.write_text(SPEC.format(duration=1.0, scale=1.0, port=0).replace("[plant]", "dt = 1e-9\n[plant]"))
    _one_line_error(capsys, ["serve", str(spec)], r"steps per wall second; .* `runtime.dt`")


def _free_udp_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_the_documented_recipe_starts_every_sensor_at_t_0(tmp_path):
    """docs/runtime.md's recipe followed literally: `etobs serve SPEC`, then `etobs sensor
    SPEC --node i` in one terminal after another. The sensors joined about 9 plant-seconds
    late (each computed its samples after the service's clock had started) and the run had
    no triggered transmission. Now serve waits for every sensor's hello: the transmissions
    are the offline reference's from t = 0, and so is the estimate along the whole trace."""
    import tomllib

    from etobs.runtime.deployment import parse_deployment
    from etobs.runtime.replay import replay, sample_outputs
    from etobs.runtime.server import read_trace

    spec = tmp_path / "arm.toml"
    spec.write_text(
        '[system]\nfactory = "robot_arm"\n[runtime]\nperiod = 0.002\nduration = 3.5\ntime_scale = 3.5\n'
        f'hold_back = 3.5\nport = {_free_udp_port()}\nsecret_file = "etobs.secret"\n'
        "[plant]\nx0 = [3.0, 2.0, 3.0, -2.0]\n"
    )
    etobs = [sys.executable, "-m", "etobs"]
    serve = subprocess.Popen(
        [*etobs, "serve", str(spec), "--trace", str(tmp_path / "trace.jsonl"), "--linger", "10"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    sensors = []
    try:
        assert serve.stderr.readline().startswith("etobs serve: UDP")
        assert "waiting for the hello of nodes [0, 1]" in serve.stderr.readline()
        for i in range(2):  # one terminal after another: each computes its samples first
            sensors.append(
                subprocess.Popen(
                    [*etobs, "sensor", str(spec), "--node", str(i)], stdout=subprocess.PIPE, text=True
                )
            )
            assert sensors[-1].stdout.readline().strip() == "ready"
        reports = [json.loads(p.communicate(timeout=600)[0].strip().splitlines()[-1]) for p in sensors]
        out, err = serve.communicate(timeout=600)
    finally:
        for p in [serve, *sensors]:
            if p.poll() is None:
                p.kill()
                p.communicate()
    assert serve.returncode == 0 and "every node said hello" in err, err
    snap = json.loads(out.strip().splitlines()[-1])
    dep = parse_deployment(tomllib.loads(spec.read_text()), tmp_path)
    pb = dep.problem()
    keys = node_keys(dep.secret(), range(2))
    t, y = sample_outputs(pb, list(dep.x0), dep.duration, dep.period)
    ref = replay(pb, keys, t, y, dep.period, dt=dep.dt)
    assert min(ref.transmissions) > 0  # the reference has triggered transmissions to miss
    assert tuple(snap["transmissions"]) == ref.transmissions == tuple(r["transmissions"] for r in reports)
    assert snap["counts"]["initial"] == 2 and snap["counts"]["hello"] >= 2 and snap["late"] == 0
    assert snap["gaps"] == [0, 0] and snap["status"] == "ok"
    tr = read_trace(tmp_path / "trace.jsonl")
    assert tr["t"][0] == 0.0 and tr["t"][-1] == 3.5
    k = np.rint(tr["t"] / dep.period).astype(int)
    scale = np.max(np.abs(ref.xhat))
    assert np.max(np.abs(tr["xhat"][1:] - ref.xhat[k[1:]])) < 1e-6 * scale
