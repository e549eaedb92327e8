"""Template of the compiled solver kernel; :func:`etobs.hybrid._kernel.build` runs it.

Not imported as a module: ``build`` executes this text in a namespace that holds the
decorators ``jit``, ``jit_inline`` (inlined where it is called) and ``jit_nogil`` and
the method's tableau as constants (``TA, TB, TC, TE, TE3, TDA, TDC, TDD, N_STAGES,
N_EXTRA, NQ, ERR_ORDER, DOP853, MAX_TERMS``), so that numba folds the coefficients. The
system's functions are called by address (:mod:`etobs.hybrid._kernel`), their lane form
once per stage for all lanes. The algorithm is documented in :mod:`etobs.hybrid._kernel`, the
lanes in :func:`_kernel`.
"""
# ruff: noqa: F821

import numpy as np
from numba import carray

from etobs.compile._stack import stack_f8, stack_i8
from etobs.hybrid._kernel import (
    COMPLETED,
    EPS,
    F_ATOL,
    F_FIRST_STEP,
    F_MAX_STEP,
    F_RTOL,
    F_XTOL,
    F_ZENO_SPAN,
    FLOW,
    FLOW_BEYOND_N_FLOW,
    GUARD,
    GUARD_NAN,
    I_KEEP_STEPS,
    I_MAX_JUMPS,
    I_MAX_STEPS,
    I_N_FLOW,
    I_N_RULES,
    I_N_WORK,
    I_SAMPLES,
    I_ZENO_JUMPS,
    IDLE,
    K_FLOW,
    K_GUARD,
    MAX_FACTOR,
    MAX_JUMPS,
    MAX_ROOT_ITER,
    MAX_STEPS,
    MIN_FACTOR,
    MODEL_ERROR,
    NONFINITE,
    RUNNING,
    SAFETY,
    STEP_UNDERFLOW,
    ZENO,
    _all_finite,
    _any_nan,
    _any_nonneg,
    _dense_eval,
    address,
    ccall,
    cube_at,
    failed,
    flow_call,
    guard_call,
    ints_at,
    jump_call,
    peak_probes,
    rows_at,
    store_i64,
    vector_at,
    zeno_window,
)


