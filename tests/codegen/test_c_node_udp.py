"""End to end: generated C nodes (the host harness ``etobs_host.c``) send UDP to the observer service.

Each node is the generated module compiled for the host, replaying the samples of its
vector file in real time (time scaled) and sending its packets by UDP to an
:class:`~etobs.runtime.server.ObserverServer` on 127.0.0.1. Reference: the Python sensor
nodes and the same observer run offline on the same samples
(:func:`etobs.runtime.replay.replay`). The run ends when every C node has exited and
every datagram has been judged (bounded by a timeout that only a broken run reaches); the
service holds packets back for the whole run, so a loaded machine delays, not changes, it.
"""

from __future__ import annotations

import asyncio
import socket
import subprocess
import threading
import time

import numpy as np
import pytest

from etobs.examples import robot_arm
from etobs.runtime.packet import decode
from etobs.runtime.server import ObserverServer
from etobs.runtime.service import ObserverCore
from tests.codegen.cnode import ROOT, build, module
from tests.estimation import linear
from tests.runtime.loopback import KEYS, final_gap, reference
from tests.runtime.test_live import _hostile, hostile_verdicts


def c_live(problem, y, period, duration, *, time_scale, folder, hostile=None):
    """Run the service and one C node process per node; return (snapshot, packets sent by the nodes)."""
    from etobs.codegen.vectors import node_vectors, write_vectors

    exes = []
    for i, nd in enumerate(problem.nodes):
        sub = folder / f"node{i}"
        module(nd.rule.sensor_spec(), period, sub, node=i, n_values=len(nd.outputs))
        exes.append(build(sub, "etobs_host.c", "host"))

    async def main():
        core = ObserverCore(problem, KEYS)
        srv = ObserverServer(core, time_scale=time_scale, hold_back=duration)
        srv.epoch = time.time() + 3600  # until the nodes are ready
        port, _ = await srv.start(port=0, http_port=0)
        srv.epoch = epoch = time.time() + 0.5
        genuine = []
        for i, nd in enumerate(problem.nodes):
            vec = node_vectors(
                nd.rule.sensor_spec(),
                period,
                node=i,
                key=KEYS[i],
                session=epoch,
                samples=y[:, list(nd.outputs)],
            )
            write_vectors(vec, folder / f"node{i}" / "vectors.txt")
            genuine += [p for pk in vec.packets for p in pk]
        procs = [
            subprocess.Popen(
                [
                    str(exe),
                    str(folder / f"node{i}" / "vectors.txt"),
                    "127.0.0.1",
                    str(port),
                    repr(time_scale),
                ],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
            for i, exe in enumerate(exes)
        ]
        extra = {"hostile_sent": 0}
        attacker = None
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM) if hostile is not None else None
        if hostile is not None:
            assert sock is not None
            sock.bind(("127.0.0.1", 0))

            def attack():
                for _ in range(600_000):  # the C nodes' initial packets have arrived
                    if core.counts["initial"] >= problem.n_nodes:
                        break
                    time.sleep(0.001)

                def send(data):
                    sock.sendto(data, ("127.0.0.1", port))
                    extra["hostile_sent"] += 1
                    for _ in range(600_000):  # one at a time: verdicts, not a flood
                        if (
                            srv.received
                            >= extra["hostile_sent"] + core.counts["initial"] + core.counts["applied"]
                        ):
                            break
                        time.sleep(0.0001)

                # what was captured on the network: the C nodes' packets (their bytes, as sent)
                hostile(port, genuine, send)

            attacker = threading.Thread(target=attack, daemon=True)
            attacker.start()

        def finished():
            if any(p.poll() is None for p in procs) or (attacker is not None and attacker.is_alive()):
                return False
            return sum(core.counts.values()) >= len(genuine) + extra["hostile_sent"]

        try:
            snap = await asyncio.wait_for(srv.run_until(duration, finished=finished, linger=300), timeout=600)
        finally:
            for p in procs:
                if p.poll() is None:
                    p.kill()
            outs = [p.communicate(timeout=30) for p in procs]
            await srv.close()
            if attacker is not None:
                attacker.join(timeout=30)
            if sock is not None:
                sock.close()
        assert all(p.returncode == 0 for p in procs), outs
        return snap, genuine, outs

    return asyncio.run(main())


def test_c_nodes_over_udp_give_the_python_sensors_estimate(tmp_path):
    """The robot arm sampled at 2 ms for 3 s, 3x faster than real time, two C nodes."""
    pb = robot_arm()
    _, y, ref = reference(pb, [3.0, 2.0, 3.0, -2.0], 3.0, 0.002)
    snap, genuine, outs = c_live(pb, y, 0.002, 3.0, time_scale=3.0, folder=tmp_path)
    assert tuple(snap["transmissions"]) == ref.transmissions and min(ref.transmissions) >= 2
    assert snap["counts"]["applied"] == sum(ref.transmissions) and snap["counts"]["initial"] == 2
    assert sum(snap["counts"].values()) == len(genuine)  # every datagram judged and used
    assert snap["gaps"] == [0, 0] and snap["status"] == "ok"
    assert final_gap(snap, ref) < 1e-6 * np.max(np.abs(ref.xhat[-1]))
    assert [o[0].split() for o in outs] == [
        ["host:", f"samples={len(y)}", f"transmissions={n}"] for n in ref.transmissions
    ]


