"""Compile a user's one-run function into a C function the engine calls by address.

A :class:`FunctionSpec` says how etobs calls a kind of function (``f_p(t, x, u, v)``,
``h(x)``, a K-function ``fn(s)``, ...) and how long its result is. :func:`compile_function`
compiles the user's function with numba (``error_model="numpy"``: ``1/0`` gives ``inf``,
which the solver reports as ``nonfinite``, instead of raising), together with every
Python function it calls, and wraps it in a C function of the one signature
(:func:`c_signature`) that returns a status. A function may return a 1-D array or a
tuple of floats (no allocation: the fastest form for functions called very often):

* ``OK`` (1): the result was written to ``out``;
* ``BAD_SHAPE`` (2): the function returned an array of another length;
* ``RAISED`` (0): the function raised (numba prints the exception; the C wrapper
  returns zero);
* ``BEYOND_N_FLOW`` (3): set by the engine, not the wrapper: a system's flow moved an
  entry that its ``n_flow`` says is constant along flows;
* ``NAN_RESULT`` (4): set by the engine: an event function (the guard) returned NaN.

The machine code is cached on disk under a hash of the function's content (see
:mod:`etobs.compile.cache`): a new process, a sweep worker, or a function named as
``"path/file.py:name"`` finds it again; editing one function recompiles only that one.
"""

from __future__ import annotations

import functools
import re
import threading
import types
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from etobs.compile.fingerprint import _names, fingerprint
from etobs.errors import ModelError, cause

RAISED, OK, BAD_SHAPE, BEYOND_N_FLOW, NAN_RESULT = 0, 1, 2, 3, 4
#: Failure codes as words, for messages.
FAILURES = {
    RAISED: "raised an exception (numba printed it above)",
    BAD_SHAPE: "returned the wrong shape",
    BEYOND_N_FLOW: (
        "returned a nonzero derivative for an entry from n_flow on (those must be constant along flows)"
    ),
    NAN_RESULT: "returned NaN (an event function that is NaN never fires, so its jump would be missed)",
}


def describe_failure(name: str, status: int, n_out: int | None = None) -> str:
    """A sentence naming the function ``name`` and how it failed (a status of :data:`FAILURES`)."""
    text = f"`{name}` {FAILURES.get(status, f'failed (status {status})')}"
    if status == BAD_SHAPE and n_out is not None:
        text += f": expected a 1-D result of length {n_out} for one run"
    return text


def with_params(fn: Any, params: Any, *args: Any) -> Any:
    """``fn(*args, params)`` when ``params`` has entries, else ``fn(*args)``.

    The calling convention of every user function (the parameter vector last, and only
    when there is one); :func:`params_call` writes the same call as text for the
    compiled forms.
    """
    return fn(*args, params) if params.size else fn(*args)


def params_call(fn: str, args: list[str], params: str | None) -> str:
    """The text of the call of ``fn`` on ``args``, with ``params`` last when there is one."""
    return f"{fn}({', '.join([*args, *([params] if params else [])])})"


@dataclass(frozen=True)
class FunctionSpec:
    """How the engine calls one kind of user function.

    Parameters
    ----------
    call : str
        The call as Python text over ``k``, ``t``, ``A0`` .. ``A3`` (1-D arrays of
        lengths ``sizes``) and ``P`` (the parameter vector), e.g. ``"t, A0, A1, A2"``.
    sizes : tuple of int
        Lengths of the arrays ``A0``, ``A1``, ... the call uses.
    n_out : int
        Length of the result; ``0`` means the function returns a float.
    n_params : int
        Length of ``P``; when positive, ``P`` is passed as the last argument.

    """

    call: str
    sizes: tuple[int, ...]
    n_out: int
    n_params: int = 0

    def source(self) -> str:
        """Text of the C wrapper (module docstring); the user function is ``USER``."""
        lines = ["def wrapper(k, t, a0, a1, a2, a3, ia, pp, outp):"]
        # the inputs are read-only: numba refuses a function that writes into them
        for i, n in enumerate(self.sizes):
            lines.append(f"    A{i} = readonly(carray(a{i}, ({n},)))")
        if self.n_params:
            lines.append(f"    P = readonly(carray(pp, ({self.n_params},)))")
        args = [a for a in self.call.split(", ") if a]
        lines.append(f"    r = {params_call('USER', args, 'P' if self.n_params else None)}")
        if self.n_out == 0:
            lines += ["    outp[0] = r", "    return 1"]
        else:
            lines += [f"    return store(r, carray(outp, ({self.n_out},)), {self.n_out})"]
        return "\n".join(lines) + "\n"