@jit_nogil
def _kernel(system, problem, options, out, logs, runs, W, stats):
    """Solve the runs ``runs`` (rows of ``problem``), ``W`` at a time, in lanes.

    Each lane holds one run with its own time, step size, accept/reject, events and
    status; the lanes step in lock step. What every lane does at every step is computed
    for all lanes at once, in loops over the lane (the last, contiguous axis of every
    lane array), which LLVM vectorizes: the stages, the error norm, the guard at the step
    end, the dense output and the event functions' samples; the system's functions are
    called once per stage for all lanes (their lane form, or the one-run form lane by
    lane). What only some lanes do (root finding, jumps, the jump log, grid points,
    the end of a run) is done lane by lane with the one-run functions, on a contiguous
    copy of the lane. A lane whose run has ended takes the next run of ``runs``; with
    none left it computes a copy of a running lane, and is not read.

    Every lane does the arithmetic that a run alone would do, in the same order: a
    run's numbers do not depend on its lane, on ``W`` or on the other runs. Run
    ``runs[r]`` writes its log and arc into row ``r`` of ``logs``. ``stats`` counts the
    lane-steps: all, idle, rejected, examined for an event (:class:`etobs.hybrid.solution.LaneStats`).
    """
    x_init, P, span, grid, dist, log_cols = problem
    fopt, iopt = options
    t0, t_end = span[0], span[1]
    rtol, atol = fopt[F_RTOL], fopt[F_ATOL]
    max_step, max_steps, S = fopt[F_MAX_STEP], iopt[I_MAX_STEPS], iopt[I_SAMPLES]
    keep_steps = iopt[I_KEEP_STEPS] != 0
    m = iopt[I_N_RULES]
    nw = iopt[I_N_WORK]
    n = x_init.shape[1]
    n_p = P.shape[1]
    # entries nf .. n-1 are constant along flows (a network's packets): they are left out
    # of the stages, the error norm and the dense output, and the flow need not write them
    nf = iopt[I_N_FLOW]
    s = N_STAGES  # stages without the FSAL one
    nk = N_STAGES + 1 + N_EXTRA
    nq = NQ
    dop853 = DOP853
    err_exp = -1.0 / (ERR_ORDER + 1)
    n_grid = grid.shape[0]
    log_cap = logs.rule.shape[1]
    arc_cap = logs.arc_t.shape[1]
    buffers = (logs.rule, logs.t, logs.j, logs.arc_t, logs.arc_j, logs.arc_x, logs.x, log_cols)
    status, t_final, j_final, x_final = out.status, out.t_final, out.j_final, out.x_final
    n_steps, n_rejected, log_n, arc_n = out.n_steps, out.n_rejected, out.log_n, out.arc_n
    grid_x, grid_j, grid_max, error_code = out.grid_x, out.grid_j, out.grid_max, out.error_code
    addresses = system.addresses
    lane_fn = addresses[3]
    ia_addr = address(system.ia)
    cf_addr = address(system.cf)
    rows = max(n, m, 1)

    # every array of the step loop is a view into one of two buffers, which own no memory
    # themselves: numba counts references on arrays that do at every call that takes
    # them, two atomic operations each (see etobs.hybrid._kernel)
    n_s = max(S - 1, 0)
    sizes = (
        nk * n * W,  # K: the stages
        nq * n * W,  # Q: the dense output's coefficients
        6 * n * W,  # X, XN, Y, DY, XS, F
        (1 + S) * m * W,  # G (at t), GS (samples θ = i/S, i = 1 .. S; the last is the step end)
        n_p * W,  # PR: the parameters, one row per lane (contiguous for the model's functions)
        nw * W,  # WK: the lane form's scratch
        9 * W,  # TT, H, HH, T, ERR, E3, ZW (2 per lane), FIN
        (6 + NQ) * n + 4 * m + 2 * rows + (n_s + 4) * (1 + m) + n_s + 2 + nw + 2,  # one lane's scratch
    )
    total = 0
    for z in sizes:
        total += z
    buffer = np.zeros(total)
    base = address(buffer)
    o = 0
    K = cube_at(base, o, nk, n, W)
    K2 = rows_at(base, o, nk, n * W)  # the same, one row per stage (for _comb)
    kb = base  # stage i at kb + 8 n W i
    o += nk * n * W
    Q = cube_at(base, o, nq, n, W)
    Q2 = rows_at(base, o, nq, n * W)
    o += nq * n * W
    X = rows_at(base, o, n, W)
    Xf = vector_at(base, o, n * W)
    XN = rows_at(base, o + n * W, n, W)
    Y = rows_at(base, o + 2 * n * W, n, W)
    DY = rows_at(base, o + 3 * n * W, n, W)
    DYf = vector_at(base, o + 3 * n * W, n * W)
    XSf = vector_at(base, o + 4 * n * W, n * W)
    F = rows_at(base, o + 5 * n * W, n, W)
    Ff = vector_at(base, o + 5 * n * W, n * W)
    a_xn, a_y, a_xs = base + 8 * (o + n * W), base + 8 * (o + 2 * n * W), base + 8 * (o + 4 * n * W)
    o += 6 * n * W
    G = rows_at(base, o, m, W)
    GS = cube_at(base, o + m * W, S, m, W)
    GA = cube_at(base, o, 1 + S, m, W)  # G and GS: each rule's samples θ = i/S, i = 0 .. S
    a_gs = base + 8 * (o + m * W)  # sample i (0 .. S - 1) at a_gs + 8 m W i
    o += (1 + S) * m * W
    PR = rows_at(base, o, W, n_p)
    a_pr = base + 8 * o
    o += n_p * W
    a_wk = base + 8 * o
    o += nw * W
    TT = vector_at(base, o, W)  # the lanes' time
    H = vector_at(base, o + W, W)  # their step size
    HH = vector_at(base, o + 2 * W, W)  # this step's size
    T = vector_at(base, o + 3 * W, W)  # the time of a stage or sample
    ERR = vector_at(base, o + 4 * W, W)
    E3 = vector_at(base, o + 5 * W, W)
    ZW = rows_at(base, o + 6 * W, W, 2)  # each lane's Zeno window: its start and its jumps
    FIN = vector_at(base, o + 8 * W, W)  # 1.0 where the step's new state and derivative are finite
    a_t = base + 8 * (o + 3 * W)
    o += 9 * W
    # one lane's contiguous copy, for the one-run functions
    x1 = vector_at(base, o, n)
    xn1 = vector_at(base, o + n, n)
    f1 = vector_at(base, o + 2 * n, n)
    y1 = vector_at(base, o + 3 * n, n)
    xs1 = vector_at(base, o + 4 * n, n)
    o += 5 * n
    g1 = vector_at(base, o, m)
    gl = vector_at(base, o + m, m)
    gtmp = vector_at(base, o + 2 * m, m)
    g0 = vector_at(base, o + 3 * m, m)
    o += 4 * m
    yo = vector_at(base, o, rows)
    oo = vector_at(base, o + rows, rows)
    o += 2 * rows
    th_s = vector_at(base, o, n_s + 4)
    o += n_s + 4
    gs = rows_at(base, o, n_s + 4, m)
    o += (n_s + 4) * m
    seq = vector_at(base, o, n_s + 2)
    o += n_s + 2
    a_wr = base + 8 * o  # the one-run functions' scratch
    o += nw + 2
    x0c = vector_at(base, o, n)  # a lane's step start and dense output, contiguous
    qc = rows_at(base, o + n, NQ, n)
    o += (1 + NQ) * n

    ibuf = np.zeros(14 * W + 3 + W, dtype=np.int64)
    ib = address(ibuf)
    ST = ints_at(ib, 0, W)  # status (RUNNING, a final status, or IDLE)
    SLOT = ints_at(ib, W, W)  # position in runs of the lane's run
    J = ints_at(ib, 2 * W, W)
    STEPS = ints_at(ib, 3 * W, W)
    REJ = ints_at(ib, 4 * W, W)
    NLOG = ints_at(ib, 5 * W, W)
    NARC = ints_at(ib, 6 * W, W)
    GNEXT = ints_at(ib, 7 * W, W)
    WASREJ = ints_at(ib, 8 * W, W)
    LAST = ints_at(ib, 9 * W, W)
    ACC = ints_at(ib, 10 * W, W)  # accepted this step (the mask of the step-end calls)
    GO = ints_at(ib, 11 * W, W)  # running this step (the mask of the stages' calls)
    FAIL = ints_at(ib, 12 * W, W)  # the first failure of the lane's run (0: none)
    a_fail = ib + 8 * 12 * W
    ADV = ints_at(ib, 13 * W, W)  # takes its step without an event: committed for all lanes at once
    IA = ints_at(ib, 14 * W, 3 + W)  # the lane form's lanes and its status per lane
    ia_lanes = ib + 8 * 14 * W
    for lane in range(W):
        ST[lane] = IDLE

    fns = (addresses[0], addresses[1], addresses[2], lane_fn, ia_addr, cf_addr, ia_lanes, a_wk, a_wr, a_fail)
    nxt = 0
    n_runs = runs.shape[0]
    while True:
        # ---- every lane running and ready for a step, or idle ----
        n_go = 0
        for lane in range(W):
            while True:
                st = ST[lane]
                if st != RUNNING and st != IDLE:  # the run has ended: write its results
                    r = SLOT[lane]
                    run = runs[r]
                    if dist.shape[0] > 0 and GNEXT[lane] < n_grid:  # grid points never reached
                        grid_max[run] = np.nan
                    status[run] = st
                    t_final[run] = TT[lane]
                    j_final[run] = J[lane]
                    for q in range(n):
                        x_final[run, q] = X[q, lane]
                    n_steps[run] = STEPS[lane]
                    n_rejected[run] = REJ[lane]
                    log_n[run] = NLOG[lane]
                    arc_n[run] = NARC[lane]
                    error_code[run] = FAIL[lane]
                    ST[lane] = IDLE
                    continue
                if st == IDLE:
                    if nxt >= n_runs:
                        break
                    SLOT[lane] = nxt
                    nxt += 1
                    _start(
                        fns,
                        lane,
                        runs[SLOT[lane]],
                        SLOT[lane],
                        x_init,
                        P,
                        t0,
                        t_end,
                        fopt,
                        iopt,
                        grid,
                        dist,
                        grid_x,
                        grid_j,
                        grid_max,
                        buffers,
                        log_cap,
                        arc_cap,
                        m,
                        W,
                        X,
                        F,
                        G,
                        K,
                        Q,
                        XN,
                        GS,
                        PR,
                        TT,
                        H,
                        ZW,
                        ST,
                        J,
                        STEPS,
                        REJ,
                        NLOG,
                        NARC,
                        GNEXT,
                        WASREJ,
                        FAIL,
                        x1,
                        f1,
                        g0,
                        y1,
                        xs1,
                    )
                    continue
                # running: this step's size
                remaining = t_end - TT[lane]
                hh = min(min(H[lane], max_step), remaining)
                last = hh >= remaining
                if not last and not (hh > 0.0):
                    # a zero or NaN step never moves t, and h * factor stays zero (the automatic
                    # first step of a huge state, from the first step on); a tiny positive one
                    # grows by up to MAX_FACTOR per accepted step
                    ST[lane] = NONFINITE if np.isnan(hh) else STEP_UNDERFLOW
                    continue
                HH[lane] = hh
                LAST[lane] = 1 if last else 0
                break
            GO[lane] = 1 if ST[lane] == RUNNING else 0
            n_go += GO[lane]
        if n_go == 0:
            break
        stats[0] += W
        stats[1] += W - n_go
        # idle lanes compute a copy of a running lane (finite numbers), never read
        donor = 0
        while GO[donor] == 0:
            donor += 1
        for lane in range(W):
            if GO[lane] == 0:
                _copy_lane(lane, donor, X, F, PR, TT, HH, n, n_p)

        # ---- one step of every lane ----
        for i in range(n * W):
            K2[0, i] = Ff[i]
        for q in range(nf, n):  # the stages' constant entries (a jump may have changed them)
            for lane in range(W):
                Y[q, lane] = X[q, lane]
                XN[q, lane] = X[q, lane]
        # stages 1..s-1, then the new state and its derivative (FSAL) at stage s
        for i in range(1, s + 1):
            if i < s:
                _comb(TA[i], K2, i, DYf, nf * W)
                for lane in range(W):
                    T[lane] = TT[lane] + TC[i] * HH[lane]
                a_yi = a_y
                Yi = Y
            else:
                _comb(TB, K2, s, DYf, nf * W)
                for lane in range(W):
                    T[lane] = TT[lane] + HH[lane]
                a_yi = a_xn
                Yi = XN
            for q in range(nf):
                for lane in range(W):
                    Yi[q, lane] = X[q, lane] + HH[lane] * DY[q, lane]
            _lanes_call(
                fns, FLOW, K_FLOW, W, n, nf, a_t, a_yi, kb + 8 * n * W * i, a_pr, PR, GO, FAIL, IA, yo, oo
            )
        # error norm: the scaled RMS norm of the embedded estimate h sum_k e_k K_k (Hairer et
        # al. II.4 (4.11)); DOP853 corrects its 5th-order estimate by the 3rd-order one,
        # err = |h| e5^2 / sqrt((e5^2 + 0.01 e3^2) n), as their code does
        _comb(TE, K2, s + 1, DYf, nf * W)
        for lane in range(W):
            ERR[lane] = 0.0
        for q in range(nf):
            for lane in range(W):
                sc = atol + rtol * max(abs(X[q, lane]), abs(XN[q, lane]))
                DY[q, lane] = DY[q, lane] / sc
                ERR[lane] += DY[q, lane] * DY[q, lane]
        if dop853:
            _comb(TE3, K2, s + 1, DYf, nf * W)
            for lane in range(W):
                E3[lane] = 0.0
            for q in range(nf):
                for lane in range(W):
                    sc = atol + rtol * max(abs(X[q, lane]), abs(XN[q, lane]))
                    v3 = DY[q, lane] / sc
                    E3[lane] += v3 * v3
            for lane in range(W):
                e5 = ERR[lane]
                denom = e5 + 0.01 * E3[lane]
                ERR[lane] = 0.0 if denom == 0.0 else abs(HH[lane]) * e5 / np.sqrt(denom * nf)
        else:
            for lane in range(W):
                ERR[lane] = abs(HH[lane]) * np.sqrt(ERR[lane] / nf)
        # whether each lane's new state (all entries) and derivative (the flowing ones) are finite
        for lane in range(W):
            FIN[lane] = 1.0
        for q in range(n):
            for lane in range(W):
                FIN[lane] = FIN[lane] if np.isfinite(XN[q, lane]) else 0.0
        for q in range(nf):
            for lane in range(W):
                FIN[lane] = FIN[lane] if np.isfinite(K[s, q, lane]) else 0.0
        # ---- the step size controller, lane by lane ----
        n_acc = 0
        for lane in range(W):
            ACC[lane] = 0
            if GO[lane] == 0:
                continue
            # the flow broke its n_flow promise (at the step's two ends: a flow that moves
            # those entries moves them there too)
            if nf < n and not (_lane_tail_zero(K, 0, nf, lane) and _lane_tail_zero(K, s, nf, lane)):
                FAIL[lane] = FLOW_BEYOND_N_FLOW
            hh = HH[lane]
            err = ERR[lane]
            # a failed call leaves its output unwritten: the step must not be taken (the run
            # then ends with model_error at its last good state)
            finite = np.isfinite(err) and FIN[lane] != 0.0 and FAIL[lane] == 0
            accept = finite and err <= 1.0
            if err == 0.0:
                factor = MAX_FACTOR
            elif finite:
                factor = min(max(SAFETY * err**err_exp, MIN_FACTOR), MAX_FACTOR)
            else:
                factor = MIN_FACTOR
            if (not accept) or WASREJ[lane] != 0:
                factor = min(factor, 1.0)
            WASREJ[lane] = 0 if accept else 1
            h_next = hh * factor
            if accept:
                STEPS[lane] += 1
                ACC[lane] = 1
                n_acc += 1
            else:
                REJ[lane] += 1
                stats[2] += 1
                if not (h_next > 4.0 * np.spacing(max(abs(TT[lane]), 1.0))):
                    ST[lane] = STEP_UNDERFLOW if finite else NONFINITE
            H[lane] = max(H[lane], h_next) if (LAST[lane] != 0 and accept) else h_next
        if n_acc > 0:
            # ---- the step end, the dense output and the samples, for every lane ----
            if m > 0:
                for lane in range(W):
                    T[lane] = t_end if LAST[lane] != 0 else TT[lane] + HH[lane]
                _lanes_call(
                    fns,
                    GUARD,
                    K_GUARD,
                    W,
                    n,
                    m,
                    a_t,
                    a_xn,
                    a_gs + 8 * m * W * (S - 1),
                    a_pr,
                    PR,
                    ACC,
                    FAIL,
                    IA,
                    yo,
                    oo,
                )
            if m > 0 or n_grid > 0:
                _dense_lanes(
                    fns,
                    K2,
                    Q2,
                    X,
                    XN,
                    Y,
                    DY,
                    DYf,
                    HH,
                    TT,
                    T,
                    a_t,
                    a_y,
                    kb,
                    a_pr,
                    PR,
                    ACC,
                    FAIL,
                    IA,
                    yo,
                    oo,
                    n,
                    nf,
                    W,
                )
            if m > 0:
                for i in range(1, S):
                    th = i / S
                    _dense_eval(Q2, nq, dop853, Xf, th, XSf)
                    for lane in range(W):
                        T[lane] = TT[lane] + th * HH[lane]
                    _lanes_call(
                        fns,
                        GUARD,
                        K_GUARD,
                        W,
                        n,
                        m,
                        a_t,
                        a_xs,
                        a_gs + 8 * m * W * (i - 1),
                        a_pr,
                        PR,
                        ACC,
                        FAIL,
                        IA,
                        yo,
                        oo,
                    )
        # ---- what only some lanes do, lane by lane ----
        for lane in range(W):
            ADV[lane] = 0
            if GO[lane] == 0:
                continue
            quiet = ACC[lane] != 0 and (m == 0 or _quiet(GA, lane, S))
            if ACC[lane] == 0:
                pass
            elif FAIL[lane] == 0 and not keep_steps and quiet:
                # no event, nothing failed: the step is taken (the rest of _accepted's work)
                run = runs[SLOT[lane]]
                t1 = t_end if LAST[lane] != 0 else TT[lane] + HH[lane]
                g = GNEXT[lane]
                if g < n_grid and grid[g] <= t1:
                    # each grid point then reads 7 n neighbouring numbers, not 7 n cache lines
                    _lane_dense(X, Q, lane, n, x0c, qc)
                GNEXT[lane] = _grid_points(
                    grid,
                    g,
                    t1,
                    TT[lane],
                    HH[lane],
                    qc,
                    x0c,
                    xs1,
                    grid_x,
                    grid_j,
                    dist,
                    grid_max,
                    run,
                    J[lane],
                )
                TT[lane] = t1
                t_final[run] = t1
                ADV[lane] = 1  # its state, derivative and guard: below, for all such lanes at once
                if LAST[lane] != 0:
                    ST[lane] = COMPLETED
            else:
                stats[3] += 1
                _accepted(
                    fns,
                    lane,
                    runs[SLOT[lane]],
                    SLOT[lane],
                    t_end,
                    fopt,
                    iopt,
                    grid,
                    dist,
                    grid_x,
                    grid_j,
                    grid_max,
                    buffers,
                    log_cap,
                    arc_cap,
                    m,
                    W,
                    X,
                    XN,
                    F,
                    G,
                    GS,
                    K,
                    Q,
                    PR,
                    TT,
                    HH,
                    LAST,
                    ZW,
                    ST,
                    J,
                    NLOG,
                    NARC,
                    GNEXT,
                    FAIL,
                    t_final,
                    x1,
                    xn1,
                    f1,
                    g0,
                    g1,
                    gl,
                    gtmp,
                    xs1,
                    th_s,
                    gs,
                    seq,
                    quiet,
                    x0c,
                    qc,
                )
            if STEPS[lane] + REJ[lane] >= max_steps and ST[lane] == RUNNING:
                ST[lane] = MAX_STEPS
            if FAIL[lane] != 0:
                ST[lane] = MODEL_ERROR
        _advance(ADV, n, m, S, X, XN, F, G, GS, K, W)
    # the views above own no memory: numba frees an array after its last use, so the
    # buffers are used here, after every view's
    buffer[0] = 0.0
    ibuf[0] = 0


