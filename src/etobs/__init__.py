"""etobs: decentralized event-triggered state estimation of nonlinear systems.

The public API re-exports the model objects, the estimation front door
:func:`simulate` and its metrics, and the solver settings. Plotting lives in
:mod:`etobs.plot` (optional extra) and is not imported here.

Every public name is written once, in ``etobs/__init__.pyi`` (what a type checker reads
as the package's interface): this module reads that file and imports each name on its
first use (PEP 562), so that ``import etobs.runtime.sensor`` on a small device needs
neither numpy nor scipy.
"""

from __future__ import annotations

import ast
import importlib
import importlib.resources
from functools import cache
from typing import Any

from etobs._version import __version__ as __version__
from etobs.errors import EtobsError as EtobsError
from etobs.errors import InputError as InputError
from etobs.errors import InputTypeError as InputTypeError
from etobs.errors import ModelError as ModelError

#: Subpackages reachable as attributes (``etobs.model``), imported on first use.
_SUBPACKAGES = frozenset(
    {"cli", "design", "estimation", "examples", "experiments", "hybrid", "model", "plot", "runtime", "tuning"}
)


@cache
def _exports() -> dict[str, str]:
    """Public name -> the module that defines it, read from ``__init__.pyi``.

    Read as package data (``importlib.resources``), so that etobs imported from a zip
    reads it too; a bundle made without it is told so.
    """
    try:
        text = importlib.resources.files(__name__).joinpath("__init__.pyi").read_text(encoding="utf-8")
    except OSError as exc:
        raise ImportError(
            "etobs lists its public names in etobs/__init__.pyi, which this installation lacks "
            "(a bundler that drops .pyi files: include it as package data)"
        ) from exc
    tree = ast.parse(text)
    return {
        alias.asname or alias.name: node.module
        for node in tree.body
        if isinstance(node, ast.ImportFrom) and node.module
        for alias in node.names
    }


def __getattr__(name: str) -> Any:
    if name == "__all__":
        return sorted(_exports())
    if name in _SUBPACKAGES:
        return importlib.import_module(f"etobs.{name}")
    module = _exports().get(name)
    if module is None:
        raise AttributeError(f"module 'etobs' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_exports()})