@dataclass(frozen=True)
class CompiledFunction:
    """A compiled user function: its C function (kept alive here) and its address."""

    name: str
    address: int
    cfunc: Any


#: Version of the cached wrappers' layout (part of the cache key).
_FORMAT = 8
#: etobs' own files whose text decides how a user function is compiled (how it is
#: inlined, which ``sin`` it calls, how its result is stored): their hash is part of
#: every cache key, so that code cached by another version of them is never linked.
_OWN = ("functions.py", "_store.py", "_stack.py", "vecmath.py", "ccall.py", "fingerprint.py")


@functools.cache
def _format() -> str:
    """:data:`_FORMAT`, numba's version and a hash of :data:`_OWN`: what every cache key starts with."""
    import numba

    here = Path(__file__).parent
    own = _hash_text("".join((here / name).read_text(encoding="utf-8") for name in _OWN))
    return f"{_FORMAT}-{own}-{numba.__version__}"


_MEMO: dict[str, CompiledFunction] = {}
_MEMO_MODULES: dict[str, tuple[CompiledFunction, ...]] = {}
_LOCK = threading.Lock()


def c_signature() -> Any:
    """The numba signature of every C function the engine calls (see :mod:`etobs.compile.ccall`)."""
    from numba import types as nt

    f8p = nt.CPointer(nt.float64)
    return nt.int64(nt.int64, nt.float64, f8p, f8p, f8p, f8p, nt.CPointer(nt.int64), f8p, f8p)


def compile_function(fn: Any, spec: FunctionSpec, name: str) -> CompiledFunction:
    """Compile ``fn`` as described by ``spec`` (module docstring); memoized and cached on disk.

    Parameters
    ----------
    fn : callable
        The user's function (a plain Python function, a lambda, a closure or a numba
        ``@njit`` function).
    spec : FunctionSpec
    name : str
        How messages name the function, e.g. ``"f_p"`` or ``"gamma of node 0"``.

    Raises
    ------
    ModelError
        When numba cannot compile it: the message names the function, gives numba's
        reason in one line and the way out.

    """
    import numba

    from etobs.compile._store import readonly, store
    from etobs.compile.cache import KEY, cache_dir, install_locator

    _refuse_non_function(fn, name)
    source = spec.source()
    key = fingerprint(fn) + "-" + _hash_text(f"{_format()}{source}")
    with _LOCK:
        done = _MEMO.get(key)
        if done is not None:
            return CompiledFunction(name, done.address, done.cfunc)
        install_locator()
        cached = cache_dir() is not None
        namespace: dict[str, Any] = {
            "__name__": "etobs.compile._generated",
            "USER": _jitted(fn, {}),
            "carray": numba.carray,
            "readonly": readonly,
            "store": store,
            KEY: key,
        }
        exec(compile(source, "<etobs wrapper>", "exec"), namespace)
        _name_by_content(namespace["wrapper"], key)
        try:
            cf = _load_or_compile(namespace["wrapper"], cached, f"`{name}`")
        except Exception as exc:  # numba raises many types; all mean "cannot compile"
            raise ModelError(_cannot_compile(name, exc, getattr(fn, ORIGIN, ""))) from cause(exc)
        out = CompiledFunction(name, int(cf.address), cf)
        _MEMO[key] = out
        return out


