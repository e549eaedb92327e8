"""The factory a spec names in ``system.factory``: resolved, refused unless marked, called.

``system.factory`` is a registered example (``"robot_arm"``), ``"package.module:function"``
or ``"path/to/file.py:function"``. The function must be marked with
:func:`etobs.factory`: a spec is data, but the function it names runs with the spec's
arguments, so ``factory = "subprocess:run"`` with ``args = [...]`` would run a command.

A module or file that is not imported yet is read first, not run: unless it defines the
function with the mark, or imports it from a module that does (followed the same way), it
is refused without being imported, so a spec cannot run a module's import-time code
either. Once imported, the mark itself is checked (by identity,
:func:`etobs._spec.is_factory`). A file is run once per process (it is kept in
``sys.modules`` under a name made from its path).
"""

from __future__ import annotations

import ast
import hashlib
import importlib
import importlib.machinery
import importlib.util
import inspect
import sys
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

from etobs._spec import SpecError, is_factory, spec_path
from etobs.errors import EtobsError
from etobs.estimation.problem import EstimationProblem
from etobs.examples.robot_arm import robot_arm, robot_arm_network

#: Factories that a spec can name directly.
REGISTRY: dict[str, Callable[..., EstimationProblem]] = {
    "robot_arm": robot_arm,
    "robot_arm_network": robot_arm_network,
}

#: How many imports deep a re-exported factory is followed to where it is marked.
MAX_REEXPORTS = 8
#: Where a module is looked for, and what to write instead, when it is not found. The
#: module is not looked for in the spec's folder: a file there is named as one (and the
#: installed ``etobs`` script's ``sys.path[0]`` is its own folder, not the current one).
_NOT_ON_PATH = (
    " on Python's path (the installed `etobs` command does not look in the current folder or "
    "the spec's; `python -m etobs` looks in the current folder): for a file next to the spec write "
    "'{full}.py:<function>', or install the module or add its folder to PYTHONPATH"
)
#: The fix, in every refusal.
_FIX = "mark it with @etobs.factory if a spec may call it (a spec names code: see docs/specs.md)"


def resolve_factory(name: str) -> Callable[..., EstimationProblem]:
    """A registered name, ``"package.module:function"`` or ``"path/to/file.py:function"``.

    Raises :class:`SpecError` when the function is not marked with
    :func:`etobs.factory` (without importing its module when that can be seen from its
    source), cannot be found or cannot be imported.
    """
    if not isinstance(name, str):
        raise SpecError(f"`system.factory` must be a string; got {type(name).__name__}")
    if name in REGISTRY:
        return REGISTRY[name]
    where, _, attr = name.rpartition(":")
    if not where or not attr.isidentifier():
        raise SpecError(
            f"`system.factory` = {name!r} is neither a registered example ({', '.join(REGISTRY)}) "
            "nor of the form 'package.module:function' or 'path/file.py:function'"
        )
    module = _load_file(name, where, attr) if where.endswith(".py") else _load_module(name, where, attr)
    try:  # a module's __getattr__ runs code (e.g. a lazy import) that may fail
        fn = getattr(module, attr, None)
    except Exception as exc:
        raise SpecError(
            f"`system.factory`: looking up {attr!r} in {where!r} failed: {type(exc).__name__}: {exc}"
        ) from None
    if not callable(fn):
        raise SpecError(f"`system.factory`: {where!r} has no callable {attr!r}")
    if not is_factory(fn):
        raise SpecError(f"`system.factory` = {name!r} is not marked as a factory; {_FIX}")
    return fn


def locate_factory(name: Any, folder: str | Path | None) -> Any:
    """``name`` with a relative ``path/file.py`` made absolute from the spec's ``folder``.

    Every format calls it on ``system.factory`` as it reads a spec file, with the file's
    folder (:func:`etobs._spec.spec_path`, as a deployment's files), so a spec names the
    same file whatever folder it is run from; a same-named file in the current folder is
    not used. ``folder=None`` (a spec given as a dictionary) takes a relative path from
    the current folder when it is resolved. A registered name, a module and anything
    that is not a file factory (refused later, naming the key) are returned unchanged.
    """
    if not isinstance(name, str) or name in REGISTRY or folder is None:
        return name
    where, _, attr = name.rpartition(":")
    if not where.endswith(".py"):
        return name
    return f"{spec_path(where, folder)}:{attr}"


def located(raw: Any, folder: str | Path | None) -> Any:
    """The spec ``raw`` with its ``system.factory`` located from ``folder`` (:func:`locate_factory`).

    ``raw`` itself is not changed; one that has no ``system.factory`` is returned as it
    is (its parser names what is missing).
    """
    system = raw.get("system") if isinstance(raw, dict) else None
    if not isinstance(system, dict) or "factory" not in system:
        return raw
    factory = locate_factory(system["factory"], folder)
    return raw if factory == system["factory"] else {**raw, "system": {**system, "factory": factory}}


