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


def _pointer(context: Any, builder: Any, ty: Any, val: Any, pointee: Any) -> Any:
    """The data pointer of an array, or an address (an integer) as a pointer to ``pointee``."""
    if isinstance(ty, types.Array):
        return context.make_array(ty)(context, builder, val).data
    return builder.inttoptr(val, pointee.as_pointer())


@intrinsic
def ccall(
    typingctx: Any, addr: Any, k: Any, t: Any, a0: Any, a1: Any, a2: Any, a3: Any, ia: Any, p: Any, out: Any
):  # type: ignore[no-untyped-def]
    """``fn(k, t, a0, a1, a2, a3, ia, p, out)`` for the function at ``addr``; returns its int64 status.

    Each pointer argument is an array (its data is passed) or an integer address
    (:func:`address`): an address costs no reference counting where a view of an array
    would (the kernel calls these functions millions of times per run).
    """
    for arg in (a0, a1, a2, a3, ia, p, out):
        if not isinstance(arg, types.Array | types.Integer):
            return None
    sig = types.int64(addr, k, t, a0, a1, a2, a3, ia, p, out)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        f8, i8 = ir.DoubleType(), ir.IntType(64)
        pointees = (f8, f8, f8, f8, i8, f8, f8)
        ptrs = [
            _pointer(context, builder, ty, val, pt)
            for ty, val, pt in zip(signature.args[3:], args[3:], pointees, strict=True)
        ]
        kk = context.cast(builder, args[1], signature.args[1], types.int64)
        tt = context.cast(builder, args[2], signature.args[2], types.float64)
        fnty = ir.FunctionType(i8, [i8, f8] + [q.type for q in ptrs])
        fn = builder.inttoptr(args[0], fnty.as_pointer())
        return builder.call(fn, [kk, tt, *ptrs])

    return sig, codegen


@intrinsic
def address(typingctx: Any, arr: Any):  # type: ignore[no-untyped-def]
    """The address of ``arr``'s data as an int64 (the array must outlive its uses)."""
    if not isinstance(arr, types.Array):
        return None
    sig = types.int64(arr)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        data = context.make_array(signature.args[0])(context, builder, args[0]).data
        return builder.ptrtoint(data, ir.IntType(64))

    return sig, codegen


@intrinsic
def load_i64(typingctx: Any, addr: Any):  # type: ignore[no-untyped-def]
    """The int64 at ``addr``."""
    sig = types.int64(addr)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        return builder.load(builder.inttoptr(args[0], ir.IntType(64).as_pointer()))

    return sig, codegen


@intrinsic
def store_i64(typingctx: Any, addr: Any, value: Any):  # type: ignore[no-untyped-def]
    """Write the int64 ``value`` at ``addr``."""
    sig = types.none(addr, value)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        val = context.cast(builder, args[1], signature.args[1], types.int64)
        builder.store(val, builder.inttoptr(args[0], ir.IntType(64).as_pointer()))
        return context.get_dummy_value()

    return sig, codegen
