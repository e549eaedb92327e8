"""The hybrid model (16)--(22) for the engine: flow, guard and jump of one run, compiled once.

These functions do not depend on the problem: its sizes, structure, rule kinds and the
addresses of the user's compiled functions travel in the integer array ``ia`` (layout
below, filled by :mod:`etobs.estimation.compiled`), its numbers in the run's parameter
vector ``p``. So they are compiled once per machine (numba's disk cache) and every
problem reuses them; a new model compiles only its own functions. They mirror
:mod:`etobs.estimation.assembly` and the rule classes of :mod:`etobs.model.rules`
operation for operation.

Every function returns ``1`` (OK) or a failure code ``16 * slot + failure`` naming the
user function that failed (slots below; see :mod:`etobs.compile.functions`).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import carray

from etobs.compile.ccall import ccall
from etobs.compile.functions import c_signature
from etobs.model.functions import CONSTANT, CUSTOM, LINEAR, POWER, QUADRATIC  # noqa: F401
from etobs.model.rules import DYNAMIC, GENERALIZED, PERIODIC, RELATIVE, STATIC
from etobs.model.signals import CONSTANT as CONST
from etobs.model.signals import SINUSOID as SINE
from etobs.model.signals import ZERO

# ---- layout of ia: header entries ------------------------------------------------
H_LEN, H_N, H_NP, H_NWORK = 0, 1, 2, 3
H_NX, H_NZ, H_NY, H_NU, H_NV, H_NN, H_PSI = 4, 5, 6, 7, 8, 9, 10
H_FP, H_H, H_FO, H_PSIA = 11, 12, 13, 14  # addresses
H_SIG = 15  # u, v, m: (kind, address, offset in p) each, 15..23
H_TP0, H_NTP, H_TO0, H_NTO = 24, 25, 26, 27
H_WU, H_WV, H_WXH, H_WYH, H_WY, H_WM, H_WK = 28, 29, 30, 31, 32, 33, 34
H_Z0, H_YB0, H_OUT, H_NODES = 35, 36, 37, 38
N_HEADER = 39
# ---- per node (NODE_W entries from ia[H_NODES] + NODE_W * i) -----------------------
R_KIND, R_P0, R_S0, R_OUT_A, R_OUT_B = 0, 1, 2, 3, 4
R_FK = 5  # kinds of the K-function slots (gamma, alpha, gamma_check, d'), 5..8
R_FA = 9  # their addresses, 9..12
NODE_W = 13
# numbers per node in p (from ia[node + R_P0])
P_SIGMA, P_C, P_B, P_EPS, P_RHO, P_PERIOD, P_F = 0, 1, 2, 3, 4, 5, 6  # P_F: 2 numbers per slot
RULE_W = 14
G, A, GC, D = 0, 1, 2, 3
# failure slots: f_p, h, f_o, psi, u, v, m, then 4 per node
S_FP, S_H, S_FO, S_PSI, S_SIG = 1, 2, 3, 4, 5
S_NODE = 8


@numba.njit(cache=True, inline="always")
def _fail(slot, st):
    return st if st >= 16 else 16 * slot + st


@numba.njit(cache=True, inline="always")
def _signal(which, t, p, ia, work, o, dim, empty):
    """Signal ``which`` (0 u, 1 v, 2 m) at ``t`` into ``work[o:o + dim]``."""
    base = H_SIG + 3 * which
    kind = ia[base]
    off = ia[base + 2]
    if kind == ZERO:
        for i in range(dim):
            work[o + i] = 0.0
    elif kind == CONST:
        for i in range(dim):
            work[o + i] = p[off + i]
    elif kind == SINE:  # amplitude * sin(omega t + phase) + offset
        s = np.sin(p[off + 2 * dim] * t + p[off + 2 * dim + 1])
        for i in range(dim):
            work[o + i] = s * p[off + i] + p[off + dim + i]
    else:
        return _signal_call(which, t, p, ia, work, o, dim)
    return 1


@numba.njit(cache=True)
def _signal_call(which, t, p, ia, work, o, dim):
    """A user's signal (called, not inlined: it keeps the common kinds' path short)."""
    empty = work[0:0]
    st = ccall(ia[H_SIG + 3 * which + 1], 0, t, empty, empty, empty, empty, ia, p, work[o : o + dim])
    if st != 1:
        return _fail(S_SIG + which, st)
    return 1


@numba.njit(cache=True, inline="always")
def _kfun(i, slot, s, p, ia, work, empty):
    """K-function ``slot`` of node ``i`` at ``s``: (value, status)."""
    nb = ia[H_NODES] + NODE_W * i
    kind = ia[nb + R_FK + slot]
    r = ia[nb + R_P0] + P_F + 2 * slot
    if kind == LINEAR:
        return p[r] * s, 1
    if kind == QUADRATIC:
        return p[r] * (s * s), 1
    if kind == POWER:
        return p[r] * s ** p[r + 1], 1
    if kind == CONSTANT:
        return p[r], 1
    return _kfun_call(i, slot, s, p, ia, work)


@numba.njit(cache=True)
def _kfun_call(i, slot, s, p, ia, work):
    """A user's K-function (called, not inlined: it keeps the common kinds' path short)."""
    empty = work[0:0]
    wk = ia[H_WK]
    addr = ia[ia[H_NODES] + NODE_W * i + R_FA + slot]
    st = ccall(addr, 0, s, empty, empty, empty, empty, ia, p, work[wk : wk + 1])
    if st != 1:
        return np.nan, _fail(S_NODE + 4 * i + slot, st)
    return work[wk], 1


@numba.njit(cache=True, inline="always")
def _ytilde(t, q, p, ia, work, empty):
    """``ytilde = h(x) + m(t)`` (eq. (46)) into ``work[WY:WY + NY]``."""
    nx, ny = ia[H_NX], ia[H_NY]
    wy, wm = ia[H_WY], ia[H_WM]
    st = ccall(ia[H_H], 0, t, q[0:nx], empty, empty, empty, ia, p[ia[H_TP0] :], work[wy : wy + ny])
    if st != 1:
        return _fail(S_H, st)
    st = _signal(2, t, p, ia, work, wm, ny, empty)
    if st != 1:
        return st
    for k in range(ny):
        work[wy + k] += work[wm + k]
    return 1


@numba.njit(cache=True, inline="always")
def _norm(i, q, ia, work, w0, relative):
    """``|e_i| = |ybar_i - ytilde_i|``, or ``|ytilde_i|`` when ``relative``."""
    nb = ia[H_NODES] + NODE_W * i
    a, b = ia[nb + R_OUT_A], ia[nb + R_OUT_B]
    yb0, out0 = ia[H_YB0], ia[H_OUT]
    acc = 0.0
    for r in range(a, b):
        k = ia[out0 + r]
        d = work[w0 + k] if relative else q[yb0 + k] - work[w0 + k]
        acc += d * d
    return np.sqrt(acc)


@numba.njit(cache=True, inline="always")
def flow_one(t, q, p, ia, work, dq):
    """``dq = q'`` (eq. (2), (7), (14), (44)); returns 1 or a failure code."""
    empty = work[0:0]
    nx, nz, ny, nu, nv = ia[H_NX], ia[H_NZ], ia[H_NY], ia[H_NU], ia[H_NV]
    z0, yb0 = ia[H_Z0], ia[H_YB0]
    wu, wv, wxh, wyh = ia[H_WU], ia[H_WV], ia[H_WXH], ia[H_WYH]
    st = _signal(0, t, p, ia, work, wu, nu, empty)
    if st != 1:
        return st
    st = _signal(1, t, p, ia, work, wv, nv, empty)
    if st != 1:
        return st
    u = work[wu : wu + nu]
    pp = p[ia[H_TP0] :]
    po = p[ia[H_TO0] :]
    st = ccall(ia[H_FP], 0, t, q[0:nx], u, work[wv : wv + nv], empty, ia, pp, dq[0:nx])  # eq. (2)
    if st != 1:
        return _fail(S_FP, st)
    z = q[z0 : z0 + nz]
    if ia[H_PSI] != 0:
        st = ccall(ia[H_PSIA], 0, t, z, empty, empty, empty, ia, po, work[wxh : wxh + nx])
        if st != 1:
            return _fail(S_PSI, st)
    else:
        for k in range(nx):
            work[wxh + k] = z[k]
    yhat = work[wyh : wyh + ny]
    st = ccall(ia[H_H], 0, t, work[wxh : wxh + nx], empty, empty, empty, ia, pp, yhat)
    if st != 1:
        return _fail(S_H, st)
    ybar = q[yb0 : yb0 + ny]
    st = ccall(ia[H_FO], 0, t, z, u, ybar, yhat, ia, po, dq[z0 : z0 + nz])  # eq. (7)
    if st != 1:
        return _fail(S_FO, st)
    for k in range(ny):
        dq[yb0 + k] = 0.0
    st = _ytilde(t, q, p, ia, work, empty)
    if st != 1:
        return st
    for i in range(ia[H_NN]):
        nb = ia[H_NODES] + NODE_W * i
        kind = ia[nb + R_KIND]
        s0 = ia[nb + R_S0]
        if kind == DYNAMIC or kind == GENERALIZED:
            # eq. (14): eta' = -alpha(eta) + c gamma(|e|); eq. (44): -alpha_check(eta) + gamma_check(|e|)
            e = _norm(i, q, ia, work, ia[H_WY], False)
            av, st = _kfun(i, A, q[s0], p, ia, work, empty)
            if st != 1:
                return st
            if kind == DYNAMIC:
                gv, st = _kfun(i, G, e, p, ia, work, empty)
                gv = p[ia[nb + R_P0] + P_C] * gv
            else:
                gv, st = _kfun(i, GC, e, p, ia, work, empty)
            if st != 1:
                return st
            dq[s0] = -av + gv
        elif kind == PERIODIC:
            dq[s0] = 1.0
    return 1


