"""The MQTT transport against a real Mosquitto broker on 127.0.0.1 (started here, bounded).

Without a broker (or paho-mqtt) these tests are skipped on a developer's machine, and
fail under ``CI=true``: CI installs both, and a failed install must not pass silently.
"""

import os
import shutil
import socket
import subprocess
import time
from pathlib import Path

import pytest

from etobs.examples import robot_arm
from etobs.runtime.packet import Packet, derive_key, encode
from tests.runtime.loopback import final_gap, live, reference

CI = os.environ.get("CI", "").lower() not in ("", "0", "false", "no")


def _missing(reason):
    if CI:
        pytest.fail(f"{reason} (CI=true: the MQTT tests must run)", pytrace=False)
    pytest.skip(reason)


MOSQUITTO = shutil.which("mosquitto") or next(
    (p for p in ("/usr/sbin/mosquitto", "/usr/bin/mosquitto") if Path(p).exists()), None
)


@pytest.fixture(scope="module")
def broker(tmp_path_factory):
    try:
        import paho.mqtt  # noqa: F401
    except ImportError:
        _missing("the MQTT transport needs the extra 'mqtt' (paho-mqtt)")
    if MOSQUITTO is None:
        _missing("mosquitto is not installed (apt-get install mosquitto; .ci/run installs it)")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    conf = tmp_path_factory.mktemp("mosquitto") / "mosquitto.conf"
    conf.write_text(f"listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\n")
    proc = subprocess.Popen([MOSQUITTO, "-c", str(conf)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.time() + 10
    while time.time() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            break
        except OSError:
            if proc.poll() is not None:
                err = proc.stderr.read().decode()[:300]
                proc.stderr.close()
                pytest.fail(f"mosquitto exited: {err}")
            time.sleep(0.05)
    else:
        proc.kill()
        proc.stderr.close()
        pytest.fail("mosquitto did not accept connections within 10 s")
    yield ("127.0.0.1", port)
    proc.terminate()
    proc.wait(timeout=10)
    proc.stderr.close()


def _forger(broker):
    def attack(port, sent, send):
        import paho.mqtt.client as mqtt

        c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="intruder")
        c.connect(*broker)
        c.loop_start()
        published = []
        for k in range(10):  # an intruder on the broker: invented, replayed and garbage payloads
            invented = encode(Packet(0, 10**9 + k, 0.1, (5.0,)), derive_key(b"guess", 0))
            published.append(c.publish("etobs/test/node/0", invented))
            published.append(c.publish("etobs/test/node/1", sent[1]))
            published.append(c.publish("etobs/test/node/0", b"\x00" * 7))
        for info in published:  # on the wire before the client goes
            info.wait_for_publish(timeout=60)
        c.loop_stop()
        c.disconnect()
        return len(published)

    return attack


def test_robot_arm_over_mqtt_matches_the_reference_and_rejects_an_intruder(broker):
    pb = robot_arm()
    _, y, ref = reference(pb, [3.0, 2.0, 3.0, -2.0], 3.0, 0.002)
    snap, _, _ = live(pb, y, 0.002, 3.0, time_scale=3.0, broker=broker, hostile=_forger(broker))
    c = snap["counts"]
    assert tuple(snap["transmissions"]) == ref.transmissions
    assert c["forged"] == 10 and c["malformed"] == 10 and c["replayed"] == 10
    assert c["applied"] == sum(ref.transmissions)
    assert final_gap(snap, ref) < 1e-4 * max(abs(v) for v in ref.xhat[-1])


def test_serve_and_sensor_commands_over_mqtt(broker, tmp_path):
    """`etobs serve` and `etobs sensor` as processes, through the broker."""
    import json
    import sys

    from etobs.runtime.packet import node_keys
    from etobs.runtime.replay import replay, sample_outputs
    from tests.estimation import linear

    spec = tmp_path / "deploy.toml"
    spec.write_text(
        f"""
name = "osc"
[system]
factory = "tests.estimation.linear:factory"
[runtime]
period = 0.005
duration = 2.0
time_scale = 4.0
hold_back = 2.0
port = 0
transport = "mqtt"
broker = "{broker[0]}:{broker[1]}"
secret_file = "secret.key"
[plant]
x0 = [1.0, -0.5]
"""
    )
    secret = os.urandom(32)
    (tmp_path / "secret.key").write_bytes(secret)
    (tmp_path / "secret.key").chmod(0o600)
    etobs = [sys.executable, "-m", "etobs"]
    pipes = {"stdin": subprocess.PIPE, "stdout": subprocess.PIPE, "stderr": subprocess.PIPE, "text": True}
    # the observer holds every packet back for the whole run, and 3 s past its end, so
    # what arrives late through the broker is still applied at its sample time
    serve = subprocess.Popen([*etobs, "serve", str(spec), "--epoch", "-", "--linger", "3"], **pipes)
    sensor = subprocess.Popen([*etobs, "sensor", str(spec), "--node", "0", "--epoch", "-"], **pipes)
    try:
        assert "MQTT" in serve.stderr.readline()
        assert sensor.stdout.readline().strip() == "ready"
        epoch = f"{time.time() + 0.3!r}\n"
        for p in (serve, sensor):
            p.stdin.write(epoch)
            p.stdin.flush()
        out_serve, _ = serve.communicate(timeout=60)
        out_sensor, _ = sensor.communicate(timeout=60)
    finally:
        for p in (serve, sensor):
            if p.poll() is None:
                p.kill()
                p.communicate()
    snap = json.loads(out_serve.strip().splitlines()[-1])
    report = json.loads(out_sensor.strip().splitlines()[-1])
    pb = linear.factory()
    t, y = sample_outputs(pb, [1.0, -0.5], 2.0, 0.005)
    ref = replay(pb, node_keys(secret, [0]), t, y, 0.005)
    assert snap["transmissions"] == [report["transmissions"]] == list(ref.transmissions)
    assert max(abs(a - b) for a, b in zip(snap["xhat"], ref.xhat[-1], strict=True)) < 1e-6
    assert snap["late"] == 0 and snap["gaps"] == [0] and snap["counts"]["wrong_session"] == 0
