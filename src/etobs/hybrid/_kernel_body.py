"""Template of the compiled solver kernel; :func:`etobs.hybrid._kernel.build` runs it.

Not imported as a module: ``build`` executes this text in a namespace that holds the
decorators ``jit``/``jit_nogil`` and the method's tableau as constants (``TA, TB, TC,
TE, TE3, TDA, TDC, TDD, N_STAGES, N_EXTRA, NQ, ERR_ORDER, DOP853``), so that numba
folds the coefficients. The system's functions are called by address through
``flow``, ``guard`` and ``jump`` of :mod:`etobs.hybrid._kernel`. The algorithm is
documented there.
"""
# ruff: noqa: F821

import numpy as np

from etobs.hybrid._kernel import (
    COMPLETED,
    EPS,
    F_ATOL,
    F_FIRST_STEP,
    F_MAX_STEP,
    F_RTOL,
    F_XTOL,
    F_ZENO_SPAN,
    FLOW_BEYOND_N_FLOW,
    GUARD_NAN,
    I_KEEP_STEPS,
    I_MAX_JUMPS,
    I_MAX_STEPS,
    I_N_FLOW,
    I_N_WORK,
    I_SAMPLES,
    I_ZENO_JUMPS,
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
    failed,
    flow,
    flow_call,
    guard,
    guard_call,
    jump_call,
    load_i64,
    peak_probes,
    rows_at,
    run_args,
    store_i64,
    vector_at,
    zeno_window,
)


@jit_nogil
def _kernel(
    args,
    X0,
    P,
    n_rules,
    t0,
    t_end,
    fopt,
    iopt,
    grid,
    log_cap,
    arc_cap,
    log_cols,
    runs,
    status,
    t_final,
    j_final,
    x_final,
    n_steps,
    n_rejected,
    log_n,
    log_rule,
    log_t,
    log_j,
    grid_x,
    grid_j,
    dist,
    grid_max,
    arc_n,
    arc_t,
    arc_j,
    arc_x,
    error_code,
    log_x,
):
    # the scratch and failure flag of the runs of this thread, one run at a time; the
    # solver's own arrays live in one buffer (see _solve_one)
    work = np.zeros(iopt[I_N_WORK])
    failure = np.zeros(1, dtype=np.int64)
    buffer = np.empty(_scratch_size(X0.shape[1], n_rules, iopt[I_SAMPLES], P.shape[1]))
    for r in range(runs.shape[0]):
        run = runs[r]
        _solve_one(
            run_args(args, work, failure),
            address(buffer),
            X0[run],
            P[run],
            n_rules,
            t0,
            t_end,
            fopt,
            iopt,
            grid,
            log_cap,
            arc_cap,
            log_cols,
            run,
            r,
            status,
            t_final,
            j_final,
            x_final,
            n_steps,
            n_rejected,
            log_n,
            log_rule,
            log_t,
            log_j,
            grid_x,
            grid_j,
            dist,
            grid_max,
            arc_n,
            arc_t,
            arc_j,
            arc_x,
            error_code,
            log_x,
        )


@jit
def _scratch_size(n, m, S, n_p):
    """Floats of the solver's arrays for one run (see ``_solve_one``)."""
    n_s = max(S - 1, 0)
    return (N_STAGES + 1 + N_EXTRA) * n + NQ * n + 6 * n + 4 * m + (n_s + 4) * (1 + m) + n_s + 2 + n_p + 2 + 1


