"""The hybrid model (16)--(22) of one problem as Python source, for the engine to compile.

:func:`model_source` writes the flow, guard and jump of one run for a given problem
*structure*: the sizes, which outputs (or inputs, section 7.3) each node sends, the
kinds of its rule, K-functions and signals, the hold (Remark 3), the network's links,
and the user's functions, which the generated code calls directly (numba compiles them
into it, so a call costs what an inlined one does). It is the model of
:mod:`etobs.estimation.assembly` (jump rules, order; the observer's flow as
:func:`~etobs.estimation.assembly.observer_flow` computes it) on the state layout of
:mod:`etobs.estimation.layout`, for one run; each rule's flow, trigger and reset are its
kind's formulas (:mod:`etobs.formulas`), called with the arguments the kind declares; the
network's packets go through the same scalar functions
(:mod:`etobs.estimation._network_jumps`). The problem's
*numbers* (the plant's and observer's ``params``, signal amplitudes, rule parameters) are
read from the run's parameter vector ``p`` at fixed offsets, so problems that differ only
in numbers share the compiled model.

Every function of the generated module returns ``1`` (OK) or a failure code ``16 * slot +
failure`` naming the user function that failed (slots in :data:`FUNCTIONS`; failures as
in :mod:`etobs.compile.functions`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from etobs import formulas as fm
from etobs.compile.functions import FunctionSpec, params_call
from etobs.estimation import _network_jumps
from etobs.estimation.calls import model_specs
from etobs.hybrid.compiled import LANES
from etobs.model.fates import LINK_WIDTH
from etobs.model.rules import EngineForm
from etobs.model.signals import CONSTANT as SIG_CONSTANT
from etobs.model.signals import FUNCTION as SIG_FUNCTION
from etobs.model.signals import SINUSOID as SIG_SINUSOID
from etobs.model.signals import ZERO as SIG_ZERO

#: Names of the failure slots (slot ``s`` is ``FUNCTIONS[s - 1]``). Slots
#: 1-3 are the kernel's (:mod:`etobs.hybrid._kernel`): a user function that raises makes
#: the whole model return 0 (numba prints the exception), known only as the model's call.
FUNCTIONS = (
    "the estimation model's flow",
    "the estimation model's guard",
    "the estimation model's jump",
    "f_p",
    "h",
    "f_o",
    "psi",
    "signal u",
    "signal v",
    "signal m",
)
S_FP, S_H, S_FO, S_PSI, S_SIG = 4, 5, 6, 7, 8


def _helpers() -> dict[str, Callable[..., Any]]:
    """The kinds' formulas the generated code calls, by global name (``K_LINEAR``, ``R_DYNAMIC_TRIGGER``).

    The one implementation of each in :mod:`etobs.formulas` (numba compiles and inlines it).
    """
    from etobs.compile import vecmath

    out: dict[str, Callable[..., Any]] = {f"K_{k.name.upper()}": k.value for k in fm.K_KINDS.values()}
    out["SIN"] = vecmath.sin  # vectorizes in the lane form (a libm call does not)
    for k in fm.K_KINDS.values():  # a sampled filter's period (etobs.formulas.eta_period)
        if k is not fm.CONSTANT:
            out[f"ETA_PERIOD_{k.name.upper()}"] = fm.eta_period(k)
    for kind in fm.RULE_KINDS.values():
        for what in ("trigger", "flow", "reset"):
            formula = getattr(kind, what)
            if formula is not None:
                out[_formula_name(kind, what)] = formula.fn
    return out


def _formula_name(kind: fm.RuleKind, what: str) -> str:
    """The global name of the formula ``what`` (trigger, flow, reset) of ``kind``."""
    return f"R_{kind.name.upper()}_{what.upper()}"


@dataclass
class ModelSource:
    """The generated module: its text, the user functions it calls, and the numbers ``p``.

    Attributes
    ----------
    text : str
        Python source defining the C function ``est``: the flow (``k = -1``), the guard
        (``k = -2``) or the jump of node ``k``, returning a status (module docstring).
    users : dict
        The user functions by the global name the text calls them with.
    names : dict
        How messages name each of them (``"f_p"``, ``"gamma of node 0"``, ...).
    specs : dict
        How each of them is called (:class:`~etobs.compile.functions.FunctionSpec`).
    helpers : dict
        etobs' own scalar functions the text calls (the network's), by global name.
    numbers : list of ndarray
        The blocks of the parameter vector, in order.
    n_work : int
        Length of the run's scratch array.
    lanes : bool
        Whether the text defines the lane forms ``est_lanes`` and ``est_lanes_shared``
        (:data:`LANE_STACK`).

    """

    text: str = ""
    users: dict[str, Callable[..., Any]] = field(default_factory=dict)
    helpers: dict[str, Callable[..., Any]] = field(default_factory=dict)
    names: dict[str, str] = field(default_factory=dict)
    specs: dict[str, FunctionSpec] = field(default_factory=dict)
    numbers: list[np.ndarray] = field(default_factory=list)
    n_work: int = 0
    lanes: bool = False
    _size: int = 0

    @property
    def size(self) -> int:
        """Length of ``p`` so far."""
        return self._size

    def put(self, values: Any) -> int:
        """Append a block of numbers to ``p``; its offset."""
        arr = np.asarray(values, dtype=float).reshape(-1)
        self.numbers.append(arr)
        self._size += arr.size
        return self._size - arr.size

    def user(self, fn: Callable[..., Any], glob: str, name: str, spec: FunctionSpec) -> str:
        """Register a user function under the global name ``glob``; returns ``glob``.

        ``spec`` says how it is called, to compile it on its own and name it when the
        model cannot be compiled.
        """
        self.users[glob] = fn
        self.names[glob] = name
        self.specs[glob] = spec
        return glob


@dataclass(frozen=True)
class _Node:
    """What the generated code needs of one node (an output node or an input node).

    Per component: ``sq`` the index in ``q`` of the value the node last sent, ``sw`` the
    index in ``work`` of the value it would send now (``ytilde_i``, ``ytilde_i - yhat_i``
    with the observer-copy hold, or ``u_k``), ``mw`` that of the current measurement
    its rule may read (``ytilde_i`` or ``u_k``).
    """

    index: int
    form: EngineForm
    sq: tuple[int, ...]
    sw: tuple[int, ...]
    mw: tuple[int, ...]
    s0: int  # index of its rule state in q (-1: none)
    p0: int  # offset of its numbers in p
    kforms: tuple[tuple[str, str | None], ...]  # per slot of its kind: (K kind's name or "", user global)
    sampled: bool = False  # a Sampled rule: its state ends with the next sample's index and the mark

    @property
    def sk(self) -> int:
        """Index in ``q`` of a sampled node's next sample index ``k`` (its mark follows)."""
        return self.s0 if self.form.kind.state == "none" else self.s0 + 1

    @property
    def mark(self) -> int:
        """Offset from ``s0`` of a sampled node's mark (a transmission due)."""
        return self.sk - self.s0 + 1

    @property
    def tp(self) -> int:
        """Offset in its numbers of a sampled node's period (its phase follows).

        After the kind's numbers and two per K-function slot (:func:`_node`).
        """
        return len(self.form.kind.numbers) + 2 * len(self.form.kind.slots)

    @property
    def size(self) -> int:
        return len(self.sq)


