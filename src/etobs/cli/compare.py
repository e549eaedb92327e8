"""``etobs compare SPEC``: several triggering rules (and networks) side by side.

Runs through the same pipeline as ``etobs sweep`` (executors, chunk store, resume).
Writes into ``--out``: ``comparison.md`` (the table), ``comparison.json`` (every run's
figures), ``runs.csv`` and ``aggregate.csv`` (tidy: one line per run, and statistics per
entry; each with a typed ``.parquet`` twin), ``tradeoff.png`` (transmissions against
error), ``spec.json`` and ``chunks/`` (each chunk of runs as soon as it finishes; a rerun
with the same spec and folder computes only what is missing).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from etobs._progress import progress_write
from etobs.cli._args import execution, execution_args, folder, load_toml
from etobs.experiments.compare import Comparison, EntryResult, compare
from etobs.experiments.compare_spec import CompareSpec, parse_compare_spec
from etobs.experiments.store import atomic_write
from etobs.experiments.tables import not_completed

PACKAGED = {"robot_arm": "robot_arm_compare.toml", "robot_arm_sampled": "robot_arm_sampled.toml"}


def add_parser(sub: Any) -> None:
    """Register ``etobs compare``."""
    p = sub.add_parser(
        "compare",
        help="compare triggering rules and network settings on the same initial states",
        description="Run every rule of SPEC on every network of SPEC; write a Markdown table, "
        "JSON figures and a trade-off plot. Rerunning with the same --out resumes.",
    )
    p.add_argument("spec", metavar="SPEC", help=f"TOML file, or a packaged spec: {', '.join(PACKAGED)}")
    p.add_argument(
        "--out", type=folder, default=Path("compare-out"), help="output folder (default compare-out)"
    )
    p.add_argument("--no-plot", action="store_true", help="skip tradeoff.png")
    execution_args(p)
    p.set_defaults(func=run)


def load(name: str) -> CompareSpec:
    """A packaged spec by name, or a TOML file (a relative factory file is taken from its folder)."""
    folder = None if name in PACKAGED else Path(name).resolve().parent
    return parse_compare_spec(load_toml(name, PACKAGED, "etobs.experiments"), folder=folder)


def run(args: argparse.Namespace) -> int:
    """Run the comparison, persisting each chunk as it finishes; print the table."""
    spec, how = execution(load(args.spec), args)
    row = {(r.name, n.name): k + 1 for k, (r, n) in enumerate(spec.entries)}

    def report(e: EntryResult) -> None:  # [row of the table / rows]
        ok = sum(s == "completed" for s in e.status)
        others = f" ({not_completed(e.status)})" if ok < len(e.status) else ""
        progress_write(
            f"[{row[(e.rule, e.network)]}/{spec.n_groups}] {e.rule} / {e.network}: "
            f"{ok}/{spec.initial_states.runs} runs completed{others} "
            f"in {e.seconds:.1f} s ({e.backend})"
        )

    result = compare(spec, args.out, on_entry=report, **how)
    if result.reused:
        print(
            f"reused {result.reused} of {spec.n_runs} runs finished earlier in {result.out}/chunks",
            file=sys.stderr,
        )
    if result.other_chunks:
        print(
            f"{result.other_chunks} chunk files in {result.out}/chunks belong to another spec or etobs "
            "version and were not used",
            file=sys.stderr,
        )
    _write(result, plot=not args.no_plot)
    print(result.markdown())
    files = "comparison.md, comparison.json, runs.csv/.parquet, aggregate.csv/.parquet"
    files += "" if args.no_plot else ", tradeoff.png"
    print(f"written to {result.out}/: {files}")
    return 0 if result.complete else 1


def _write(result: Comparison, *, plot: bool) -> None:
    out = result.out
    atomic_write(out / "comparison.md", f"# {result.spec.name}\n\n" + result.markdown())
    atomic_write(out / "comparison.json", json.dumps(result.to_json(), indent=1))
    if plot:
        from etobs.plot import plot_tradeoff

        fig, _ = plot_tradeoff(result)
        tmp = out / ".tradeoff.tmp.png"
        fig.savefig(tmp, dpi=120)
        tmp.replace(out / "tradeoff.png")