@jit
def _start(
    fns,
    lane,
    run,
    slot,
    x_init,
    P,
    t0,
    t_end,
    fopt,
    iopt,
    grid,
    dist,
    grid_x,
    grid_j,
    grid_max,
    buffers,
    log_cap,
    arc_cap,
    m,
    W,
    X,
    F,
    G,
    K,
    Q,
    XN,
    GS,
    PR,
    TT,
    H,
    ZW,
    ST,
    J,
    STEPS,
    REJ,
    NLOG,
    NARC,
    GNEXT,
    WASREJ,
    FAIL,
    x1,
    f1,
    g0,
    y1,
    xs1,
):
    """Put run ``run`` in lane ``lane``: its arrays, grid points and jumps at ``t0``, its first step."""
    n = x1.shape[0]
    n_grid = grid.shape[0]
    # zeros: the flow and the dense output leave the entries nf.. of their rows unwritten
    for r in range(K.shape[0]):
        for q in range(n):
            K[r, q, lane] = 0.0
    for r in range(Q.shape[0]):
        for q in range(n):
            Q[r, q, lane] = 0.0
    for r in range(GS.shape[0]):
        for k in range(m):
            GS[r, k, lane] = 0.0
    for q in range(n):
        x1[q] = x_init[run, q]
        X[q, lane] = x1[q]
        XN[q, lane] = 0.0
    for i in range(P.shape[1]):
        PR[lane, i] = P[run, i]
    ZW[lane, 0] = -np.inf
    ZW[lane, 1] = 0.0
    TT[lane] = t0
    H[lane] = 0.0
    J[lane] = 0
    STEPS[lane] = 0
    REJ[lane] = 0
    NLOG[lane] = 0
    NARC[lane] = 0
    WASREJ[lane] = 0
    FAIL[lane] = 0
    # grid points at or after t0 (those before t0 are never filled)
    gnext = 0
    while gnext < n_grid and grid[gnext] < t0:
        gnext += 1
    if dist.shape[0] > 0 and gnext > 0:  # points before t0 are never reached
        grid_max[run] = np.nan
    if iopt[I_KEEP_STEPS] != 0:
        NARC[lane] = _record_arc(buffers, slot, arc_cap, NARC[lane], t0, 0, x1)
    while gnext < n_grid and grid[gnext] <= t0:
        _grid_keep(grid_x, grid_j, dist, grid_max, run, gnext, 0, x1)
        gnext += 1
    GNEXT[lane] = gnext
    args = _lane_args(fns, lane)
    p = PR[lane]
    # jumps at t0
    st, j, nlog, narc = _jump_until_flow(
        _ctx(args, p, g0, f1, t_end, m, iopt, log_cap, arc_cap, slot, buffers, fopt, ZW[lane]),
        t0,
        x1,
        0,
        NLOG[lane],
        NARC[lane],
    )
    J[lane] = j
    NLOG[lane] = nlog
    NARC[lane] = narc
    _put_lane(lane, x1, f1, g0, X, F, G)
    if st == RUNNING:
        if fopt[F_FIRST_STEP] > 0.0:
            H[lane] = fopt[F_FIRST_STEP]
        else:
            H[lane] = _initial_step(
                args,
                p,
                t0,
                x1,
                f1,
                t_end,
                fopt[F_RTOL],
                fopt[F_ATOL],
                fopt[F_MAX_STEP],
                y1,
                xs1,
                iopt[I_N_FLOW],
            )
            if failed(args):
                st = MODEL_ERROR
    ST[lane] = st


