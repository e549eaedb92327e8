"""``etobs compare SPEC``: several triggering rules (and networks) side by side.

Writes into ``--out``: ``comparison.md`` (the table), ``comparison.json`` (every run's
figures), ``tradeoff.png`` (transmissions against error) and ``entries/`` (each entry
as soon as it finishes; a rerun with the same spec and folder reuses them).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from etobs.cli._args import load_toml, positive_int
from etobs.experiments.compare import Comparison, EntryResult, compare, entry_key
from etobs.experiments.compare_spec import CompareSpec, parse_compare_spec
from etobs.experiments.store import atomic_write

PACKAGED = {"robot_arm": "robot_arm_compare.toml"}


def add_parser(sub: Any) -> None:
    """Register ``etobs compare``."""
    p = sub.add_parser(
        "compare",
        help="compare triggering rules and network settings on the same initial states",
        description="Run every rule of SPEC on every network of SPEC; write a Markdown table, "
        "JSON figures and a trade-off plot.",
    )
    p.add_argument("spec", metavar="SPEC", help=f"TOML file, or a packaged spec: {', '.join(PACKAGED)}")
    p.add_argument(
        "--out", type=Path, default=Path("compare-out"), help="output folder (default compare-out)"
    )
    p.add_argument("--runs", type=positive_int, default=None, help="override initial_states.runs")
    p.add_argument("--no-plot", action="store_true", help="skip tradeoff.png")
    p.set_defaults(func=run)


def load(name: str) -> CompareSpec:
    """A packaged spec by name, or a TOML file."""
    return parse_compare_spec(load_toml(name, PACKAGED, "etobs.experiments"))


def run(args: argparse.Namespace) -> int:
    """Run the comparison, persisting each entry as it finishes; print the table."""
    spec = load(args.spec).with_runs(args.runs)
    out: Path = args.out
    entries = out / "entries"
    done = _finished(spec, entries)
    total = len(spec.rules) * len(spec.networks)
    if done:
        print(f"reusing {len(done)} of {total} entries finished earlier in {entries}", file=sys.stderr)
    count = [len(done)]

    def save(key: str, e: EntryResult) -> None:
        atomic_write(entries / f"{key}.json", json.dumps(e.to_json()))
        count[0] += 1
        ok = sum(s == "completed" for s in e.status)
        print(
            f"[{count[0]}/{total}] {e.rule} / {e.network}: {ok}/{len(e.status)} runs completed "
            f"in {e.seconds:.1f} s ({e.backend})",
            file=sys.stderr,
            flush=True,
        )

    result = compare(spec, done=done, on_entry=save)
    _write(result, out, plot=not args.no_plot)
    print(result.markdown())
    print(f"written to {out}/: comparison.md, comparison.json" + ("" if args.no_plot else ", tradeoff.png"))
    return 0


def _finished(spec: CompareSpec, folder: Path) -> dict[str, EntryResult]:
    done = {}
    for network in spec.networks:
        for rule in spec.rules:
            key = entry_key(spec, rule, network)
            path = folder / f"{key}.json"
            if path.is_file():
                try:
                    done[key] = EntryResult.from_json(json.loads(path.read_text()))
                except (ValueError, KeyError, TypeError):  # a damaged file is recomputed
                    continue
    return done


def _write(result: Comparison, out: Path, *, plot: bool) -> None:
    atomic_write(out / "comparison.md", f"# {result.spec.name}\n\n" + result.markdown())
    atomic_write(out / "comparison.json", json.dumps(result.to_json(), indent=1))
    if plot:
        from etobs.plot import plot_tradeoff

        fig, _ = plot_tradeoff(result)
        tmp = out / ".tradeoff.tmp.png"
        fig.savefig(tmp, dpi=120)
        tmp.replace(out / "tradeoff.png")
