"""Template of the compiled hybrid model (16)--(22); :mod:`etobs.estimation.compiled` runs it.

Not imported as a module: the builder executes this text in a namespace holding the
user's compiled plant and observer functions (``F_P``, ``H``, ``F_O`` and ``PSI``
when ``HAS_PSI``), the decorator ``jit`` and the layout constants below, so numba
inlines the user functions (see :mod:`etobs.hybrid._jitcache`). Each function handles one run; it mirrors
:meth:`etobs.estimation.problem.EstimationProblem.hybrid_system` and the rule classes
of :mod:`etobs.model.rules` operation for operation.

Layout constants: state ``q = (x, z, ybar, rule states)`` with sizes ``NX, NZ, NY``
and offsets ``Z0, YB0``; parameter vector ``p`` with the plant's ``theta`` at
``TP0:TP1``, the observer's at ``TO0:TO1``, the signals ``u, v, m`` at ``SU0, SV0, SM0``
(amplitudes, offsets, omega, phase) and ``RS`` numbers per node from ``R0``; scratch
``work`` with ``u, v, xhat, yhat, ytilde, m`` at ``WU, WV, WXH, WYH, WY, WM``.
``args = (out_ptr, out_idx, rule_kind, gamma_kind, alpha_kind, s_off)``.
"""
# ruff: noqa: F821

import numpy as np

DYNAMIC, STATIC, PERIODIC = 0, 1, 2
# per-node parameters, offsets from R0 + RS*i
P_SIGMA, P_C, P_B, P_EPS, P_G1, P_G2, P_A1, P_A2, P_PERIOD = 0, 1, 2, 3, 4, 5, 6, 7, 8

if not HAS_PSI:

    @jit
    def PSI(z, theta, out):
        """Stand-in for an absent ``psi`` (never called: ``xhat = z``)."""


@jit
def _signal(p, off, dim, t, out):
    """``amplitude * sin(omega t + phase) + offset`` (Zero and Constant included)."""
    s = np.sin(p[off + 2 * dim] * t + p[off + 2 * dim + 1])
    for i in range(dim):
        out[i] = s * p[off + i] + p[off + dim + i]


@jit
def _kfun(kind, k1, k2, s):
    """Linear ``k1 s``, Quadratic ``k1 s^2`` or Power ``k1 s^k2`` (etobs.model.functions)."""
    if kind == 0:
        return k1 * s
    if kind == 1:
        return k1 * (s * s)
    return k1 * s**k2


@jit
def _ytilde(t, q, p, work):
    """``ytilde = h(x) + m(t)`` (eq. (46)) into ``work[WY:WY + NY]``."""
    y = work[WY : WY + NY]
    H(q[0:NX], p[TP0:TP1], y)
    m = work[WM : WM + NY]
    _signal(p, SM0, NY, t, m)
    for i in range(NY):
        y[i] = y[i] + m[i]


@jit
def _enorm(q, work, out_ptr, out_idx, i):
    """``|e_i| = |ybar_i - ytilde_i|`` of node ``i`` (needs ``_ytilde`` first)."""
    a = out_ptr[i]
    b = out_ptr[i + 1]
    if b - a == 1:
        k = out_idx[a]
        return abs(q[YB0 + k] - work[WY + k])
    acc = 0.0
    for r in range(a, b):
        k = out_idx[r]
        d = q[YB0 + k] - work[WY + k]
        acc += d * d
    return np.sqrt(acc)


@jit
def est_flow(t, q, p, args, work, dq):
    out_ptr, out_idx, rule_kind, gamma_kind, alpha_kind, s_off = args
    u = work[WU : WU + NU]
    v = work[WV : WV + NV]
    _signal(p, SU0, NU, t, u)
    _signal(p, SV0, NV, t, v)
    F_P(t, q[0:NX], u, v, p[TP0:TP1], dq[0:NX])  # eq. (2)
    xhat = work[WXH : WXH + NX]
    if HAS_PSI:
        PSI(q[Z0 : Z0 + NZ], p[TO0:TO1], xhat)
    else:
        for i in range(NX):
            xhat[i] = q[Z0 + i]
    yhat = work[WYH : WYH + NY]
    H(xhat, p[TP0:TP1], yhat)
    F_O(t, q[Z0 : Z0 + NZ], u, q[YB0 : YB0 + NY], yhat, p[TO0:TO1], dq[Z0 : Z0 + NZ])  # eq. (7)
    for i in range(NY):
        dq[YB0 + i] = 0.0
    _ytilde(t, q, p, work)
    for i in range(rule_kind.shape[0]):
        kind = rule_kind[i]
        off = s_off[i]
        r = R0 + RS * i
        if kind == DYNAMIC:
            # eq. (14): eta' = -alpha(eta) + c*gamma(|e|)
            e = _enorm(q, work, out_ptr, out_idx, i)
            dq[off] = -_kfun(alpha_kind[i], p[r + P_A1], p[r + P_A2], q[off]) + p[r + P_C] * _kfun(
                gamma_kind[i], p[r + P_G1], p[r + P_G2], e
            )
        elif kind == PERIODIC:
            dq[off] = 1.0


@jit
def est_guard(t, q, p, args, work, g):
    out_ptr, out_idx, rule_kind, gamma_kind, alpha_kind, s_off = args
    _ytilde(t, q, p, work)
    for i in range(rule_kind.shape[0]):
        kind = rule_kind[i]
        off = s_off[i]
        r = R0 + RS * i
        if kind == PERIODIC:
            g[i] = q[off] - p[r + P_PERIOD]
            continue
        gam = _kfun(gamma_kind[i], p[r + P_G1], p[r + P_G2], _enorm(q, work, out_ptr, out_idx, i))
        if kind == DYNAMIC:
            # eq. (15): transmit when gamma(|e|) >= sigma*alpha(eta) + eps
            g[i] = (
                gam - p[r + P_SIGMA] * _kfun(alpha_kind[i], p[r + P_A1], p[r + P_A2], q[off]) - p[r + P_EPS]
            )
        else:
            g[i] = gam - p[r + P_EPS]


@jit
def est_jump(k, t, q, p, args, work):
    # eq. (22): node k sends ytilde_k (e_k+ = 0) and resets its own rule state
    out_ptr, out_idx, rule_kind, _, _, s_off = args
    _ytilde(t, q, p, work)
    for r in range(out_ptr[k], out_ptr[k + 1]):
        idx = out_idx[r]
        q[YB0 + idx] = work[WY + idx]
    kind = rule_kind[k]
    if kind == DYNAMIC:
        q[s_off[k]] = p[R0 + RS * k + P_B] * q[s_off[k]]  # eta+ = b*eta
    elif kind == PERIODIC:
        q[s_off[k]] = 0.0
