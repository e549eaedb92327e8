"""Is a model's lane form right, and is it vector code? Checked once per compiled model.

The engine calls a model's lane form (``est_lanes`` of :mod:`etobs.estimation._model_source`)
once per stage for :data:`~etobs.estimation._model_source.LANE_WIDTH` runs. It must give
every lane the numbers the one-run form (``est``) gives that run alone, bit for bit (the
engine's results must not depend on a run's lane), and it is only worth its name when the
compiler turned its loop over lanes into vector instructions. :class:`LaneProbe` calls
both forms on the same random states: :meth:`~LaneProbe.agrees` compares their numbers,
:meth:`~LaneProbe.cost` times them in compiled code (nanoseconds per run and call), and
:func:`blockers` reads the user's functions for what keeps a loop from vectorizing.
"""

from __future__ import annotations

import dis
import time
import types
from typing import Any

import numba
import numpy as np

from etobs.compile.ccall import ccall

#: Names in a user function's code that keep a loop over lanes from becoming vector code.
_ALLOCATES = {"array", "zeros", "empty", "ones", "copy", "concatenate", "stack", "hstack", "vstack", "append"}
_LIBM = {"exp", "log", "log10", "log2", "tan", "tanh", "sinh", "cosh", "arctan", "arctan2", "atan", "atan2"}
_LIBM |= {"arcsin", "arccos", "asin", "acos", "power", "pow", "expm1", "log1p", "erf", "gamma"}


