"""The compiled solver kernel (numba): many runs per thread, in lanes (see :mod:`etobs.hybrid.solver`).

This module imports numba at the top; :mod:`etobs.hybrid.compiled` imports it only
when the compiled backend is asked for, so numba stays optional.

The algorithm is the one of :mod:`etobs.hybrid.solver` (see its contract), for each
run on its own (its own steps and events), with runs side by side in lanes
(``_kernel`` in ``_kernel_body.py``; docs/solver.md, "Lanes"):

* steps of an embedded Runge--Kutta pair with the same step-size controller;
* on every accepted step, the event functions sampled on the dense output at
  ``event_samples - 1`` interior points, the step end and the parabolic peak probes
  (:mod:`etobs.hybrid.peaks`);
* the first crossing bracketed and refined by regula falsi (Illinois) with bisection
  safeguard to ``event_xtol`` in time, the event reported at the right end;
* all rules with ``g_k >= 0`` jump once, in rule order, until all are negative.

The system's flow, guard and jump are C functions called by address (see
:mod:`etobs.compile.ccall`); the kernel's ``args`` are ``(addresses, ia, cf)``: the
three addresses, and integer and float data shared by all runs that the functions
receive as ``ia`` and ``a1``. Each call gets the run's parameter vector ``p`` (a row
of ``P``) and, as ``a2``, the run's scratch array of ``n_work`` floats. Inside a run
these travel as plain addresses (``_lane_args`` of the template), and rows of the stage and sample
arrays as addresses too: an array taken from a tuple, or a view of a row, costs two
atomic reference-count updates, which were 40 % of a run's time. So the kernel
does not depend on the system: it is compiled once per machine and method, and cached.

``flow`` (called with ``k = -1``): ``out = x'`` at ``(t, x = a0)``; ``guard`` (``k =
-2``): ``out = g`` (rule ``r`` jumps where ``g_r >= 0``); ``jump``: ``out = x+`` of rule
``k >= 0``. The three addresses may be one function that branches on ``k``. A call that does not return
``OK`` (1) stops the run with status ``model_error``, and the run's ``error_code`` says
which function failed and how (``16 * slot + failure``, slots 1, 2, 3 for flow, guard,
jump unless the function reports its own code >= 16).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple, TypeAlias, cast

import numba
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.core.extending import intrinsic
from numba.np.numpy_support import carray
from numpy.typing import NDArray

from etobs.compile import ccall as _ccall
from etobs.hybrid import _jitcache
from etobs.hybrid.options import MAX_FACTOR, MIN_FACTOR, SAFETY  # noqa: F401 - read by the template
from etobs.hybrid.peaks import peak_probes as _peak_probes
from etobs.hybrid.status import Status
from etobs.hybrid.zeno import zeno_window as _zeno_window

# Status codes as plain integers (numba folds them as constants).
RUNNING = int(Status.RUNNING)
COMPLETED = int(Status.COMPLETED)
MAX_JUMPS = int(Status.MAX_JUMPS)
MAX_STEPS = int(Status.MAX_STEPS)
NONFINITE = int(Status.NONFINITE)
STEP_UNDERFLOW = int(Status.STEP_UNDERFLOW)
MODEL_ERROR = int(Status.MODEL_ERROR)
ZENO = int(Status.ZENO)

MAX_ROOT_ITER = 200
EPS = np.finfo(np.float64).eps

# Indices into the float and integer option vectors.
F_RTOL, F_ATOL, F_MAX_STEP, F_FIRST_STEP, F_XTOL, F_ZENO_SPAN = 0, 1, 2, 3, 4, 5
I_MAX_JUMPS, I_MAX_STEPS, I_SAMPLES, I_KEEP_STEPS, I_N_WORK, I_N_FLOW, I_ZENO_JUMPS, I_N_RULES = range(8)
#: A lane that holds no run (the queue is empty); it computes a copy of a running lane.
IDLE = -100
#: Slots of the system's functions in failure codes.
FLOW, GUARD, JUMP = 1, 2, 3
#: The flow's failure code when it moves an entry that n_flow says is constant.
FLOW_BEYOND_N_FLOW = 16 * FLOW + 3  # etobs.compile.functions.BEYOND_N_FLOW
#: The guard's failure code when an event function is NaN (it would never fire).
GUARD_NAN = 16 * GUARD + 4  # etobs.compile.functions.NAN_RESULT
#: The ``k`` that flow and guard are called with (a jump gets its rule, >= 0), so that
#: one C function may serve as all three (the estimation model does: one compile).
K_FLOW, K_GUARD = -1, -2

if TYPE_CHECKING:
    import ctypes


class System(NamedTuple):
    """What the kernel calls: the functions' addresses and the data they share.

    ``addresses``: flow, guard and jump of one run, and the lane form of flow and guard
    (0 when the system has none: the kernel then calls the one-run functions lane by
    lane); ``ia`` and ``cf``: integer and float data shared by all runs.
    """

    addresses: NDArray[np.int64]
    ia: NDArray[np.int64]
    cf: NDArray[np.float64]


class Problem(NamedTuple):
    """The runs: initial states, parameter rows, ``span = (t0, t_end)`` and what to keep.

    ``grid`` is the save grid, ``dist`` the distance pairs of ``SaveAt(max_distance=...)``,
    ``log_cols`` the state entries logged at every jump.
    """

    x0: NDArray[np.float64]
    params: NDArray[np.float64]
    span: NDArray[np.float64]
    grid: NDArray[np.float64]
    dist: NDArray[np.int64]
    log_cols: NDArray[np.int64]


class Options(NamedTuple):
    """The solver's options as numbers: floats at ``F_*``, integers at ``I_*``."""

    f: NDArray[np.float64]
    i: NDArray[np.int64]


