"""Small input checks shared by the configuration objects.

Each helper raises :class:`~etobs.errors.InputError` whose message names the
argument, the expectation and the received value.
"""

from __future__ import annotations

import math
import reprlib
from collections.abc import Callable
from typing import Any

import numpy as np

from etobs.errors import InputError, InputTypeError

#: How values are shown in messages: a spec value may be a 1 MiB list or a 400-digit integer.
_REPR = reprlib.Repr()
_REPR.maxlist = _REPR.maxtuple = 8
_REPR.maxstring = _REPR.maxother = 60
_REPR.maxlong = 24
_REPR.maxlevel = 3


def shown(value: Any) -> str:
    """``repr(value)``, shortened for an error message (long lists and numbers are elided)."""
    if isinstance(value, np.ndarray):
        value = value.tolist() if value.size <= 64 else f"array of shape {value.shape}"
    return _REPR.repr(value)


def real(
    name: str,
    value: Any,
    *,
    lower: float | None = None,
    upper: float | None = None,
    lower_open: bool = False,
    upper_open: bool = False,
    allow_inf: bool = False,
) -> float:
    """Return ``value`` as a float after checking it lies in the stated interval."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputTypeError(f"`{name}` must be a real number; got {shown(value)} ({type(value).__name__})")
    try:
        v = float(value)
    except OverflowError:  # an int beyond float range
        raise InputError(f"`{name}` must be a finite real number; got {shown(value)}") from None
    if math.isnan(v) or (math.isinf(v) and not allow_inf):
        raise InputError(f"`{name}` must be a finite real number; got {v}")
    if lower is not None and (v < lower or (lower_open and v == lower)):
        op = ">" if lower_open else ">="
        raise InputError(f"`{name}` must be {op} {lower:g}; got {v:g}")
    if upper is not None and (v > upper or (upper_open and v == upper)):
        op = "<" if upper_open else "<="
        raise InputError(f"`{name}` must be {op} {upper:g}; got {v:g}")
    return v


def integer(name: str, value: Any, *, lower: int | None = None, upper: int | None = None) -> int:
    """Return ``value`` as an int after checking its type and bounds."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise InputTypeError(f"`{name}` must be an integer; got {shown(value)} ({type(value).__name__})")
    v = int(value)
    if lower is not None and v < lower:
        raise InputError(f"`{name}` must be an integer >= {lower}; got {v}")
    if upper is not None and v > upper:
        raise InputError(f"`{name}` must be an integer <= {upper}; got {v}")
    return v


def flag(name: str, value: Any) -> bool:
    """Return ``value`` after checking it is ``True`` or ``False`` (not ``"false"``, not 0)."""
    if not isinstance(value, bool | np.bool_):
        raise InputTypeError(f"`{name}` must be true or false; got {shown(value)} ({type(value).__name__})")
    return bool(value)


def vector(name: str, value: Any, size: int | None = None) -> np.ndarray:
    """Return a finite float vector of the given size (read-only copy)."""
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError, OverflowError) as exc:
        raise InputTypeError(f"`{name}` must be a vector of real numbers; got {shown(value)}") from exc
    if arr.ndim == 0:
        arr = arr.reshape(1)
    if arr.ndim != 1:
        raise InputError(f"`{name}` must be a vector (1-D); got an array of shape {arr.shape}")
    if size is not None and arr.shape[0] != size:
        raise InputError(f"`{name}` must have {size} entries; got {arr.shape[0]} (shape {arr.shape})")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"`{name}` must be finite; got {arr.tolist()}")
    arr.setflags(write=False)
    return arr


def params(name: str, value: Any) -> np.ndarray:
    """A model's parameter vector: ``None`` (no parameters) or a finite vector (read-only copy)."""
    if value is None:
        out = np.zeros(0)
        out.setflags(write=False)
        return out
    return vector(name, value)


def matrix(name: str, value: Any, shape: tuple[int | None, int | None]) -> np.ndarray:
    """Return a finite float matrix, checking each known dimension of ``shape``."""
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError, OverflowError) as exc:
        raise InputTypeError(f"`{name}` must be a matrix of real numbers; got {shown(value)}") from exc
    expected = tuple("*" if s is None else s for s in shape)
    if arr.ndim != 2 or any(s is not None and s != a for s, a in zip(shape, arr.shape, strict=False)):
        raise InputError(f"`{name}` has shape {arr.shape}; expected {expected}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"`{name}` must be finite")
    arr.setflags(write=False)
    return arr


def batch(name: str, value: Any, n: int) -> np.ndarray:
    """Return a finite ``(B, n)`` float array from a vector ``(n,)`` or a batch ``(B, n)``."""
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError, OverflowError) as exc:
        raise InputTypeError(f"`{name}` must be an array of real numbers; got {shown(value)}") from exc
    if arr.ndim == 1:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != n or arr.shape[0] == 0:
        raise InputError(
            f"`{name}` has shape {np.shape(value)}; expected ({n},) for one run or (B, {n}) for B runs"
        )
    bad = ~np.all(np.isfinite(arr), axis=1)
    if bad.any():
        raise InputError(f"`{name}` must be finite; runs {np.flatnonzero(bad).tolist()} are not")
    return arr


def function(name: str, value: object) -> Callable[..., Any]:
    """Check that ``value`` is callable."""
    if not callable(value):
        raise InputTypeError(f"`{name}` must be callable; got {shown(value)} ({type(value).__name__})")
    return value


def index_tuple(name: str, value: Any, what: str = "output") -> tuple[int, ...]:
    """Return a non-empty tuple of distinct non-negative integers."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        value = (int(value),)
    try:
        items = tuple(value)
    except TypeError as exc:
        raise InputTypeError(f"`{name}` must be an int or a sequence of ints; got {shown(value)}") from exc
    if not items:
        raise InputError(f"`{name}` must name at least one {what} index; got an empty sequence")
    out = tuple(integer(f"{name}[{k}]", v, lower=0) for k, v in enumerate(items))
    if len(set(out)) != len(out):
        raise InputError(f"`{name}` must not repeat an index; got {list(out)}")
    return out
