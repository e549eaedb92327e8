"""Building the compiled backend's templates, with an on-disk cache of their machine code.

The compiled kernel (:mod:`etobs.hybrid._kernel`) and the compiled estimation model
(:mod:`etobs.estimation.compiled`) are templates: Python text whose globals are the
user's numba functions and some constants, so that numba inlines them. Compiling one
takes about ten seconds.

numba can keep machine code on disk (``cache=True``), keyed by the path and time stamp
of the function's source file, but only for functions defined in a real file. So when
every function a template uses can be imported again by name (it is a module-level
``@numba.njit`` function of an importable module), :func:`build` writes the filled-in
template to a file in the cache folder, named by a hash of its text, of the files of
the modules it imports functions from, and of the numba and Python versions, and
imports it with ``cache=True``: the next process (a sweep worker, a second run of a
script) loads the machine code instead of compiling. Otherwise (functions defined in
``__main__``, in a closure or a notebook) the template is compiled in memory as before.

The cache folder is ``$ETOBS_CACHE_DIR`` if set (``off`` disables the cache), else
``$XDG_CACHE_HOME/etobs/kernels`` or ``~/.cache/etobs/kernels``. Deleting it is
always safe.

Limitation (numba's own): a change to a module that the user's compiled functions read
constants from, other than the module that defines them, is not seen; the defining
module's text is part of the hash.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import os
import sys
import threading
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

ENV = "ETOBS_CACHE_DIR"
#: Prefix of the names under which generated modules are registered in ``sys.modules``.
GENERATED = "_etobs_generated_"
_OFF = {"", "0", "off", "none", "false", "no"}
_LOCK = threading.RLock()  # a generated module may import another while loading
_WARNED: list[str] = []


def cache_dir() -> Path | None:
    """The folder of generated modules and their machine code, or ``None`` when disabled."""
    raw = os.environ.get(ENV)
    if raw is not None:
        if raw.strip().lower() in _OFF:
            return None
        return Path(raw).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg).expanduser() if xdg else Path.home() / ".cache"
    return base / "etobs" / "kernels"


def reference(fn: Any) -> str | None:
    """``"module:qualname"`` under which the compiled function ``fn`` can be imported again.

    Functions of generated modules are referred to by their file (``"/path.py:name"``).
    Returns ``None`` for functions that cannot be found by name (``__main__``, closures,
    lambdas, replaced module attributes).
    """
    py = getattr(fn, "py_func", None)
    if py is None:
        return None
    mod_name, qual = py.__module__, py.__qualname__
    if mod_name == "__main__" or "<" in qual:
        return None
    module = sys.modules.get(mod_name)
    file = getattr(module, "__file__", None)
    if module is None or not file:
        return None
    obj: Any = module
    for part in qual.split("."):
        obj = getattr(obj, part, None)
    if obj is not fn:
        return None
    return f"{file}:{qual}" if mod_name.startswith(GENERATED) else f"{mod_name}:{qual}"


def resolve(ref: str) -> Any:
    """The object a :func:`reference` names (imports its module)."""
    where, _, qual = ref.rpartition(":")
    module = _load_file(Path(where)) if where.endswith(".py") else importlib.import_module(where)
    obj: Any = module
    for part in qual.split("."):
        obj = getattr(obj, part)
    return obj


def build(
    kind: str,
    template: Path,
    constants: Mapping[str, Any],
    functions: Mapping[str, Any],
    decorators: Mapping[str, Mapping[str, Any]],
    depends: tuple[Path, ...] = (),
    inline: bool = False,
) -> Mapping[str, Any]:
    """Run ``template`` with ``constants``, ``functions`` and numba ``decorators`` as globals.

    Parameters
    ----------
    kind : str
        Short name of the template (part of the generated file's name).
    template : Path
        The template's text.
    constants : mapping
        Globals of type bool, int, float or float64/int64 ndarray, written into the module as literals.
    functions : mapping
        Globals that are numba-compiled functions.
    decorators : mapping
        Globals that are ``numba.njit(**kwargs)`` decorators, by their keyword arguments.
    depends : tuple of Path
        Files whose text the compiled code depends on besides the template (their text
        is part of the cache key).
    inline : bool
        Inline ``functions`` into the template's functions at numba's IR level (their
        Python code is compiled again as ``numba.njit(inline="always")``); the original
        compiled function stays available as ``<name>_call``. A call to a separately
        compiled function costs several nanoseconds; for functions called hundreds of
        thousands of times per run, that is most of their cost. Every call site of an
        inlined function gets a copy of its code, so keep their number small.

    Returns
    -------
    mapping
        The globals of the executed template.

    """
    job = _Template(kind, template, constants, functions, decorators, depends, inline)
    folder = cache_dir()
    if folder is not None and all(reference(fn) for fn in functions.values()):
        try:
            return _generate(job, folder)
        except OSError as exc:
            _warn_once(f"etobs: cannot use the compile cache in {folder} ({exc}); compiling in memory")
    return _generate(job, None)


@dataclass(frozen=True)
class _Template:
    """The arguments of :func:`build`."""

    kind: str
    template: Path
    constants: Mapping[str, Any]
    functions: Mapping[str, Any]
    decorators: Mapping[str, Mapping[str, Any]]
    depends: tuple[Path, ...]
    inline: bool


def _generate(job: _Template, folder: Path | None) -> Mapping[str, Any]:
    """Run ``job`` with the cache in ``folder``, or in memory when ``folder`` is None."""
    import numba

    kind, template, constants, functions = job.kind, job.template, job.constants, job.functions
    decorators, depends, inline = job.decorators, job.depends, job.inline
    cached = folder is not None
    lines = [f"# generated by etobs from {template.name}; do not edit", "import numba", "import numpy"]
    for name, value in constants.items():
        lines.append(f"{name} = {_literal(name, value)}")
    refs = {name: reference(fn) for name, fn in functions.items()}
    if cached:
        lines.append("from etobs.hybrid._jitcache import resolve as _resolve")
        lines += [f"{name} = _resolve({ref!r})" for name, ref in refs.items()]
    if not inline:
        lines += [f"{name}_call = {name}" for name in functions]
    if inline:
        for name in functions:
            lines.append(f"{name}_call = {name}")
            lines.append(f"{name} = numba.njit(inline='always')({name}.py_func)")
    for name, kwargs in decorators.items():
        args = ", ".join(f"{k}={v!r}" for k, v in {**kwargs, "cache": cached}.items())
        lines.append(f"{name} = numba.njit({args})")
    source = "\n".join(lines) + "\n\n" + template.read_text(encoding="utf-8")
    if folder is not None:
        key = hashlib.sha256(source.encode())
        for ref in refs.values():
            assert ref is not None
            key.update(_file_bytes(ref))
        for path in depends:
            key.update(path.read_bytes())
        key.update(f"{numba.__version__} {sys.version}".encode())
        path = folder / f"{kind}_{key.hexdigest()[:24]}.py"
        _write_once(path, source)
        return vars(_load_file(path))
    namespace: dict[str, Any] = {"__name__": f"etobs._template_{kind}", **functions}
    exec(compile(source, str(template), "exec"), namespace)
    return namespace


def _literal(name: str, value: Any) -> str:
    """Python text that evaluates to ``value`` exactly (floats by ``repr``)."""
    if isinstance(value, bool | np.bool_):
        return repr(bool(value))
    if isinstance(value, int | np.integer):
        return repr(int(value))
    if isinstance(value, float | np.floating):
        return _float(value)
    if isinstance(value, np.ndarray) and value.dtype == np.float64:
        flat = ", ".join(_float(x) for x in value.ravel())
        return f"numpy.array([{flat}], dtype=numpy.float64).reshape({value.shape!r})"
    if isinstance(value, np.ndarray) and value.dtype == np.int64:
        flat = ", ".join(repr(int(x)) for x in value.ravel())
        return f"numpy.array([{flat}], dtype=numpy.int64).reshape({value.shape!r})"
    raise TypeError(
        f"constant {name!r} must be a bool, int, float or a float64 or int64 array; "
        f"got {type(value).__name__}"
    )


def _float(x: Any) -> str:
    text = repr(float(x))
    return text if np.isfinite(x) else f"float({text!r})"


def _file_bytes(ref: str) -> bytes:
    """Text of the file that defines the function ``ref`` names."""
    where = ref.rpartition(":")[0]
    if where.endswith(".py"):
        return where.encode()  # a generated file: its name is the hash of its text
    file = getattr(sys.modules[where], "__file__", None) or ""
    return Path(file).read_bytes() if file else where.encode()


def _write_once(path: Path, source: str) -> None:
    """Create ``path`` with ``source`` unless it exists; never rewrite it.

    numba's cache is keyed by the file's time stamp, so an existing file is left alone;
    concurrent writers each write a private file and link it into place.
    """
    if path.exists():
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    tmp.write_text(source, encoding="utf-8")
    try:
        os.link(tmp, path)
    except FileExistsError:
        pass
    except OSError:
        if not path.exists():
            os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _load_file(path: Path) -> ModuleType:
    """Import a generated module file once per process."""
    name = GENERATED + path.stem
    with _LOCK:
        module = sys.modules.get(name)
        if module is not None:
            return module
        spec = importlib.util.spec_from_file_location(name, path)
        if spec is None or spec.loader is None:
            raise OSError(f"cannot import {path}")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        try:
            spec.loader.exec_module(module)
        except BaseException:
            del sys.modules[name]
            raise
        return module


def _warn_once(message: str) -> None:
    if message not in _WARNED:
        _WARNED.append(message)
        warnings.warn(message, RuntimeWarning, stacklevel=3)