@dataclass(frozen=True)
class _Group:
    """Nodes of one kind (rule, K-functions, number of outputs): the generated code loops over them.

    A loop over a group, with the nodes' offsets in constant tables, keeps the model's
    text (and its compile time) independent of the number of nodes; its trip count and
    tables are constants, so the compiler unrolls short ones.
    """

    index: int
    nodes: tuple[_Node, ...]

    @property
    def first(self) -> _Node:
        return self.nodes[0]

    def tables(self) -> list[str]:
        """The group's constant tables: node index, rule-state index, numbers offset, components."""
        g = self.index
        rows = {
            "I": [nd.index for nd in self.nodes],
            "S": [nd.s0 for nd in self.nodes],
            "P": [nd.p0 for nd in self.nodes],
        }
        out = [f"G{g}{k} = np.array({v!r}, dtype=np.int64)" for k, v in rows.items()]
        for key in ("sq", "sw", "mw"):
            cols = [list(getattr(nd, key)) for nd in self.nodes]
            out.append(f"G{g}{key.upper()} = np.array({cols!r}, dtype=np.int64)")
        return out

    def loop(self) -> list[str]:
        """Loop header and the node's locals ``jj, i, s0, r``."""
        return [f"for jj in range({len(self.nodes)}):", *("    " + t for t in self.locals("jj"))]

    def locals(self, jj: str) -> list[str]:
        """The locals of the node at position ``jj`` (a name) of the group.

        ``i`` is the node's index, ``s0`` the index in ``q`` of its rule state and ``r``
        the offset of its numbers in ``p``. Its components are read from the tables in
        loops (:meth:`norm`, :meth:`send`), not unrolled: code unrolled over thousands of
        components took minutes to compile (100 components: 278 s) and nested so deep
        that Python's compiler ran out of recursion at 5,000.
        """
        g = self.index
        return [f"i = G{g}I[{jj}]", f"s0 = G{g}S[{jj}]", f"r = G{g}P[{jj}]"]

    def norm(self, jj: str, relative: bool, out: str) -> list[str]:
        """``out = |e_i| = |sent - current|``, or ``|current measurement|`` when ``relative``.

        The squares are summed from the first component on, as the unrolled sum did.
        """
        g = self.index
        d = f"work[G{g}MW[{jj}, cc]]" if relative else f"(q[G{g}SQ[{jj}, cc]] - work[G{g}SW[{jj}, cc]])"
        return [
            "acc = 0.0",
            f"for cc in range({self.first.size}):",
            f"    dd = {d}",
            "    acc += dd * dd",
            f"{out} = np.sqrt(acc)",
        ]

    def send(self, jj: str) -> list[str]:
        """The node's current values into its held values (eq. (22): ``e_i+ = 0``)."""
        g = self.index
        return [
            f"for cc in range({self.first.size}):",
            f"    q[G{g}SQ[{jj}, cc]] = work[G{g}SW[{jj}, cc]]",
        ]