@numba.njit(cache=True, inline="always")
def guard_one(t, q, p, ia, work, g):
    """Every node's trigger function (eq. (15), (45)): the node sends when ``g_i >= 0``."""
    empty = work[0:0]
    st = _ytilde(t, q, p, ia, work, empty)
    if st != 1:
        return st
    wy = ia[H_WY]
    for i in range(ia[H_NN]):
        nb = ia[H_NODES] + NODE_W * i
        kind = ia[nb + R_KIND]
        s0 = ia[nb + R_S0]
        r = ia[nb + R_P0]
        if kind == PERIODIC:
            g[i] = q[s0] - p[r + P_PERIOD]
            continue
        e = _norm(i, q, ia, work, wy, False)
        if kind == RELATIVE:
            g[i] = e - p[r + P_RHO] * _norm(i, q, ia, work, wy, True) - p[r + P_EPS]
            continue
        gv, st = _kfun(i, G, e, p, ia, work, empty)
        if st != 1:
            return st
        if kind == STATIC:
            g[i] = gv - p[r + P_EPS]
        elif kind == DYNAMIC:
            # eq. (15): gamma(|e|) >= sigma alpha(eta) + eps
            av, st = _kfun(i, A, q[s0], p, ia, work, empty)
            if st != 1:
                return st
            g[i] = gv - p[r + P_SIGMA] * av - p[r + P_EPS]
        else:
            # eq. (45): gamma(|e|) + d'(eta) gamma_check(|e|) >= sigma d'(eta) alpha_check(eta) + eps
            w, st1 = _kfun(i, D, q[s0], p, ia, work, empty)
            gc, st2 = _kfun(i, GC, e, p, ia, work, empty)
            ac, st3 = _kfun(i, A, q[s0], p, ia, work, empty)
            for st in (st1, st2, st3):
                if st != 1:
                    return st
            g[i] = gv + w * gc - p[r + P_SIGMA] * w * ac - p[r + P_EPS]
    return 1


