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


#: ``--backend`` choices, as :func:`~etobs.estimation.simulate.simulate` takes them.
BACKEND_CHOICES = ("auto", "engine", "numpy", "scipy")
BACKEND_HELP = (
    "auto (the compiled engine when it models the problem, else numpy), engine, numpy "
    "(the batched numpy solver) or scipy (the solve_ivp reference); the earlier names "
    "numba and fast are accepted"
)


def backend(text: str) -> str:
    """An argparse type for ``--backend``: earlier names mapped to the current ones."""
    return {"numba": "engine", "fast": "numpy"}.get(text, text)


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