def _groups(nodes: list[_Node]) -> list[_Group]:
    """The nodes grouped by kind, in the order of their first node."""
    keyed: dict[tuple[Any, ...], list[_Node]] = {}
    for nd in nodes:
        keyed.setdefault((nd.form.kind.name, nd.kforms, nd.size, nd.sampled), []).append(nd)
    return [_Group(g, tuple(members)) for g, members in enumerate(keyed.values())]


@dataclass(frozen=True)
class _Where:
    """Where the generated code finds things: sizes, offsets in ``q``, ``work`` and ``p``."""

    nx: int
    nz: int
    ny: int
    nu: int
    nv: int
    z0: int  # q[z0:z0 + nz] is z
    yb0: int  # q[yb0:yb0 + ny] is ybar
    w: dict[str, int]  # offsets in work of u, v, xhat, yhat, ytilde, m, [ubar], [innov, ybar_o]
    pp: str | None  # the plant's params as an expression, or None
    po: str | None  # the observer's params
    psi: bool
    signals: tuple[tuple[int, int, int], ...]  # (kind, offset in p, dim) of u, v, m
    held_u: tuple[tuple[int, int], ...]  # (input k, index in q of ubar_k) of the input nodes
    innovation: bool  # Remark 3: nodes send ytilde_i - yhat_i
    n_ch: int  # nodes of every kind
    network: int  # offset in p of the network's numbers (-1: no network)
    run: int  # index in q of the run's index (-1: no network)