class Outputs(NamedTuple):
    """Per run (indexed by the run): what the kernel writes when the run ends.

    ``t_final`` is also written after every accepted step (the progress bar reads it).
    """

    status: NDArray[np.int64]
    t_final: NDArray[np.float64]
    j_final: NDArray[np.int64]
    x_final: NDArray[np.float64]
    n_steps: NDArray[np.int64]
    n_rejected: NDArray[np.int64]
    log_n: NDArray[np.int64]
    arc_n: NDArray[np.int64]
    grid_x: NDArray[np.float64]
    grid_j: NDArray[np.int64]
    grid_max: NDArray[np.float64]
    error_code: NDArray[np.int64]


class Logs(NamedTuple):
    """Per slot (the run's position in the thread's queue): its jump log and arc points."""

    rule: NDArray[np.int64]
    t: NDArray[np.float64]
    j: NDArray[np.int64]
    x: NDArray[np.float64]
    arc_t: NDArray[np.float64]
    arc_j: NDArray[np.int64]
    arc_x: NDArray[np.float64]


#: What the system's functions read and write: a float64 array, or its address (an int).
Pointer: TypeAlias = "NDArray[np.float64] | int"
#: A run's addresses (``_lane_args``): flow, guard, jump, ``ia``, ``cf``, scratch, failure flag.
RunArgs: TypeAlias = tuple[int, int, int, int, int, int, int]

# The intrinsics of etobs.compile.ccall, typed as compiled code calls them: numba's stubs
# type the call of an intrinsic as a call of its typing function (the typing context
# first) that never returns (true of a call from Python, which raises).
ccall = cast(
    "Callable[[int, int, float, Pointer, Pointer, Pointer, Pointer, Pointer, Pointer, Pointer], int]",
    _ccall.ccall,
)
address = cast("Callable[[NDArray[Any]], int]", _ccall.address)
load_i64 = cast("Callable[[int], int]", _ccall.load_i64)
store_i64 = cast("Callable[[int, int], None]", _ccall.store_i64)


@numba.njit(inline="always", error_model="numpy")
def _system(slot: int, k: int, t: float, x: Pointer, p: Pointer, args: RunArgs, out: Pointer) -> None:
    """Call the system's function ``slot`` (FLOW, GUARD, JUMP) by address into ``out``.

    ``args`` is the run's tuple of addresses (:data:`RunArgs`); ``x``, ``p`` and ``out``
    are arrays or addresses. On failure, record the run's first failure (``16 * slot +
    st`` unless ``st`` is already a code); ``out`` may be left partly written, so the
    kernel does not take the step and ends the run at its last good state.
    """
    st = ccall(args[slot - 1], k, t, x, args[4], args[5], args[4], args[3], p, out)
    if st != 1 and load_i64(args[6]) == 0:
        store_i64(args[6], st if st >= 16 else 16 * slot + st)