@jit
def _accepted(
    fns,
    lane,
    run,
    slot,
    t_end,
    fopt,
    iopt,
    grid,
    dist,
    grid_x,
    grid_j,
    grid_max,
    buffers,
    log_cap,
    arc_cap,
    m,
    W,
    X,
    XN,
    F,
    G,
    GS,
    K,
    Q,
    PR,
    TT,
    HH,
    LAST,
    ZW,
    ST,
    J,
    NLOG,
    NARC,
    GNEXT,
    FAIL,
    t_final,
    x1,
    xn1,
    f1,
    g0,
    g1,
    gl,
    gtmp,
    xs1,
    th_s,
    gs,
    seq,
    quiet,
    x0c,
    qc,
):
    """The rest of lane ``lane``'s accepted step: its event, its grid points, the step, its jumps.

    The guard at the step end, the dense output and the samples are in ``GS``, ``Q``
    (computed for all lanes); the event is located on the lane's own copy, unless the
    lane is ``quiet`` (:func:`_quiet`: then there is none).
    """
    S = iopt[I_SAMPLES]
    nq = NQ
    dop853 = DOP853
    xtol_t = fopt[F_XTOL]
    n = x1.shape[0]
    args = _lane_args(fns, lane)
    p = PR[lane]
    t_start = TT[lane]
    hh = HH[lane]
    last = LAST[lane] != 0
    t1 = t_end if last else t_start + hh
    _lane_dense(X, Q, lane, n, x0c, qc)  # as fast to read as one run's
    xv = x0c
    qv = qc
    accept = True
    st = RUNNING
    theta_ev = np.nan
    if m > 0 and FAIL[lane] == 0 and not quiet:
        for k in range(m):
            g0[k] = G[k, lane]
            g1[k] = GS[S - 1, k, lane]
        for i in range(S):
            th_s[i] = (i + 1) / S if i < S - 1 else 1.0
            for k in range(m):
                gs[i, k] = GS[i, k, lane]
        theta_ev = _locate(
            args, p, t_start, hh, xv, qv, nq, dop853, g0, gl, gtmp, S, th_s, gs, seq, xs1, xtol_t
        )
    if FAIL[lane] != 0:  # the guard or the dense output failed: keep the last good state
        accept = False
        st = MODEL_ERROR
    elif theta_ev == -np.inf:  # the dense state overflowed where the guard was NaN
        accept = False
        st = NONFINITE
    # a jump due at the final time (within event_xtol of it) is not applied: the run
    # ends on its flow at t_end (docs/solver.md, "Jumps at the final time")
    if np.isfinite(theta_ev) and t_start + theta_ev * hh > t_end - xtol_t:
        theta_ev = np.nan
    if not accept:
        ST[lane] = st
        return
    t_stop = t1
    for q in range(n):
        xn1[q] = XN[q, lane]
    if np.isfinite(theta_ev) and theta_ev < 1.0:
        t_stop = t_start + theta_ev * hh
        _dense_eval(qv, nq, dop853, xv, theta_ev, xs1)
        for q in range(n):
            xn1[q] = xs1[q]
    # grid values up to the stop time, before any jump there
    GNEXT[lane] = _grid_points(
        grid, GNEXT[lane], t_stop, t_start, hh, qv, xv, xs1, grid_x, grid_j, dist, grid_max, run, J[lane]
    )
    TT[lane] = t_stop
    t_final[run] = t_stop  # read while the run goes on: the progress bar's simulated time
    for q in range(n):
        X[q, lane] = xn1[q]
    if iopt[I_KEEP_STEPS] != 0:
        NARC[lane] = _record_arc(buffers, slot, arc_cap, NARC[lane], t_stop, J[lane], xn1)
    if np.isfinite(theta_ev):
        st, j, nlog, narc = _jump_until_flow(
            _ctx(args, p, g0, f1, t_end, m, iopt, log_cap, arc_cap, slot, buffers, fopt, ZW[lane]),
            t_stop,
            xn1,
            J[lane],
            NLOG[lane],
            NARC[lane],
        )
        J[lane] = j
        NLOG[lane] = nlog
        NARC[lane] = narc
        _put_lane(lane, xn1, f1, g0, X, F, G)
    else:
        for q in range(n):
            F[q, lane] = K[N_STAGES, q, lane]  # X is xn1 already
        for k in range(m):
            G[k, lane] = GS[S - 1, k, lane]
        if last:
            st = COMPLETED
    ST[lane] = st