def model_source(problem: Any, forms: list[EngineForm]) -> ModelSource:
    """The model of ``problem`` (an :class:`EstimationProblem`) as source.

    ``forms`` are the engine forms of the nodes' rules, output nodes then input nodes
    (:func:`etobs.model.rules.engine_form_of`).
    """
    pl, ob, lay = problem.plant, problem.observer, problem.layout
    src = ModelSource()
    src.helpers.update(_helpers())
    nx, nz, ny, nu, nv = pl.n_x, ob.n_z, pl.n_y, pl.n_u, pl.n_v
    tp = src.put(pl.params)
    to = src.put(ob.params)
    npp, npo = pl.params.size, ob.params.size
    for name, (fn, spec, _) in model_specs(problem).items():
        src.user(fn, name.upper(), name, spec)  # globals F_P, H, F_O, PSI
    innovation = problem.hold == "innovation"
    held_u = tuple(
        (int(k), int(h))
        for ch in lay.channels
        if ch.kind == "u"
        for k, h in zip(ch.index, ch.held, strict=True)
    )
    # scratch: u, v, xhat, yhat, ytilde, m, then the held input and the copy hold's signals
    parts = [("u", nu), ("v", nv), ("xhat", nx), ("yhat", ny), ("ytilde", ny), ("m", ny)]
    if held_u:
        parts.append(("ubar", nu))
    if innovation:
        parts += [("innov", ny), ("ybar_o", ny)]
    offsets = np.cumsum([0] + [n for _, n in parts]).tolist()
    w = {name: int(off) for (name, _), off in zip(parts, offsets, strict=False)}
    src.n_work = offsets[-1]
    signals = []
    for name in ("u", "v", "m"):
        sig = getattr(problem, name)
        kind, values, fn = sig.engine_form()
        off = src.put(values)
        if fn is not None:
            src.user(fn, f"SIG_{name.upper()}", f"signal {name}", FunctionSpec("t", (), sig.dim))
        signals.append((kind, off, sig.dim))
    network = -1
    if problem.network is not None:
        seed = problem.network.seed
        network = src.put([seed >> 32, seed & 0xFFFFFFFF])  # two exact halves
        for ch in lay.channels:
            assert ch.link is not None
            src.put(ch.link.form())
        for glob, fn in (("NET_SEND", _network_jumps.send), ("NET_DELIVER", _network_jumps.deliver)):
            src.helpers[glob] = fn
        src.helpers["NET_GAP"] = _network_jumps.arrival_gap
    nodes = [
        _node(src, c, ch, form, w, innovation)
        for c, (ch, form) in enumerate(zip(lay.channels, forms, strict=True))
    ]
    at = _Where(
        nx,
        nz,
        ny,
        nu,
        nv,
        lay.z.start,
        lay.ybar.start,
        w,
        f"p[{tp}:{tp + npp}]" if npp else None,
        f"p[{to}:{to + npo}]" if npo else None,
        ob.psi is not None,
        tuple(signals),
        held_u,
        innovation,
        len(nodes),
        network,
        -1 if lay.run is None else lay.run,
    )
    groups = _groups(nodes)
    c = _Code()
    for grp in groups:
        c.lines(grp.tables())
    # jump: node k is in group JG[k], at position JP[k]
    jg = [next(grp.index for grp in groups if nd in grp.nodes) for nd in nodes]
    jp = [next(grp.nodes.index(nd) for grp in groups if nd in grp.nodes) for nd in nodes]
    c.line(f"JG = np.array({jg!r}, dtype=np.int64)")
    c.line(f"JP = np.array({jp!r}, dtype=np.int64)")
    samples = [nd for nd in nodes if nd.sampled]  # sample rule m is samples[m]'s
    if samples:
        c.line(f"SG = np.array({[jg[nd.index] for nd in samples]!r}, dtype=np.int64)")
        c.line(f"SP = np.array({[jp[nd.index] for nd in samples]!r}, dtype=np.int64)")
    if network >= 0:
        c.lines(_network_tables(lay.channels, network))
    c.line("")
    # the model of one run, on 1-D arrays: the flow (k = -1) into ``out``, the guard (k = -2)
    # into ``out``, the jump of rule k >= 0 into ``q``; it returns a status
    n_rules = len(problem.rule_names)  # deliveries, transmissions, samples
    rows = max(lay.n, n_rules)
    # the flow and the guard are functions of their own, so that the lane form inlines
    # only them: inlining the whole body (its jumps too) twice was two thirds of the
    # lane form's compile (numba copies the IR it inlines)
    c.line("def flow(t, q, p, work, out):")
    c.indent()
    c.line("dq = out")
    _flow(c, at, groups, lay.n_flow or lay.n)
    c.line("return 1")
    c.dedent()
    c.line("")
    c.line("def guard(t, q, p, work, out):")
    c.indent()
    c.line("g = out")
    _guard(c, at, groups, samples)
    c.line("return 1")
    c.dedent()
    c.line("")
    c.line("FLOW = inline(flow)")
    c.line("GUARD = inline(guard)")
    c.line("")
    c.line("def body(k, t, q, p, work, out):")
    c.indent()
    c.line("if k == -1:")
    c.line("    return FLOW(t, q, p, work, out)")
    c.line("if k == -2:")
    c.line("    return GUARD(t, q, p, work, out)")
    _jump(c, at, groups, samples)
    c.line("return 1")
    c.dedent()
    c.line("")
    # compiled as a function of its own for ``est``: numba inlines a function into the
    # caller's IR, where it drops writes into an array made by carray that nothing reads
    # after them (a jump's last write into q was lost); the lane forms inline only FLOW or
    # GUARD into their loops, which write only into arrays read after the loop (checked
    # by etobs.estimation._lane_probe.LaneProbe.agrees)
    c.line("BODY = jit(body)")
    c.line("")
    # two C functions (:func:`etobs.compile.functions.c_signature`) of the one body: the
    # kernel calls ``est`` as the flow with k = -1, the guard with k = -2 and the jump of
    # rule k >= 0 of one run, with a scratch array of n_work + 1 floats, and ``est_lanes``
    # as the flow or guard of the lanes lo .. hi-1 of W (etobs.hybrid.compiled.CompiledSystem)
    c.line("def est(k, t, qp, cfp, wp, a3, iap, pp, outp):")
    c.line(
        f"    return BODY(k, t, carray(qp, ({lay.n},)), carray(pp, ({src.size},)), "
        f"carray(wp, ({src.n_work + 1},)), carray(outp, ({rows},)))"
    )
    c.line("")
    src.lanes = _lane_form_fits(src.n_work + 1, rows)
    if src.lanes:
        _lanes(c, src, lay.n, lay.n_flow or lay.n, rows, n_rules)
    src.text = c.text()
    return src


#: Bytes of the lane form's arrays on its stack (scratch and results), at most: a model
#: larger than this has no lane form (the kernel calls its one-run form lane by lane).
LANE_STACK = 2**19
#: Lanes the lane form computes, a constant of its code: the engine's lanes per thread.
LANE_WIDTH = LANES


def _lane_form_fits(n_work: int, rows: int) -> bool:
    """Whether the lane form's scratch and results fit in :data:`LANE_STACK`."""
    return (n_work + rows) * LANE_WIDTH * 8 <= LANE_STACK


def _lanes(c: _Code, src: ModelSource, n: int, n_flow: int, rows: int, n_guard: int) -> None:
    """``est_lanes`` and ``est_lanes_shared``: the flow or guard of :data:`LANE_WIDTH` runs side by side.

    The lanes' states and times are read where the kernel keeps them (the lane axis
    last), their parameters from one row per lane (contiguous, as a function that
    reshapes them needs); the scratch and the results are arrays on the stack, which nothing
    the kernel passed can alias (:mod:`etobs.compile._stack`), copied out after the loop.
    So LLVM may run the loop over lanes as vector instructions. One loop per function,
    so that it inlines one of the flow and the guard. ``est_lanes_shared`` is for lanes
    whose parameter rows are all equal, bit for bit (a batch of one problem): it reads
    every lane's parameters from the first row, one number for all lanes where
    ``est_lanes`` gathers one per lane (the robot arm's flow: 16 against 40 ns per run).
    """
    for name, row in (("est_lanes", "lane"), ("est_lanes_shared", "0")):
        _lane_entry(c, src, name, row, n, n_flow, rows, n_guard)


