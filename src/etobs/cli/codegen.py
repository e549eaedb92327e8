"""``etobs codegen c SPEC --node i --out DIR`` and ``etobs codegen vectors SPEC --node i --out FILE``.

``c`` writes node ``i`` of a deployment spec as a self-contained C99 module (its sampled
rule at ``runtime.period``, packets, HMAC-SHA256, sequence numbers through callbacks; see
the generated README.md and docs/embedded.md). ``vectors`` writes what the Python sensor
node does on the spec's simulated samples (:mod:`etobs.codegen.vectors`), for the
generated ``etobs_vectors.c`` to replay; with ``--deployment EPOCH`` signed with the
deployment's key and session, for ``etobs_host.c`` to send to ``etobs serve --epoch
EPOCH``. A rule or K-function the generator cannot write is one line naming it, exit 2.
"""

from __future__ import annotations

import argparse
import hashlib
import os
from pathlib import Path
from typing import Any

from etobs.cli._args import positive_float
from etobs.cli.runtime import PACKAGED, load

#: The vectors' key and session when none is given: public test values, not a deployment's.
VECTOR_SECRET = b"etobs conformance vectors (a public test secret)"
VECTOR_SESSION = 1.7e9


def add_parser(sub: Any) -> None:
    """Register ``etobs codegen``."""
    p = sub.add_parser(
        "codegen", help="a sensor node as C99 for microcontrollers, and its conformance vectors"
    )
    kinds = p.add_subparsers(dest="what", required=True, metavar="{c,vectors}")
    c = kinds.add_parser("c", help="write node i of SPEC as a C99 module")
    v = kinds.add_parser("vectors", help="write the Python sensor node's decisions on SPEC's samples")
    for q in (c, v):
        q.add_argument(
            "spec", metavar="SPEC", help=f"deployment TOML, or a packaged one: {', '.join(PACKAGED)}"
        )
        q.add_argument("--node", type=int, required=True, help="the node (0-based)")
    c.add_argument("--out", type=Path, required=True, help="folder to write the module into")
    c.add_argument(
        "--profile",
        choices=("float64", "float32"),
        default="float64",
        help="precision of the rule's arithmetic (float32 for single-precision FPUs); default float64",
    )
    c.set_defaults(func=run_c)
    v.add_argument("--out", type=Path, required=True, help="the vector file to write")
    v.add_argument("--duration", type=positive_float, help="seconds of samples (default runtime.duration)")
    v.add_argument(
        "--deployment",
        metavar="EPOCH",
        type=positive_float,
        help="sign with the node's key of the spec's secret and the session EPOCH (the --epoch of etobs "
        "serve), so that etobs_host.c can replay the vectors to the running service; the file then "
        "holds the node's key (written mode 600). Default: a public test key and session",
    )
    v.set_defaults(func=run_vectors)


def run_c(args: argparse.Namespace) -> int:
    """Write the module; print what was written."""
    from etobs.codegen.c_node import generate_node, write_node

    dep = load(args.spec)
    pb = dep.problem()
    spec, period = dep.node_rule(pb, args.node)
    n = len(pb.nodes[args.node].outputs)
    mod = generate_node(spec, period, node=args.node, n_values=n, profile=args.profile, name=dep.name)
    paths = write_node(mod, args.out)
    print(
        f"wrote {len(paths)} files to {args.out}/: node {args.node}, the sampled {mod.kind} rule at "
        f"T = {period:g} s, {n} value(s), profile {args.profile} (see {args.out}/README.md)"
    )
    return 0


def run_vectors(args: argparse.Namespace) -> int:
    """Simulate the spec's plant, run the Python sensor node on its samples, write the vectors."""
    from etobs.codegen.vectors import node_vectors, write_vectors
    from etobs.errors import InputError
    from etobs.runtime.packet import derive_key
    from etobs.runtime.replay import sample_outputs

    dep = load(args.spec)
    pb = dep.problem()
    spec, period = dep.node_rule(pb, args.node)
    if dep.x0 is None:
        raise InputError("the spec has no [plant] x0: the vectors need the plant's initial state")
    _, y = sample_outputs(pb, list(dep.x0), args.duration or dep.duration, period)
    if args.deployment is None:
        key, session = derive_key(hashlib.sha256(VECTOR_SECRET).digest(), args.node), VECTOR_SESSION
    else:
        key, session = derive_key(dep.secret(), args.node), args.deployment
    samples = y[:, list(pb.nodes[args.node].outputs)]
    vec = node_vectors(spec, period, node=args.node, key=key, session=session, samples=samples)
    if args.deployment is not None:  # it holds the node's key: readable by its owner only
        args.out.unlink(missing_ok=True)
        os.close(os.open(args.out, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
    write_vectors(vec, args.out)
    said = " (it holds the node's key: keep it as the secret)" if args.deployment is not None else ""
    print(
        f"wrote {args.out}: {len(vec.k)} samples, {vec.transmissions} transmissions of node {args.node}{said}"
    )
    return 0