@jit_inline
def _lane_dense(X, Q, lane, n, x0c, qc):
    """Lane ``lane``'s step start ``x0c`` and dense output ``qc``, contiguous copies."""
    for q in range(n):
        x0c[q] = X[q, lane]
    for r in range(NQ):
        for q in range(n):
            qc[r, q] = Q[r, q, lane]


@jit_inline
def _grid_points(grid, gnext, t_stop, t_start, hh, qv, xv, xs1, grid_x, grid_j, dist, grid_max, run, j):
    """The grid points from ``grid[gnext]`` up to ``t_stop`` on a lane's step; the next one's index.

    The step starts at ``t_start`` from ``xv`` with size ``hh`` and dense output ``qv``.
    """
    while gnext < grid.shape[0] and grid[gnext] <= t_stop:
        th = min(max((grid[gnext] - t_start) / hh, 0.0), 1.0)
        _dense_eval(qv, NQ, DOP853, xv, th, xs1)
        _grid_keep(grid_x, grid_j, dist, grid_max, run, gnext, j, xs1)
        gnext += 1
    return gnext


@jit_inline
def _advance(adv, n, m, S, X, XN, F, G, GS, K, W):
    """The lanes with ``adv[lane] != 0`` take their step without a jump: state, derivative (FSAL), guard.

    A loop over lanes with a mask, which LLVM makes vector code.
    """
    for q in range(n):
        for lane in range(W):
            go = adv[lane] != 0
            X[q, lane] = XN[q, lane] if go else X[q, lane]
            F[q, lane] = K[N_STAGES, q, lane] if go else F[q, lane]
    for k in range(m):
        for lane in range(W):
            G[k, lane] = GS[S - 1, k, lane] if adv[lane] != 0 else G[k, lane]