@pytest.mark.parametrize("n", [10])
def test_the_service_refuses_forged_and_replayed_packets_around_a_c_node(tmp_path, n):
    """The attack of tests/runtime/test_live.py, with the C node's own packets captured and replayed."""
    pb = linear.factory()
    _, y, ref = reference(pb, [1.0, -0.5], 4.0, 0.005)
    snap, _, _ = c_live(
        pb,
        y,
        0.005,
        4.0,
        time_scale=4.0,
        folder=tmp_path,
        hostile=_hostile(lambda d: decode(d, KEYS).session, n),
    )
    assert snap["counts"] == hostile_verdicts(n, sum(ref.transmissions))
    assert tuple(snap["transmissions"]) == ref.transmissions and snap["gaps"] == [0]
    assert final_gap(snap, ref) < 1e-6


DEPLOYMENT = """
name = "oscillator"
[system]
factory = "tests.estimation.linear:factory"
[runtime]
period = 0.005
duration = 3.0
time_scale = 3.0
host = "127.0.0.1"
port = 0
hold_back = 3.0
secret_file = "secret.key"
[plant]
x0 = [1.0, -0.5]
"""


def test_a_c_node_talks_to_etobs_serve(tmp_path):
    """The commands as a user runs them: `etobs serve SPEC --epoch -`, `etobs codegen c`, `etobs codegen
    vectors --deployment EPOCH` and the host harness; serve's final estimate is the offline reference's."""
    import json
    import os
    import sys

    from etobs.cli.main import main
    from etobs.runtime.packet import node_keys
    from etobs.runtime.replay import replay, sample_outputs

    spec = tmp_path / "deploy.toml"
    spec.write_text(DEPLOYMENT)
    (tmp_path / "secret.key").write_bytes(os.urandom(32))
    (tmp_path / "secret.key").chmod(0o600)
    assert main(["codegen", "c", str(spec), "--node", "0", "--out", str(tmp_path / "node0")]) == 0
    exe = build(tmp_path / "node0", "etobs_host.c", "host")
    vectors = tmp_path / "v0.txt"
    assert (
        main(["codegen", "vectors", str(spec), "--node", "0", "--out", str(vectors)]) == 0
    )  # warm, public key
    serve = subprocess.Popen(
        # --linger: serve waits 8 s past the end for late packets (a loaded machine), with the
        # observer held back the whole run (hold_back = duration), so lateness changes nothing
        [sys.executable, "-m", "etobs", "serve", str(spec), "--epoch", "-", "--linger", "8"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(ROOT)},  # the spec's factory is tests.estimation.linear
    )
    try:
        said = [serve.stderr.readline() for _ in range(1)]  # "etobs serve: UDP 127.0.0.1:PORT": it listens
        assert said[0].startswith("etobs serve: UDP 127.0.0.1:"), said
        port = int(said[0].split("UDP 127.0.0.1:")[1].split()[0].rstrip(","))
        epoch = time.time() + 1.0
        assert (
            main(
                [
                    "codegen",
                    "vectors",
                    str(spec),
                    "--node",
                    "0",
                    "--out",
                    str(vectors),
                    "--deployment",
                    repr(epoch),
                ]
            )
            == 0
        )
        assert oct(vectors.stat().st_mode & 0o777) == "0o600"
        serve.stdin.write(repr(epoch) + "\n")
        serve.stdin.flush()
        host = subprocess.run(
            [str(exe), str(vectors), "127.0.0.1", str(port), "3.0"],
            capture_output=True,
            text=True,
            timeout=120,
        )
        out, err = serve.communicate(timeout=120)
    finally:
        if serve.poll() is None:
            serve.kill()
            serve.communicate()
    assert host.returncode == 0 and serve.returncode == 0, (host.stderr, err)
    snap = json.loads(out)
    pb = linear.factory()
    t, y = sample_outputs(pb, [1.0, -0.5], 3.0, 0.005)
    ref = replay(pb, node_keys((tmp_path / "secret.key").read_bytes(), [0]), t, y, 0.005)
    assert tuple(snap["transmissions"]) == ref.transmissions and ref.transmissions[0] > 3
    assert snap["counts"]["applied"] == ref.transmissions[0] and snap["counts"]["initial"] == 1
    assert snap["late"] == 0 and snap["gaps"] == [0] and snap["status"] == "ok"
    assert final_gap(snap, ref) < 1e-6
    assert host.stdout.split() == ["host:", f"samples={len(t)}", f"transmissions={ref.transmissions[0]}"]
