"""A content hash of a Python function and of everything numba freezes into its code.

numba compiles a function's globals and closure variables as constants, and calls the
functions it refers to. Two functions with the same fingerprint therefore compile to
the same machine code: the hash covers the bytecode and constants of the function and
of its nested code, its defaults, the values of its closure cells and of the globals
its code names (arrays by dtype, shape and bytes; numbers by ``repr``), its default and
keyword-only default values, and, through
them, every Python or numba function it calls (with a numba function's options).
Modules count by name and by the values of the attributes the code may read
(``mod.CONST``: numba freezes module attributes too).
"""

from __future__ import annotations

import hashlib
import types
from typing import Any

import numpy as np


def fingerprint(fn: Any) -> str:
    """Hex digest identifying the code numba would compile for ``fn`` (see module docstring)."""
    h = hashlib.sha256()
    _feed(h, fn, set())
    return h.hexdigest()


def _names(code: types.CodeType) -> set[str]:
    """Global names read by ``code`` and by the code objects nested in it."""
    out = set(code.co_names)
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            out |= _names(const)
    return out


def _code(h: Any, code: types.CodeType) -> None:
    h.update(code.co_code)
    h.update(repr(code.co_names).encode())
    h.update(repr(code.co_varnames).encode())
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            _code(h, const)
        else:
            h.update(repr(const).encode())


def _module(h: Any, mod: types.ModuleType, names: set[str], seen: set[int], depth: int) -> None:
    """Hash a module the code reads attributes of: its name and those attributes' values.

    ``mod.CONST`` is frozen by numba like any global, so every attribute the code may
    read counts by its value.
    """
    h.update(f"module {mod.__name__}".encode())
    if id(mod) in seen or depth > 2:
        return
    seen.add(id(mod))
    for name in sorted(names):
        value = getattr(mod, name, _MISSING)
        if value is _MISSING:
            continue
        h.update(name.encode())
        if isinstance(value, types.ModuleType):
            _module(h, value, names, seen, depth + 1)
        else:
            _feed(h, value, seen)
    seen.discard(id(mod))


_MISSING = object()


def _feed(h: Any, obj: Any, seen: set[int]) -> None:
    py = getattr(obj, "py_func", None)  # a numba dispatcher: what it compiles, and how
    if py is not None:
        h.update(repr(sorted(getattr(obj, "targetoptions", {}).items())).encode())
        obj = py
    if isinstance(obj, types.FunctionType):
        h.update(b"function")
        if id(obj) in seen:  # recursion
            h.update(obj.__qualname__.encode())
            return
        seen.add(id(obj))
        _code(h, obj.__code__)
        for d in obj.__defaults__ or ():
            _feed(h, d, seen)
        for name, d in sorted((obj.__kwdefaults__ or {}).items()):
            h.update(name.encode())
            _feed(h, d, seen)
        names = _names(obj.__code__)

        def value(v: Any) -> None:
            if isinstance(v, types.ModuleType):
                _module(h, v, names, seen, 0)
            else:
                _feed(h, v, seen)

        for cell in obj.__closure__ or ():
            value(cell.cell_contents)
        builtins = vars(__builtins__) if isinstance(__builtins__, types.ModuleType) else __builtins__
        for name in sorted(names):
            h.update(name.encode())
            if name in obj.__globals__:
                value(obj.__globals__[name])
            elif name in builtins:
                h.update(b"builtin")
        return
    if isinstance(obj, types.ModuleType):
        h.update(f"module {obj.__name__}".encode())
        return
    if isinstance(obj, np.ndarray):
        h.update(f"ndarray {obj.dtype.str} {obj.shape}".encode())
        h.update(np.ascontiguousarray(obj).tobytes())
        return
    if isinstance(obj, tuple | list):
        h.update(f"{type(obj).__name__} {len(obj)}".encode())
        for item in obj:
            _feed(h, item, seen)
        return
    if type(obj).__name__ == "_ArrayFunctionDispatcher":
        # numpy's functions (np.sum, np.ravel, ...): their repr holds an address, which
        # changed the hash in every process, so their callers were never found on disk
        h.update(f"numpy function {obj.__module__}.{obj.__qualname__}".encode())
        return
    h.update(f"{type(obj).__module__}.{type(obj).__qualname__} {obj!r}".encode())