@jit_inline
def _quiet(GA, lane, S):
    """Whether :func:`_locate` finds nothing in lane ``lane``'s step without evaluating anything.

    So when every sample ``GA[i, k, lane]`` (``θ = i/S``, ``i = 0 .. S``) is negative (not
    NaN) and no rule has a peak probe: ``_locate`` then returns NaN, as it would.
    """
    for k in range(GA.shape[1]):
        for i in range(S + 1):
            if not GA[i, k, lane] < 0.0:
                return False
        if S > 1:
            start, inside, end = peak_probes(GA[:, k, lane], S)
            if not (np.isnan(start) and np.isnan(inside) and np.isnan(end)):
                return False
    return True


@jit_inline
def _ctx(args, p, g, f, t_end, m, iopt, log_cap, arc_cap, slot, buffers, fopt, zw):
    """What :func:`_jump_until_flow` needs of a run besides the changing ``(t, x, j, nlog, narc)``."""
    zeno = (iopt[I_ZENO_JUMPS], fopt[F_ZENO_SPAN], zw)
    keep_steps = iopt[I_KEEP_STEPS] != 0
    return (args, p, g, f, t_end, m, iopt[I_MAX_JUMPS], keep_steps, log_cap, arc_cap, slot, buffers, zeno)


@jit_inline
def _lane_args(fns, lane):
    """The run addresses (:data:`etobs.hybrid._kernel.RunArgs`) of lane ``lane``'s one-run calls."""
    return (fns[0], fns[1], fns[2], fns[4], fns[5], fns[8], fns[9] + 8 * lane)


@jit_inline
def _put_lane(lane, x1, f1, g1, X, F, G):
    """Lane ``lane``'s state, derivative and event functions from its contiguous copy."""
    for q in range(x1.shape[0]):
        X[q, lane] = x1[q]
        F[q, lane] = f1[q]
    for k in range(g1.shape[0]):
        G[k, lane] = g1[k]


@jit
def _copy_lane(lane, donor, X, F, PR, TT, HH, n, n_p):
    """An idle lane computes what the running lane ``donor`` does (finite numbers, never read)."""
    for q in range(n):
        X[q, lane] = X[q, donor]
        F[q, lane] = F[q, donor]
    for i in range(n_p):
        PR[lane, i] = PR[donor, i]
    TT[lane] = TT[donor]
    HH[lane] = HH[donor]


@jit_inline
def _lanes_call(fns, slot, k, W, n, rows, a_t, a_x, a_out, a_p, PR, mask, FAIL, IA, x1, o1):
    """The system's function ``slot`` (flow or guard) at every lane: ``out[:, l] = fn(t[l], x[:, l])``.

    ``a_t``, ``a_x``, ``a_out`` and ``a_p`` are the addresses of lane arrays (lane axis
    last, ``W`` lanes). With the system's lane form, one call; else (or when the lane form
    raised: numba printed it) the one-run function lane by lane, on the lanes of ``mask``.
    Failures of the lanes of ``mask`` are recorded in ``FAIL`` as one-run calls record them.
    ``rows`` results are copied out: for the flow its first ``n_flow`` (a flow leaves the
    others unwritten, and the scratch ``o1`` may hold the guard's values there).
    """
    lane_fn = fns[3]
    if lane_fn != 0:
        IA[0] = 0
        IA[1] = W
        IA[2] = W
        ok = ccall(lane_fn, k, 0.0, a_x, a_t, fns[7], fns[5], fns[6], a_p, a_out)
        if ok == 1:
            for lane in range(W):
                st = IA[3 + lane]
                if mask[lane] != 0 and st != 1 and FAIL[lane] == 0:
                    FAIL[lane] = st if st >= 16 else 16 * slot + st
            return
    T = vector_at(a_t, 0, W)
    Xl = rows_at(a_x, 0, n, W)
    Out = rows_at(a_out, 0, rows, W)
    for lane in range(W):
        if mask[lane] == 0:
            continue
        for q in range(n):
            x1[q] = Xl[q, lane]
        args = _lane_args(fns, lane)
        if slot == FLOW:
            flow_call(T[lane], x1, PR[lane], args, o1)
        else:
            guard_call(T[lane], x1, PR[lane], args, o1)
        for q in range(rows):
            Out[q, lane] = o1[q]


