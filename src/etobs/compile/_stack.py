"""Arrays on the stack of a compiled function, for the lane form of a model.

The lane form of the estimation model (:mod:`etobs.estimation._model_source`) runs one
run's model in a loop over lanes. LLVM turns that loop into vector instructions only
when it can prove that one lane's writes do not reach another lane's reads; through
pointers the kernel passed in, it cannot (it would need a run-time check for every
pair of arrays, more than it makes). Its scratch and results are therefore written to
arrays on the function's own stack, which no pointer passed in can alias, and copied
out after the loop.
"""

from __future__ import annotations

from typing import Any

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic


@intrinsic
def stack_f8(typingctx: Any, size: Any):  # type: ignore[no-untyped-def]
    """A pointer to ``size`` float64 on the stack (``size`` a constant), for ``numba.carray``."""
    if not isinstance(size, types.IntegerLiteral):
        return None
    count = int(size.literal_value)
    sig = types.CPointer(types.float64)(size)  # type: ignore[no-untyped-call]  # untyped in numba's stubs

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        return cgutils.alloca_once(builder, ir.DoubleType(), size=max(count, 1))

    return sig, codegen


@intrinsic
def stack_i8(typingctx: Any, size: Any):  # type: ignore[no-untyped-def]
    """A pointer to ``size`` int64 on the stack (``size`` a constant), for ``numba.carray``."""
    if not isinstance(size, types.IntegerLiteral):
        return None
    count = int(size.literal_value)
    sig = types.CPointer(types.int64)(size)  # type: ignore[no-untyped-call]  # untyped in numba's stubs

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        return cgutils.alloca_once(builder, ir.IntType(64), size=max(count, 1))

    return sig, codegen
