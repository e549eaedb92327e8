"""``etobs serve``, ``etobs sensor`` and ``etobs demo live``: the rules deployed over UDP.

``serve SPEC`` runs the observer service until the spec's duration and prints its final
estimate and counters (JSON); ``sensor SPEC --node i`` runs node ``i`` on the spec's
simulated plant. They share a clock: time 0 is the epoch, a ``time.time()`` value.
Without ``--epoch`` (UDP), they agree on it by a start-up handshake: ``serve`` waits
until every node's sensor has said hello, then sets the epoch and tells each sensor,
so sensors started one after another by hand all begin at t = 0; a sensor restarted
mid-run joins at the current time (:mod:`etobs.runtime.server`). With ``--epoch E``
(the same for every process, or ``-`` to read it from standard input, how ``demo live``
starts every process at once after they are ready) there is no handshake. ``demo live`` starts the service
in this process and one sensor process per node on 127.0.0.1, then compares the live
run with the offline reference (same sensors and observer, no network).

The epoch is also the session every packet carries: a packet of another run is refused
(``wrong_session``), and ``serve`` keeps the nodes' high-water marks in
``runtime.state_file``, so a packet it applied is refused after any restart. Every
mistake (a bad spec value, an epoch far off, a port in use, an unknown host, an
unreachable broker) ends with one line naming it and exit 2.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from etobs.cli._args import load_toml, positive_float
from etobs.errors import InputError
from etobs.runtime.deployment import Deployment, parse_deployment

PACKAGED = {"robot_arm": "robot_arm_live.toml"}
#: A simulated sensor computes every sample of its plant before it starts.
MAX_SIMULATED_SAMPLES = 1e7
#: How long ``demo live`` waits for a sensor process to compute its samples: only a broken
#: one takes that long, even on a loaded machine compiling its model first.
READY_TIMEOUT = 1800.0
#: How long ``serve`` waits for every sensor's hello by default (``--wait``).
HANDSHAKE_WAIT = 3600.0


def load(name: str) -> Deployment:
    """A packaged deployment by name (paths relative to the working folder), or a TOML file."""
    base = Path(".") if name in PACKAGED else Path(name).resolve().parent
    return parse_deployment(load_toml(name, PACKAGED, "etobs.runtime"), base)


def add_parsers(sub: Any) -> None:
    """Register ``serve`` and ``sensor``."""
    p = sub.add_parser("serve", help="run the observer service (UDP packets in, estimate out)")
    p.add_argument("spec", metavar="SPEC", help=f"deployment TOML, or a packaged one: {', '.join(PACKAGED)}")
    p.add_argument(
        "--epoch",
        default=None,
        help="time.time() of service time 0, or '-' to read it from stdin (default: set when every "
        "sensor has said hello)",
    )
    p.add_argument(
        "--wait",
        type=_seconds,
        default=HANDSHAKE_WAIT,
        help=f"wall seconds to wait for every sensor's hello (default {HANDSHAKE_WAIT:g})",
    )
    p.add_argument("--trace", type=Path, default=None, help="write the trace (JSON lines) here")
    p.add_argument(
        "--linger",
        type=_seconds,
        default=0.0,
        help="wall seconds to keep taking packets after the run's end, the observer held "
        "hold_back short of it (default 0)",
    )
    p.set_defaults(func=run_serve)
    s = sub.add_parser("sensor", help="run one sensor node on the spec's simulated plant")
    s.add_argument("spec", metavar="SPEC", help=f"deployment TOML, or a packaged one: {', '.join(PACKAGED)}")
    s.add_argument("--node", type=int, required=True, help="node index (0-based)")
    s.add_argument(
        "--epoch",
        default=None,
        help="the service's epoch, or '-' to read it from stdin (default: ask the service, UDP)",
    )
    s.add_argument(
        "--wait",
        type=_seconds,
        default=HANDSHAKE_WAIT,
        help=f"wall seconds to wait for the service's answer to the hello (default {HANDSHAKE_WAIT:g})",
    )
    s.add_argument(
        "--state", type=Path, default=None, help="sequence-number file (default NODE.seq next to the secret)"
    )
    s.set_defaults(func=run_sensor)


def add_demo(cases: Any) -> None:
    """Register ``demo live``."""
    p = cases.add_parser(
        "live",
        help="the observer service and one sensor process per node on 127.0.0.1",
        description="Start the observer service and the sensor processes of SPEC on loopback, run them, and "
        "compare with the offline reference.",
    )
    p.add_argument("--spec", default="robot_arm", help="deployment TOML or packaged name (default robot_arm)")
    p.add_argument(
        "--out", type=Path, default=Path("live-out"), help="output folder (secret, trace, summary)"
    )
    p.add_argument(
        "--duration", type=positive_float, default=None, help="plant seconds (default: the spec's)"
    )
    p.add_argument(
        "--time-scale",
        type=positive_float,
        default=None,
        help="speed-up over real time (default: the spec's)",
    )
    p.set_defaults(func=run_demo_live)


def _seconds(text: str) -> float:
    """An argparse type: a finite number of seconds ``>= 0`` (at most a day)."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0 <= value <= 86400:
        raise argparse.ArgumentTypeError(f"must be a number of seconds in 0..86400; got {text!r}")
    return value