@jit_inline
def _dense_lanes(
    fns, K2, Q2, X, XN, Y, DY, DYf, HH, TT, T, a_t, a_y, kb, a_pr, PR, mask, FAIL, IA, yo, oo, n, nf, W
):
    """Rows ``Q`` of the continuous extension of every lane's step (read by ``_dense_eval``).

    Dormand--Prince 5(4): ``Q_k = h sum_i P_ik K_i``. DOP853: ``Q_0 = x_new - x``,
    ``Q_1 = h K_0 - Q_0``, ``Q_2 = 2 Q_0 - h (K_s + K_0)`` and ``Q_(3+r) = h sum_i D_ri K_i``
    over the stages and the extra stages computed here.
    """
    if not DOP853:
        for k in range(NQ):
            _comb(TDD[k], K2, N_STAGES + 1, DYf, nf * W)
            for q in range(nf):
                for lane in range(W):
                    Q2[k, q * W + lane] = HH[lane] * DY[q, lane]
        return
    for r in range(N_EXTRA):
        mm = N_STAGES + 1 + r
        _comb(TDA[r], K2, mm, DYf, nf * W)
        for q in range(nf):
            for lane in range(W):
                Y[q, lane] = X[q, lane] + HH[lane] * DY[q, lane]
        for lane in range(W):
            T[lane] = TT[lane] + TDC[r] * HH[lane]
        _lanes_call(
            fns, FLOW, K_FLOW, W, n, nf, a_t, a_y, kb + 8 * n * W * mm, a_pr, PR, mask, FAIL, IA, yo, oo
        )
    for q in range(nf):
        for lane in range(W):
            i = q * W + lane
            h = HH[lane]
            d = XN[q, lane] - X[q, lane]
            Q2[0, i] = d
            Q2[1, i] = h * K2[0, i] - d
            Q2[2, i] = 2.0 * d - h * (K2[N_STAGES, i] + K2[0, i])
    for r in range(NQ - 3):
        _comb(TDD[r], K2, N_STAGES + 1 + N_EXTRA, DYf, nf * W)
        for q in range(nf):
            for lane in range(W):
                Q2[3 + r, q * W + lane] = HH[lane] * DY[q, lane]


@jit_inline
def _lane_tail_zero(K, r, nf, lane):
    """Whether stage ``r`` of lane ``lane`` is zero from entry ``nf`` on."""
    for i in range(nf, K.shape[1]):
        if K[r, i, lane] != 0.0:
            return False
    return True


@jit_inline
def _grid_keep(grid_x, grid_j, dist, grid_max, run, gk, j, xs):
    """Keep the state ``xs`` at grid point ``gk``, or only fold it into the run's maximum.

    With index pairs ``dist`` (rows ``(a, b)``), ``grid_max[run]`` becomes the largest
    ``sqrt(sum (xs[a] - xs[b])**2)`` so far (``SaveAt(max_distance=...)``), NaN once a
    value is not finite; the states are not kept.
    """
    if dist.shape[0] == 0:
        grid_x[run, gk, :] = xs
        grid_j[run, gk] = j
        return
    acc = 0.0
    for i in range(dist.shape[0]):
        d = xs[dist[i, 0]] - xs[dist[i, 1]]
        acc += d * d
    e = np.sqrt(acc)
    if not np.isfinite(e) or np.isnan(grid_max[run]):
        grid_max[run] = np.nan
    elif e > grid_max[run]:
        grid_max[run] = e


@jit
def _jump_until_flow(ctx, t, x, j, nlog, narc):
    """Apply jumps until every event function is negative, then refresh ``f = flow(t, x)``.

    Returns (status, j, nlog, narc); the status is ``completed`` at ``t_end``,
    ``nonfinite`` when the state or its derivative is not finite, ``zeno`` when the
    jumps pile up in time (:mod:`etobs.hybrid.zeno`) and ``model_error`` when an event
    function is NaN (it would never fire). ``ctx`` is the run's fixed context (see
    ``_solve_one``); its ``buffers`` hold the jump log and arc arrays ``(log_rule, log_t,
    log_j, arc_t, arc_j, arc_x, log_x)`` and the logged state entries ``log_cols``, its
    ``zeno`` the rule's limit, span and window.
    """
    args, p, g, f, t_end, m, max_jumps, keep_steps, log_cap, arc_cap, slot, buffers, zeno = ctx
    log_rule, log_t, log_j, log_x, log_cols = buffers[0], buffers[1], buffers[2], buffers[6], buffers[7]
    zeno_jumps, zeno_span, zw = zeno
    while m > 0:
        guard_call(t, x, p, args, g)
        if not failed(args) and _any_nan(g):
            store_i64(args[6], GUARD_NAN)
        if failed(args):
            return MODEL_ERROR, j, nlog, narc
        if not _any_nonneg(g):
            break
        for k in range(m):
            if g[k] < 0.0:
                continue
            if j >= max_jumps:
                return MAX_JUMPS, j, nlog, narc
            jump_call(k, t, x, p, args)
            if failed(args):
                return MODEL_ERROR, j, nlog, narc
            if nlog < log_cap:
                log_rule[slot, nlog] = k
                log_t[slot, nlog] = t
                log_j[slot, nlog] = j
                for c in range(log_cols.shape[0]):  # the logged entries after the jump
                    log_x[slot, nlog, c] = x[log_cols[c]]
            nlog += 1
            j += 1
            if keep_steps:
                narc = _record_arc(buffers, slot, arc_cap, narc, t, j, x)
            if not _all_finite(x):
                return NONFINITE, j, nlog, narc
            start, count = zeno_window(t, zw[0], int(zw[1]), zeno_span)
            zw[0] = start
            zw[1] = count
            if count > zeno_jumps:
                return ZENO, j, nlog, narc
    flow_call(t, x, p, args, f)
    if failed(args):
        return MODEL_ERROR, j, nlog, narc
    if t >= t_end:
        return COMPLETED, j, nlog, narc
    if not _all_finite(f):
        return NONFINITE, j, nlog, narc
    return RUNNING, j, nlog, narc


@jit
def _record_arc(buffers, slot, arc_cap, narc, t, j, x):
    """Keep ``(t, j, x)`` as the arc's point ``narc`` if there is room; count it anyway."""
    if narc < arc_cap:
        buffers[3][slot, narc] = t
        buffers[4][slot, narc] = j
        buffers[5][slot, narc, :] = x
    return narc + 1


@jit
def _initial_step(args, p, t, x, f, t_end, rtol, atol, max_step, y, f1, nf):
    """Hairer, Nørsett & Wanner (1993), II.4, with norms over the first ``nf`` entries."""
    n = x.shape[0]
    remaining = t_end - t
    d0 = 0.0
    d1 = 0.0
    for q in range(nf):
        sc = atol + rtol * abs(x[q])
        d0 += (x[q] / sc) ** 2
        d1 += (f[q] / sc) ** 2
    d0 = np.sqrt(d0 / nf)
    d1 = np.sqrt(d1 / nf)
    if d0 < 1e-5 or d1 < 1e-5:
        h0 = 1e-6
    else:
        h0 = 0.01 * d0 / d1
    h0 = min(h0, max(remaining, 1e-12))
    for q in range(n):
        y[q] = x[q] + h0 * f[q]
    flow_call(t + h0, y, p, args, f1)
    d2 = 0.0
    for q in range(nf):
        sc = atol + rtol * abs(x[q])
        d2 += ((f1[q] - f[q]) / sc) ** 2
    d2 = np.sqrt(d2 / nf) / h0
    big = max(d1, d2)
    if big <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / big) ** (1.0 / (ERR_ORDER + 1))
    h = min(min(100 * h0, h1), max_step)
    if not (np.isfinite(h) and h > 0):
        h = min(h0, max_step)
    return h