def _lane_entry(
    c: _Code, src: ModelSource, name: str, row: str, n: int, n_flow: int, rows: int, n_guard: int
) -> None:
    """The lane form ``name``, which reads lane ``lane``'s parameters from row ``row`` (:func:`_lanes`)."""
    W, nw = LANE_WIDTH, src.n_work + 1
    c.line(f"def {name}(k, t, qp, tp, wp, cfp, iap, pp, outp):")
    c.indent()
    c.line(f"st = carray(iap, ({3 + W},))")
    c.line(f"q = carray(qp, ({n}, {W}))")
    c.line(f"ts = carray(tp, ({W},))")
    c.line(f"p = carray(pp, ({W}, {max(src.size, 1)}))  # one row per lane: contiguous")
    c.line(f"out = carray(outp, ({rows}, {W}))")
    c.line(f"work = carray(stack_f8({nw * W}), ({nw}, {W}))")
    c.line(f"res = carray(stack_f8({rows * W}), ({rows}, {W}))")
    c.line(f"sts = carray(stack_i8({W}), ({W},))")
    # the flow's rows from n_flow on are not written, as the one-run form leaves them
    for k, fn, n_out in ((-1, "FLOW", n_flow), (-2, "GUARD", n_guard)):
        c.line(f"if k == {k}:")
        c.indent()
        call = f"{fn}(ts[lane], q[:, lane], p[{row}], work[:, lane], res[:, lane])"
        c.line(f"for lane in range({W}):")
        c.line(f"    sts[lane] = {call}")
        c.line(f"for i in range({n_out}):")
        c.line(f"    for lane in range({W}):")
        c.line("        out[i, lane] = res[i, lane]")
        c.dedent()
    c.line(f"for lane in range({W}):")
    c.line("    st[3 + lane] = sts[lane]")
    c.line("return 1")
    c.dedent()


def _network_tables(channels: Any, network: int) -> list[str]:
    """Per node: its network block (``NM``), size, capacity, link numbers in ``p``, sent and held."""
    width = max(ch.size for ch in channels)

    def pad(idx: Any) -> list[int]:
        return [int(a) for a in idx] + [0] * (width - len(idx))

    rows = {
        "NM": [ch.net.start for ch in channels],
        "NN": [ch.size for ch in channels],
        "NC": [ch.link.capacity for ch in channels],
        "NP": [network + 2 + LINK_WIDTH * c for c in range(len(channels))],
    }
    out = [f"{k} = np.array({v!r}, dtype=np.int64)" for k, v in rows.items()]
    out.append(f"NS = np.array({[pad(ch.sent) for ch in channels]!r}, dtype=np.int64)")
    out.append(f"NH = np.array({[pad(ch.held) for ch in channels]!r}, dtype=np.int64)")
    return out


def _node(src: ModelSource, c: int, ch: Any, form: EngineForm, w: dict[str, int], innovation: bool) -> _Node:
    """Node ``c``'s numbers into ``p`` and its user K-functions into ``src``.

    Its block of ``p``: the kind's numbers in order, then two numbers per K-function slot.
    """
    kind = form.kind
    numbers = [form.numbers[n.name] for n in kind.numbers]
    kforms: list[tuple[str, str | None]] = []
    for slot in kind.slots:
        fn = form.kfunctions[slot.name]
        if isinstance(fn, float | int):
            kk, k1, k2, user = fm.CONSTANT, float(fn), 0.0, None
        else:
            kk, k1, k2, user = fn.engine_form()
        numbers += [k1, k2]
        glob = None
        if user is not None:
            glob = src.user(user, f"K{c}_{slot.name}", f"{slot.name} of node {c}", FunctionSpec("t", (), 0))
        kforms.append(("" if kk is None else kk.name, glob))
    index = [int(k) for k in ch.index]
    if ch.kind == "u":  # an input node sends u_k (section 7.3)
        sw = mw = tuple(w["u"] + k for k in index)
    else:
        mw = tuple(w["ytilde"] + k for k in index)
        sw = tuple(w["innov"] + k for k in index) if innovation else mw
    s0 = ch.rule_state.start if ch.rule_state.stop > ch.rule_state.start else -1
    sq = tuple(int(a) for a in ch.sent)
    if form.sampled is not None:
        numbers += list(form.sampled)  # period, phase
    return _Node(c, form, sq, sw, mw, s0, src.put(numbers), tuple(kforms), form.sampled is not None)


