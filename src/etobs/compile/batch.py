"""Calling a compiled one-run function on a batch of runs (to evaluate results on grids).

:func:`batch_call` loops over the rows in compiled code and calls the function by
address, so a batch costs one Python call. It is compiled once per machine.
"""

from __future__ import annotations

import numba
import numpy as np

from etobs.compile.ccall import ccall


@numba.njit(cache=True)
def batch_call(addr, k, t, a0, a1, a2, a3, p, out):  # type: ignore[no-untyped-def]
    """Row ``b`` of ``out`` = the function at ``addr`` of row ``b`` of the inputs; first failure status."""
    ia = np.zeros(1, dtype=np.int64)
    for b in range(t.shape[0]):
        st = ccall(addr, k, t[b], a0[b], a1[b], a2[b], a3[b], ia, p, out[b])
        if st != 1:
            return st
    return 1
