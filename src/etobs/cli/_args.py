"""Argument helpers shared by the commands: positive integers, TOML specs by file or name."""

from __future__ import annotations

import argparse
import math
from importlib import resources
from pathlib import Path
from typing import Any

from etobs._spec import SpecError, parse_toml, read_toml


def positive_int(text: str) -> int:
    """An argparse type: an integer ``>= 1``."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer; got {text!r}")
    return value


def positive_float(text: str) -> float:
    """An argparse type: a finite number ``> 0`` (a time or a tolerance)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0; got {text!r}")
    return value


def folder(text: str) -> Path:
    """An argparse type: an output folder, which may not exist yet but may not be a file."""
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"must be a folder; {text!r} is a file")
    return path


BACKEND_HELP = (
    "auto (the compiled engine; the scipy reference for a rule of your own), engine or "
    "scipy (the solve_ivp reference); numba is an earlier name of engine"
)


def backend(text: str) -> str:
    """An argparse type for ``--backend`` (:func:`~etobs.hybrid.checks.check_backend`)."""
    from etobs.errors import InputError
    from etobs.hybrid.checks import check_backend

    try:
        return check_backend(text, "--backend")
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def load_toml(name: str, packaged: dict[str, str], package: str) -> dict[str, Any]:
    """The TOML spec ``name``: a packaged one (``package/data/packaged[name]``) or a file.

    A file is read in bounded memory and checked as :func:`etobs._spec.read_toml` does.
    """
    if name in packaged:
        data = resources.files(package).joinpath("data", packaged[name]).read_bytes()
        return parse_toml(data, name)
    if not Path(name).exists():
        raise SpecError(
            f"spec file {name!r} does not exist (SPEC is a TOML file or one of {', '.join(packaged)})"
        )
    return read_toml(name)


def execution_args(p: argparse.ArgumentParser) -> None:
    """The options of commands that run an experiment (``sweep``, ``reproduce``, ``compare``)."""
    from etobs.experiments.executors import EXECUTORS

    p.add_argument(
        "--executor",
        choices=EXECUTORS,
        default=None,
        help="where chunks run (default: process, or dask with --scheduler)",
    )
    p.add_argument("--workers", type=positive_int, default=None, help="local processes (default: cores)")
    p.add_argument("--scheduler", default=None, help="Dask scheduler address, e.g. tcp://10.0.0.5:8786")
    p.add_argument("--chunk-size", type=positive_int, default=None, help="runs per chunk")
    p.add_argument("--runs", type=positive_int, default=None, help="initial states (overrides the spec)")
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
        help="progress bar on stderr counting runs and failed runs (default: when stderr is a terminal)",
    )


def execution(spec: Any, args: argparse.Namespace) -> tuple[Any, dict[str, Any]]:
    """The experiment ``spec`` with the overrides of :func:`execution_args`, and how to run it."""
    from etobs.errors import InputError

    if args.runs is not None or args.seed is not None:
        spec = spec.with_runs(args.runs, args.seed)
    if args.backend is not None:
        spec = spec.with_backend(args.backend)
    executor = args.executor or ("dask" if args.scheduler else "process")
    if args.scheduler and executor != "dask":
        raise InputError(f"--scheduler needs --executor dask; got --executor {executor}")
    how = {
        "executor": executor,
        "workers": args.workers,
        "scheduler": args.scheduler,
        "chunk": args.chunk_size,
        "progress": args.progress,  # None: etobs._progress decides (stderr a terminal)
    }
    return spec, how
