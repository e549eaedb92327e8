"""``etobs demo robot-arm``: the paper's case study, figures and a summary."""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from etobs._version import __version__
from etobs.cli._args import BACKEND_HELP, backend, folder, positive_float
from etobs.errors import InputError
from etobs.estimation import (
    max_estimation_error,
    min_inter_event_time,
    simulate,
    transmission_counts,
)
from etobs.examples import X0_PAPER, robot_arm
from etobs.experiments.common import MAX_GRID_POINTS
from etobs.hybrid import SaveAt, SolverOptions
from etobs.hybrid.options import step_grid

#: The paper's measured minimum inter-event times (section 8), sensor 1 and sensor 2.
PAPER_MIN_INTER_EVENT = (0.201, 0.112)
#: Spacing of the grid on which max |x - xhat| is taken.
GRID_STEP = 1e-3


def _floats(text: str, what: str, example: str) -> list[float]:
    n = example.count(",") + 1
    parts = [p for p in text.replace(" ", "").split(",") if p]
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        vals = []
    if len(vals) != n or not all(np.isfinite(vals)):
        raise argparse.ArgumentTypeError(
            f"{what} must be {n} comma-separated finite numbers (e.g. {example}); got {text!r}"
        )
    return vals


def add_parser(sub: Any) -> None:
    """Register ``demo robot-arm`` on the CLI's sub-parsers."""
    demo = sub.add_parser("demo", help="run a built-in case study")
    cases = demo.add_subparsers(dest="case", required=True, metavar="CASE")
    p = cases.add_parser(
        "robot-arm",
        help="the paper's flexible-joint robot arm (section 8)",
        description="Simulate the paper's robot-arm case study and write its three figures and summary.json.",
    )
    p.add_argument("--out", type=folder, default=Path("robot-arm-out"), help="output folder")
    p.add_argument(
        "--x0",
        type=lambda s: _floats(s, "--x0", "3,2,3,-2"),
        default=list(X0_PAPER),
        help="plant initial state x1,x2,x3,x4 (default 3,2,3,-2)",
    )
    p.add_argument("--t-end", type=positive_float, default=30.0, help="horizon in seconds (default 30)")
    p.add_argument(
        "--window",
        type=lambda s: _floats(s, "--window", "20,30"),
        default=[20.0, 30.0],
        help="window of the max |x - xhat| metric (default 20,30)",
    )
    p.add_argument("--no-noise", action="store_true", help="drop the measurement noise m")
    p.add_argument("--no-disturbance", action="store_true", help="drop the disturbance v")
    p.add_argument(
        "--backend",
        type=backend,
        default="auto",
        help=f"solver: {BACKEND_HELP} (default auto)",
    )
    p.add_argument("--rtol", type=positive_float, default=1e-10, help="relative and absolute tolerance")
    p.add_argument("--no-plots", action="store_true", help="write summary.json only")
    p.set_defaults(func=run_robot_arm)
    from etobs.cli.runtime import add_demo

    add_demo(cases)


def _atomic_write(path: Path, data: bytes) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def run_robot_arm(args: argparse.Namespace) -> int:
    """Run the case study; return the exit code (non-zero when the run failed)."""
    if args.t_end / GRID_STEP > MAX_GRID_POINTS:  # the grid is built whole, before the run
        raise InputError(
            f"--t-end {args.t_end:g} s is too long for the {GRID_STEP:g}-s error grid (at most "
            f"{MAX_GRID_POINTS:.0e} points): use --t-end <= {MAX_GRID_POINTS * GRID_STEP:g}"
        )
    lo, hi = args.window
    if lo > hi:
        raise InputError(f"--window {lo:g},{hi:g}: its start lies after its end")
    problem = robot_arm(noise=not args.no_noise, disturbance=not args.no_disturbance)
    grid = step_grid(0.0, args.t_end, GRID_STEP)
    options = SolverOptions(rtol=args.rtol, atol=args.rtol)
    result = simulate(
        problem,
        args.x0,
        args.t_end,
        options=options,
        save=SaveAt(steps=True, grid=grid),
        backend=args.backend,
    )
    in_window = lo <= args.t_end
    err = float(max_estimation_error(result, (lo, min(hi, args.t_end)))[0]) if in_window else None
    counts = transmission_counts(result)[0]
    mins = min_inter_event_time(result)[0]
    summary = {
        "status": result.status_labels()[0],
        "message": result.messages()[0],
        "t_end": args.t_end,
        "x0": list(map(float, args.x0)),
        "transmissions": [int(c) for c in counts],
        "min_inter_event_time": [None if np.isnan(m) else float(m) for m in mins],
        "max_error_window": err,
        "window": [lo, hi],
        "error_grid_step": GRID_STEP,
        "noise": not args.no_noise,
        "disturbance": not args.no_disturbance,
        "backend": result.backend,
        "backend_reason": result.backend_reason,
        "rtol": args.rtol,
        "paper": {"min_inter_event_time": list(PAPER_MIN_INTER_EVENT)},
        "versions": {"etobs": __version__, "numpy": np.__version__, "python": platform.python_version()},
    }
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    _atomic_write(out / "summary.json", (json.dumps(summary, indent=2) + "\n").encode())
    written = ["summary.json"]
    if not args.no_plots:
        written += _write_figures(result, out)
    print(_table(summary))
    print(f"wrote {', '.join(written)} to {out}/")
    return 0 if summary["status"] == "completed" else 1


def _write_figures(result: Any, out: Path) -> list[str]:
    from etobs.plot import plot_error, plot_inter_event_times, plot_states

    names = []
    for name, (fig, _) in (
        ("states.png", plot_states(result)),
        ("error.png", plot_error(result)),
        ("inter_event_times.png", plot_inter_event_times(result)),
    ):
        tmp = out / f".{name}.tmp.png"
        fig.savefig(tmp, dpi=120)
        os.replace(tmp, out / name)
        names.append(name)
    return names


def _table(s: dict[str, Any]) -> str:
    def fmt(x: float | None, spec: str = ".4f") -> str:
        return "n/a" if x is None else format(x, spec)

    lines = [
        f"robot arm, x0 = {s['x0']}, t in [0, {s['t_end']:g}], status: {s['status']} "
        f"({s['backend']} backend)",
        f"{'':28}{'sensor 1':>12}{'sensor 2':>12}",
        f"{'transmissions':28}{s['transmissions'][0]:>12d}{s['transmissions'][1]:>12d}",
        f"{'min inter-event time [s]':28}" + "".join(f"{fmt(m):>12}" for m in s["min_inter_event_time"]),
        f"{'  paper':28}" + "".join(f"{m:>12.3f}" for m in s["paper"]["min_inter_event_time"]),
        f"max |x - xhat| on [{s['window'][0]:g}, {s['window'][1]:g}]: {fmt(s['max_error_window'], '.4g')}",
    ]
    return "\n".join(lines)