def _check_samples(dep: Deployment, duration: str) -> None:
    """Refuse a run whose simulated sensors would compute more than ``MAX_SIMULATED_SAMPLES``."""
    if dep.duration / dep.period > MAX_SIMULATED_SAMPLES:
        raise InputError(
            f"{duration} / `runtime.period` = {dep.duration / dep.period:.3g} samples; a simulated "
            f"sensor computes its plant's samples first, at most {MAX_SIMULATED_SAMPLES:.0e}"
        )


def _epoch(value: str | None, dep: Deployment) -> float:
    """The epoch ``--epoch`` gives (``-``: a line of stdin; None: now), checked for ``dep``'s run."""
    from etobs.runtime.sensor import check_epoch

    if value is None:
        return time.time()
    if value == "-":
        value = sys.stdin.readline().strip()
    try:
        epoch = float(value)
    except ValueError:
        raise InputError(
            f"--epoch must be a time.time() value (seconds since 1970) or '-'; got {value!r}"
        ) from None
    return check_epoch(epoch, dep.duration, dep.time_scale, time.time(), "--epoch")


async def _open(srv: Any, dep: Deployment) -> tuple[int, int | None]:
    """Open ``srv``'s endpoints as ``dep`` says; an error names the spec's keys."""
    try:
        return await srv.start(dep.host, dep.port, dep.http_port, dep.http_host)
    except InputError as exc:
        raise InputError(f"[runtime] {exc}") from exc


def _mqtt(make: Any, dep: Deployment, *args: Any) -> Any:
    """An MQTT client of ``dep``; an unreachable broker or a missing paho is one line."""
    try:
        return make(*dep.broker, dep.topic, *args)
    except (ConnectionError, ImportError) as exc:
        raise InputError(f"`runtime.broker` = '{dep.broker[0]}:{dep.broker[1]}': {exc}") from exc


