"""``etobs check SPEC``: the certificate of a design (which conditions hold, what is guaranteed).

The spec is a TOML file (or the name of a packaged one, ``robot_arm``)::

    [system]                 # the event-triggered problem: its rules are certified
    factory = "robot_arm"    # registered example or "module:function" / "file.py:function"
    params = { sigma = [600.0, 800.0], eps = [10.0, 10.0] }

    [observer]               # where the ISS gains come from (optional)
    structure = "robot_arm"  # A, C and the slope vertices of a registered example, or
    # A = [[...]], C = [[...]], G = [[...]], H = [[...]], slopes = [[-3.3, 3.3]]
    L = "paper"              # "paper" (the example's printed gain), "design", or a matrix
    # P = [[...]]            # optional, with a given L: the Lyapunov matrix of your design
    # (ObserverGain.P), symmetric positive definite, shape (n_x, n_x); it is only re-checked.
    # Without it check_gain finds a P for L, which gives other gains and bounds than yours;
    # the report says which P it used and how it was found.
    c_v = 0.1                # split constants of the ISS gains (section 8)
    c = [0.1, 0.1]
    # E_v = [[...]]          # optional: how v enters the plant, x' = ... + E_v v, shape (n_x, n_v);
    # default the matrix read from the plant's f_p (the identity for the robot arm)

    [guarantees]             # optional
    E = [10.0, 25.0]         # bound on |dh_i/dx f_p|: a number or one per node; or
    # E_estimate = { low = [0, 0, 0, 0], high = [20, 10, 20, 10], runs = 20, margin = 1.2 }
    # (the largest rate seen on seeded runs in that box and from its corners, times the
    # margin: a lower estimate, which the certificate names as such; also t_end = 30.0,
    # seed = 0; runs x (t_end / 0.01 + 1) is limited to 5e6 grid points)
    noise = [0.0, 0.01]      # bounds m_i of the measurement noise (section 7.2)
    disturbance = 0.0283     # bound on |v(t)| for the error bound (default: sup |v(t)| of the
    # system's v when it is a constant or a sinusoid); needs [observer], as a_U does
    a_U = 0.15               # rate asked of Theorem 2 (default: 0.9 x the largest admissible)
    d = [3000.0, 8000.0]     # d_i of U (default 2 d_i*)

Exit status 0 when every condition holds, 1 when one fails (the report names it), 2 on
bad input.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from etobs.cli._args import load_toml
from etobs.examples.registry import located
from etobs.experiments.check_spec import certificate_of, check_problem

PACKAGED = {"robot_arm": "robot_arm_check.toml"}


def add_parser(sub: Any) -> None:
    """Register ``etobs check``."""
    p = sub.add_parser("check", help="certificate of a design: the theorems' conditions and guarantees")
    p.add_argument("spec", metavar="SPEC", help=f"TOML file, or a packaged spec: {', '.join(PACKAGED)}")
    p.add_argument("--json", action="store_true", help="print the certificate as JSON")
    p.add_argument(
        "--cost",
        action="store_true",
        help="print what the model costs on the engine: each function's time per call, slow ones named",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Build the problem and the ISS gains of the spec, certify, print; 1 if a condition fails."""
    # a relative factory file is taken from the spec's folder, as in every format
    raw = located(_load(args.spec), None if args.spec in PACKAGED else Path(args.spec).resolve().parent)
    if args.cost:  # etobs.estimation.model_cost: the model alone, no certificate
        from etobs.estimation.cost import model_cost

        print(model_cost(check_problem(raw)[1]))
        return 0
    cert = certificate_of(raw).certificate
    print(cert.to_json() if args.json else cert.format())
    if not cert.ok and not args.json:
        for c in cert.failures():
            where = "" if c.node is None else f"node {c.node}: "
            print(f"etobs: condition failed: {where}{c.name} ({c.detail})", file=sys.stderr)
    return 0 if cert.ok else 1


def _load(name: str) -> dict[str, Any]:
    return load_toml(name, PACKAGED, "etobs.design")