def _f8ptr_typing(typingctx: Any, addr: Any) -> tuple[Any, Callable[..., Any]]:
    """``addr`` (an integer) as a pointer to float64."""
    sig = types.CPointer(types.float64)(addr)  # type: ignore[no-untyped-call]  # untyped in numba's stubs

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        return builder.inttoptr(args[0], ir.DoubleType().as_pointer())

    return sig, codegen


#: ``_f8ptr(addr)``: the intrinsic, typed as compiled code calls it (see ``ccall`` above).
_f8ptr = cast("Callable[[int], ctypes._Pointer[ctypes.c_double]]", intrinsic(_f8ptr_typing))


@numba.njit(inline="always", error_model="numpy")
def rows_at(base: int, offset: int, rows: int, cols: int) -> NDArray[np.float64]:
    """A ``(rows, cols)`` array at ``base + 8 offset`` (an address into the thread's scratch).

    It owns no memory, so numba counts no references on it: the step loop's arrays are
    all of this kind (a counted array costs two atomic operations at every call that
    takes it).
    """
    return carray(_f8ptr(base + 8 * offset), (rows, cols))


def _i8ptr_typing(typingctx: Any, addr: Any) -> tuple[Any, Callable[..., Any]]:
    """``addr`` (an integer) as a pointer to int64."""
    sig = types.CPointer(types.int64)(addr)  # type: ignore[no-untyped-call]  # untyped in numba's stubs

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        return builder.inttoptr(args[0], ir.IntType(64).as_pointer())

    return sig, codegen


#: ``_i8ptr(addr)``: the intrinsic, typed as compiled code calls it.
_i8ptr = cast("Callable[[int], ctypes._Pointer[ctypes.c_int64]]", intrinsic(_i8ptr_typing))


@numba.njit(inline="always", error_model="numpy")
def ints_at(base: int, offset: int, size: int) -> NDArray[np.int64]:
    """A 1-D int64 array of ``size`` at ``base + 8 offset`` (see :func:`rows_at`)."""
    return carray(_i8ptr(base + 8 * offset), (size,))


@numba.njit(inline="always", error_model="numpy")
def cube_at(base: int, offset: int, a: int, b: int, c: int) -> NDArray[np.float64]:
    """An ``(a, b, c)`` array at ``base + 8 offset`` (see :func:`rows_at`)."""
    return carray(_f8ptr(base + 8 * offset), (a, b, c))


@numba.njit(inline="always", error_model="numpy")
def vector_at(base: int, offset: int, size: int) -> NDArray[np.float64]:
    """A 1-D array of ``size`` at ``base + 8 offset`` (see :func:`rows_at`)."""
    return carray(_f8ptr(base + 8 * offset), (size,))


@numba.njit(inline="always", error_model="numpy")
def failed(args: RunArgs) -> bool:
    """Whether a call of this run failed (its code is then at ``args[6]``)."""
    return load_i64(args[6]) != 0


@numba.njit(inline="always", error_model="numpy")
def flow(t: float, x: Pointer, p: Pointer, args: RunArgs, dx: Pointer) -> None:
    """``dx = x'`` by the system's flow function."""
    _system(FLOW, K_FLOW, t, x, p, args, dx)


@numba.njit(inline="always", error_model="numpy")
def guard(t: float, x: Pointer, p: Pointer, args: RunArgs, g: Pointer) -> None:
    """``g`` = every rule's event function."""
    _system(GUARD, K_GUARD, t, x, p, args, g)


@numba.njit(inline="always", error_model="numpy")
def jump(k: int, t: float, x: Pointer, p: Pointer, args: RunArgs) -> None:
    """Apply rule ``k``'s jump map to ``x`` in place."""
    _system(JUMP, k, t, x, p, args, x)


flow_call, guard_call, jump_call = flow, guard, jump


