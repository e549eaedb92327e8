"""The compiled (numba) backend against the numpy solver on the same hybrid systems."""

import numpy as np
import pytest

numba = pytest.importorskip("numba")

from etobs.errors import InputError, InputTypeError  # noqa: E402
from etobs.hybrid import (  # noqa: E402
    HybridSystem,
    SaveAt,
    SolverOptions,
    Status,
    _kernel,
    solve,
)
from etobs.hybrid import compiled as comp  # noqa: E402
from etobs.hybrid.compiled import CompiledSystem, solve_compiled  # noqa: E402

G = 9.81


@numba.njit
def ball_flow(t, x, p, args, work, dx):
    dx[0] = x[1]
    dx[1] = -G


@numba.njit
def ball_guard(t, x, p, args, work, g):
    g[0] = -x[0] if x[1] < 0 else -1.0


@numba.njit
def ball_jump(k, t, x, p, args, work):
    x[0] = 0.0
    x[1] = -p[0] * x[1]


BALL = CompiledSystem(n=2, n_rules=1, flow=ball_flow, guard=ball_guard, jump=ball_jump, n_params=1)
X0 = np.array([[1.0, 0.0], [2.0, 1.0], [0.5, -1.0]])


def numpy_ball(r):
    return HybridSystem(
        n=2,
        n_rules=1,
        flow=lambda t, x: np.stack([x[:, 1], -G + 0 * x[:, 0]], axis=1),
        guard=lambda t, x: np.where(x[:, 1] < 0, -x[:, 0], -1.0)[:, None],
        jump=lambda k, t, x: np.stack([0 * x[:, 0], -r * x[:, 1]], axis=1),
    )


def bounce_times(h0, v0, r, n):
    """Closed form: first impact from (h0, v0), then flights of 2 v_k / g."""
    v = np.sqrt(v0**2 + 2 * G * h0)  # impact speed
    t = (v0 + np.sqrt(v0**2 + 2 * G * h0)) / G
    out = [t]
    for _ in range(n - 1):
        v *= r
        t += 2 * v / G
        out.append(t)
    return np.array(out)


def test_status_codes_match_the_enum():
    for status in Status:
        assert getattr(_kernel, status.name) == status.value


def test_ball_matches_closed_form_and_numpy_solver():
    grid = np.linspace(0.0, 1.5, 31)
    save = SaveAt(steps=True, grid=grid)
    ours = solve_compiled(BALL, X0, (0.0, 1.5), params=[0.8], save=save)
    ref = solve(numpy_ball(0.8), X0, (0.0, 1.5), save=save)
    assert ours.backend == "numba" and ours.ok
    for r, (h0, v0) in enumerate(X0):
        t = ours.jumps.times(r, 0)
        np.testing.assert_allclose(t, bounce_times(h0, v0, 0.8, t.size), rtol=0, atol=1e-9)
        np.testing.assert_allclose(t, ref.jumps.times(r, 0), rtol=0, atol=1e-11)
        assert t.size == ref.jumps.times(r, 0).size
        np.testing.assert_array_equal(ours.arcs[r].j, ref.arcs[r].j)
        np.testing.assert_allclose(ours.arcs[r].t, ref.arcs[r].t, atol=1e-11)
        np.testing.assert_allclose(ours.arcs[r].x, ref.arcs[r].x, atol=1e-9)
    np.testing.assert_array_equal(ours.grid.j, ref.grid.j)
    np.testing.assert_allclose(ours.grid.x, ref.grid.x, atol=1e-9)
    np.testing.assert_array_equal(ours.n_steps, ref.n_steps)


def test_per_run_parameters_and_thread_split_do_not_change_runs():
    P = np.array([[0.5], [0.8], [0.9]])
    many = solve_compiled(BALL, X0, (0.0, 1.0), params=P, save=SaveAt(steps=False))
    for r in range(3):
        one = solve_compiled(BALL, X0[r], (0.0, 1.0), params=P[r], save=SaveAt(steps=False), parallel=False)
        np.testing.assert_array_equal(one.jumps.t, many.jumps.select(run=r).t)
        np.testing.assert_array_equal(one.x_final[0], many.x_final[r])


def test_small_buffers_are_regrown_without_changing_results(monkeypatch):
    # A Zeno-like ball (restitution 0.9) bounces ~100 times: more than the smallest
    # first-pass buffer of 64 entries, so those runs are solved again with room.
    big = solve_compiled(BALL, X0, (0.0, 8.0), params=[0.9], save=SaveAt(steps=True))
    monkeypatch.setattr(comp, "_BUFFER_BUDGET", 1)
    small = solve_compiled(BALL, X0, (0.0, 8.0), params=[0.9], save=SaveAt(steps=True))
    assert len(small.jumps) == len(big.jumps) > 3 * 64
    np.testing.assert_array_equal(small.jumps.t, big.jumps.t)
    for a, b in zip(small.arcs, big.arcs, strict=True):
        np.testing.assert_array_equal(a.x, b.x)


def test_max_jumps_stops_a_zeno_run():
    sol = solve_compiled(BALL, [1.0, 0.0], (0.0, 3.0), params=[0.5], options=SolverOptions(max_jumps=20))
    assert sol.status[0] == Status.MAX_JUMPS
    assert len(sol.jumps) == 20


@pytest.mark.slow
def test_dopri5_matches_numpy_solver():
    opts = SolverOptions(method="dopri5", rtol=1e-9, atol=1e-9)
    ours = solve_compiled(BALL, X0, (0.0, 1.5), params=[0.8], options=opts, save=SaveAt(steps=False))
    ref = solve(numpy_ball(0.8), X0, (0.0, 1.5), options=opts, save=SaveAt(steps=False))
    np.testing.assert_allclose(ours.jumps.t, ref.jumps.t, atol=1e-11)
    np.testing.assert_array_equal(ours.n_steps, ref.n_steps)


def test_bad_inputs_are_named():
    with pytest.raises(InputTypeError, match=r"`flow` must be a numba-compiled function .*got function"):
        CompiledSystem(n=2, n_rules=1, flow=lambda *a: None, guard=ball_guard, jump=ball_jump)
    with pytest.raises(InputError, match=r"`params` must have shape \(1,\) or \(3, 1\); got \(2,\)"):
        solve_compiled(BALL, X0, (0.0, 1.0), params=[0.5, 0.5])
    with pytest.raises(InputError, match="`params` is required: the system has n_params=1"):
        solve_compiled(BALL, X0, (0.0, 1.0))
    with pytest.raises(InputError, match=r"`x0` .*"):
        solve_compiled(BALL, [1.0, 2.0, 3.0], (0.0, 1.0), params=[0.5])
    with pytest.raises(InputTypeError, match="`system` must be a CompiledSystem; got HybridSystem"):
        solve_compiled(numpy_ball(0.5), X0, (0.0, 1.0))
    with pytest.raises(InputError, match="`rule_names` has 2 names; expected n_rules=1"):
        CompiledSystem(
            n=2, n_rules=1, flow=ball_flow, guard=ball_guard, jump=ball_jump, rule_names=("a", "b")
        )


def test_missing_numba_says_how_to_install(monkeypatch):
    import builtins

    real = builtins.__import__

    def no_numba(name, *args, **kwargs):
        if name == "numba":
            raise ImportError("no numba here")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_numba)
    assert not comp.numba_available()
    with pytest.raises(
        InputError, match=r"needs the optional dependency numba.*pip install 'etobs\[numba\]'"
    ):
        comp.require_numba()