def run_serve(args: argparse.Namespace) -> int:
    """The observer service until the spec's duration; print the final snapshot."""
    from etobs.runtime.marks import HighWaterMarks
    from etobs.runtime.packet import node_keys
    from etobs.runtime.server import START_LEAD, ObserverServer, to_json
    from etobs.runtime.service import ObserverCore

    dep = load(args.spec)
    pb = dep.problem()
    keys = node_keys(dep.secret(create=True), range(pb.n_nodes))
    core = ObserverCore(pb, keys, dt=dep.dt, marks=HighWaterMarks(dep.marks_file), max_value=dep.max_value)
    token = dep.token()
    given = None if args.epoch in (None, "-") else _epoch(args.epoch, dep)  # before anything opens
    if args.trace is not None:  # written from the run's first tick on: refused now if it cannot be
        from etobs.runtime.files import open_regular

        open_regular(args.trace, "--trace", write=True).close()

    shake = args.epoch is None and dep.transport == "udp"

    async def main() -> dict[str, Any]:
        srv = ObserverServer(
            core,
            epoch=given,
            time_scale=dep.time_scale,
            hold_back=dep.hold_back,
            trace=args.trace,
            token=token,
            handshake=shake,
        )
        udp, web = await _open(srv, dep)
        receiver = None
        try:
            where = f"UDP {dep.host}:{udp}"
            if dep.transport == "mqtt":
                from etobs.runtime.mqtt import MqttReceiver

                receiver = await asyncio.to_thread(_mqtt, MqttReceiver, dep, srv.feed)
                where += f" and MQTT {dep.broker[0]}:{dep.broker[1]} {dep.topic}/node/+"
            web_note = f", GET http://{dep.http_host}:{web}/estimate" if web else ""
            if token is not None:
                web_note += f" (Authorization: Bearer <the token in {dep.token_file}>)"
            print(f"etobs serve: {where}{web_note}", file=sys.stderr, flush=True)
            if shake:
                print(
                    f"etobs serve: waiting for the hello of nodes {srv.waiting_for()}: start each with "
                    f"`etobs sensor {args.spec} --node i`",
                    file=sys.stderr,
                    flush=True,
                )
                await srv.wait_start(args.wait)
                note = f"every node said hello; t = 0 in {START_LEAD:g} s"
            else:
                if given is None:  # stdin is read off the event loop
                    srv.epoch = await asyncio.to_thread(_epoch, args.epoch, dep)
                note = f"the same for every sensor: --epoch {srv.epoch!r}"
            print(f"etobs serve: epoch {srv.epoch!r} ({note})", file=sys.stderr, flush=True)
            if args.linger:  # the observer waits hold_back short of the end for late packets
                return await srv.run_until(dep.duration, finished=lambda: False, linger=args.linger)
            return await srv.run_until(dep.duration)
        finally:
            if receiver is not None:
                receiver.close()
            await srv.close()

    try:
        snap = asyncio.run(main())
    except KeyboardInterrupt:  # Ctrl-C: the state so far, no traceback
        print("etobs serve: interrupted", file=sys.stderr)
        print(to_json(core.snapshot()))
        return 130
    print(to_json(snap))
    return 0


def run_sensor(args: argparse.Namespace) -> int:
    """Sensor node ``--node`` on the spec's simulated plant, sending to the service."""
    from etobs.runtime.packet import derive_key
    from etobs.runtime.replay import sample_outputs
    from etobs.runtime.sampled_rule import SampledRule
    from etobs.runtime.sensor import SensorNode, SequenceStore, check_epoch, handshake, run, udp_sender

    dep = load(args.spec)
    pb = dep.problem()
    dep.node_rule(pb, args.node)  # a node out of range, a rule no node runs: said before anything starts
    if dep.x0 is None:
        raise InputError("the spec has no [plant] x0: a simulated sensor needs the plant's initial state")
    _check_samples(dep, "`runtime.duration`")
    outputs = list(pb.nodes[args.node].outputs)
    key = derive_key(dep.secret(), args.node)
    seq = SequenceStore(args.state or dep.secret_file.with_name(f"node{args.node}.seq"))
    if dep.transport == "mqtt" and args.epoch is None:
        raise InputError(
            "--epoch is needed with `runtime.transport` = 'mqtt' (the start-up handshake is UDP)"
        )
    if dep.transport == "mqtt":
        from etobs.runtime.mqtt import MqttSender

        sender: Any = _mqtt(MqttSender, dep, args.node)
    else:
        sender = udp_sender(dep.host, dep.port)
    with sender as send:
        _, y = sample_outputs(pb, list(dep.x0), dep.duration, dep.period)
        node = None
        try:
            print("ready", flush=True)
            first = None
            if args.epoch is None:  # ask the service (hello): every sensor begins at its t = 0
                epoch, first = handshake(send, args.node, key, seq, timeout=args.wait)
                check_epoch(epoch, dep.duration, dep.time_scale, time.time(), "the service's epoch")
            else:
                epoch = _epoch(args.epoch, dep)
            rule = SampledRule(*dep.node_rule(pb, args.node))
            listen = send.recv_nowait if dep.transport == "udp" else None  # resync requests (UDP only)
            node = SensorNode(args.node, key, rule, send, seq, session=epoch, listen=listen)
            n = run(
                node,
                lambda t: y[round(t / dep.period), outputs],
                dep.period,
                dep.duration,
                epoch=epoch,
                time_scale=dep.time_scale,
                first=first,
            )
        except KeyboardInterrupt:  # Ctrl-C: what was sent so far, no traceback
            print("etobs sensor: interrupted", file=sys.stderr)
            sent = 0 if node is None else node.transmissions
            print(json.dumps({"node": args.node, "transmissions": sent}))
            return 130
    done = {"node": args.node, "samples": n, "transmissions": node.transmissions, "resyncs": node.resyncs}
    print(json.dumps({**done, "resent": node.resent, "resync_refused": node.resync_refused}))
    return 0


