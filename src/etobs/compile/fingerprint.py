"""A content hash of a Python function and of everything numba freezes into its code.

numba compiles a function's globals and closure variables as constants, and calls the
functions it refers to. Two functions with the same fingerprint therefore compile to
the same machine code: the hash covers the bytecode and constants of the function and
of its nested code, its defaults, the values of its closure cells and of the globals
its code names (arrays by dtype, shape and bytes; numbers by ``repr``), its default and
keyword-only default values, and, through
them, every Python or numba function it calls. Modules count by name, and modules of
the user's own files (outside the interpreter's prefix) also by the size and
modification time of their file, since numba freezes module attributes too.
"""

from __future__ import annotations

import hashlib
import sys
import types
from pathlib import Path
from typing import Any

import numpy as np

_PREFIXES = tuple(str(Path(p).resolve()) for p in {sys.prefix, sys.base_prefix, sys.exec_prefix})


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


def _feed(h: Any, obj: Any, seen: set[int]) -> None:
    py = getattr(obj, "py_func", None)  # a numba dispatcher: what it compiles
    if py is not None:
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
        for cell in obj.__closure__ or ():
            _feed(h, cell.cell_contents, seen)
        builtins = vars(__builtins__) if isinstance(__builtins__, types.ModuleType) else __builtins__
        for name in sorted(_names(obj.__code__)):
            h.update(name.encode())
            if name in obj.__globals__:
                _feed(h, obj.__globals__[name], seen)
            elif name in builtins:
                h.update(b"builtin")
        return
    if isinstance(obj, types.ModuleType):
        h.update(f"module {obj.__name__}".encode())
        file = getattr(obj, "__file__", None)
        if file and not str(Path(file).resolve()).startswith(_PREFIXES):
            try:
                st = Path(file).stat()
                h.update(f"{st.st_size} {st.st_mtime_ns}".encode())
            except OSError:
                pass
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
    h.update(f"{type(obj).__module__}.{type(obj).__qualname__} {obj!r}".encode())