def compile_module(
    text: str, users: dict[str, Any], entries: tuple[str, ...], what: str, *, inline: bool = True
) -> tuple[CompiledFunction, ...]:
    """Compile the C functions ``entries`` of a generated module that calls user functions.

    ``text`` defines every name of ``entries`` as a function of :func:`c_signature`; it may
    call ``carray``, ``readonly``, ``store``, ``np`` and the user functions ``users`` by
    their global names, compile its own functions with ``jit`` or ``inline`` (numba
    inlines those where they are called) and take arrays on its stack
    (:mod:`etobs.compile._stack`). Each user function is compiled on its own and cached under its fingerprint
    (so editing one recompiles only it and this module); the module links them. Memoized,
    and cached on disk by the text and the user functions' fingerprints.

    With ``inline`` the user functions are inlined into the module by numba (so that a
    loop over lanes that calls them can become vector instructions); without, LLVM
    inlines them where it can.

    Raises
    ------
    ModelError
        When numba cannot compile the module (``what`` names it). The caller can find
        the user function at fault by compiling each on its own (:func:`compile_function`).

    """
    import numba
    import numpy as np

    from etobs.compile._stack import stack_f8, stack_i8
    from etobs.compile._store import readonly, store, store_inlined
    from etobs.compile.cache import KEY, cache_dir, install_locator

    parts = [f"{g}={fingerprint(fn)}" for g, fn in sorted(users.items())]
    key = _hash_text(f"{_format()}{inline}{entries}{text}{' '.join(parts)}")
    with _LOCK:
        done = _MEMO_MODULES.get(key)
        if done is not None:
            return done
        install_locator()
        cached = cache_dir() is not None
        memo: dict[int, Any] = {}
        namespace: dict[str, Any] = {
            "__name__": "etobs.compile._generated",
            "carray": numba.carray,
            "readonly": readonly,
            "store": store_inlined if inline else store,
            "np": np,
            "jit": numba.njit(error_model="numpy"),
            "inline": numba.njit(inline="always", error_model="numpy"),
            "stack_f8": stack_f8,
            "stack_i8": stack_i8,
            KEY: key,
        }
        namespace.update({g: _jitted(fn, memo, cached, inline) for g, fn in users.items()})
        exec(compile(text, f"<etobs {what}>", "exec"), namespace)
        # every function the text defines is named by the module's content (the entries and
        # the helpers they call alike): two models' `body` must never link as one symbol
        for value in list(namespace.values()):
            fn = getattr(value, "py_func", value)
            if isinstance(fn, types.FunctionType) and fn.__globals__ is namespace and not hasattr(fn, NAMED):
                _name_by_content(fn, key)
        out = []
        for entry in entries:
            try:
                cf = _load_or_compile(namespace[entry], cached, f"{entry} of the {what}")
            except Exception as exc:  # numba raises many types; all mean "cannot compile"
                raise ModelError(f"the {what} cannot be compiled: {_reason(exc)}") from cause(exc)
            out.append(CompiledFunction(entry, int(cf.address), cf))
        _MEMO_MODULES[key] = tuple(out)
        return _MEMO_MODULES[key]


def _refuse_non_function(fn: Any, name: str) -> None:
    """Refuse, in the user's words, a callable numba cannot compile: a bound method, a partial, an object.

    numba would say ``Untyped global name 'USER'`` (the wrapper's name for it).
    """
    if hasattr(fn, "py_func") or isinstance(fn, types.FunctionType):
        return
    if isinstance(fn, types.MethodType):
        what = f"a bound method ({fn.__qualname__}), whose `self` numba cannot compile"
    else:
        what = f"a {type(fn).__module__}.{type(fn).__qualname__}, not a Python function"
    raise ModelError(
        f"`{name}` is {what}: write it as a function (def or lambda) that reads the numbers it needs "
        "from `params` or from a closure, or use backend='scipy', which runs any Python"
    ) from None  # raised while the model's own compile error is handled: that one says less


