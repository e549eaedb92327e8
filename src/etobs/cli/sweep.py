"""``etobs sweep SPEC`` and ``etobs reproduce table1``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from etobs.cli._args import execution, execution_args, folder
from etobs.experiments import SweepResult, load_spec, run_sweep
from etobs.experiments.store import atomic_write, last_line
from etobs.experiments.tables import write_table


def add_parsers(sub: Any) -> None:
    """Register ``sweep`` and ``reproduce`` on the CLI's sub-parsers."""
    p = sub.add_parser(
        "sweep",
        help="run or resume a Monte-Carlo sweep from a TOML spec",
        description="Run a sweep; rerunning with the same --out resumes it.",
    )
    p.add_argument("spec", type=Path, help="sweep spec (TOML), e.g. examples/table1.toml")
    p.add_argument("--out", type=folder, default=None, help="output folder (default: sweep-NAME)")
    execution_args(p)
    p.set_defaults(func=run_sweep_command)

    r = sub.add_parser("reproduce", help="reproduce a result of the paper")
    what = r.add_subparsers(dest="what", required=True, metavar="WHAT")
    t = what.add_parser("table1", help="the paper's Table 1 (13 rows x 2 scenarios x 100 runs)")
    t.add_argument("--out", type=folder, default=Path("table1-out"), help="output folder")
    execution_args(t)
    t.set_defaults(func=run_table1_command)


def _run(spec: Any, out: Path, args: argparse.Namespace) -> SweepResult:
    spec, how = execution(spec, args)
    return run_sweep(spec, out, **how)


def _report(result: SweepResult) -> int:
    print(
        f"{len(result.runs)} of {result.spec.n_runs} runs present ({result.computed} computed now, "
        f"{result.reused} reused); {len(result.failures)} failed chunks; results in {result.out}/"
    )
    for f in result.failures:
        last = last_line(f)
        print(f"  failed: runs {f['runs'][0]}..{f['runs'][-1]} of chunk {f['key']}: {last}", file=sys.stderr)
    return 0 if result.complete else 1


def run_sweep_command(args: argparse.Namespace) -> int:
    """``etobs sweep``."""
    spec = load_spec(args.spec)
    result = _run(spec, args.out or Path(f"sweep-{spec.name}"), args)
    print((result.out / "report.md").read_text())
    return _report(result)


def run_table1_command(args: argparse.Namespace) -> int:
    """``etobs reproduce table1``."""
    from etobs.experiments.table1 import COLUMNS, compare, markdown, table1_spec

    result = _run(table1_spec(), args.out, args)
    lines = compare(result)
    write_table(result.out, "table1", [{k: ln[k] for k in COLUMNS} for ln in lines])
    text = markdown(lines, result)
    atomic_write(result.out / "table1.md", text)
    print(text)
    return _report(result)
