"""``etobs sweep SPEC`` and ``etobs reproduce table1``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from etobs.cli._args import BACKEND_HELP, backend, positive_int
from etobs.errors import InputError
from etobs.experiments import SweepResult, load_spec, run_sweep
from etobs.experiments.executors import EXECUTORS
from etobs.experiments.store import atomic_write
from etobs.experiments.tables import to_csv


def _execution_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--executor",
        choices=EXECUTORS,
        default=None,
        help="where chunks run (default: process, or dask with --scheduler)",
    )
    p.add_argument("--workers", type=positive_int, default=None, help="local processes (default: cores)")
    p.add_argument("--scheduler", default=None, help="Dask scheduler address, e.g. tcp://10.0.0.5:8786")
    p.add_argument("--chunk-size", type=positive_int, default=None, help="runs per chunk")
    p.add_argument("--runs", type=positive_int, default=None, help="initial states per row (overrides spec)")
    p.add_argument("--seed", type=int, default=None, help="seed of the initial states (overrides spec)")
    p.add_argument(
        "--backend",
        type=backend,
        default=None,
        help=f"solver, overriding the spec's execution.backend: {BACKEND_HELP}",
    )
    p.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="progress line on stderr (default: when stderr is a terminal)",
    )


def add_parsers(sub: Any) -> None:
    """Register ``sweep`` and ``reproduce`` on the CLI's sub-parsers."""
    p = sub.add_parser(
        "sweep",
        help="run or resume a Monte-Carlo sweep from a TOML spec",
        description="Run a sweep; rerunning with the same --out resumes it.",
    )
    p.add_argument("spec", type=Path, help="sweep spec (TOML), e.g. examples/table1.toml")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: sweep-NAME)")
    _execution_args(p)
    p.set_defaults(func=run_sweep_command)

    r = sub.add_parser("reproduce", help="reproduce a result of the paper")
    what = r.add_subparsers(dest="what", required=True, metavar="WHAT")
    t = what.add_parser("table1", help="the paper's Table 1 (13 rows x 2 scenarios x 100 runs)")
    t.add_argument("--out", type=Path, default=Path("table1-out"), help="output folder")
    _execution_args(t)
    t.set_defaults(func=run_table1_command)


def _run(spec: Any, out: Path, args: argparse.Namespace) -> SweepResult:
    if args.runs is not None or args.seed is not None:
        spec = spec.with_runs(args.runs, args.seed)
    if args.backend is not None:
        spec = spec.with_backend(args.backend)
    executor = args.executor or ("dask" if args.scheduler else "process")
    if args.scheduler and executor != "dask":
        raise InputError(f"--scheduler needs --executor dask; got --executor {executor}")
    progress = sys.stderr.isatty() if args.progress is None else args.progress
    return run_sweep(
        spec,
        out,
        executor=executor,
        workers=args.workers,
        scheduler=args.scheduler,
        chunk=args.chunk_size,
        progress=progress,
    )


def _report(result: SweepResult) -> int:
    print(
        f"{len(result.runs)} of {result.spec.n_runs} runs present ({result.computed} computed now, "
        f"{result.reused} reused); {len(result.failures)} failed chunks; results in {result.out}/"
    )
    for f in result.failures:
        last = f["error"].strip().splitlines()[-1] if f["error"].strip() else "unknown error"
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
    atomic_write(result.out / "table1.csv", to_csv([{k: ln[k] for k in COLUMNS} for ln in lines]))
    text = markdown(lines, result)
    atomic_write(result.out / "table1.md", text)
    print(text)
    return _report(result)
