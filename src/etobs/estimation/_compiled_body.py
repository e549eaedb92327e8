"""Template of the compiled hybrid model (16)--(22); :mod:`etobs.estimation.compiled` runs it.

Not imported as a module: the builder runs this text (see :mod:`etobs.hybrid._jitcache`)
with these globals: the user's compiled plant and observer functions ``F_P``, ``H``,
``F_O`` and ``PSI`` when ``HAS_PSI`` (recompiled to be inlined); the decorators ``jit``
and ``jit_inline`` (``inline="always"``: the helpers below are called several times per
evaluation, hundreds of thousands of times per run); and the constants below. Each
function handles one run; it mirrors
:meth:`etobs.estimation.problem.EstimationProblem.hybrid_system` and the rule classes
of :mod:`etobs.model.rules` operation for operation.

Layout constants: state ``q = (x, z, ybar, rule states)`` with sizes ``NX, NZ, NY``
and offsets ``Z0, YB0``; parameter vector ``p`` with the plant's ``theta`` at
``TP0:TP1``, the observer's at ``TO0:TO1``, the signals ``u, v, m`` at ``SU0, SV0, SM0``
(amplitudes, offsets, omega, phase) and ``RS`` numbers per node from ``R0``; scratch
``work`` with ``u, v, xhat, yhat, ytilde, m`` at ``WU, WV, WXH, WYH, WY, WM``.
Structure constants (int arrays, so that numba folds them): ``NN`` nodes, node ``i``
owns outputs ``OUT_IDX[OUT_PTR[i]:OUT_PTR[i + 1]]``, has rule kind ``RULE_KIND[i]``,
function kinds ``GAMMA_KIND[i]``, ``ALPHA_KIND[i]`` and its rule state at ``S_OFF[i]``.
The functions take ``args = ()``.
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


@jit_inline
def _signal(p, off, dim, t, out, o):
    """``amplitude * sin(omega t + phase) + offset`` into ``out[o:o + dim]``.

    Zero and Constant signals (all amplitudes zero) skip the sine.
    """
    moving = False
    for i in range(dim):
        if p[off + i] != 0.0:
            moving = True
    s = np.sin(p[off + 2 * dim] * t + p[off + 2 * dim + 1]) if moving else 0.0
    for i in range(dim):
        out[o + i] = s * p[off + i] + p[off + dim + i]


@jit_inline
def _kfun(kind, k1, k2, s):
    """Linear ``k1 s``, Quadratic ``k1 s^2`` or Power ``k1 s^k2`` (etobs.model.functions)."""
    if kind == 0:
        return k1 * s
    if kind == 1:
        return k1 * (s * s)
    return k1 * s**k2


@jit_inline
def _ytilde(t, q, p, work):
    """``ytilde = h(x) + m(t)`` (eq. (46)) into ``work[WY:WY + NY]``."""
    H(q[0:NX], p[TP0:TP1], work[WY : WY + NY])
    _signal(p, SM0, NY, t, work, WM)
    for i in range(NY):
        work[WY + i] = work[WY + i] + work[WM + i]


@jit_inline
def _enorm(q, work, i):
    """``|e_i| = |ybar_i - ytilde_i|`` of node ``i`` (needs ``_ytilde`` first)."""
    a = OUT_PTR[i]
    b = OUT_PTR[i + 1]
    if b - a == 1:
        k = OUT_IDX[a]
        return abs(q[YB0 + k] - work[WY + k])
    acc = 0.0
    for r in range(a, b):
        k = OUT_IDX[r]
        d = q[YB0 + k] - work[WY + k]
        acc += d * d
    return np.sqrt(acc)


@jit
def est_flow(t, q, p, args, work, dq):
    _signal(p, SU0, NU, t, work, WU)
    _signal(p, SV0, NV, t, work, WV)
    u = work[WU : WU + NU]
    F_P(t, q[0:NX], u, work[WV : WV + NV], p[TP0:TP1], dq[0:NX])  # eq. (2)
    if HAS_PSI:
        PSI(q[Z0 : Z0 + NZ], p[TO0:TO1], work[WXH : WXH + NX])
    else:
        for i in range(NX):
            work[WXH + i] = q[Z0 + i]
    yhat = work[WYH : WYH + NY]
    H(work[WXH : WXH + NX], p[TP0:TP1], yhat)
    F_O(t, q[Z0 : Z0 + NZ], u, q[YB0 : YB0 + NY], yhat, p[TO0:TO1], dq[Z0 : Z0 + NZ])  # eq. (7)
    for i in range(NY):
        dq[YB0 + i] = 0.0
    _ytilde(t, q, p, work)
    for i in range(NN):
        kind = RULE_KIND[i]
        off = S_OFF[i]
        r = R0 + RS * i
        if kind == DYNAMIC:
            # eq. (14): eta' = -alpha(eta) + c*gamma(|e|)
            e = _enorm(q, work, i)
            dq[off] = -_kfun(ALPHA_KIND[i], p[r + P_A1], p[r + P_A2], q[off]) + p[r + P_C] * _kfun(
                GAMMA_KIND[i], p[r + P_G1], p[r + P_G2], e
            )
        elif kind == PERIODIC:
            dq[off] = 1.0


@jit
def est_guard(t, q, p, args, work, g):
    _ytilde(t, q, p, work)
    for i in range(NN):
        kind = RULE_KIND[i]
        off = S_OFF[i]
        r = R0 + RS * i
        if kind == PERIODIC:
            g[i] = q[off] - p[r + P_PERIOD]
            continue
        gam = _kfun(GAMMA_KIND[i], p[r + P_G1], p[r + P_G2], _enorm(q, work, i))
        if kind == DYNAMIC:
            # eq. (15): transmit when gamma(|e|) >= sigma*alpha(eta) + eps
            g[i] = (
                gam - p[r + P_SIGMA] * _kfun(ALPHA_KIND[i], p[r + P_A1], p[r + P_A2], q[off]) - p[r + P_EPS]
            )
        else:
            g[i] = gam - p[r + P_EPS]


@jit
def est_jump(k, t, q, p, args, work):
    # eq. (22): node k sends ytilde_k (e_k+ = 0) and resets its own rule state
    _ytilde(t, q, p, work)
    for r in range(OUT_PTR[k], OUT_PTR[k + 1]):
        idx = OUT_IDX[r]
        q[YB0 + idx] = work[WY + idx]
    kind = RULE_KIND[k]
    if kind == DYNAMIC:
        q[S_OFF[k]] = p[R0 + RS * k + P_B] * q[S_OFF[k]]  # eta+ = b*eta
    elif kind == PERIODIC:
        q[S_OFF[k]] = 0.0
