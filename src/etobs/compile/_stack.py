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


def _stack(numba_type: Any, llvm_type: Any) -> Any:
    """An intrinsic ``stack(size)``: a pointer to ``size`` values on the stack (``size`` a constant)."""

    def stack(typingctx: Any, size: Any):  # type: ignore[no-untyped-def]
        if not isinstance(size, types.IntegerLiteral):
            return None
        count = int(size.literal_value)
        sig = types.CPointer(numba_type)(size)  # type: ignore[no-untyped-call]  # untyped in numba's stubs

        def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
            return cgutils.alloca_once(builder, llvm_type, size=max(count, 1))

        return sig, codegen

    return intrinsic(stack)


#: ``stack_f8(size)``: float64 on the stack, for ``numba.carray``.
stack_f8 = _stack(types.float64, ir.DoubleType())
#: ``stack_i8(size)``: int64 on the stack, for ``numba.carray``.
stack_i8 = _stack(types.int64, ir.IntType(64))
