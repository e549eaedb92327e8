"""Writing a user function's result into the engine's output, for arrays and tuples alike.

A one-run function may return a 1-D array, a list or a tuple of floats; a tuple costs no
allocation (numba keeps it in registers), which matters for a function called hundreds
of thousands of times per run. :func:`store` copies either into ``out`` and returns
``OK`` (1) or ``BAD_SHAPE`` (2) when the length is not ``n``.

:func:`readonly` is how a user function sees its inputs: numba then refuses, when it
compiles the function, any write into them (a write changed the solver's state behind
its back: a stage of the step, the state before a jump).
"""

from __future__ import annotations

import functools
from typing import Any

from numba.core import types
from numba.core.imputils import impl_ret_borrowed
from numba.extending import intrinsic, overload


def store(r: Any, out: Any, n: int) -> int:
    """Copy ``r`` (array, list or tuple) into ``out[:n]``; 1 when ``len(r) == n``, else 2."""
    raise NotImplementedError("compiled only")  # pragma: no cover


def store_inlined(r: Any, out: Any, n: int) -> int:
    """:func:`store`, inlined by numba where it is called.

    Where ``n`` is then a constant LLVM unrolls the copy: the lane form's loop over lanes
    around it stays vector code.
    """
    raise NotImplementedError("compiled only")  # pragma: no cover


#: Tuples up to this length are copied by code written out element by element: a loop
#: over a tuple indexes it by a run-time number (a switch), which keeps a loop over lanes
#: around it from becoming vector instructions.
WRITTEN_OUT = 64


@functools.cache
def _written_out(check: str, count: int) -> Any:
    """``out[0] = r[0]; ...; out[count-1] = r[count-1]`` after ``if check: return 2``, as a function."""
    lines = ["def impl(r, out, n):", f"    if {check}:", "        return 2"]
    lines += [f"    out[{i}] = r[{i}]" for i in range(count)]
    lines.append("    return 1")
    namespace: dict[str, Any] = {}
    exec("\n".join(lines), namespace)
    return namespace["impl"]


def _store(r, out, n):  # type: ignore[no-untyped-def]  # numba: the implementations' signature must be the typer's
    if isinstance(r, types.Array) and not isinstance(r.dtype, types.Complex):
        # inlined where n is a constant: LLVM unrolls the loop there
        def from_array(r, out, n):  # type: ignore[no-untyped-def]
            if r.shape[0] != n:
                return 2
            for i in range(n):
                out[i] = r[i]
            return 1

        return from_array
    if isinstance(r, types.List) and isinstance(r.dtype, (types.Float, types.Integer)):
        # a Python list, as the reference accepts (it calls np.asarray)
        def from_list(r, out, n):  # type: ignore[no-untyped-def]
            if len(r) != n:
                return 2
            for i in range(n):
                out[i] = r[i]
            return 1

        return from_list
    if isinstance(r, (types.UniTuple, types.Tuple)) and not any(isinstance(a, types.Complex) for a in r):
        m = len(r)
        if m <= WRITTEN_OUT:  # its length is in its type
            return _written_out(f"n != {m}", m)

        def from_tuple(r, out, n):  # type: ignore[no-untyped-def]
            if m != n:
                return 2
            for i in range(n):
                out[i] = r[i]
            return 1

        return from_tuple
    return None


@intrinsic
def readonly(typingctx: Any, arr: Any):  # type: ignore[no-untyped-def]
    """The same array typed read-only (no copy): numba refuses code that writes into it."""
    if not isinstance(arr, types.Array):
        return None
    sig = arr.copy(readonly=True)(arr)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        return impl_ret_borrowed(context, builder, signature.return_type, args[0])

    return sig, codegen


# one implementation, two ways to compile it: called (a quick compile), or inlined
overload(store, jit_options={"forceinline": True})(_store)
overload(store_inlined, inline="always")(_store)
