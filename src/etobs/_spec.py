"""Specs given as data (TOML): reading them safely, validating them, and what they may call.

Shared by sweeps, comparisons, checks and deployments. Every error is a
:class:`SpecError` that names the offending key (or the file).

A spec names code: ``system.factory`` is a function that etobs imports and calls with
the spec's arguments. Only functions marked with :func:`factory` may be named, so a spec
cannot call ``subprocess:run`` or any other function that was not written to be one
(see ``docs/specs.md``). A spec must still be trusted like the code it names.
"""

from __future__ import annotations

import contextlib
import datetime
import math
import os
import re
import stat
import tomllib
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from etobs._validate import shown
from etobs.errors import InputError


class SpecError(InputError):
    """A spec is invalid; the message names the offending key."""


#: Largest spec file read, in bytes. Specs are a few kB; a limit keeps reading bounded
#: (``etobs sweep /dev/zero`` read until memory ran out).
MAX_SPEC_BYTES = 1 << 20
#: Deepest nesting of tables and arrays in a spec. The formats need 5 (a comparison's
#: ``networks[1].delay.uniform[0]``); deeper nesting reached Python's recursion limit
#: inside the TOML parser.
MAX_DEPTH = 16

#: What ``system.factory`` expects, in every format's missing-key error.
FACTORY = "a string: a registered example, 'package.module:function' or 'path/file.py:function'"
#: What a required table expects.
TABLE = "a table"

_F = TypeVar("_F", bound=Callable[..., Any])
#: The mark :func:`factory` sets; compared by identity, so no other object can fake it.
_MARK = object()


def factory(fn: _F) -> _F:
    """Mark ``fn`` as a factory that a spec may name in ``system.factory``.

    A spec can name only marked functions: ``factory = "subprocess:run"`` is refused
    without being called. Mark a function only if any keyword arguments a spec gives it
    are harmless (it builds a problem from numbers and switches).

    Parameters
    ----------
    fn : callable
        ``fn(**params) -> EstimationProblem``.

    Returns
    -------
    callable
        ``fn`` itself (marked).

    Examples
    --------
    >>> import etobs
    >>> @etobs.factory
    ... def my_problem(k=1.0):
    ...     ...
    >>> etobs._spec.is_factory(my_problem)
    True

    """
    if not callable(fn):
        raise InputError(f"@etobs.factory marks a function; got {fn!r} ({type(fn).__name__})")
    fn.__etobs_factory__ = _MARK  # type: ignore[attr-defined]
    return fn


def is_factory(obj: Any) -> bool:
    """Whether ``obj`` was marked with :func:`factory`."""
    try:
        return getattr(obj, "__etobs_factory__", None) is _MARK
    except Exception:  # an object whose attribute lookup fails is not a factory
        return False


def read_toml(path: str | Path) -> dict[str, Any]:
    """The parsed TOML file ``path``, read in bounded memory (at most :data:`MAX_SPEC_BYTES`).

    Raises :class:`SpecError` naming the file when it is missing, a directory, unreadable,
    too large, not UTF-8, not TOML or nested deeper than :data:`MAX_DEPTH`.
    """
    name = str(path)
    try:
        # O_NONBLOCK: opening a named pipe with no writer would otherwise wait for good
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
        with open(fd, "rb") as fh:
            if stat.S_ISFIFO(os.fstat(fd).st_mode) or stat.S_ISSOCK(os.fstat(fd).st_mode):
                raise SpecError(f"spec file {name!r} is a pipe or socket; expected a TOML file")
            data = fh.read(MAX_SPEC_BYTES + 1)
    except FileNotFoundError:
        raise SpecError(f"spec file {name!r} does not exist") from None
    except IsADirectoryError:
        raise SpecError(f"spec file {name!r} is a directory; expected a TOML file") from None
    except OSError as exc:
        raise SpecError(f"cannot read spec file {name!r}: {exc.strerror or exc}") from None
    if len(data) > MAX_SPEC_BYTES:
        raise SpecError(
            f"spec file {name!r} is larger than {MAX_SPEC_BYTES} bytes (1 MiB); a spec is a few kB of TOML"
        )
    return parse_toml(data, name)