def check_arguments(
    factory: str,
    calls: Iterable[tuple[str, dict[str, Any]]],
    origin: Callable[[int, str], str] | None = None,
) -> None:
    """Fail early, naming the key, when a call ``(where, kwargs)`` does not fit the factory.

    ``origin(i, key)``, when given, is the spec key that gave the argument ``key`` of call
    ``i`` (a sweep's ``system.fixed``, row or scenario), named with ``where``. The factory
    itself is not called here (in a sweep, it runs in the workers).
    """
    fn = resolve_factory(factory)
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):  # builtins without a signature: checked when called
        return
    open_ended = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in sig.parameters.values())
    for i, (where, kwargs) in enumerate(calls):
        for key in kwargs:
            if not open_ended and key not in sig.parameters:
                given = f"`{origin(i, key)}`, {where}" if origin else where
                raise SpecError(
                    f"parameter `{key}` ({given}) is not an argument of the factory "
                    f"{factory!r}; it takes: {', '.join(sig.parameters) or 'no arguments'}"
                )
        try:
            sig.bind(**kwargs)
        except TypeError as exc:
            raise SpecError(
                f"the arguments {', '.join(kwargs) or '(none)'} ({where}) do not fit the factory "
                f"{factory!r}: {exc}"
            ) from None


def make_problem(factory: str, kwargs: dict[str, Any], where: str) -> EstimationProblem:
    """``factory(**kwargs)``, checked to be an :class:`EstimationProblem`.

    ``where`` names the arguments' origin in errors (``"system.params"``, ``"row 0, ..."``).
    Whatever the factory raises becomes a :class:`SpecError` that names ``where``.
    """
    check_arguments(factory, [(where, kwargs)])
    fn = resolve_factory(factory)
    try:
        problem = fn(**kwargs)
    except EtobsError as exc:  # the factory checked its arguments: say which spec table they came from
        raise SpecError(f"{where}: {exc}") from exc
    except Exception as exc:
        raise SpecError(
            f"the factory {factory!r} failed on the arguments of {where}: {type(exc).__name__}: {exc}"
        ) from exc
    if not isinstance(problem, EstimationProblem):
        kind = type(problem).__name__
        raise SpecError(f"the factory {factory!r} returned {kind}, not an EstimationProblem")
    return problem


def _load_file(name: str, where: str, attr: str) -> ModuleType:
    """The module of ``path/file.py``, executed (once per process) only if its source marks ``attr``.

    It is kept in ``sys.modules`` under a name made from the file's path, size and time
    of change, as an import would keep it: a second resolution (every command resolves its
    factory more than once) does not run the file again, and code that looks its module
    up there (dataclasses, pickle) works.
    """
    path = spec_path(where, None)  # a spec given as a dictionary: from the current folder
    if not path.is_file():
        relative = (
            "" if Path(where).is_absolute() else " (a spec given as a dictionary: from the current folder)"
        )
        raise SpecError(f"`system.factory`: cannot import {str(path)!r}: no such file{relative}")
    st = path.stat()
    ident = f"{path.resolve()}\0{st.st_size}\0{st.st_mtime_ns}"
    module_name = f"_etobs_factory_file_{hashlib.sha256(ident.encode()).hexdigest()[:16]}"
    if module_name in sys.modules:
        return sys.modules[module_name]
    _require_mark(name, path, attr, None)
    loc = importlib.util.spec_from_file_location(module_name, path)
    if loc is None or loc.loader is None:
        raise SpecError(f"`system.factory`: cannot import {str(path)!r}: not a Python file")
    module = importlib.util.module_from_spec(loc)
    sys.modules[module_name] = module
    try:
        loc.loader.exec_module(module)
    except Exception as exc:
        del sys.modules[module_name]
        raise SpecError(
            f"`system.factory`: importing {str(path)!r} failed: {type(exc).__name__}: {exc}"
        ) from exc
    return module


def _load_module(name: str, where: str, attr: str) -> ModuleType:
    """The module ``where``; one not imported yet is imported only if its source marks ``attr``."""
    if where in sys.modules:
        return sys.modules[where]
    if not all(part.isidentifier() for part in where.split(".")):
        raise SpecError(f"`system.factory`: cannot import {where!r}: not a module name")
    origin = _source_of(where)
    if origin is None:
        raise SpecError(
            f"`system.factory` = {name!r}: {where!r} has no Python source in which to look for "
            f"the mark, so it is not imported; {_FIX}"
        )
    _require_mark(name, origin, attr, _package_of(where, origin))
    try:
        return importlib.import_module(where)
    except Exception as exc:
        raise SpecError(f"`system.factory`: importing {where!r} failed: {type(exc).__name__}: {exc}") from exc


def _source_of(module: str) -> Path | None:
    """The source file of ``module`` found without importing it or its packages (``None``: none).

    Raises :class:`SpecError` when there is no such module.
    """
    parts = module.split(".")
    spec = None
    for i in range(len(parts)):
        full = ".".join(parts[: i + 1])
        if full in sys.modules:
            spec = getattr(sys.modules[full], "__spec__", None)
        elif i == 0:
            spec = importlib.machinery.PathFinder.find_spec(full)
        else:
            places = None if spec is None else spec.submodule_search_locations
            spec = None if places is None else importlib.machinery.PathFinder.find_spec(full, list(places))
        if spec is None:
            hint = _NOT_ON_PATH.format(full=full) if i == 0 else ""
            raise SpecError(f"`system.factory`: cannot import {module!r}: no module named {full!r}{hint}")
    origin = spec.origin if spec is not None else None
    if not origin or not origin.endswith(".py") or not Path(origin).is_file():
        return None
    return Path(origin)