def _prelude(c: _Code, at: _Where, flow: bool) -> None:
    """The signals the nodes read, into ``work``.

    ``u`` (for input nodes), ``ytilde``, and with the observer-copy hold ``yhat`` and
    ``ytilde - yhat``; the flow has computed ``u`` and ``yhat`` already.
    """
    w, ny = at.w, at.ny
    if at.held_u and not flow:
        c.lines(_signal(0, at.signals[0], w["u"]))
    c.lines(_ytilde(at))
    if at.innovation:
        if not flow:
            _estimate(c, at)
        c.line(f"for ii in range({ny}):")
        c.line(f"    work[{w['innov']} + ii] = work[{w['ytilde']} + ii] - work[{w['yhat']} + ii]")


def _estimate(c: _Code, at: _Where) -> None:
    """``xhat = psi(z)`` and ``yhat = h(xhat)`` into the scratch."""
    w, nx, nz, ny = at.w, at.nx, at.nz, at.ny
    z = f"q[{at.z0}:{at.z0 + nz}]"
    xhat, yhat = f"work[{w['xhat']}:{w['xhat'] + nx}]", f"work[{w['yhat']}:{w['yhat'] + ny}]"
    if at.psi:
        c.call("PSI", z, at.po, xhat, nx, S_PSI)
    else:
        c.line(f"for ii in range({nx}):")
        c.line(f"    work[{w['xhat']} + ii] = q[{at.z0} + ii]")
    c.call("H", xhat, at.pp, yhat, ny, S_H)


def _flow(c: _Code, at: _Where, groups: list[_Group], n_flow: int) -> None:
    """``dq = q'`` (eq. (2), (7), (14), (44), (50), (53)) in the entries below ``n_flow``."""
    w, nx, nz, ny, nu, nv = at.w, at.nx, at.nz, at.ny, at.nu, at.nv
    c.lines(_signal(0, at.signals[0], w["u"]))
    c.lines(_signal(1, at.signals[1], w["v"]))
    u = f"work[{w['u']}:{w['u'] + nu}]"
    c.call("F_P", f"t, q[0:{nx}], {u}, work[{w['v']}:{w['v'] + nv}]", at.pp, f"dq[0:{nx}]", nx, S_FP)  # (2)
    _estimate(c, at)
    z = f"q[{at.z0}:{at.z0 + nz}]"
    yhat = f"work[{w['yhat']}:{w['yhat'] + ny}]"
    ubar = u
    if at.held_u:  # eq. (50): the observer runs on the held input
        ubar = f"work[{w['ubar']}:{w['ubar'] + nu}]"
        c.line(f"for ii in range({nu}):")
        c.line(f"    work[{w['ubar']} + ii] = work[{w['u']} + ii]")
        for k, h in at.held_u:
            c.line(f"work[{w['ubar'] + k}] = q[{h}]")
    ybar = f"q[{at.yb0}:{at.yb0 + ny}]"
    if at.innovation:  # Remark 3: the observer holds ytilde - yhat as sent
        ybar = f"work[{w['ybar_o']}:{w['ybar_o'] + ny}]"
        c.line(f"for ii in range({ny}):")
        c.line(f"    work[{w['ybar_o']} + ii] = work[{w['yhat']} + ii] + q[{at.yb0} + ii]")
    c.call("F_O", f"t, {z}, {ubar}, {ybar}, {yhat}", at.po, f"dq[{at.z0}:{at.z0 + nz}]", nz, S_FO)  # eq. (7)
    c.line(f"for ii in range({at.yb0}, {n_flow}):")
    c.line("    dq[ii] = 0.0  # held values and rule states; the rules' flows follow")
    _prelude(c, at, flow=True)
    for grp in groups:
        kind = grp.first.form.kind
        if kind.flow is None or grp.first.sampled:  # a sampled filter moves at samples only
            continue
        c.lines(grp.loop())
        c.indent()
        c.line(f"dq[s0] = {_apply(c, grp, kind, 'flow')}")  # e.g. eq. (14), (44)
        c.dedent()


def _guard(c: _Code, at: _Where, groups: list[_Group], samples: list[_Node]) -> None:
    """Every node's trigger function (eq. (15), (45), (54)): the node sends when ``g_i >= 0``.

    With a network the deliveries come first: ``g[c]`` is zero when a packet of node
    ``c`` arrives, and the nodes' triggers follow (:mod:`etobs.estimation.assembly`).
    A sampled node's trigger is its mark (``due - 1/2``), and its sample's guard,
    ``t - t_k`` with ``t_k = phase + k T``, comes after every node's
    (:mod:`etobs.model.sampled`).
    """
    _prelude(c, at, flow=False)
    off = 0
    if at.network >= 0:
        off = at.n_ch
        c.line(f"for cc in range({at.n_ch}):")
        c.line("    g[cc] = NET_GAP(q, t, NM[cc], NN[cc], NC[cc])")
    for grp in groups:
        kind = grp.first.form.kind
        c.lines(grp.loop())
        c.indent()
        gi = f"g[{off} + i]" if off else "g[i]"
        if grp.first.sampled:
            c.line(f"{gi} = q[s0 + {grp.first.mark}] - 0.5  # due at this sample")
        else:
            c.line(f"{gi} = {_apply(c, grp, kind, 'trigger')}")  # e.g. eq. (15), (45), (54)
        c.dedent()
    for m, nd in enumerate(samples):
        c.line(f"g[{off + at.n_ch + m}] = t - (p[{nd.p0 + nd.tp + 1}] + q[{nd.sk}] * p[{nd.p0 + nd.tp}])")