def _load_or_compile(wrapper: Any, cached: bool, name: str) -> Any:
    """``wrapper`` as a C function, from the disk cache when it is there.

    A cache entry that cannot be loaded (damaged, or written by another version) is
    discarded, with one warning, and the code compiled and cached again; if even that
    fails, it is compiled in memory. The functions it calls are discarded with it.
    """
    from etobs.compile.cache import KEY, discard

    try:
        return _cfunc(wrapper, cached, name)
    except Exception as exc:
        if not cached:
            raise
        keys = [wrapper.__globals__[KEY]]
        keys += [g.py_func.__globals__[KEY] for g in wrapper.__globals__.values() if _cached_jit(g)]
        discard(keys)
        try:
            cf = _cfunc(wrapper, True, name)
            what = "discarded it and compiled it again"
        except Exception:
            cf = _cfunc(wrapper, False, name)
            what = "compiled it again in memory"
        warnings.warn(
            f"etobs: could not load the cached code of {name} ({_reason(exc)}); {what}. "
            "Deleting the cache folder (see etobs.compile.cache) is always safe",
            RuntimeWarning,
            stacklevel=3,
        )
        return cf


def _cached_jit(g: Any) -> bool:
    from etobs.compile.cache import KEY

    return hasattr(g, "py_func") and KEY in getattr(g.py_func, "__globals__", {})