@jit
def _solve_one(
    args,
    base,
    x_init,
    p_run,
    m,
    t0,
    t_end,
    fopt,
    iopt,
    grid,
    log_cap,
    arc_cap,
    log_cols,
    run,
    slot,
    status,
    t_final,
    j_final,
    x_final,
    n_steps,
    n_rejected,
    log_n,
    log_rule,
    log_t,
    log_j,
    grid_x,
    grid_j,
    dist,
    grid_max,
    arc_n,
    arc_t,
    arc_j,
    arc_x,
    error_code,
    log_x,
):
    rtol, atol = fopt[F_RTOL], fopt[F_ATOL]
    max_step, first_step, xtol_t = fopt[F_MAX_STEP], fopt[F_FIRST_STEP], fopt[F_XTOL]
    max_jumps, max_steps, S = iopt[I_MAX_JUMPS], iopt[I_MAX_STEPS], iopt[I_SAMPLES]
    dop853 = DOP853
    keep_steps = iopt[I_KEEP_STEPS] != 0
    n = x_init.shape[0]
    # entries nf .. n-1 are constant along flows (a network's packets): they are left out
    # of the stages, the error norm and the dense output, and the flow need not write them
    nf = iopt[I_N_FLOW]
    s = N_STAGES  # stages without the FSAL one
    n_extra = N_EXTRA
    nq = NQ
    err_exp = -1.0 / (ERR_ORDER + 1)
    n_grid = grid.shape[0]

    buffers = (log_rule, log_t, log_j, arc_t, arc_j, arc_x, log_x, log_cols)
    # every array of the step loop is a view into the thread's buffer at ``base``, which
    # owns no memory: numba counts references on arrays that do at every call that takes
    # them, two atomic operations each (shared ones, like a row of P, also across threads)
    n_s = max(S - 1, 0)
    o = 0
    K = rows_at(base, o, s + 1 + n_extra, n)
    kp = base + 8 * o  # row i of K is at kp + 8 n i (no views in the step loop)
    o += (s + 1 + n_extra) * n
    Q = rows_at(base, o, nq, n)
    o += nq * n
    x = vector_at(base, o, n)
    x_new = vector_at(base, o + n, n)
    y = vector_at(base, o + 2 * n, n)
    dy = vector_at(base, o + 3 * n, nf)
    xs = vector_at(base, o + 4 * n, n)
    f = vector_at(base, o + 5 * n, n)
    o += 6 * n
    g = vector_at(base, o, m)
    g1 = vector_at(base, o + m, m)
    gl = vector_at(base, o + 2 * m, m)
    gtmp = vector_at(base, o + 3 * m, m)
    o += 4 * m
    # the samples of a step (S - 1 inside, the end) and up to three peak probes
    th_s = vector_at(base, o, n_s + 4)
    o += n_s + 4
    gs = rows_at(base, o, n_s + 4, m)
    o += (n_s + 4) * m
    seq = vector_at(base, o, n_s + 2)  # one event function's samples, θ = 0 .. 1
    o += n_s + 2
    p = vector_at(base, o, p_run.shape[0])
    o += p_run.shape[0]
    zw = vector_at(base, o, 2)  # the Zeno rule's window: its start and its jumps
    o += 2
    # zeros: the flow and the dense output leave the entries nf.. of their rows unwritten
    everything = vector_at(base, 0, o)
    for i in range(o):
        everything[i] = 0.0
    for i in range(n):
        x[i] = x_init[i]
    for i in range(p_run.shape[0]):
        p[i] = p_run[i]
    zw[0] = -np.inf
    zeno = (iopt[I_ZENO_JUMPS], fopt[F_ZENO_SPAN], zw)
    # what _jump_until_flow needs besides the changing (t, x, j, nlog, narc)
    ctx = (args, p, g, f, t_end, m, max_jumps, keep_steps, log_cap, arc_cap, slot, buffers, zeno)
    t = t0
    j = 0
    st = RUNNING
    steps = 0
    rejected_n = 0
    nlog = 0
    narc = 0
    h = 0.0
    was_rejected = False

    # grid points at or after t0 (those before t0 are never filled)
    gnext = 0
    while gnext < n_grid and grid[gnext] < t0:
        gnext += 1
    if dist.shape[0] > 0 and gnext > 0:  # points before t0 are never reached
        grid_max[run] = np.nan

    if keep_steps:
        narc = _record_arc(buffers, slot, arc_cap, narc, t, j, x)
    while gnext < n_grid and grid[gnext] <= t:
        _grid_keep(grid_x, grid_j, dist, grid_max, run, gnext, j, x)
        gnext += 1

    # jumps at t0
    st, j, nlog, narc = _jump_until_flow(ctx, t, x, j, nlog, narc)
    if st == RUNNING:
        if first_step > 0.0:
            h = first_step
        else:
            h = _initial_step(args, p, t, x, f, t_end, rtol, atol, max_step, y, xs, nf)
            if failed(args):
                st = MODEL_ERROR

    while st == RUNNING:
        # ---- one step ----
        remaining = t_end - t
        hh = min(min(h, max_step), remaining)
        last = hh >= remaining
        if not last and not (hh > 0.0):
            # a zero or NaN step never moves t, and h * factor stays zero (the automatic
            # first step of a huge state, from the first step on); a tiny positive one
            # grows by up to MAX_FACTOR per accepted step
            st = NONFINITE if np.isnan(hh) else STEP_UNDERFLOW
            break
        for i in range(n):
            K[0, i] = f[i]
        for q in range(nf, n):  # the stages' constant entries (a jump may have changed them)
            y[q] = x[q]
            x_new[q] = x[q]
        # stages 1..s-1, then the new state and its derivative (FSAL) at stage s;
        # one call site, because ``flow`` is inlined
        for i in range(1, s + 1):
            if i < s:
                _comb(TA[i], K, i, dy, nf)
                ti = t + TC[i] * hh
                yi = y
            else:
                _comb(TB, K, s, dy, nf)
                ti = t + hh
                yi = x_new
            for q in range(nf):
                yi[q] = x[q] + hh * dy[q]
            flow(ti, yi, p, args, kp + 8 * n * i)
        # the flow broke its n_flow promise (at the step's two ends: a flow that moves those
        # entries moves them there too, and a check of every stage would cost a step's sums)
        if nf < n and not (_tail_zero(K, 0, nf) and _tail_zero(K, s, nf)):
            store_i64(args[6], FLOW_BEYOND_N_FLOW)
        # error norm: the scaled RMS norm of the embedded estimate h sum_k e_k K_k (Hairer et
        # al. II.4 (4.11)); DOP853 corrects its 5th-order estimate by the 3rd-order one,
        # err = |h| e5^2 / sqrt((e5^2 + 0.01 e3^2) n), as their code does
        _comb(TE, K, s + 1, dy, nf)
        e5 = 0.0
        for q in range(nf):
            sc = atol + rtol * max(abs(x[q]), abs(x_new[q]))
            dy[q] = dy[q] / sc
            e5 += dy[q] * dy[q]
        if dop853:
            _comb(TE3, K, s + 1, y, nf)
            e3 = 0.0
            for q in range(nf):
                sc = atol + rtol * max(abs(x[q]), abs(x_new[q]))
                v3 = y[q] / sc
                e3 += v3 * v3
            denom = e5 + 0.01 * e3
            err = 0.0 if denom == 0.0 else abs(hh) * e5 / np.sqrt(denom * nf)
        else:
            err = abs(hh) * np.sqrt(e5 / nf)
        # a failed call leaves its output unwritten: the step must not be taken (the run
        # then ends with model_error at its last good state)
        finite = np.isfinite(err) and _all_finite(x_new) and _row_finite(K, s, nf) and not failed(args)
        accept = finite and err <= 1.0
        if err == 0.0:
            factor = MAX_FACTOR
        elif finite:
            factor = min(max(SAFETY * err**err_exp, MIN_FACTOR), MAX_FACTOR)
        else:
            factor = MIN_FACTOR
        if (not accept) or was_rejected:
            factor = min(factor, 1.0)
        was_rejected = not accept
        h_next = hh * factor
        if accept:
            steps += 1
        else:
            rejected_n += 1
            if not (h_next > 4.0 * np.spacing(max(abs(t), 1.0))):
                st = STEP_UNDERFLOW if finite else NONFINITE
        h = max(h, h_next) if (last and accept) else h_next
        too_many = steps + rejected_n >= max_steps
        if accept:
            # ---- accepted step ----
            t_start = t
            t1 = t_end if last else t + hh
            guard_call(t1, x_new, p, args, g1)
            have_q = m > 0 or n_grid > 0
            if have_q:
                _dense_coeffs(args, p, t_start, x, x_new, K, hh, Q, y, dy)
            theta_ev = np.nan
            if m > 0 and not failed(args):
                theta_ev = _locate(
                    args, p, t_start, hh, x, Q, nq, dop853, g, g1, gl, gtmp, S, th_s, gs, seq, xs, xtol_t
                )
            if failed(args):  # the guard or the dense output failed: keep the last good state
                accept = False
                st = MODEL_ERROR
            elif theta_ev == -np.inf:  # the dense state overflowed where the guard was NaN
                accept = False
                st = NONFINITE
            # a jump due at the final time (within event_xtol of it) is not applied: the run
            # ends on its flow at t_end (docs/solver.md, "Jumps at the final time")
            if np.isfinite(theta_ev) and t_start + theta_ev * hh > t_end - xtol_t:
                theta_ev = np.nan
        if accept:
            t_stop = t1
            if np.isfinite(theta_ev) and theta_ev < 1.0:
                t_stop = t_start + theta_ev * hh
                _dense_eval(Q, nq, dop853, x, theta_ev, xs)
                for q in range(n):
                    x_new[q] = xs[q]
            # grid values up to the stop time, before any jump there
            while gnext < n_grid and grid[gnext] <= t_stop:
                th = min(max((grid[gnext] - t_start) / hh, 0.0), 1.0)
                _dense_eval(Q, nq, dop853, x, th, xs)
                _grid_keep(grid_x, grid_j, dist, grid_max, run, gnext, j, xs)
                gnext += 1
            t = t_stop
            t_final[run] = t  # read while the run goes on: the progress bar's simulated time
            for q in range(n):
                x[q] = x_new[q]
            if keep_steps:
                narc = _record_arc(buffers, slot, arc_cap, narc, t, j, x)
            if np.isfinite(theta_ev):
                st, j, nlog, narc = _jump_until_flow(ctx, t, x, j, nlog, narc)
            else:
                for q in range(n):
                    f[q] = K[s, q]
                for k in range(m):
                    g[k] = g1[k]
                if last:
                    st = COMPLETED
        if too_many and st == RUNNING:
            st = MAX_STEPS
        if failed(args):
            st = MODEL_ERROR

    if dist.shape[0] > 0 and gnext < n_grid:  # grid points never reached
        grid_max[run] = np.nan
    status[run] = st
    t_final[run] = t
    j_final[run] = j
    x_final[run, :] = x
    n_steps[run] = steps
    n_rejected[run] = rejected_n
    log_n[run] = nlog
    arc_n[run] = narc
    error_code[run] = load_i64(args[6])