def _jump(c: _Code, at: _Where, groups: list[_Group], samples: list[_Node]) -> None:
    """Node ``k`` sends its current value (eq. (22): ``e_k+ = 0``) and resets its own rule state.

    With a network, rules ``0 .. C-1`` deliver node ``k``'s earliest packet, and rule
    ``C + c`` is node ``c``'s transmission, whose packet then enters its link. The rules
    after the transmissions are the sampled nodes' samples (:func:`_sample`).
    """
    if at.network >= 0:
        c.line(f"if k < {at.n_ch}:")
        c.line("    NET_DELIVER(q, NM[k], NH[k], NN[k], NC[k])")
        c.line("    return 1")
        c.line(f"k = k - {at.n_ch}")
    _prelude(c, at, flow=False)
    if samples:
        c.line(f"if k >= {at.n_ch}:")
        c.indent()
        _sample(c, at, [grp for grp in groups if grp.first.sampled])
        c.line("return 1")
        c.dedent()
    c.line("gk = JG[k]")
    for grp in groups:
        c.line(f"{'if' if grp.index == 0 else 'elif'} gk == {grp.index}:")
        c.indent()
        c.line("jj = JP[k]")
        c.lines(grp.locals("jj"))
        c.lines(grp.send("jj"))
        kind = grp.first.form.kind
        if grp.first.sampled:  # its sample reset the filter: the mark is cleared
            c.line(f"q[s0 + {grp.first.mark}] = 0.0")
        elif kind.reset is not None:
            c.line(f"q[s0] = {_apply(c, grp, kind, 'reset')}")  # e.g. eq. (14)
        c.dedent()
    if at.network >= 0:
        n = at.network
        c.line(f"seed = int(p[{n}]) * 4294967296 + int(p[{n + 1}])")
        c.line(
            f"NET_SEND(q, t, seed, int(q[{at.run}]), k, NM[k], NS[k], NH[k], NN[k], NC[k], "
            f"p[NP[k]:NP[k] + {LINK_WIDTH}])"
        )


def _sample(c: _Code, at: _Where, groups: list[_Group]) -> None:
    """The sample of sampled node ``SG/SP[k - C]``: :func:`etobs.formulas.sample_decision`, step by step.

    Send when the trigger is ``>= 0`` at ``(|e_k|, |y_k|, eta_k)`` (the mark is set, the
    transmission rule sends at this instant); then ``eta <- reset(eta)`` and ``|e| = 0``;
    then ``eta`` over the period with ``|e|`` held (:func:`etobs.formulas.eta_period`);
    and ``k <- k + 1``. The same formulas in the same order as the sensor node, so the
    same bits (tested).
    """
    c.line(f"m = k - {at.n_ch}")
    c.line("gs = SG[m]")
    for idx, grp in enumerate(groups):
        nd, kind = grp.first, grp.first.form.kind
        dk = nd.sk - nd.s0  # the next sample's index, then the mark, after the rule's own state
        c.line(f"{'if' if idx == 0 else 'elif'} gs == {grp.index}:")
        c.indent()
        c.line("jj = SP[m]")
        c.lines(grp.locals("jj"))
        reads = set().union(*(f.reads for f in kind.formulas()))
        given = {}
        for arg, local in (("e", "e"), ("y", "ym")):
            if arg in reads:  # once, before the decision (|e| is then held at 0 if it sends)
                c.lines(grp.norm("jj", arg == "y", local))
                given[arg] = local
        c.line(f"tr = {_apply(c, grp, kind, 'trigger', given)}")  # eq. (15) at the sample
        c.line(f"q[s0 + {dk}] = q[s0 + {dk}] + 1.0")
        c.line("if tr >= 0.0:")
        c.indent()
        c.line(f"q[s0 + {nd.mark}] = 1.0")
        if kind.state == "eta":
            assert kind.reset is not None and kind.decay is not None
            c.line(f"q[s0] = {_apply(c, grp, kind, 'reset', given)}")  # eq. (14), jump
            c.line("e = 0.0")
        c.dedent()
        if kind.state == "eta":
            c.line(f"drive = {_apply(c, grp, kind, 'flow', {**given, 's': '0.0'})}")
            j = [slot.name for slot in kind.slots].index(kind.decay or "")
            kname, base = nd.kforms[j][0], len(kind.numbers) + 2 * j
            k12 = f"p[r + {base}], p[r + {base + 1}]"
            c.line(f"q[s0] = ETA_PERIOD_{kname.upper()}(q[s0], drive, {k12}, p[r + {nd.tp}])")
        c.dedent()