def _cfunc(wrapper: Any, cached: bool, name: str) -> Any:
    import numba

    with warnings.catch_warnings(record=True) as seen:
        # numba's own warnings (performance hints, unsafe casts) are not the user's errors
        warnings.simplefilter("always", numba.NumbaWarning)
        out = numba.cfunc(c_signature(), cache=cached, error_model="numpy")(wrapper)
    for w in seen:
        if "Cannot cache" in str(w.message):  # a silent slow path: every process compiles it again
            warnings.warn(
                f"etobs: the machine code of {name} cannot be cached ({w.message}): every new "
                "process compiles it again. A large array read as a constant (over 1 MB) does this: "
                "pass it in `params` instead",
                RuntimeWarning,
                stacklevel=4,
            )
        elif not issubclass(w.category, numba.NumbaWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return out


def _name_by_content(fn: Any, key: str) -> None:
    """Put a hash of ``key`` (a cache key, by content) in ``fn.__qualname__``, the name numba links by.

    numba names a compiled function's symbol by module, qualified name, argument types
    and a per-process counter, and links and looks up symbols by that name alone. Code
    from the disk cache was named in another process: a lambda cached there and a
    different lambda with the same argument types compiled here could get the same
    symbol, and a model linked the wrong one's machine code, a silent wrong result
    (``h = lambda x: 0.0 * x`` ran as the plant's ``lambda s: s * s``, and ``x' = x**2``
    from ``x = 1`` completed instead of blowing up). With the content in the name, two
    functions share a symbol only when they compile to the same code.
    """
    # a name numba can build identifiers from (it names an inlined function's variables so)
    fn.__qualname__ = f"{fn.__qualname__}_h{_hash_text(key)}"
    setattr(fn, NAMED, True)


def _hash_text(text: str) -> str:
    import hashlib

    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _jitted(fn: Any, memo: dict[int, Any], cached: bool = False, inline: bool = False) -> Any:
    """``fn`` as a numba function, with the Python functions it calls compiled too.

    With ``inline``, numba inlines each where it is called (``inline="always"``), else
    LLVM does (``forceinline``) once the code is linked.

    With ``cached``, each is compiled on its own and its machine code kept in the disk
    cache under its fingerprint (:mod:`etobs.compile.cache`): code that calls it links
    it, so editing one function recompiles only that function and its callers.
    """
    import numba

    from etobs.compile import vecmath
    from etobs.compile.cache import KEY

    if hasattr(fn, "py_func"):
        return fn
    if not isinstance(fn, types.FunctionType):
        return fn  # numba says what it cannot type
    if id(fn) in memo:
        return memo[id(fn)]

    swap = vecmath.replacements(inline)

    def convert(value: Any) -> Any:
        if id(value) in swap:  # libm's sin and cos: the engine's, which vectorize
            return swap[id(value)]
        return _jitted(value, memo, cached, inline) if isinstance(value, types.FunctionType) else value

    glb = dict(fn.__globals__)
    # numba imports a compiled function's module again when it loads it from the disk
    # cache; the user's module may not be importable by name (a file loaded by path,
    # __main__, a notebook), and the cached code does not depend on it
    glb["__name__"] = "etobs.compile._generated"
    for nm in _names(fn.__code__):
        if nm in glb:
            glb[nm] = convert(glb[nm])
    cells = tuple(types.CellType(convert(c.cell_contents)) for c in fn.__closure__ or ())
    clone = types.FunctionType(fn.__code__, glb, fn.__name__, fn.__defaults__, cells or None)
    clone.__qualname__ = fn.__qualname__
    if cached:
        glb[KEY] = f"fn-{fingerprint(fn)}-{_format()}-{inline}"
        _name_by_content(clone, glb[KEY])
    # inlined where it is called: numba's inlining puts it into the caller's module before
    # LLVM optimizes it, so that a loop over lanes that calls it can become vector code
    how: dict[str, Any] = {"inline": "always"} if inline else {"forceinline": True}
    out = numba.njit(error_model="numpy", cache=cached, **how)(clone)
    memo[id(fn)] = out
    return out


#: The attribute of a function already named by its content (:func:`_name_by_content`).
NAMED = "_etobs_named"
#: The attribute of a user function that says where its code comes from, when not written
#: by the user as such (a python-control system's updfcn): messages name it too.
ORIGIN = "etobs_origin"

#: How both solvers word a function that writes into its (read-only) input.
WRITES_INPUT = (
    "writes into one of its input arrays, which are read-only (a write would change the solver's "
    "state behind its back): work on a copy (x = x.copy()) or build a new array"
)
#: How both solvers word a function that returns complex numbers.
COMPLEX_RESULT = (
    "returned complex values; the states are real: return the real part (np.real) when the imaginary "
    "part is zero by construction, or carry real and imaginary parts as separate states"
)
#: What numba says of a write into a read-only array.
_READONLY_WRITE = ("readonly array", "Cannot modify readonly")


def _cannot_compile(name: str, exc: Exception, origin: str = "") -> str:
    """Why the function ``name`` cannot be compiled, and the way out; ``origin`` says whose code it runs."""
    text = str(exc)
    who = f"`{name}` ({origin})" if origin else f"`{name}`"
    if any(k in text for k in _READONLY_WRITE) and ("setitem" in text or "Cannot modify" in text):
        return f"{who} {WRITES_INPUT}"
    returned = re.search(r"store\((.+?), array\(float64, 1d, C\), ", text)
    if returned and "complex" in returned.group(1):
        return f"{who} {COMPLEX_RESULT}"
    if returned:  # the wrapper's `store` could not take the result: say what the user returned
        return (
            f"{who} returned {returned.group(1)}, which the engine cannot store: return a 1-D float "
            "array (np.array([...])) or a tuple of floats"
        )
    return (
        f"{who} cannot be compiled: {_reason(exc)}. Write it for one run with numpy or "
        "math on 1-D arrays (returning a 1-D array), or use backend='scipy', which runs any Python"
    )


def _reason(exc: Exception) -> str:
    """Numba's reason in one line (with the call it could not type, when it names one)."""
    skip = ("Failed in nopython mode", "During:", "File ", "Traceback", "-", "^", "There are")
    text = re.sub(r"_h[0-9a-f]{16}", "", str(exc))  # the content hash in names (_name_by_content)
    lines = [line.strip() for line in text.splitlines()]
    for k, text in enumerate(lines):
        if text and not text.startswith(skip):
            if text.endswith("signature:"):
                call = next((t for t in lines[k + 1 :] if t.startswith(">>>")), "")
                text = f"{text} {call.removeprefix('>>>').strip()}"
            return text[:300].rstrip(".")
    return type(exc).__name__