@jit
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
def _tail_zero(K, r, nf):
    """Whether row ``r`` of ``K`` is zero from entry ``nf`` on."""
    for i in range(nf, K.shape[1]):
        if K[r, i] != 0.0:
            return False
    return True


@jit
def _row_finite(K, r, nf):
    """Whether row ``r`` of ``K`` is finite in its first ``nf`` entries (read in place)."""
    for i in range(nf):
        if not np.isfinite(K[r, i]):
            return False
    return True


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
def _dense_coeffs(args, p, t, x, x_new, K, h, Q, y, dy):
    """Rows ``Q`` of the continuous extension of the first ``len(dy)`` entries (read by ``_dense_eval``).

    Dormand--Prince 5(4): ``Q_k = h sum_i P_ik K_i``. DOP853: ``Q_0 = x_new - x``,
    ``Q_1 = h K_0 - Q_0``, ``Q_2 = 2 Q_0 - h (K_s + K_0)`` and ``Q_(3+r) = h sum_i D_ri K_i``
    over the stages and the extra stages computed here.
    """
    n = x.shape[0]
    nf = dy.shape[0]
    if not DOP853:
        # Dormand--Prince 5(4): Q[k] = h * sum_i P[i, k] K[i]
        for k in range(NQ):
            _comb(TDD[k], K, N_STAGES + 1, dy, nf)
            for q in range(nf):
                Q[k, q] = h * dy[q]
        return
    for r in range(N_EXTRA):
        mm = N_STAGES + 1 + r
        _comb(TDA[r], K, mm, dy, nf)
        for q in range(nf):
            y[q] = x[q] + h * dy[q]
        flow(t + TDC[r] * h, y, p, args, address(K) + 8 * n * mm)
    for q in range(nf):
        d = x_new[q] - x[q]
        Q[0, q] = d
        Q[1, q] = h * K[0, q] - d
        Q[2, q] = 2.0 * d - h * (K[N_STAGES, q] + K[0, q])
    for r in range(NQ - 3):
        _comb(TDD[r], K, N_STAGES + 1 + N_EXTRA, dy, nf)
        for q in range(nf):
            Q[3 + r, q] = h * dy[q]


@jit
def _locate(args, p, t0, h, x0, Q, nq, dop853, g0, g1, gl, gtmp, S, th_s, gs, seq, xs, xtol_t):
    """θ of the first event in the step, or NaN (the contract's points 2 and 3)."""
    m = g0.shape[0]
    # samples θ = i/S (i = 1..S-1), then the end θ = 1, then maybe the peak probes
    ns = 0
    gp = address(gs)  # row i of gs is at gp + 8 m i
    for i in range(1, S):
        th_s[ns] = i / S
        _dense_eval(Q, nq, dop853, x0, th_s[ns], xs)
        guard(t0 + th_s[ns] * h, xs, p, args, gp + 8 * m * ns)
        ns += 1
    th_s[ns] = 1.0
    for k in range(m):
        gs[ns, k] = g1[k]
    ns += 1
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


@jit
def _comb(w, K, nstage, out, n):
    """``out[:n] = sum_k w[k] K[k, :n]`` over the first ``nstage`` stages, zero weights skipped."""
    for i in range(n):
        out[i] = 0.0
    for k in range(nstage):
        wk = w[k]
        if wk != 0.0:
            for i in range(n):
                out[i] += wk * K[k, i]