@numba.njit(inline="always", error_model="numpy")
def _dense_eval(
    Q: NDArray[np.float64],
    nq: int,
    dop853: bool,
    x0: NDArray[np.float64],
    theta: float,
    out: NDArray[np.float64],
) -> None:
    """Continuous extension at ``theta`` in [0, 1] of the step from ``x0``, into ``out``.

    With the ``nq`` rows ``Q_k`` of :func:`_dense_coeffs` (in ``_kernel_body.py``),
    Horner's scheme in ``theta``: ``x0 + theta (Q_0 + theta (Q_1 + ...))`` for
    Dormand--Prince 5(4), and for DOP853 (Hairer et al.'s form) with the factors
    ``theta`` and ``1 - theta`` alternating: ``x0 + theta (Q_0 + (1 - theta) (Q_1 +
    theta (Q_2 + ...)))``. One pass over the components, each summed in a register over
    the ``nq`` rows (a constant where the kernel inlines it: LLVM unrolls that loop and
    vectorizes the one over components; the sampled event functions evaluate this on
    every step).
    """
    n = x0.shape[0]
    one_minus = 1.0 - theta
    for i in range(n):
        acc = 0.0
        for r in range(nq):
            w = theta if (not dop853 or r % 2 == 0) else one_minus
            acc = (acc + Q[nq - 1 - r, i]) * w
        out[i] = x0[i] + acc


@numba.njit(inline="always", error_model="numpy")
def _any_nonneg(g: NDArray[np.float64]) -> bool:
    for k in range(g.shape[0]):
        if g[k] >= 0.0:
            return True
    return False


@numba.njit(inline="always", error_model="numpy")
def _any_nan(g: NDArray[np.float64]) -> bool:
    for k in range(g.shape[0]):
        if np.isnan(g[k]):
            return True
    return False


@numba.njit(inline="always", error_model="numpy")
def _all_finite(x: NDArray[np.float64]) -> bool:
    for i in range(x.shape[0]):
        if not np.isfinite(x[i]):
            return False
    return True


#: The peak probes' one definition (:mod:`etobs.hybrid.peaks`), compiled into the kernel.
peak_probes = numba.njit(inline="always", error_model="numpy")(_peak_probes)

#: The Zeno rule's one definition (:mod:`etobs.hybrid.zeno`), compiled into the kernel.
zeno_window = numba.njit(inline="always", error_model="numpy")(_zeno_window)

_BODY = Path(__file__).with_name("_kernel_body.py")


def tableau_constants(method: str) -> dict[str, object]:
    """The method's coefficients, laid out as the kernel template reads them."""
    from etobs.hybrid.tableau import TABLEAUS  # imports scipy.integrate: only on a cache miss

    tab = TABLEAUS[method]
    dop853 = tab.dense_a is not None
    s = tab.stages
    return {
        "TA": np.ascontiguousarray(tab.a),
        "TB": np.ascontiguousarray(tab.b),
        "TC": np.ascontiguousarray(tab.c),
        "TE": np.ascontiguousarray(tab.e),
        "TE3": np.ascontiguousarray(tab.e_low if tab.e_low is not None else np.zeros_like(tab.e)),
        "TDA": np.ascontiguousarray(tab.dense_a if dop853 else np.zeros((0, s + 1))),
        "TDC": np.ascontiguousarray(tab.dense_c if dop853 else np.zeros(0)),
        # rows: one per dense coefficient (Dormand--Prince 5(4) stores P transposed)
        "TDD": np.ascontiguousarray(tab.dense_d if dop853 else tab.dense_d.T),
        "N_STAGES": s,
        "N_EXTRA": tab.dense_a.shape[0] if tab.dense_a is not None else 0,
        # the most terms of a sum of stages (_comb): the stages, FSAL and the extra ones
        "MAX_TERMS": s + 1 + (tab.dense_a.shape[0] if tab.dense_a is not None else 0),
        "NQ": 7 if dop853 else tab.dense_d.shape[1],
        "ERR_ORDER": tab.error_order,
        "DOP853": dop853,
    }


def build(method: str) -> Any:
    """Compile the kernel for one method (once per machine: the machine code is cached on disk).

    The template runs with the method's tableau as constants, so numba folds the
    coefficients (see :mod:`etobs.hybrid._jitcache`).
    """
    here = Path(__file__).parent
    namespace = _jitcache.build(
        f"kernel_{method}",
        _BODY,
        lambda: tableau_constants(method),
        # error_model="numpy": 1/0 gives inf (then a named status), never an exception
        {
            "jit": {"error_model": "numpy"},
            "jit_inline": {"error_model": "numpy", "inline": "always"},
            "jit_nogil": {"nogil": True, "error_model": "numpy"},
        },
        depends=tuple(
            here / f
            for f in (
                "_kernel.py",
                "options.py",
                "status.py",
                "tableau.py",
                "zeno.py",
                "peaks.py",
                "../compile/ccall.py",
                "../compile/_stack.py",
            )
        ),
        packages=("scipy",),
    )
    return namespace["_kernel"]