def parse_toml(data: bytes, name: str) -> dict[str, Any]:
    """The TOML document ``data`` (UTF-8) of the file ``name``, checked as :func:`read_toml` does."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SpecError(
            f"spec file {name!r} is not UTF-8 text: byte {exc.start} is {data[exc.start]:#04x}"
        ) from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"spec file {name!r} is not valid TOML: {exc}") from None
    except RecursionError:
        raise SpecError(f"spec file {name!r} nests arrays or tables deeper than {MAX_DEPTH} levels") from None
    except ValueError as exc:  # e.g. an integer of more than 4300 digits
        raise SpecError(f"spec file {name!r} holds a value Python cannot read: {exc}") from None
    check_tree(raw, name)
    return raw


def check_tree(raw: Any, name: str | None = None) -> None:
    """Refuse, naming the key, what no spec key takes: deep nesting, huge integers, dates.

    That is nesting deeper than :data:`MAX_DEPTH`, integers beyond float range and TOML
    dates and times. ``name`` is the spec file, if any. Called on every spec read from a
    file and on every spec given as a dictionary, before its keys are parsed.
    """
    in_file = "" if name is None else f" in spec file {name!r}"
    stack: list[tuple[Any, str, int]] = [(raw, "", 0)]
    while stack:  # bounded: each value of the parsed document is visited once
        value, where, depth = stack.pop()
        if depth > MAX_DEPTH:
            raise SpecError(
                f"`{where}`{in_file} is nested {depth} levels deep; a spec nests at most {MAX_DEPTH}"
            )
        if isinstance(value, dict):
            stack.extend((v, f"{where}.{k}" if where else str(k), depth + 1) for k, v in value.items())
        elif isinstance(value, list | tuple):
            stack.extend((v, f"{where}[{i}]", depth + 1) for i, v in enumerate(value))
        elif isinstance(value, int) and not isinstance(value, bool):
            number(where, value)
        elif isinstance(value, datetime.date | datetime.time):
            raise SpecError(
                f"`{where}`{in_file} must be a number, string, boolean, array or table; got a date or time"
            )


#: The ``where`` of a spec's top level in :func:`keys`: its keys are written bare
#: (`horizon`, not `spec.horizon`), as in ``docs/specs.md`` and every other error.
TOP = "spec"


def keys(
    where: str, table: Any, required: Mapping[str, str] | set[str], optional: Iterable[str]
) -> dict[str, Any]:
    """``table`` after checking it is a table with the required keys and no others.

    ``where`` is the table's key path, or :data:`TOP` for the spec's top level.
    ``required`` maps each required key to what it expects (``"a number > 0"``), which a
    missing key's error states; the keys of every format are listed in ``docs/specs.md``.
    """
    top = where == TOP
    table_name = "the spec" if top else f"`{where}`"
    if not isinstance(table, dict):
        raise SpecError(f"{table_name} must be a table; got {shown(table)} ({type(table).__name__})")
    unknown = sorted(set(table) - set(required) - set(optional))
    if unknown:
        allowed = ", ".join(sorted(set(required) | set(optional)))
        of = "allowed top-level keys" if top else f"allowed keys of `{where}`"
        raise SpecError(f"unknown key `{_path(where, unknown[0])}`; {of}: {allowed}")
    missing = sorted(set(required) - set(table))
    if missing:
        expected = required.get(missing[0]) if isinstance(required, Mapping) else None
        what = f": expected {expected}" if expected else ""
        raise SpecError(f"missing key `{_path(where, missing[0])}`{what}; {table_name} has {_listed(table)}")
    return table


def _path(where: str, key: Any) -> str:
    """The key path of ``key`` in the table ``where`` (a top-level key bare)."""
    return str(key) if where == TOP else f"{where}.{key}"


def _listed(table: dict[str, Any]) -> str:
    """The keys a table has, for a missing key's error."""
    if not table:
        return "no keys"
    return "keys " + ", ".join(sorted(map(str, table))) if len(table) <= 12 else f"{len(table)} other keys"


