"""Resolve a factory named in a spec: a registered example, ``module:function`` or ``file.py:function``."""

from __future__ import annotations

import importlib
import importlib.util
from collections.abc import Callable
from pathlib import Path

from etobs._spec import SpecError
from etobs.estimation.problem import EstimationProblem
from etobs.examples.robot_arm import robot_arm

#: Factories that a spec can name directly.
REGISTRY: dict[str, Callable[..., EstimationProblem]] = {"robot_arm": robot_arm}


def resolve_factory(name: str) -> Callable[..., EstimationProblem]:
    """A registered name, ``"package.module:function"`` or ``"path/to/file.py:function"``."""
    if name in REGISTRY:
        return REGISTRY[name]
    if ":" not in name:
        raise SpecError(
            f"`system.factory` = {name!r} is neither a registered example ({', '.join(REGISTRY)}) "
            "nor of the form 'package.module:function' or 'path/file.py:function'"
        )
    where, _, attr = name.rpartition(":")
    try:
        if where.endswith(".py"):
            loc = importlib.util.spec_from_file_location(Path(where).stem, where)
            if loc is None or loc.loader is None or not Path(where).exists():
                raise ImportError(f"no file {where!r}")
            module = importlib.util.module_from_spec(loc)
            loc.loader.exec_module(module)
        else:
            module = importlib.import_module(where)
    except ImportError as exc:
        raise SpecError(f"`system.factory`: cannot import {where!r}: {exc}") from exc
    fn = getattr(module, attr, None)
    if not callable(fn):
        raise SpecError(f"`system.factory`: {where!r} has no callable {attr!r}")
    return fn
