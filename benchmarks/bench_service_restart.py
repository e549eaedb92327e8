"""Measurement: the observer service SIGKILLed mid-run and restarted, against the offline reference.

Run: ``python benchmarks/bench_service_restart.py [--down S] [--out DIR]``. The robot arm
is deployed as the docs describe (``etobs serve`` and two ``etobs sensor`` processes on
loopback, 10 s at 1x, sampling period 2 ms). The service is SIGKILLed at t = 5 s and
started again ``--down`` wall seconds later (default 2.6) on the same epoch and state
file. It prints when the restarted service asked its sensors to resend and when they
answered, what was recovered, and the estimate's gap to the offline reference
(:func:`etobs.runtime.replay.replay`, the same sensors and observer with no network) over
the restarted service's trace, next to the undisturbed run's gap before the kill.

Real processes and the wall clock: about a minute, and not part of ``make test`` (the
behaviour is tested on a virtual clock in ``tests/runtime/test_service_state.py``).
"""

from __future__ import annotations

import argparse
import json
import signal
import socket
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np

from etobs.runtime.deployment import parse_deployment
from etobs.runtime.packet import node_keys
from etobs.runtime.replay import replay, sample_outputs
from etobs.runtime.server import read_trace

SPEC = """[system]
factory = "robot_arm"
[runtime]
period = 0.002
duration = 10.0
time_scale = 1.0
port = {port}
secret_file = "etobs.secret"
[plant]
x0 = [3.0, 2.0, 3.0, -2.0]
"""
#: Wall seconds from now to the epoch: every process has started and built its problem.
LEAD = 40.0
KILL_AT = 5.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--down", type=float, default=2.6, help="wall seconds the service is down")
    ap.add_argument("--out", type=Path, default=None, help="folder for the spec, state and traces")
    args = ap.parse_args()
    d = args.out or Path(tempfile.mkdtemp(prefix="etobs-restart-"))
    d.mkdir(parents=True, exist_ok=True)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    spec = d / "arm.toml"
    spec.write_text(SPEC.format(port=port))
    etobs = [sys.executable, "-m", "etobs"]
    epoch = time.time() + LEAD
    pipes = {"stdout": subprocess.PIPE, "stderr": subprocess.PIPE, "text": True}

    def serve(trace: str) -> subprocess.Popen:
        return subprocess.Popen(
            [*etobs, "serve", str(spec), "--epoch", repr(epoch), "--trace", str(d / trace)], **pipes
        )

    first = serve("before.jsonl")
    first.stderr.readline()  # the secret exists once the endpoints are open
    sensors = [
        subprocess.Popen([*etobs, "sensor", str(spec), "--node", str(i), "--epoch", repr(epoch)], **pipes)
        for i in range(2)
    ]
    time.sleep(max(0.0, epoch + KILL_AT - time.time()))
    first.send_signal(signal.SIGKILL)
    first.communicate()
    time.sleep(args.down)
    second = serve("after.jsonl")
    out, _ = second.communicate(timeout=300)
    ends = [json.loads(p.communicate(timeout=300)[0].strip().splitlines()[-1]) for p in sensors]
    snap = json.loads(out.strip().splitlines()[-1])

    dep = parse_deployment(tomllib.loads(spec.read_text()), d)
    pb = dep.problem()
    t, y = sample_outputs(pb, list(dep.x0), dep.duration, dep.period)
    ref = replay(pb, node_keys(dep.secret(), range(2)), t, y, dep.period, dt=dep.dt)

    def gap(trace: dict) -> np.ndarray:
        k = np.rint(trace["t"] / dep.period).astype(int)
        return np.max(np.abs(trace["xhat"] - ref.xhat[k]), axis=1)

    before, after = read_trace(d / "before.jsonl"), read_trace(d / "after.jsonl")
    print(f"folder {d}; service down from t = {KILL_AT:g} s for {args.down:g} s (wall)")
    print(f"sensors: resyncs {[e['resyncs'] for e in ends]}, resent {[e['resent'] for e in ends]}")
    asked, answered = snap["resync_since"], snap["resync_answered"]
    lags = [
        None if a is None or b is None else round(1e3 * (b - a), 1)
        for a, b in zip(asked, answered, strict=True)
    ]
    print(
        f"restarted: resumed {snap['resumed']}, first request at t = {asked}, answers at {answered} ({lags} ms)"
    )
    print(
        f"recovered {snap['recovered']}, gaps {snap['gaps']}, gave up {snap['resync_gave_up']}, late {snap['late']}"
    )
    print(f"gap to the reference: undisturbed (before the kill) max {np.nanmax(gap(before)):.3e}")
    print(
        f"                      restarted trace (from t = {after['t'][0]:.3f}) max {np.nanmax(gap(after)):.3e}"
    )
    final = np.max(np.abs(np.array(snap["xhat"]) - ref.xhat[-1]))
    print(
        f"final gap {final:.3e}; transmissions {snap['transmissions']} (reference {list(ref.transmissions)})"
    )


if __name__ == "__main__":
    main()
