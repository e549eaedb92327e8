"""Argument helpers shared by the commands: positive integers, TOML specs by file or name."""

from __future__ import annotations

import argparse
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any

from etobs._spec import SpecError


def positive_int(text: str) -> int:
    """An argparse type: an integer ``>= 1``."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer; got {text!r}")
    return value


BACKEND_HELP = (
    "auto (the compiled engine; the scipy reference for a rule of your own), engine or "
    "scipy (the solve_ivp reference); numba is an earlier name of engine"
)


def backend(text: str) -> str:
    """An argparse type for ``--backend`` (:func:`~etobs.hybrid.solver.check_backend`)."""
    from etobs.errors import InputError
    from etobs.hybrid.solver import check_backend

    try:
        return check_backend(text, "--backend")
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def load_toml(name: str, packaged: dict[str, str], package: str) -> dict[str, Any]:
    """The TOML spec ``name``: a packaged one (``package/data/packaged[name]``) or a file."""
    if name in packaged:
        text = resources.files(package).joinpath("data", packaged[name]).read_text()
    else:
        path = Path(name)
        if not path.is_file():
            raise SpecError(f"SPEC must be a TOML file or one of {', '.join(packaged)}; got {name!r}")
        text = path.read_text(encoding="utf-8")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"SPEC {name!r} is not valid TOML: {exc}") from exc
