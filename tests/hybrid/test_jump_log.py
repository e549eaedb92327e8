"""The jump log as data: the logged state after every jump, rows, tables, short reprs, progress.

``log_columns`` makes both backends keep the post-jump values of chosen state entries
(``JumpLog.x``); they are checked against closed forms (the bouncing ball's velocity
after each bounce, two clocks' resets) and against each other. The log reads as a table
(``len``, rows, masks, ``to_pandas``); results print in a few lines; ``progress`` reports
every run once and changes no number.
"""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from etobs.errors import InputError, InputTypeError
from etobs.hybrid import SaveAt, SolverOptions, solve
from etobs.hybrid import compiled as comp
from etobs.hybrid.compiled import compile_system, solve_compiled
from etobs.hybrid.recorder import Recorder
from etobs.hybrid.solution import JumpLog, JumpRow

from .systems import G, _ball_flow, _ball_guard, _ball_jump, bouncing_ball, two_clocks

BACKENDS = ("engine", "scipy")
RESTITUTION = 0.8
H0 = np.array([1.0, 2.0, 0.7])  # Zeno at 9 sqrt(2 h0 / g) >= 3.4 s (r = 0.8)


def logged_ball(log_columns=(0, 1)):
    """The bouncing ball logging ``log_columns`` of ``x = (height, velocity)``."""
    return replace(bouncing_ball(RESTITUTION), log_columns=log_columns)


def velocities_after_bounces(h0, r, k, g=G):
    """Closed form: dropped from rest at ``h0`` the ball hits at ``sqrt(2 g h0)``, leaves at ``r^k`` times it."""
    return np.sqrt(2 * g * h0) * r ** np.arange(1, k + 1)


# ---- the post-jump values ---------------------------------------------------------------


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_log_keeps_the_velocity_after_each_bounce(backend):
    sol = solve(logged_ball(), np.c_[H0, np.zeros(3)], (0.0, 3.0), save=SaveAt(steps=False), backend=backend)
    assert sol.ok and sol.jumps.names == ("x_0", "x_1")
    assert sol.jumps.x.shape == (len(sol.jumps), 2)
    for r, h in enumerate(H0):
        rows = sol.jumps.select(run=r)
        assert len(rows) >= 3
        np.testing.assert_array_equal(rows.x[:, 0], 0.0)  # the jump map puts the ball on the floor
        np.testing.assert_allclose(
            rows.x[:, 1], velocities_after_bounces(h, RESTITUTION, len(rows)), rtol=1e-7
        )


def test_backends_agree_on_the_logged_values_and_the_order_of_columns():
    x0, span = np.c_[H0, np.zeros(3)], (0.0, 2.0)
    ours, sci = (solve(logged_ball((1, 0)), x0, span, backend=b) for b in BACKENDS)
    assert ours.jumps.names == sci.jumps.names == ("x_1", "x_0")
    np.testing.assert_array_equal(ours.jumps.run, sci.jumps.run)
    np.testing.assert_allclose(ours.jumps.x, sci.jumps.x, rtol=1e-7, atol=1e-12)
    # the log holds what the arcs hold just after each jump (steps=True, the default)
    for r, arc in enumerate(ours.arcs):
        after = np.flatnonzero(np.diff(arc.j) == 1) + 1
        np.testing.assert_array_equal(arc.x[after][:, [1, 0]], ours.jumps.select(run=r).x)


@pytest.mark.parametrize("backend", BACKENDS)
def test_simultaneous_jumps_each_log_the_state_after_their_own_jump(backend):
    # equal periods: both clocks reach 1 at t = 0.5, 1.5; rule 0 resets clock 0 first, then
    # rule 1 resets clock 1 (contract point 4), each row shows the state after its own jump
    system = replace(two_clocks(1.0, 1.0), log_columns=(0, 1))
    sol = solve(system, [0.5, 0.5], (0.0, 2.0), backend=backend)
    assert sol.jumps.rule.tolist() == [0, 1, 0, 1]
    np.testing.assert_allclose(sol.jumps.x, [[0.0, 1.0], [0.0, 0.0]] * 2, atol=1e-9)


@pytest.mark.parametrize("backend", BACKENDS)
def test_without_log_columns_the_log_has_no_columns(backend):
    sol = solve(bouncing_ball(), [1.0, 0.0], (0.0, 1.0), backend=backend)
    assert sol.jumps.x.shape == (len(sol.jumps), 0) and sol.jumps.names == ()
    assert sol.jumps.to_pandas().columns.tolist() == ["run", "rule", "t", "j"]