@numba.njit(cache=True, inline="always")
def jump_one(k, t, q, p, ia, work):
    """Node ``k`` sends ``ytilde_k`` (eq. (22): ``e_k+ = 0``) and resets its own rule state."""
    empty = work[0:0]
    st = _ytilde(t, q, p, ia, work, empty)
    if st != 1:
        return st
    nb = ia[H_NODES] + NODE_W * k
    yb0, out0, wy = ia[H_YB0], ia[H_OUT], ia[H_WY]
    for r in range(ia[nb + R_OUT_A], ia[nb + R_OUT_B]):
        idx = ia[out0 + r]
        q[yb0 + idx] = work[wy + idx]
    kind = ia[nb + R_KIND]
    s0 = ia[nb + R_S0]
    if kind == DYNAMIC or kind == GENERALIZED:
        q[s0] = p[ia[nb + R_P0] + P_B] * q[s0]  # eta+ = b eta
    elif kind == PERIODIC:
        q[s0] = 0.0
    return 1


def _views(qp, pp, iap, wp):
    ia = carray(iap, (iap[H_LEN],))
    return carray(qp, (ia[H_N],)), carray(pp, (ia[H_NP],)), ia, carray(wp, (ia[H_NWORK],))


_views_jit = numba.njit(cache=True, inline="always")(_views)


@numba.cfunc(c_signature(), cache=True)
def est_flow(k, t, qp, cfp, wp, a3, iap, pp, outp):
    q, p, ia, work = _views_jit(qp, pp, iap, wp)
    return flow_one(t, q, p, ia, work, carray(outp, (ia[H_N],)))


@numba.cfunc(c_signature(), cache=True)
def est_guard(k, t, qp, cfp, wp, a3, iap, pp, outp):
    q, p, ia, work = _views_jit(qp, pp, iap, wp)
    return guard_one(t, q, p, ia, work, carray(outp, (ia[H_NN],)))


@numba.cfunc(c_signature(), cache=True)
def est_jump(k, t, qp, cfp, wp, a3, iap, pp, outp):
    q, p, ia, work = _views_jit(qp, pp, iap, wp)
    return jump_one(k, t, q, p, ia, work)
