"""Validation of specs given as data (parsed TOML): shared by sweeps, comparisons, checks and deployments.

Every error is a :class:`SpecError` that names the offending key.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from etobs.errors import InputError


class SpecError(InputError):
    """A spec is invalid; the message names the offending key."""


def keys(where: str, table: Any, required: set[str], optional: set[str]) -> dict[str, Any]:
    """``table`` after checking it is a table with the required keys and no others."""
    if not isinstance(table, dict):
        raise SpecError(f"`{where}` must be a table; got {type(table).__name__}")
    unknown = sorted(set(table) - required - optional)
    if unknown:
        allowed = ", ".join(sorted(required | optional))
        raise SpecError(f"unknown key `{where}.{unknown[0]}`; allowed keys of `{where}`: {allowed}")
    missing = sorted(required - set(table))
    if missing:
        raise SpecError(f"missing key `{where}.{missing[0]}`")
    return table


def number(
    key: str, value: Any, *, lower: float | None = None, integer: bool = False, strict: bool = False
) -> float:
    """``value`` after checking it is a finite number (an integer if asked) above ``lower``."""
    if isinstance(value, np.generic):
        value = value.item()
    ok = isinstance(value, int) if integer else isinstance(value, (int, float))
    if isinstance(value, bool) or not ok:
        kind = "an integer" if integer else "a number"
        raise SpecError(f"`{key}` must be {kind}; got {value!r}")
    if not np.isfinite(value):
        raise SpecError(f"`{key}` must be finite; got {value!r}")
    if lower is not None and (value < lower or (strict and value == lower)):
        raise SpecError(f"`{key}` must be {'>' if strict else '>='} {lower:g}; got {value!r}")
    return value