def test_log_columns_pass_from_the_system_to_every_form():
    system = logged_ball((1,))
    assert system.compiled().log_columns == system.batched().log_columns == (1,)
    ball = compile_system(
        _ball_flow, _ball_guard, _ball_jump, n=2, n_rules=1, n_params=2, log_columns=np.array([1])
    )
    sol = solve_compiled(ball, [1.0, 0.0], (0.0, 2.0), params=[RESTITUTION, G])
    assert len(sol.jumps) == 3  # at 0.45, 1.17 and 1.75 s
    np.testing.assert_allclose(sol.jumps.x[:, 0], velocities_after_bounces(1.0, RESTITUTION, 3), rtol=1e-7)


@pytest.mark.parametrize(
    ("log_columns", "error", "match"),
    [
        ((2,), InputError, r"`log_columns` must be state indices 0\.\.1 \(n = 2\); got \[2\]"),
        ((1, 1), InputError, r"`log_columns` must not repeat an index; got \[1, 1\]"),
        ((-1,), InputError, r"`log_columns\[0\]` must be an integer >= 0; got -1"),
        ((0.5,), InputTypeError, r"`log_columns\[0\]` must be an integer; got 0\.5"),
        ("x", InputTypeError, r"`log_columns\[0\]` must be an integer; got 'x'"),
    ],
)
def test_bad_log_columns_are_refused_by_every_system(log_columns, error, match):
    with pytest.raises(error, match=match):
        logged_ball(log_columns)
    with pytest.raises(error, match=match):
        replace(bouncing_ball().compiled(), log_columns=log_columns)
    with pytest.raises(error, match=match):
        replace(bouncing_ball().batched(), log_columns=log_columns)


# ---- the engine's buffers ---------------------------------------------------------------


def test_logged_values_survive_the_rerun_of_runs_whose_buffers_overflowed(monkeypatch):
    # restitution 0.9 from (0.5, -1): Zeno at t ~ 6.2 s, stopped at max_jumps = 300, more
    # than the smallest first-pass buffer of 64 rows, so that run is solved again
    ball = replace(bouncing_ball(0.9), log_columns=(1,)).compiled()
    opts, X0 = SolverOptions(max_jumps=300), [[1.0, 0.0], [2.0, 1.0], [0.5, -1.0]]
    big = solve_compiled(ball, X0, (0.0, 8.0), params=[0.9, G], options=opts, save=SaveAt(steps=False))
    monkeypatch.setattr(comp, "_BUFFER_BUDGET", 1)
    small = solve_compiled(ball, X0, (0.0, 8.0), params=[0.9, G], options=opts, save=SaveAt(steps=False))
    assert small.status_labels()[2] == "max_jumps" and len(small.jumps.select(run=2)) == 300
    np.testing.assert_array_equal(small.jumps.x, big.jumps.x)
    np.testing.assert_array_equal(small.jumps.t, big.jumps.t)


def test_the_first_pass_buffers_of_a_sweep_chunk_stay_within_the_budget():
    # 1000 runs of a 40-state model logging 8 columns, arcs kept: each kind of buffer
    # within its budget of _BUFFER_BUDGET words (32 MiB)
    R, n, c = 1000, 40, 8
    log_cap, arc_cap = comp.capacities(R, n, c, keep_steps=True)
    assert R * log_cap * (3 + c) <= comp._BUFFER_BUDGET and R * arc_cap * (2 + n) <= comp._BUFFER_BUDGET
    assert log_cap < comp.capacities(R, n, 0, keep_steps=False)[0]  # logged columns cost room
    assert comp.capacities(1, n, c, keep_steps=False) == (comp.LOG_CAPACITY, 0)


def test_the_engine_runs_the_kernel_built_from_the_current_template():
    # the kernel is cached on disk under a hash of its template's text: the module loaded
    # is the current template (with the logged columns), never an older build
    kernel = comp._built("dop853")
    generated = Path(kernel.py_func.__globals__["__file__"]).read_text(encoding="utf-8")
    body = Path(comp.__file__).with_name("_kernel_body.py").read_text(encoding="utf-8")
    assert generated.endswith(body) and "log_x[slot, nlog, c] = x[log_cols[c]]" in body


def test_the_reference_recorder_copies_the_logged_values():
    rec = Recorder(1, 2, SaveAt(steps=False), 0.0, log_columns=(1,))
    x = np.array([[0.0, 3.0]])
    rec.jumps(np.array([0]), 0, np.array([0.5]), np.array([0]), x)
    x[0, 1] = -1.0  # the solver's state moves on
    assert rec.jump_log().x.tolist() == [[3.0]]