def _package_of(module: str, origin: Path) -> str:
    """The package a relative import in ``module`` (source ``origin``) is resolved against."""
    return module if origin.name == "__init__.py" else module.rpartition(".")[0]


def _require_mark(name: str, path: Path, attr: str, package: str | None) -> None:
    """Refuse, before running ``path``, a source that does not define ``attr`` with the mark.

    ``package`` resolves relative imports (``None``: a file, which has none).
    """
    marked = _marked_in_source(path, attr, package, MAX_REEXPORTS)
    if marked is None:
        raise SpecError(f"`system.factory`: {str(path)!r} has no callable {attr!r}")
    if not marked:
        raise SpecError(
            f"`system.factory` = {name!r}: {attr!r} in {str(path)!r} is not marked as a factory, "
            f"so its module is not imported; {_FIX}"
        )


def _marked_in_source(path: Path, attr: str, package: str | None, depth: int) -> bool | None:
    """Whether the source ``path`` defines ``attr`` with the mark; ``None``: it does not define it.

    A name imported from another module counts only if that module marks it: its source
    is read in turn (at most ``depth`` imports deep), or, if it is imported already, the
    mark itself is checked. An imported module (``import webbrowser``) is not a factory:
    it used to count, and naming it ran the importing module (``antigravity:webbrowser``
    opened a web browser).
    """
    try:
        tree = ast.parse(importlib.util.decode_source(path.read_bytes()), filename=str(path))
    except (OSError, SyntaxError, ValueError) as exc:
        raise SpecError(f"`system.factory`: cannot read {str(path)!r}: {exc}") from None
    found = None
    for node in _top_level(tree.body):
        marked = _marks(node, attr)
        if isinstance(marked, tuple):
            marked = _marked_in_module(*marked, package, depth)
        if marked:
            return True
        found = False if marked is False else found
    return found


def _marked_in_module(source: str, level: int, name: str, package: str | None, depth: int) -> bool:
    """Whether ``name`` imported ``from source import name`` (``level`` dots) is a marked factory."""
    if depth <= 0 or (level and not package):  # too long a chain; a relative import in a file
        return False
    try:
        module = importlib.util.resolve_name("." * level + source, package) if level else source
    except (ImportError, ValueError):
        return False
    if module in sys.modules:  # imported already: its name is checked, not its source
        try:
            return is_factory(getattr(sys.modules[module], name, None))
        except Exception:  # a module __getattr__ that fails: not a factory
            return False
    if not all(part.isidentifier() for part in module.split(".")):
        return False
    try:
        origin = _source_of(module)
    except SpecError:
        return False
    if origin is None:
        return False
    return bool(_marked_in_source(origin, name, _package_of(module, origin), depth - 1))


def _top_level(body: list[ast.stmt]) -> Iterator[ast.stmt]:
    """The module's statements, including those inside top-level ``if`` and ``try`` blocks."""
    for node in body:
        yield node
        if isinstance(node, ast.If):
            yield from _top_level(node.body + node.orelse)
        elif isinstance(node, ast.Try):
            blocks = node.body + node.orelse + node.finalbody
            yield from _top_level(blocks + [s for h in node.handlers for s in h.body])


def _marks(node: ast.stmt, attr: str) -> bool | tuple[str, int, str] | None:
    """Whether ``node`` defines ``attr`` with the mark; ``None`` when it does not define it.

    ``from source import name as attr`` gives ``(source, level, name)``: whether it is
    marked is decided where it comes from (:func:`_marked_in_module`).
    """
    if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef) and node.name == attr:
        return any(_is_mark(d) for d in node.decorator_list)
    if isinstance(node, ast.Assign | ast.AnnAssign):  # attr = etobs.factory(fn)
        targets = node.targets if isinstance(node, ast.Assign) else [node.target]
        if any(isinstance(t, ast.Name) and t.id == attr for t in targets):
            return isinstance(node.value, ast.Call) and _is_mark(node.value.func)
    if isinstance(node, ast.Import) and any(
        (a.asname or a.name.partition(".")[0]) == attr for a in node.names
    ):
        return False  # a module is not a factory
    if isinstance(node, ast.ImportFrom):
        for a in node.names:
            if (a.asname or a.name) == attr:
                return (node.module or "", node.level, a.name)
    return None


def _is_mark(expr: ast.expr) -> bool:
    """``factory`` or ``<anything>.factory`` (the mark itself is checked once imported)."""
    return (isinstance(expr, ast.Name) and expr.id == "factory") or (
        isinstance(expr, ast.Attribute) and expr.attr == "factory"
    )