@jit
def _locate(args, p, t0, h, x0, Q, nq, dop853, g0, gl, gtmp, S, th_s, gs, seq, xs, xtol_t):
    """θ of the first event in the step, or NaN (the contract's points 2 and 3).

    ``th_s[:S]`` and the rows ``gs[:S]`` hold the samples of the event functions at
    ``θ = i/S``, ``i = 1 .. S`` (the last is the step end); ``g0`` is their value at the
    step start. The peak probes are evaluated and inserted here.
    """
    m = g0.shape[0]
    ns = S
    gp = address(gs)  # row i of gs is at gp + 8 m i
    if S > 1:
        # etobs.hybrid.peaks: of each kind (start, inside, end) the earliest over the rules
        first_start = np.inf
        first_inside = np.inf
        first_end = np.inf
        for k in range(m):
            seq[0] = g0[k]
            for i in range(S):
                seq[i + 1] = gs[i, k]
            start, inside, end = peak_probes(seq, S)
            # NaN (no probe) compares false
            if start < first_start:
                first_start = start
            if inside < first_inside:
                first_inside = inside
            if end < first_end:
                first_end = end
        for probe in (first_start, first_inside, first_end):
            if probe == np.inf:
                continue
            # insert the probe in θ order (stable: after equal θ)
            pos = ns
            while pos > 0 and th_s[pos - 1] > probe:
                pos -= 1
            for i in range(ns, pos, -1):
                th_s[i] = th_s[i - 1]
                for k in range(m):
                    gs[i, k] = gs[i - 1, k]
            th_s[pos] = probe
            _dense_eval(Q, nq, dop853, x0, probe, xs)
            guard_call(t0 + probe * h, xs, p, args, gp + 8 * m * pos)
            ns += 1
    # a NaN event function never fires: the run must not go on as if it were negative.
    # At a state that has overflowed it is the state's failure (-inf: nonfinite), at a
    # finite state the guard's (model_error), on both solvers
    for i in range(ns):
        if _any_nan(gs[i]):
            _dense_eval(Q, nq, dop853, x0, th_s[i], xs)
            if not _all_finite(xs):
                return -np.inf
            store_i64(args[6], GUARD_NAN)
            return np.nan
    # first sample with any g >= 0
    first = -1
    for i in range(ns):
        if _any_nonneg(gs[i]):
            first = i
            break
    if first < 0:
        return np.nan
    lo = 0.0 if first == 0 else th_s[first - 1]
    hi = th_s[first]
    for k in range(m):
        gl[k] = g0[k] if first == 0 else gs[first - 1, k]
    xtol = max(xtol_t / h, 4 * EPS)
    best = np.inf
    for k in range(m):
        if gl[k] < 0.0 and gs[first, k] >= 0.0:
            root = _bracket_root(
                args, p, t0, h, x0, Q, nq, dop853, k, lo, hi, gl[k], gs[first, k], xtol, xs, gtmp
            )
            if root < best:
                best = root
    if best == np.inf:
        return np.nan
    return best


@jit
def _bracket_root(args, p, t0, h, x0, Q, nq, dop853, k, lo, hi, f_lo, f_hi, xtol, xs, gtmp):
    """Regula falsi (Illinois) with bisection fallback on ``[lo, hi]``; returns the right end."""
    side = 0
    width_before = hi - lo
    for it in range(MAX_ROOT_ITER):
        w = hi - lo
        if not (w > xtol):
            break
        x = hi - f_hi * w / (f_hi - f_lo)
        bisect = (not np.isfinite(x)) or (it % 2 == 1 and w > 0.5 * width_before)
        if bisect:
            x = 0.5 * (lo + hi)
        half = min(0.5 * xtol, 0.5 * w)
        x = min(max(x, lo + half), hi - half)
        if it % 2 == 0:
            width_before = w
        _dense_eval(Q, nq, dop853, x0, x, xs)
        guard_call(t0 + x * h, xs, p, args, gtmp)
        fx = gtmp[k]
        if np.isnan(fx):
            if not _all_finite(xs):  # the state overflowed (see _locate)
                return -np.inf
            store_i64(args[6], GUARD_NAN)
            break
        if fx >= 0:
            if side == 1:
                f_lo *= 0.5
            hi = x
            f_hi = fx
            side = 1
        else:
            if side == -1:
                f_hi *= 0.5
            lo = x
            f_lo = fx
            side = -1
    return hi


@jit_inline
def _comb(w, K, nstage, out, n):
    """``out[:n] = sum_k w[k] K[k, :n]`` over the first ``nstage`` stages, zero weights skipped.

    The terms are added in the order of ``k``, as one by one, but four per pass over ``out``
    (a quarter of its loads and stores: the sums of a step are a third of its work).
    """
    ks = carray(stack_i8(MAX_TERMS), (MAX_TERMS,))
    ws = carray(stack_f8(MAX_TERMS), (MAX_TERMS,))
    nz = 0
    for k in range(nstage):
        if w[k] != 0.0:
            ks[nz] = k
            ws[nz] = w[k]
            nz += 1
    for i in range(n):
        out[i] = 0.0
    g = 0
    while g + 4 <= nz:
        k0, k1, k2, k3 = ks[g], ks[g + 1], ks[g + 2], ks[g + 3]
        w0, w1, w2, w3 = ws[g], ws[g + 1], ws[g + 2], ws[g + 3]
        for i in range(n):
            out[i] = (((out[i] + w0 * K[k0, i]) + w1 * K[k1, i]) + w2 * K[k2, i]) + w3 * K[k3, i]
        g += 4
    while g < nz:
        k0, w0 = ks[g], ws[g]
        for i in range(n):
            out[i] += w0 * K[k0, i]
        g += 1
