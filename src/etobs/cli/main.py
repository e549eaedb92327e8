"""The ``etobs`` command line."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from etobs import __version__
from etobs.cli import check, compare, demo, runtime, sweep
from etobs.errors import EtobsError


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``etobs`` command."""
    parser = argparse.ArgumentParser(
        prog="etobs", description="Decentralized event-triggered state estimation of nonlinear systems."
    )
    parser.add_argument("--version", action="version", version=f"etobs {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    demo.add_parser(sub)
    sweep.add_parsers(sub)
    check.add_parser(sub)
    compare.add_parser(sub)
    runtime.add_parsers(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point: parse ``argv`` and run the chosen command."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except EtobsError as exc:  # bad input or an unsolvable design: one clear line, no traceback
        parser.exit(2, f"etobs: error: {exc}\n")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
