"""``etobs demo live``, ``etobs sensor`` as a process that is killed and restarted, spec errors."""

import json
import os
import signal
import socket
import struct
import subprocess
import sys
import time

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


def test_demo_live_matches_its_reference(tmp_path, capsys):
    assert main(["demo", "live", "--out", str(tmp_path), "--duration", "2", "--time-scale", "4"]) == 0
    out = capsys.readouterr().out
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["transmissions_live"] == s["transmissions_reference"] == s["transmissions_sensors"]
    assert s["final_gap"] < 1e-4 and s["late"] == 0
    assert "transmissions per node: live" in out and (tmp_path / "trace.jsonl").is_file()
    assert (tmp_path / "trace.png").stat().st_size > 10_000
    assert oct((tmp_path / "etobs.secret").stat().st_mode & 0o777) == "0o600"


def test_killed_sensor_process_resumes_its_sequence_numbers(tmp_path):
    """A sensor process is killed (SIGKILL) after it has sent packets and started again
    with the same state file and epoch: it joins at the current time, every packet of
    both runs is accepted, none is stale or replayed, sequence numbers keep increasing."""
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(0.2)
    spec = tmp_path / "deploy.toml"
    spec.write_text(SPEC.format(duration=120.0, scale=4.0, port=rx.getsockname()[1]))
    (tmp_path / "secret.key").write_bytes(os.urandom(32))
    epoch = repr(time.time())
    cmd = [
        sys.executable,
        "-m",
        "etobs",
        "sensor",
        str(spec),
        "--node",
        "0",
        "--epoch",
        epoch,
        "--state",
        str(tmp_path / "n0.seq"),
    ]
    got = []

    def collect(until_count, seconds):
        end = time.time() + seconds
        while time.time() < end and len(got) < until_count:
            try:
                got.append(rx.recv(4096))
            except TimeoutError:
                pass

    for run in range(2):
        before = len(got)
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        collect(before + 6, 60.0)  # bounded: 60 s at most, 6 packets per run
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        assert len(got) >= before + 6, f"run {run}: only {len(got) - before} packets"
    rx.close()
    core = ObserverCore(linear.factory(), node_keys((tmp_path / "secret.key").read_bytes(), [0]))
    verdicts = [core.receive(d) for d in got]
    assert verdicts.count("initial") == 2 and set(verdicts) <= {"initial", "applied"}
    seqs = [struct.unpack(">Q", d[8:16])[0] for d in got]
    times = [struct.unpack(">d", d[16:24])[0] for d in got]
    assert seqs == sorted(set(seqs))
    second = verdicts.index("initial", 1)
    assert times[second] > times[second - 1]  # the restarted node joined at the current time


def test_runtime_spec_errors(tmp_path):
    spec = tmp_path / "deploy.toml"
    spec.write_text(SPEC.format(duration=1.0, scale=1.0, port=70000))
    with pytest.raises(SystemExit) as e:
        main(["serve", str(spec)])
    assert e.value.code == 2
    spec.write_text(SPEC.format(duration=1.0, scale=1.0, port=0))
    with pytest.raises(SystemExit) as e:
        main(["sensor", str(spec), "--node", "0"])  # no --epoch: argparse names it
    assert e.value.code == 2
    with pytest.raises(SystemExit) as e:
        main(["sensor", str(spec), "--node", "0", "--epoch", "nan"])
    assert e.value.code == 2


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ("port = 0", None),
        ("port = 70000", r"`runtime.port` must be <= 65535; got 70000"),
        ("period = 0.005\nbogus = 1", r"unknown key `runtime.bogus`"),
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
        with pytest.raises(SpecError, match=r"does not exist; `etobs serve` creates it"):
            dep.secret()
        assert len(dep.secret(create=True)) == 32
    else:
        with pytest.raises(SpecError, match=message):
            parse_deployment(raw, tmp_path)