class LaneProbe:
    """Both forms of one compiled model on the same ``W`` random states.

    Parameters
    ----------
    one, lanes : CompiledFunction
        ``est`` and ``est_lanes`` (:func:`etobs.compile.functions.compile_module`).
    states : ndarray, shape (width, n)
        One valid hybrid state per lane (a network's packet records must be ones, their
        counts index arrays); the lane form computes ``width`` lanes.
    n_work, n_rules : int
        Scratch length (with its extra entry), event functions.
    params : ndarray
        The model's numbers (one run's), put in every lane.

    """

    def __init__(
        self, one: Any, lanes: Any, states: np.ndarray, n_work: int, n_rules: int, params: np.ndarray
    ) -> None:
        rng = np.random.default_rng(0)
        W, n = states.shape
        self.one, self.lanes, self.n, self.n_rules, self.W = one, lanes, n, n_rules, W
        self.q1 = np.ascontiguousarray(states, dtype=float)  # each lane's state, contiguous
        self.q = np.ascontiguousarray(self.q1.T)
        self.ts = np.ascontiguousarray(rng.uniform(0.0, 1.0, W))
        p = params if params.size else np.zeros(1)
        self.P1 = np.ascontiguousarray(np.repeat(p.reshape(1, -1), W, axis=0))  # one row per lane
        self.rows = max(n, n_rules, 1)
        self.work = np.zeros((n_work, W))
        self.work1 = np.zeros(n_work)
        self.cf = np.zeros(2)

    def _lanes(self, k: int) -> tuple[np.ndarray, np.ndarray, int]:
        out = np.zeros((self.rows, self.W))
        ia = np.zeros(3 + self.W, dtype=np.int64)
        ia[1] = ia[2] = self.W
        ok = _call_lanes(self.lanes.address, k, 1, self.q, self.ts, self.work, self.cf, ia, self.P1, out)
        return out, ia[3:].copy(), int(ok)

    def _ones(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        out = np.zeros((self.W, self.rows))
        st = np.zeros(self.W, dtype=np.int64)
        ia = np.zeros(3 + self.W, dtype=np.int64)
        _call_ones(self.one.address, k, 1, self.q1, self.ts, self.work1, self.cf, ia, self.P1, out, st)
        return out, st

    def agrees(self) -> bool:
        """Whether every lane's flow and guard (and status) equal the one-run form's, bit for bit.

        True also when a model function raised on these states (nothing to compare: numba
        printed the exception).
        """
        for k, width in ((-1, self.n), (-2, self.n_rules)):
            out, st, ok = self._lanes(k)
            if ok != 1:
                return True
            one, st1 = self._ones(k)
            if not np.array_equal(st, st1):
                return False
            good = st1 == 1
            if not np.array_equal(out[:width, good], one[good, :width].T, equal_nan=True):
                return False
        return True

    def cost(self, reps: int = 200) -> tuple[float, float]:
        """Nanoseconds per run and call of the flow: ``(one-run form, lane form)``, the best of 5 timings."""
        ia = np.zeros(3 + self.W, dtype=np.int64)
        ia[1] = ia[2] = self.W
        out = np.zeros((self.rows, self.W))
        out1 = np.zeros((self.W, self.rows))
        st = np.zeros(self.W, dtype=np.int64)
        best_one = best_lanes = np.inf
        for _ in range(5):
            t = time.perf_counter()
            _call_ones(
                self.one.address, -1, reps, self.q1, self.ts, self.work1, self.cf, ia, self.P1, out1, st
            )
            best_one = min(best_one, time.perf_counter() - t)
            t = time.perf_counter()
            _call_lanes(self.lanes.address, -1, reps, self.q, self.ts, self.work, self.cf, ia, self.P1, out)
            best_lanes = min(best_lanes, time.perf_counter() - t)
        scale = 1e9 / (reps * self.W)
        return best_one * scale, best_lanes * scale


def blockers(users: dict[str, Any], names: dict[str, str]) -> list[str]:
    """What in the user's functions keeps a loop over lanes from becoming vector code, in words.

    Read from their code (and the Python functions they call): arrays made per call,
    libm functions other than ``sin``/``cos``/``sqrt``/``abs`` (which have vector forms),
    loops, and functions already compiled with ``@njit`` (compiled as written: their
    ``np.sin`` is libm's).
    """
    out = []
    for glob, fn in users.items():
        found: list[str] = []
        _scan(fn, found, set())
        if found:
            out.append(f"`{names.get(glob, glob)}` {', '.join(sorted(set(found)))}")
    return out


def _scan(fn: Any, found: list[str], seen: set[int]) -> None:
    if id(fn) in seen:
        return
    seen.add(id(fn))
    if hasattr(fn, "py_func"):
        found.append("is an @njit function (compiled as written: its sin and cos are libm's)")
        return
    if not isinstance(fn, types.FunctionType):
        return
    code = fn.__code__
    names = set(code.co_names)
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            names |= set(const.co_names)
    if names & _ALLOCATES:
        found.append(f"makes arrays per call ({', '.join(sorted(names & _ALLOCATES))})")
    if names & _LIBM:
        found.append(f"calls libm ({', '.join(sorted(names & _LIBM))})")
    if any(ins.opname == "FOR_ITER" for ins in dis.get_instructions(code)):
        found.append("has a loop")
    for name in names:
        value = fn.__globals__.get(name)
        if isinstance(value, types.FunctionType) or hasattr(value, "py_func"):
            _scan(value, found, seen)


@numba.njit(cache=True)
def _call_lanes(addr, k, reps, q, ts, work, cf, ia, P1, out):  # type: ignore[no-untyped-def]
    """Call the lane form at ``addr`` ``reps`` times on all lanes; its last status.

    At module level, not made in a function: numba keys its disk cache of a closure by
    the closure's cells, which differ in every process, so a closure was compiled again
    (0.44 s, the lane check's whole cost) and written to a new cache file in every
    process that checked a model, hundreds of files in a test run.
    """
    ok = 1
    for _ in range(reps):
        ok = ccall(addr, k, 0.0, q, ts, work, cf, ia, P1, out)  # type: ignore[call-arg]
    return ok


@numba.njit(cache=True)
def _call_ones(addr, k, reps, q1, ts, work, cf, ia, P1, out1, st):  # type: ignore[no-untyped-def]
    """Call the one-run form at ``addr`` ``reps`` times on each lane's state in turn."""
    for _ in range(reps):
        for lane in range(q1.shape[0]):
            st[lane] = ccall(addr, k, ts[lane], q1[lane], cf, work, cf, ia, P1[lane], out1[lane])  # type: ignore[call-arg]