class _Code:
    """Indented lines of Python text."""

    def __init__(self) -> None:
        self._lines: list[str] = []
        self._depth = 0

    def line(self, text: str) -> None:
        self._lines.append("    " * self._depth + text if text else "")

    def lines(self, texts: list[str]) -> None:
        for t in texts:
            self.line(t)

    def indent(self) -> None:
        self._depth += 1

    def dedent(self) -> None:
        self._depth -= 1

    def call(self, fn: str, args: str, params: str | None, out: str, n: int, slot: int) -> None:
        self.lines(_call(fn, args, params, out, n, slot))

    def text(self) -> str:
        return "\n".join(self._lines) + "\n"


def _call(fn: str, args: str, params: str | None, out: str, n: int, slot: int) -> list[str]:
    """Call a user function and store its result into ``out`` (length ``n``), checking the length.

    Its array arguments (every one but ``t``) are read-only: numba refuses a function
    that writes into them, which would change the state or the signals behind the
    solver's back.
    """
    call = params_call(
        fn, [a if a == "t" else f"readonly({a})" for a in args.split(", ")], params and f"readonly({params})"
    )
    return [
        f"st = store({call}, {out}, {n})",
        "if st != 1:",
        f"    return {16 * slot} + st",
    ]


def _signal(which: int, sig: tuple[int, int, int], w0: int) -> list[str]:
    """Signal ``which`` (0 u, 1 v, 2 m) at ``t`` into ``work[w0:w0 + dim]``."""
    kind, off, dim = sig
    if dim == 0:
        return []
    if kind == SIG_ZERO:
        return [f"for ii in range({dim}):", f"    work[{w0} + ii] = 0.0"]
    if kind == SIG_CONSTANT:
        return [f"for ii in range({dim}):", f"    work[{w0} + ii] = p[{off} + ii]"]
    if kind == SIG_SINUSOID:  # amplitude * sin(omega t + phase) + offset
        return [
            f"s = SIN(p[{off + 2 * dim}] * t + p[{off + 2 * dim + 1}])",
            f"for ii in range({dim}):",
            f"    work[{w0} + ii] = s * p[{off} + ii] + p[{off + dim} + ii]",
        ]
    if kind == SIG_FUNCTION:
        glob = f"SIG_{'UVM'[which]}"
        return _call(glob, "t", None, f"work[{w0}:{w0 + dim}]", dim, S_SIG + which)
    raise ValueError(f"unknown signal kind {kind}")  # pragma: no cover - the kinds above are all


def _ytilde(at: _Where) -> list[str]:
    """``ytilde = h(x) + m(t)`` (eq. (46)) into the scratch."""
    wy, wm, ny = at.w["ytilde"], at.w["m"], at.ny
    out = _call("H", f"q[0:{at.nx}]", at.pp, f"work[{wy}:{wy + ny}]", ny, S_H)
    out += _signal(2, at.signals[2], wm)
    return [*out, f"for ii in range({ny}):", f"    work[{wy} + ii] += work[{wm} + ii]"]


def _apply(c: _Code, grp: _Group, kind: fm.RuleKind, what: str, given: dict[str, str] | None = None) -> str:
    """The call of ``kind``'s formula ``what`` for the group's node ``jj``; its arguments' lines into ``c``.

    Each argument of the formula (:class:`etobs.formulas.Formula`) becomes a local:
    ``|e_i|``, ``|ytilde_i|``, the rule state ``q[s0]``, a K-function's value or a number
    of the node's block of ``p``; ``given`` names some of them (``{"s": "0.0"}``).
    """
    formula = getattr(kind, what)
    names = {n.name: i for i, n in enumerate(kind.numbers)}
    slots = {slot.name: i for i, slot in enumerate(kind.slots)}
    done: dict[str, str] = {"s": "q[s0]", **(given or {})}  # given: locals computed already, or values

    def local(arg: str) -> str:
        if arg in done:
            return done[arg]
        if arg in ("e", "y"):
            out = "e" if arg == "e" else "ym"
            c.lines(grp.norm("jj", arg == "y", out))
        elif arg in names:
            out = f"p[r + {names[arg]}]"
        else:
            split = fm.split_arg(arg)
            if split is None or split[0] not in slots:
                raise ValueError(f"rule kind {kind.name!r}: the argument {arg!r} of its {what} is unknown")
            slot, at = split
            j = slots[slot]
            out = f"k_{slot}_{at}"
            kname, glob = grp.first.kforms[j]
            base = len(kind.numbers) + 2 * j
            if glob is not None:
                c.line(f"{out} = float({glob}({local(at)}))")
            else:
                c.line(f"{out} = K_{kname.upper()}(p[r + {base}], p[r + {base + 1}], {local(at)})")
        done[arg] = out
        return out

    args = [local(a) for a in formula.args]
    return f"{_formula_name(kind, what)}({', '.join(args)})"
