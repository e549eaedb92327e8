"""The problem's one-run model functions called on batches of runs.

The scipy reference's model and the helpers that evaluate results (``xhat`` on a grid,
the initial state) work on arrays with the runs on axis 0. :class:`ModelCalls` gives
them ``f_p``, ``h``, ``f_o`` and ``psi`` in that form: compiled (one compiled loop over
the rows, see :mod:`etobs.compile.batch`; for evaluating results) or the user's Python
functions called row by row (the reference, and functions numba cannot compile).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from etobs.errors import ModelError
from etobs.hybrid.system import raised

if TYPE_CHECKING:
    from etobs.estimation.problem import EstimationProblem


class ModelCalls:
    """Batched ``f_p, h, f_o, psi`` of a problem (module docstring)."""

    def __init__(self, problem: EstimationProblem, compiled: bool) -> None:
        self.pb = problem
        self.compiled = compiled
        self._fns: dict[str, Any] = {}
        if compiled:
            from etobs.compile.functions import compile_function

            specs = model_specs(problem)
            for name, (fn, spec, params) in specs.items():
                self._fns[name] = (
                    compile_function(fn, spec, name),
                    spec.n_out,
                    np.array(params, dtype=float),
                )

    def _run(self, name: str, t: np.ndarray, *arrays: np.ndarray) -> np.ndarray:
        from etobs.compile.batch import batch_call

        cf, n_out, params = self._fns[name]
        B = t.shape[0]
        ins = [np.ascontiguousarray(a, dtype=float) for a in arrays]
        ins += [np.zeros((B, 0))] * (4 - len(ins))
        out = np.empty((B, n_out))
        st = batch_call(cf.address, 0, np.ascontiguousarray(t, dtype=float), *ins, params, out)
        if st != 1:
            from etobs.compile.functions import describe_failure

            raise ModelError(describe_failure(name, st, n_out) + " during the simulation")
        return out

    def f_p(self, t: np.ndarray, x: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        if self.compiled:
            return self._run("f_p", t, x, u, v)
        pl = self.pb.plant
        return _rows("f_p", pl.n_x, pl.call_f_p, t, x, u, v)

    def h(self, x: np.ndarray) -> np.ndarray:
        if self.compiled:
            return self._run("h", np.zeros(x.shape[0]), x)
        pl = self.pb.plant
        return _rows("h", pl.n_y, lambda xb: pl.call_h(xb), x)

    def f_o(
        self, t: np.ndarray, z: np.ndarray, u: np.ndarray, ybar: np.ndarray, yhat: np.ndarray
    ) -> np.ndarray:
        if self.compiled:
            return self._run("f_o", t, z, u, ybar, yhat)
        ob = self.pb.observer
        return _rows("f_o", ob.n_z, ob.call_f_o, t, z, u, ybar, yhat)

    def psi(self, z: np.ndarray) -> np.ndarray:
        n_x = self.pb.plant.n_x
        if self.pb.observer.psi is None:
            return z[..., :n_x]
        if self.compiled:
            return self._run("psi", np.zeros(z.shape[0]), z)
        ob = self.pb.observer
        return _rows("psi", n_x, lambda zb: ob.call_psi(zb, n_x), z)


def model_specs(problem: EstimationProblem) -> dict[str, tuple[Any, Any, np.ndarray]]:
    """How etobs calls ``f_p``, ``h``, ``f_o`` (and ``psi``): ``name: (function, FunctionSpec, params)``."""
    from etobs.compile.functions import FunctionSpec

    pl, ob = problem.plant, problem.observer
    nx, nz, ny, nu, nv = pl.n_x, ob.n_z, pl.n_y, pl.n_u, pl.n_v
    specs = {
        "f_p": (pl.f_p, FunctionSpec("t, A0, A1, A2", (nx, nu, nv), nx, pl.params.size), pl.params),
        "h": (pl.h, FunctionSpec("A0", (nx,), ny, pl.params.size), pl.params),
        "f_o": (ob.f_o, FunctionSpec("t, A0, A1, A2, A3", (nz, nu, ny, ny), nz, ob.params.size), ob.params),
    }
    if ob.psi is not None:
        specs["psi"] = (ob.psi, FunctionSpec("A0", (nz,), nx, ob.params.size), ob.params)
    return specs


def refuse_complex(name: str, arr: np.ndarray) -> np.ndarray:
    """``arr``, or a ``ModelError`` in the engine's words when ``name`` returned complex values."""
    from etobs.compile.functions import COMPLEX_RESULT

    if np.iscomplexobj(arr):
        raise ModelError(f"`{name}` {COMPLEX_RESULT}")
    return arr


def _rows(name: str, n: int, fn: Any, *batches: np.ndarray) -> np.ndarray:
    """``fn`` called run by run on rows of ``batches`` (read-only), checked: shape ``(B, n)``.

    Any failure, an exception or a result of another shape, is a ``ModelError`` naming
    ``name``: the scipy reference ends that run with ``model_error``.
    """
    B = batches[0].shape[0]
    out = np.empty((B, n))
    for b in range(B):
        args = [a[b] for a in batches]  # rows are new views: read-only without another view
        for a in args:
            if a.ndim:
                a.setflags(write=False)
        try:
            raw = np.asarray(fn(*args))
            if not np.iscomplexobj(raw):  # complex: refused below, as on the engine
                raw = np.asarray(raw, dtype=float)
        except Exception as exc:  # the user's function: any failure ends the run the same way
            raise ModelError(raised(name, exc)) from exc
        arr = refuse_complex(name, raw)
        if arr.shape != (n,):
            raise ModelError(f"`{name}` returned shape {arr.shape}; expected ({n},) for one run")
        out[b] = arr
    return out