def name(key: str, value: Any) -> str:
    """``value`` after checking it is a name: letters, digits, ``_`` or ``-`` (file and topic safe)."""
    if not isinstance(value, str) or not value or not all(c.isalnum() or c in "_-" for c in value):
        raise SpecError(
            f"`{key}` must be a non-empty name of letters, digits, '_' or '-'; got {shown(value)}"
        )
    return value


@contextlib.contextmanager
def in_file(path: str | Path) -> Iterator[None]:
    """Name the spec file ``path`` in a :class:`SpecError` raised inside, unless it names it."""
    try:
        yield
    except SpecError as exc:
        if str(path) in str(exc):
            raise
        raise SpecError(f"{path}: {exc}") from exc


def spec_path(value: str | Path, folder: str | Path | None) -> Path:
    """The absolute path of the file ``value`` a spec names, relative to the spec's ``folder``.

    A relative name is taken from the folder of the spec file (``None``: a spec given
    as a dictionary, taken from the current folder), so a spec means the same files
    whatever folder it is run from. Used for a deployment's files and for a
    ``path/file.py:function`` factory.
    """
    path = Path(value)
    if not path.is_absolute() and folder is not None:
        path = Path(folder) / path
    return Path(os.path.abspath(path))


#: The argument an etobs check names first (`` `p` must be <= 1; got 1.2 ``).
_ARGUMENT = re.compile(r"`(\w+)`")


def argument_named(message: str) -> str | None:
    """The argument an etobs check's ``message`` starts with, in backquotes (``None``: none)."""
    found = _ARGUMENT.match(message)
    return None if found is None else found[1]


def renamed(exc: Exception, keys: Mapping[str, str], where: str) -> SpecError:
    """``exc`` (a check of a class etobs builds from a spec) naming the spec key, not the argument.

    ``keys`` maps the class's arguments to the spec keys that gave them
    (``{"p": "networks[1].loss"}``): `` `p` must be <= 1`` becomes
    `` `networks[1].loss` must be <= 1``. A message about another argument is prefixed
    with ``where``, the table the class was built from.
    """
    text = str(exc)
    arg = argument_named(text)
    if arg in keys:
        return SpecError(f"`{keys[arg]}`{text[len(arg) + 2 :]}")
    return SpecError(f"`{where}`: {text}")


def number(
    key: str, value: Any, *, lower: float | None = None, integer: bool = False, strict: bool = False
) -> float:
    """``value`` after checking it is a finite number (an integer if asked) above ``lower``."""
    if isinstance(value, np.generic):
        value = value.item()
    ok = isinstance(value, int) if integer else isinstance(value, (int, float))
    if isinstance(value, bool) or not ok:
        kind = "an integer" if integer else "a number"
        raise SpecError(f"`{key}` must be {kind}; got {shown(value)}")
    if isinstance(value, int) and abs(value) > _FLOAT_MAX:  # 10**400 has no float (nor isfinite)
        digits = math.floor(value.bit_length() * math.log10(2)) + 1
        raise SpecError(f"`{key}` must lie within +-1.8e308; got an integer of about {digits} digits")
    if not math.isfinite(value):
        raise SpecError(f"`{key}` must be finite; got {value!r}")
    if lower is not None and (value < lower or (strict and value == lower)):
        raise SpecError(f"`{key}` must be {'>' if strict else '>='} {lower:g}; got {value!r}")
    return value


_FLOAT_MAX = int(np.finfo(float).max)
