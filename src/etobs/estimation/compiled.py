"""The estimation problem as a :class:`~etobs.hybrid.compiled.CompiledSystem` (numba backend).

The hybrid model (16)--(22) is the one of :meth:`EstimationProblem.hybrid_system`,
compiled for one run at a time: the plant and observer must carry numba-compiled
versions of their functions (``Plant(jit=JitPlant(...))``,
``Observer(jit=JitObserver(...))``); the signals ``u, v, m`` must be :class:`Zero`,
:class:`Constant` or :class:`Sinusoid`; the rules :class:`DynamicRule`,
:class:`StaticRule` or :class:`PeriodicRule` with :class:`Linear`, :class:`Quadratic`
or :class:`Power` functions. Every number of the problem (rule parameters, signal
amplitudes, the plant's and observer's ``theta``) travels in the run's parameter
vector, so problems that differ only in numbers share one compiled kernel: a sweep
over rows compiles once per process.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from etobs.errors import InputError
from etobs.estimation.problem import EstimationProblem
from etobs.hybrid import _jitcache
from etobs.hybrid.compiled import CompiledSystem, require_numba
from etobs.model.functions import KFunction, Linear, Power, Quadratic
from etobs.model.rules import DynamicRule, PeriodicRule, StaticRule
from etobs.model.signals import Constant, Signal, Sinusoid, Zero

_BODY = Path(__file__).with_name("_compiled_body.py")
RS = 9  # numbers per node in the parameter vector (see the template)
_KINDS = {DynamicRule: 0, StaticRule: 1, PeriodicRule: 2}


@dataclass(frozen=True)
class CompiledProblem:
    """An estimation problem ready for the compiled solver.

    Attributes
    ----------
    system : CompiledSystem
    params : ndarray
        The problem's parameter vector (one run's row).

    """

    system: CompiledSystem
    params: np.ndarray


def compile_problem(problem: EstimationProblem) -> CompiledProblem:
    """Build (or reuse) the compiled hybrid model of ``problem`` and its parameters.

    Raises
    ------
    InputError
        When a part of the problem has no compiled form (the message names it).

    """
    require_numba("backend='numba'")
    plant, obs = problem.plant, problem.observer
    if problem.extended:
        used = [
            what
            for what, on in (
                ("input_nodes (section 6.3)", bool(problem.input_nodes)),
                (f"hold={problem.hold!r} (Remark 3)", problem.hold != "output"),
                ("a network (delay, loss)", problem.network is not None),
            )
            if on
        ]
        raise InputError(
            f"backend='numba' models the paper's base setting only; this problem uses {', '.join(used)}: "
            "use backend='fast'"
        )
    if plant.jit is None:
        raise InputError(
            f"backend='numba' needs compiled plant functions: give Plant(jit=JitPlant(f_p, h)); "
            f"plant {plant.name!r} has none"
        )
    if obs.jit is None:
        raise InputError(
            f"backend='numba' needs compiled observer functions: give Observer(jit=JitObserver(f_o)); "
            f"observer {obs.name!r} has none"
        )
    parts = [plant.jit.theta, obs.jit.theta]
    for name in ("u", "v", "m"):
        parts.append(_signal_params(name, getattr(problem, name)))
    kinds = []
    for i, nd in enumerate(problem.nodes):
        row, kind = _rule_params(i, nd.name, nd.rule)
        parts.append(row)
        kinds.append(kind)
    params = np.concatenate([np.asarray(pp, dtype=float).reshape(-1) for pp in parts])

    lay = problem.layout
    sizes = dict(
        NX=plant.n_x,
        NZ=obs.n_z,
        NY=plant.n_y,
        NU=plant.n_u,
        NV=plant.n_v,
        NTP=plant.jit.theta.size,
        NTO=obs.jit.theta.size,
        N=lay.n,
    )
    # the problem's structure is compiled in (rows of a sweep share it)
    structure = dict(
        OUT_PTR=np.concatenate([[0], np.cumsum([len(nd.outputs) for nd in problem.nodes])]),
        OUT_IDX=np.concatenate(lay.outputs),
        RULE_KIND=np.array([k[0] for k in kinds]),
        GAMMA_KIND=np.array([k[1] for k in kinds]),
        ALPHA_KIND=np.array([k[2] for k in kinds]),
        S_OFF=np.array([sl.start for sl in lay.rule]),
    )
    structure = {k: np.asarray(a, dtype=np.int64) for k, a in structure.items()}
    fns = _functions(plant.jit.f_p, plant.jit.h, obs.jit.f_o, obs.jit.psi, sizes, structure)
    names = tuple(nd.name or f"node{i}" for i, nd in enumerate(problem.nodes))
    system = CompiledSystem(
        n=lay.n,
        n_rules=problem.n_nodes,
        flow=fns["est_flow"],
        guard=fns["est_guard"],
        jump=fns["est_jump"],
        n_params=params.size,
        n_work=fns["n_work"],
        rule_names=names,
    )
    return CompiledProblem(system=system, params=params)


def _signal_params(name: str, sig: Signal) -> np.ndarray:
    """``(amplitude, offset, omega, phase)`` of a signal the template can evaluate."""
    dim = sig.dim
    if isinstance(sig, Zero):
        return np.zeros(2 * dim + 2)
    if isinstance(sig, Constant):
        return np.concatenate([np.zeros(dim), sig.value, [0.0, 0.0]])
    if isinstance(sig, Sinusoid):
        return np.concatenate([sig.amplitude, sig.offset, [sig.omega, sig.phase]])
    raise InputError(
        f"backend='numba' evaluates signals of type Zero, Constant or Sinusoid; "
        f"signal `{name}` is a {type(sig).__name__} (use backend='fast')"
    )


def _kfun(node: str, what: str, fn: KFunction) -> tuple[int, float, float]:
    if isinstance(fn, Linear):
        return 0, fn.a, 0.0
    if isinstance(fn, Quadratic):
        return 1, fn.ell, 0.0
    if isinstance(fn, Power):
        return 2, fn.k, fn.p
    raise InputError(
        f"backend='numba' supports Linear, Quadratic and Power functions; {what} of node {node!r} "
        f"is a {type(fn).__name__} (use backend='fast')"
    )


def _rule_params(i: int, name: str, rule: Any) -> tuple[np.ndarray, tuple[int, int, int]]:
    node = name or f"node{i}"
    kind = _KINDS.get(type(rule))
    if kind is None:
        raise InputError(
            f"backend='numba' supports DynamicRule, StaticRule and PeriodicRule; node {node!r} "
            f"has a {type(rule).__name__} (use backend='fast')"
        )
    row = np.zeros(RS)
    gk = ak = 0
    if isinstance(rule, DynamicRule):
        gk, row[4], row[5] = _kfun(node, "gamma", rule.gamma)
        ak, row[6], row[7] = _kfun(node, "alpha", rule.alpha)
        row[0], row[1], row[2], row[3] = rule.sigma, rule.c, rule.b, rule.eps
    elif isinstance(rule, StaticRule):
        gk, row[4], row[5] = _kfun(node, "gamma", rule.gamma)
        row[3] = rule.eps
    else:
        row[8] = rule.period
    return row, (kind, gk, ak)


_CACHE: dict[tuple[Any, ...], dict[str, Any]] = {}
_LOCK = threading.Lock()


def _functions(
    f_p: Any, h: Any, f_o: Any, psi: Any, sizes: dict[str, int], structure: dict[str, np.ndarray]
) -> dict[str, Any]:
    """Compile the template for these user functions and sizes (memoized per process).

    The machine code is cached on disk when the user's functions can be imported by
    name (see :mod:`etobs.hybrid._jitcache`).
    """
    key = (
        id(f_p),
        id(h),
        id(f_o),
        id(psi),
        tuple(sorted(sizes.items())),
        tuple((k, tuple(a.tolist())) for k, a in sorted(structure.items())),
    )
    with _LOCK:
        if key in _CACHE:
            return _CACHE[key]
        require_numba()
        nx, nz, ny, nu, nv = (sizes[k] for k in ("NX", "NZ", "NY", "NU", "NV"))
        tp1 = sizes["NTP"]
        to1 = tp1 + sizes["NTO"]
        su0 = to1
        sv0 = su0 + 2 * nu + 2
        sm0 = sv0 + 2 * nv + 2
        r0 = sm0 + 2 * ny + 2
        wu, wv = 0, nu
        wxh = wv + nv
        wyh = wxh + nx
        wy = wyh + ny
        wm = wy + ny
        constants = dict(
            HAS_PSI=psi is not None,
            NX=nx,
            NZ=nz,
            NY=ny,
            NU=nu,
            NV=nv,
            Z0=nx,
            YB0=nx + nz,
            TP0=0,
            TP1=tp1,
            TO0=tp1,
            TO1=to1,
            SU0=su0,
            SV0=sv0,
            SM0=sm0,
            R0=r0,
            RS=RS,
            WU=wu,
            WV=wv,
            WXH=wxh,
            WYH=wyh,
            WY=wy,
            WM=wm,
            NN=int(structure["RULE_KIND"].size),
            **structure,
        )
        functions = {"F_P": f_p, "H": h, "F_O": f_o}
        if psi is not None:
            functions["PSI"] = psi
        namespace = _jitcache.build(
            "estimation",
            _BODY,
            constants,
            functions,
            {"jit": {}, "jit_inline": {"inline": "always"}},
            inline=True,
        )
        out = {k: namespace[k] for k in ("est_flow", "est_guard", "est_jump")}
        out["n_work"] = wm + ny
        out["_keep"] = (f_p, h, f_o, psi)  # ids in the key stay valid
        _CACHE[key] = out
        return out
