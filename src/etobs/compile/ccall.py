"""Calling a compiled user function by its address, from compiled code.

Every function the engine calls is a C function with one signature (see
:func:`etobs.compile.functions.c_signature`)::

    int64 fn(int64 k, double t, double *a0, double *a1, double *a2, double *a3,
             int64 *ia, double *p, double *out)

:func:`ccall` takes the address as an ``int64`` and numpy arrays for the pointers, so
the code that calls it does not depend on which function it calls: it is compiled once
per machine and cached, and the user's functions are compiled (and cached) on their own.
An indirect call costs a few nanoseconds.
"""

from __future__ import annotations

from typing import Any

from llvmlite import ir
from numba.core import types
from numba.core.extending import intrinsic


@intrinsic
def ccall(
    typingctx: Any, addr: Any, k: Any, t: Any, a0: Any, a1: Any, a2: Any, a3: Any, ia: Any, p: Any, out: Any
):  # type: ignore[no-untyped-def]
    """``fn(k, t, a0, a1, a2, a3, ia, p, out)`` for the function at ``addr``; returns its int64 status."""
    sig = types.int64(addr, k, t, a0, a1, a2, a3, ia, p, out)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        ptrs = [
            context.make_array(ty)(context, builder, val).data
            for ty, val in zip(signature.args[3:], args[3:], strict=True)
        ]
        kk = context.cast(builder, args[1], signature.args[1], types.int64)
        tt = context.cast(builder, args[2], signature.args[2], types.float64)
        fnty = ir.FunctionType(ir.IntType(64), [ir.IntType(64), ir.DoubleType()] + [q.type for q in ptrs])
        fn = builder.inttoptr(args[0], fnty.as_pointer())
        return builder.call(fn, [kk, tt, *ptrs])

    return sig, codegen