def run_demo_live(args: argparse.Namespace) -> int:
    """Service here, sensors as processes; compare with the offline reference."""
    from dataclasses import replace

    from etobs.runtime.marks import HighWaterMarks
    from etobs.runtime.packet import node_keys
    from etobs.runtime.replay import replay, sample_outputs
    from etobs.runtime.server import ObserverServer, read_trace
    from etobs.runtime.service import ObserverCore

    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    dep = load(args.spec)
    dep = replace(
        dep,
        secret_file=out / "etobs.secret",
        duration=dep.duration if args.duration is None else args.duration,
        time_scale=dep.time_scale if args.time_scale is None else args.time_scale,
        port=0,
        http_port=0,
        host="127.0.0.1",
    )
    # before any process starts: each would print its own error, then the demo its own
    _check_samples(dep, "`runtime.duration`" if args.duration is None else "--duration")
    pb = dep.problem()
    keys = node_keys(dep.secret(create=True), range(pb.n_nodes))
    core = ObserverCore(pb, keys, dt=dep.dt, marks=HighWaterMarks(dep.marks_file), max_value=dep.max_value)

    async def main() -> tuple[dict[str, Any], list[dict[str, Any]]]:
        srv = ObserverServer(
            core, time_scale=dep.time_scale, hold_back=dep.hold_back, trace=out / "trace.jsonl"
        )
        srv.epoch = time.time() + 3600  # set once every sensor is ready
        udp, _ = await srv.start("127.0.0.1", 0, None)
        spec = _write_spec(dep, out, udp)
        procs = [
            subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "etobs",
                    "sensor",
                    str(spec),
                    "--node",
                    str(i),
                    "--epoch",
                    "-",
                    "--state",
                    str(out / f"node{i}.seq"),
                ],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                text=True,
            )
            for i in range(pb.n_nodes)
        ]
        try:
            for i, p in enumerate(procs):  # each prints "ready" once its plant samples are computed
                try:
                    line = await asyncio.wait_for(
                        asyncio.to_thread(p.stdout.readline),  # type: ignore[union-attr]
                        timeout=READY_TIMEOUT,
                    )
                except TimeoutError:
                    raise InputError(
                        f"the sensor process of node {i} was not ready after {READY_TIMEOUT:g} s "
                        "(it computes its plant's samples first)"
                    ) from None
                if line.strip() != "ready":  # it printed its error; its status comes once it has exited
                    try:
                        code = await asyncio.to_thread(p.wait, 60)
                    except subprocess.TimeoutExpired:
                        code = None
                    raise InputError(f"the sensor process of node {i} failed to start (exit {code})")
            srv.epoch = time.time() + 0.2
            for p in procs:
                p.stdin.write(f"{srv.epoch!r}\n")  # type: ignore[union-attr]
                p.stdin.flush()  # type: ignore[union-attr]
            print(
                f"etobs demo live: {pb.n_nodes} sensor processes -> UDP 127.0.0.1:{udp}, "
                f"{dep.duration:g} s of plant time at {dep.time_scale:g}x",
                file=sys.stderr,
                flush=True,
            )
            # the observer waits for the sensors' last packets (they exit after their last sample)
            snap = await srv.run_until(
                dep.duration, finished=lambda: all(p.poll() is not None for p in procs)
            )
            reports = []
            for i, p in enumerate(procs):
                stdout, _ = await asyncio.to_thread(p.communicate, timeout=60)
                lines = stdout.strip().splitlines()
                if p.returncode != 0 or not lines:
                    raise InputError(
                        f"sensor process of node {i} failed (exit {p.returncode}); its run is incomplete"
                    )
                reports.append(json.loads(lines[-1]))
            return snap, reports
        finally:
            for p in procs:
                if p.poll() is None:
                    p.kill()
                for pipe in (p.stdin, p.stdout):  # not left for the garbage collector (ResourceWarning)
                    if pipe is not None:
                        pipe.close()
            await srv.close()

    snap, reports = asyncio.run(main())
    t, y = sample_outputs(pb, list(dep.x0 or ()), dep.duration, dep.period)
    ref = replay(pb, keys, t, y, dep.period, dt=dep.dt)
    gap = float(np.max(np.abs(np.array(snap["xhat"]) - ref.xhat[-1])))
    summary = {
        "duration": dep.duration,
        "time_scale": dep.time_scale,
        "period": dep.period,
        "transmissions_live": snap["transmissions"],
        "transmissions_sensors": [r["transmissions"] for r in reports],
        "transmissions_reference": list(ref.transmissions),
        "final_xhat_live": snap["xhat"],
        "final_xhat_reference": [float(v) for v in ref.xhat[-1]],
        "final_gap": gap,
        "counts": snap["counts"],
        "gaps": snap["gaps"],
        "late": snap["late"],
        "status": snap["status"],
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1, allow_nan=False))
    tr = read_trace(out / "trace.jsonl")
    try:
        from etobs.plot import plot_trace

        fig, _ = plot_trace(tr, ref)
        fig.savefig(out / "trace.png", dpi=110)
    except ImportError:  # pragma: no cover - matplotlib is the optional extra `plot`
        pass
    print(f"transmissions per node: live {snap['transmissions']}, reference {list(ref.transmissions)}")
    print(
        f"final estimate: live {np.round(snap['xhat'], 4).tolist()}, reference "
        f"{np.round(ref.xhat[-1], 4).tolist()}, max gap {gap:.2e}"
    )
    lines = len(tr["t"])
    print(
        f"packets: {snap['counts']}; missing sequence numbers: {snap['gaps']}; applied late: "
        f"{snap['late']}; trace: {lines} lines in {out}/trace.jsonl"
    )
    same = list(ref.transmissions) == list(snap["transmissions"])
    return 0 if same else 1


def _write_spec(dep: Deployment, out: Path, port: int) -> Path:
    """The resolved spec the sensor processes read (the port is the one the service got)."""
    lines = [
        f"name = {json.dumps(dep.name)}",
        "[system]",
        f"factory = {json.dumps(dep.factory)}",
        "params = {" + ", ".join(f"{k} = {json.dumps(v)}" for k, v in dep.params.items()) + "}",
        "[runtime]",
        f"period = {dep.period!r}",
        f"duration = {dep.duration!r}",
        f"time_scale = {dep.time_scale!r}",
        'host = "127.0.0.1"',
        f"port = {port}",
        f"secret_file = {json.dumps(str(dep.secret_file.resolve()))}",
        "[plant]",
        f"x0 = {json.dumps(list(dep.x0 or ()))}",
    ]
    path = out / "deployment.toml"
    path.write_text("\n".join(lines) + "\n")
    return path