# ---- the log as a table -----------------------------------------------------------------


@pytest.fixture(scope="module")
def log():
    """Two runs of the ball logging its velocity: 2 + 3 bounces (at 0.45, 1.17 and 0.25, 0.64, 0.96 s)."""
    sol = solve(logged_ball((1,)), [[1.0, 0.0], [0.3, 0.0]], (0.0, 1.2), backend="engine")
    assert sol.jumps.select(run=0).j.tolist() == [0, 1] and sol.jumps.select(run=1).j.tolist() == [0, 1, 2]
    return sol.jumps


def test_rows_slices_masks_and_iteration(log):
    assert len(log) == 5
    row = log[1]
    assert isinstance(row, JumpRow) and (row.run, row.rule, row.j) == (0, 0, 1)
    assert row.t == log.t[1] and row.x.tolist() == log.x[1].tolist()
    assert log[-1].run == 1 and log[np.int64(4)].j == 2
    assert isinstance(log[1:3], JumpLog) and log[1:3].run.tolist() == [0, 1]
    late = log[log.t > 0.8]
    assert late.t.min() > 0.8 and late.x.shape == (len(late), 1) and late.names == ("x_1",)
    assert log[[4, 0]].run.tolist() == [1, 0] and len(log[[]]) == 0
    rows = list(log)
    assert [r.t for r in rows] == log.t.tolist() and all(isinstance(r.x, np.ndarray) for r in rows)
    rows[0].x[0] = 99.0  # a row is a copy
    assert log.x[0, 0] != 99.0
    assert log.select(run=1, rule=0).x.tolist() == log.x[2:].tolist()


def test_bad_keys_are_refused_with_what_the_log_holds(log):
    with pytest.raises(IndexError, match=r"JumpLog row 5 is out of range: the log has 5 rows"):
        log[5]
    with pytest.raises(IndexError, match=r"JumpLog rows \[0, 7\] are out of range: the log has 5 rows"):
        log[[0, 7]]
    with pytest.raises(IndexError, match=r"boolean mask of a JumpLog must have shape \(5,\).*got \(2,\)"):
        log[np.array([True, False])]
    with pytest.raises(InputTypeError, match=r"indexed by an int, a slice, a boolean mask.*dtype float64"):
        log[np.array([0.5])]
    with pytest.raises(InputTypeError, match=r"columns are attributes: log\.t, log\.x\); got str 't'"):
        log["t"]


def test_to_pandas_and_to_dict(log):
    df = log.to_pandas()
    assert df.columns.tolist() == ["run", "rule", "t", "j", "x_1"]
    assert df["t"].tolist() == log.t.tolist() and df["x_1"].tolist() == log.x[:, 0].tolist()
    assert df.dtypes["run"] == np.int64 and df.dtypes["j"] == np.int64
    named = log.to_pandas(names=["v_after"])
    assert named.columns.tolist()[-1] == "v_after"
    d = log.to_dict()
    assert list(d) == ["run", "rule", "t", "j", "x_1"] and d["x_1"].tolist() == log.x[:, 0].tolist()
    assert np.asarray(log.t).shape == (5,) and np.asarray(log.x).shape == (5, 1)


def test_names_without_values_are_refused():
    # the values would have been uninitialised memory (6.9e-310 seen)
    one = np.zeros(1, dtype=np.int64)
    with pytest.raises(
        InputError, match=r"JumpLog `names` \['a'\] given without `x`: give the logged values too"
    ):
        JumpLog(one, one, np.zeros(1), one, names=("a",))
    assert JumpLog(one, one, np.zeros(1), one).x.shape == (1, 0)


@pytest.mark.parametrize(
    ("names", "error", "match"),
    [
        (["a", "b"], InputError, r"`names` must give 1 names \(one per logged state entry\); got 2"),
        (["t"], InputError, r"`names` must be distinct strings other than run, rule, t, j; got \['t'\]"),
        ([3], InputError, r"`names` must be distinct strings.*got \[3\]"),
        ("v", InputTypeError, r"`names` must be a sequence of column names; got the string 'v'"),
        (5, InputTypeError, r"`names` must be a sequence of column names; got int"),
    ],
)
def test_bad_column_names_are_refused(log, names, error, match):
    with pytest.raises(error, match=match):
        log.to_pandas(names=names)


