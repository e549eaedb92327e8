"""The ``etobs`` command line."""

from __future__ import annotations

import argparse
import os
import sys
import traceback
from collections.abc import Sequence
from typing import NoReturn

from etobs._spec import SpecError
from etobs._version import __version__
from etobs.cli import check, codegen, compare, demo, runtime, sweep, tune
from etobs.errors import EtobsError, debug


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (the usage is one ``--help`` away)."""

    def error(self, message: str) -> NoReturn:
        """Print ``PROG: error: MESSAGE`` on one line and exit with status 2."""
        self.exit(2, f"{self.prog}: error: {_one_line(message)} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``etobs`` command (its sub-parsers are of the same class)."""
    parser = _Parser(
        prog="etobs", description="Decentralized event-triggered state estimation of nonlinear systems."
    )
    parser.add_argument("--version", action="version", version=f"etobs {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    demo.add_parser(sub)
    sweep.add_parsers(sub)
    check.add_parser(sub)
    compare.add_parser(sub)
    codegen.add_parser(sub)
    tune.add_parser(sub)
    runtime.add_parsers(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point: parse ``argv`` and run the chosen command.

    Bad input never ends in a traceback: an :class:`~etobs.errors.EtobsError` (bad input
    or an unsolvable design) or an :class:`OSError` (a file or folder that cannot be
    read or written, an address in use) is one line on stderr and exit status 2; a spec
    error names the spec file. With ``ETOBS_DEBUG=1`` an ``EtobsError``'s traceback and
    its cause (numba's, say) come first. Ctrl-C is one line and exit status 130; a closed pipe on
    stdout (``etobs ... | head``) ends quietly with status 141, as a shell reports it.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code = int(args.func(args))
        sys.stdout.flush()  # inside the try: a reader that left is seen here, not at exit
        return code
    except EtobsError as exc:
        if debug():  # ETOBS_DEBUG=1: the whole chain (numba's, say) above the one line
            traceback.print_exception(exc, file=sys.stderr)
        parser.exit(2, f"etobs: error: {_one_line(_in_spec(args, exc))}\n")
    except BrokenPipeError:  # `etobs ... | head`: the reader left; end quietly, as a shell would
        _silence_stdout()
        return 141
    except OSError as exc:
        where = f"{exc.filename}: " if exc.filename is not None else ""
        parser.exit(
            2, f"etobs: error: {_one_line(where + (exc.strerror or str(exc) or type(exc).__name__))}\n"
        )
    except KeyboardInterrupt:  # Ctrl-C: what is stored stays (a rerun resumes), no traceback
        parser.exit(130, "etobs: interrupted\n")


def _silence_stdout() -> None:
    """Point stdout at /dev/null so that the interpreter's final flush does not fail again."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)


def _in_spec(args: argparse.Namespace, exc: EtobsError) -> str:
    """The message of ``exc``, prefixed by the spec file for a spec error that does not name it."""
    spec = getattr(args, "spec", None)
    text = str(exc)
    if isinstance(exc, SpecError) and spec is not None and str(spec) not in text:
        return f"{spec}: {text}"
    return text


def _one_line(text: str) -> str:
    """``text`` with line breaks and other control characters escaped (a spec key may hold them)."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
