"""The estimation problem as a :class:`~etobs.hybrid.compiled.CompiledSystem` (the engine).

The hybrid model (16)--(22) is the one of :meth:`EstimationProblem.hybrid_system`, run
by the functions of :mod:`etobs.estimation._engine_model`, which are compiled once per
machine. Here the problem becomes data for them: its structure (sizes, which outputs
each node sends, rule and K-function kinds) and the addresses of the user's compiled
functions go into the integer array ``ia``; its numbers (the plant's and observer's
``params``, signal amplitudes, rule parameters) into the run's parameter vector, so
problems that differ only in numbers share every compiled function.

The engine models the paper's base setting with every built-in rule (dynamic, static
and send-on-delta, periodic, relative, generalized), any K-function and any signal.
:func:`engine_support` says why a problem is not covered (input nodes, the observer-copy
hold or a network, until they move to the engine; or a rule of the user's own).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from etobs.errors import InputError
from etobs.estimation.problem import EstimationProblem
from etobs.hybrid.compiled import CompiledSystem
from etobs.model.rules import engine_form_of


@dataclass(frozen=True)
class CompiledProblem:
    """An estimation problem ready for the engine.

    Attributes
    ----------
    system : CompiledSystem
    params : ndarray
        The problem's parameter vector (one run's row).

    """

    system: CompiledSystem
    params: np.ndarray


def engine_support(problem: EstimationProblem) -> str:
    """Why the engine cannot run ``problem`` (``""`` when it can)."""
    used = [
        what
        for what, on in (
            ("input nodes (section 7.3)", bool(problem.input_nodes)),
            (f"hold={problem.hold!r} (Remark 3)", problem.hold != "output"),
            ("a network (delay, loss)", problem.network is not None),
        )
        if on
    ]
    for i, nd in enumerate(problem.nodes):
        if engine_form_of(nd.rule) is None:
            used.append(f"node {i}'s rule {type(nd.rule).__name__} (a rule of your own)")
    if used:
        return "the engine models the base setting with etobs' rules; this problem uses " + ", ".join(used)
    return ""


def compile_problem(problem: EstimationProblem) -> CompiledProblem:
    """Compile (or reuse) the user's functions and lay the problem out for the engine.

    Raises
    ------
    InputError
        When the problem uses something the engine does not model (:func:`engine_support`).
    ModelError
        When a user function cannot be compiled (the message names it).

    """
    from etobs.compile.functions import FunctionSpec, compile_function
    from etobs.estimation import _engine_model as em

    why = engine_support(problem)
    if why:
        raise InputError(f"backend='engine': {why}; use backend='numpy' or 'scipy'")
    pl, ob = problem.plant, problem.observer
    nx, nz, ny, nu, nv = pl.n_x, ob.n_z, pl.n_y, pl.n_u, pl.n_v
    keep: list[Any] = []
    names = ["f_p", "h", "f_o", "psi", "u", "v", "m"]

    def compiled(fn: Any, spec: FunctionSpec, name: str) -> int:
        cf = compile_function(fn, spec, name)
        keep.append(cf)
        return cf.address

    numbers: list[np.ndarray] = []
    n_numbers = 0

    def put(values: Any) -> int:
        nonlocal n_numbers
        arr = np.asarray(values, dtype=float).reshape(-1)
        numbers.append(arr)
        n_numbers += arr.size
        return n_numbers - arr.size

    h = np.zeros(em.N_HEADER, dtype=np.int64)
    h[em.H_NX], h[em.H_NZ], h[em.H_NY], h[em.H_NU], h[em.H_NV] = nx, nz, ny, nu, nv
    h[em.H_NN] = problem.n_nodes
    h[em.H_TP0], h[em.H_NTP] = put(pl.params), pl.params.size
    h[em.H_TO0], h[em.H_NTO] = put(ob.params), ob.params.size
    h[em.H_FP] = compiled(pl.f_p, FunctionSpec("t, A0, A1, A2", (nx, nu, nv), nx, pl.params.size), "f_p")
    h[em.H_H] = compiled(pl.h, FunctionSpec("A0", (nx,), ny, pl.params.size), "h")
    h[em.H_FO] = compiled(
        ob.f_o, FunctionSpec("t, A0, A1, A2, A3", (nz, nu, ny, ny), nz, ob.params.size), "f_o"
    )
    if ob.psi is not None:
        h[em.H_PSI] = 1
        h[em.H_PSIA] = compiled(ob.psi, FunctionSpec("A0", (nz,), nx, ob.params.size), "psi")
    for w, name in enumerate(("u", "v", "m")):
        kind, values, fn = getattr(problem, name).engine_form()
        base = em.H_SIG + 3 * w
        h[base], h[base + 2] = kind, put(values)
        if fn is not None:
            h[base + 1] = compiled(fn, FunctionSpec("t", (), getattr(problem, name).dim), f"signal {name}")
    lay = problem.layout
    out_idx = np.concatenate(lay.outputs).astype(np.int64)
    nodes = np.zeros((problem.n_nodes, em.NODE_W), dtype=np.int64)
    ptr = 0
    for i, nd in enumerate(problem.nodes):
        form = engine_form_of(nd.rule)
        assert form is not None  # engine_support checked it
        row = nodes[i]
        row[em.R_KIND] = form.kind
        rule_numbers = np.zeros(em.RULE_W)
        for key, val in form.numbers.items():
            rule_numbers[getattr(em, f"P_{key.upper()}")] = val
        for slot, fn in enumerate(form.kfunctions):
            kname = ("gamma", "alpha", "gamma_check", "d_prime")[slot]
            names_slot = f"{kname} of node {i}"
            if fn is None:
                continue
            kind, k1, k2, user = _kform(fn)
            row[em.R_FK + slot] = kind
            rule_numbers[em.P_F + 2 * slot : em.P_F + 2 * slot + 2] = k1, k2
            if user is not None:
                row[em.R_FA + slot] = compiled(user, FunctionSpec("t", (), 0), names_slot)
        row[em.R_P0] = put(rule_numbers)
        row[em.R_S0] = lay.rule[i].start
        row[em.R_OUT_A], row[em.R_OUT_B] = ptr, ptr + len(nd.outputs)
        ptr += len(nd.outputs)
        names += [f"{k} of node {i}" for k in ("gamma", "alpha", "gamma_check", "d_prime")]
    # scratch: u, v, xhat, yhat, ytilde, m, one K-function value
    w = np.cumsum([0, nu, nv, nx, ny, ny, ny, 1])
    h[em.H_WU], h[em.H_WV], h[em.H_WXH], h[em.H_WYH], h[em.H_WY], h[em.H_WM], h[em.H_WK] = w[:-1]
    h[em.H_NWORK] = w[-1]
    h[em.H_Z0], h[em.H_YB0] = lay.z.start, lay.ybar.start
    h[em.H_N], h[em.H_NP] = lay.n, n_numbers
    h[em.H_OUT] = em.N_HEADER
    h[em.H_NODES] = em.N_HEADER + out_idx.size
    ia = np.concatenate([h, out_idx, nodes.reshape(-1)])
    ia[em.H_LEN] = ia.size
    params = np.concatenate(numbers) if numbers else np.zeros(0)
    system = CompiledSystem(
        n=lay.n,
        n_rules=problem.n_nodes,
        addresses=(em.est_flow.address, em.est_guard.address, em.est_jump.address),
        ia=ia,
        n_params=params.size,
        n_work=int(w[-1]),
        rule_names=tuple(nd.name or f"node{i}" for i, nd in enumerate(problem.nodes)),
        function_names=tuple(names),
        keep=tuple(keep),
    )
    return CompiledProblem(system=system, params=params)


def _kform(fn: Any) -> tuple[int, float, float, Any]:
    """(kind, k1, k2, user function or None) of a K-function slot (a KFunction or a constant)."""
    from etobs.model.functions import CONSTANT

    if isinstance(fn, float | int):
        return CONSTANT, float(fn), 0.0, None
    return fn.engine_form()