def test_a_log_must_have_consistent_columns():
    one = np.zeros(1, dtype=np.int64)
    with pytest.raises(InputError, match=r"JumpLog `t` must have shape \(1,\) like `run`; got \(2,\)"):
        JumpLog(one, one, np.zeros(2), one)
    with pytest.raises(
        InputError, match=r"JumpLog `x` must have shape \(1, 1\) \(rows, names\); got \(1, 2\)"
    ):
        JumpLog(one, one, np.zeros(1), one, x=np.zeros((1, 2)), names=("a",))
    plain = JumpLog(one, one, np.zeros(1), one, x=np.ones((1, 2)))
    assert plain.names == ("x_0", "x_1")  # columns of x named by position when not named


# ---- short reprs ------------------------------------------------------------------------


def test_reprs_are_a_few_lines_whatever_the_result_holds():
    x0 = np.c_[np.linspace(0.5, 2.0, 2), np.zeros(2)]
    sol = solve(logged_ball((1,)), x0, (0.0, 5.0), save=SaveAt(steps=True, grid=np.linspace(0, 5, 501)))
    text = repr(sol)
    assert len(text.splitlines()) == 3 and len(text) < 400, text
    assert text.startswith("HybridSolution (engine): 2 runs on t in [0, 5]; 1 completed, 1 zeno\n")
    assert (
        f"jumps: {len(sol.jumps)} (impact: {len(sol.jumps)})" in text
        and "SavedGrid: 2 runs x 501 points" in text
    )
    arc = repr(sol.arcs[0])
    assert "\n" not in arc and arc.startswith(f"HybridArc: {len(sol.arcs[0])} points, n = 2, t in [0, ")
    log = repr(sol.jumps)
    assert len(log.splitlines()) <= 8 and len(log) < 600, log
    assert log.startswith(f"JumpLog: {len(sol.jumps)} jumps in 2 runs (jumps per rule: 0: {len(sol.jumps)})")
    assert log.splitlines()[1].split() == ["run", "rule", "t", "j", "x_1"]
    assert log.endswith(f"... {len(sol.jumps) - 5} more rows")
    html = sol.jumps._repr_html_()
    assert html.count("<tr>") == 1 + 10 and "<th>x_1</th>" in html and len(html) < 3000
    empty = JumpLog(*(np.zeros(0, dtype=np.int64),) * 2, np.zeros(0), np.zeros(0, dtype=np.int64))
    assert repr(empty) == "JumpLog: 0 jumps in 0 runs (jumps per rule: none)"


# ---- progress ---------------------------------------------------------------------------


def _batch(B):
    return np.c_[np.linspace(0.2, 2.0, B), np.zeros(B)]


def _assert_same(a, b):
    for key in ("status", "t_final", "j_final", "x_final", "n_steps", "n_rejected"):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key))
    for key in ("run", "rule", "t", "j", "x"):
        np.testing.assert_array_equal(getattr(a.jumps, key), getattr(b.jumps, key))


@pytest.mark.parametrize("parallel", [True, False])
def test_engine_progress_reports_every_run_once_and_changes_no_number(parallel, monkeypatch):
    ball = logged_ball((1,)).compiled()
    B = 11
    calls = []
    kernel_calls = []
    real_call = comp._call
    monkeypatch.setattr(comp, "_call", lambda *a: kernel_calls.append(a[9].size) or real_call(*a))
    args = (ball, _batch(B), (0.0, 1.5))
    kw = {"params": [RESTITUTION, G], "save": SaveAt(steps=False), "parallel": parallel}
    plain = solve_compiled(*args, **kw)
    reported = solve_compiled(*args, **kw, progress=calls.append)
    # one pass over the whole batch, with or without progress (no chunks that wait for
    # their slowest run); the reports, by simulated time, add up to the B runs
    assert kernel_calls == [B, B]
    assert sum(calls) == pytest.approx(B, rel=1e-12) and all(c > 0 for c in calls)
    _assert_same(plain, reported)


def test_progress_through_the_front_door_on_both_backends():
    for backend in BACKENDS:
        calls = []
        sol = solve(logged_ball(), _batch(3), (0.0, 1.0), backend=backend, progress=calls.append)
        assert sum(calls) == 3 and sol.ok
        _assert_same(sol, solve(logged_ball(), _batch(3), (0.0, 1.0), backend=backend))
    calls = []
    solve(bouncing_ball(), _batch(2), (0.0, 0.5), backend="scipy", progress=calls.append)
    assert calls == [1, 1]  # the reference reports each run as it ends


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_progress_that_is_not_callable_is_refused(backend):
    with pytest.raises(
        InputTypeError, match=r"`progress` must be a callable progress\(n_runs_finished\).*got int"
    ):
        solve(bouncing_ball(), [1.0, 0.0], (0.0, 1.0), backend=backend, progress=3)
