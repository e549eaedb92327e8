"""The peak probe (contract point 2 of etobs.hybrid.solver) against closed-form crossing times.

An event function that rises above zero and falls back inside one step is invisible to
a sign test at the step's ends, and to the step's samples when the excursion is shorter
than the sample spacing. The solvers then fit a parabola through a negative local
maximum of the samples and probe its predicted peak. Here the event function *is* a
parabola in time, so the probe's prediction is exact and every crossing has a closed
form.

The system: ``s' = 1``, ``k' = 0`` (integrated exactly by any Runge--Kutta method, at
any tolerance), event function ``w^2 - (s - P (k + 1))^2``, positive only on the window
``(P (k + 1) - w, P (k + 1) + w)``; the jump ``k <- k + 1`` moves on to the next window.
From ``s(0) = 0`` the events are at ``t_k = P (k + 1) - w``, ``k = 0, 1, ...``. The flow
is so simple that steps grow tenfold each time (to 1 s and more), while a window lasts
``2 w = 0.02`` s: each crossing pair lies inside one step.
"""

import numpy as np
import pytest

from etobs.hybrid import HybridSystem, SolverOptions, solve

BACKENDS = ("engine", "scipy")
P, W, T_END = 1.0, 0.01, 7.5
#: The closed form: t_k = P (k + 1) - w, seven of them before T_END.
EVENTS = P * np.arange(1, 8) - W


@pytest.fixture(params=BACKENDS)
def backend(request):
    return request.param


def _unit_speed(t, x, p):
    return np.array([1.0, 0.0])


def _window(t, x, p):
    d = x[0] - p[0] * (x[1] + 1.0)
    return np.array([p[1] * p[1] - d * d])


def _next_window(k, t, x, p):
    return np.array([x[0], x[1] + 1.0])


def windows(period=P, half_width=W):
    return HybridSystem(
        n=2, n_rules=1, flow=_unit_speed, guard=_window, jump=_next_window, params=[period, half_width]
    )


@pytest.mark.parametrize("tol", [1e-10, 1e-3], ids=["tight", "loose"])
def test_every_short_excursion_inside_a_step_is_found_at_its_closed_form_time(backend, tol):
    # guards against: the peak probe disabled (engine _locate, reference scan): 0 of 7 found
    opts = SolverOptions(rtol=tol, atol=tol)
    sol = solve(windows(), [0.0, 0.0], (0.0, T_END), options=opts, backend=backend)
    found = sol.jumps.t
    assert len(found) == len(EVENTS), f"{len(found)} of {len(EVENTS)} excursions found: {found.tolist()}"
    # the flow is exact, so only the root finding's bracket (event_xtol = 1e-12) separates them
    np.testing.assert_allclose(found, EVENTS, rtol=0, atol=1e-9)
    assert sol.x_final[0, 1] == 7.0  # seven jumps, no more
    assert sol.x_final[0, 0] == pytest.approx(T_END, abs=1e-12)  # s = t (sums of step lengths)
    # the event function is zero from below at every event (contract point 3)
    g = [_window(t, x, [P, W])[0] for t, x in zip(sol.arcs[0].t, sol.arcs[0].x, strict=True)]
    at_jump = np.flatnonzero(np.diff(sol.arcs[0].j) == 1)
    assert all(0.0 <= g[i] < 1e-9 for i in at_jump)


def test_the_excursions_lie_between_step_ends(backend):
    # guards against: a case the step ends' sign test would find anyway (then the test above proves nothing)
    sign_only = solve(
        windows(), [0.0, 0.0], (0.0, T_END), options=SolverOptions(event_samples=1), backend=backend
    )
    assert len(sign_only.jumps) == 0
    steps = np.diff(sign_only.arcs[0].t)
    assert steps.max() > 10 * 2 * W  # steps much longer than a window


@pytest.mark.xfail(
    strict=True,
    reason="open (issue 14): the probe fits a parabola only at an interior maximum of the samples, "
    "so a peak in the first or last 1/(2 event_samples) of a step is missed, on both solvers",
)
def test_every_excursion_is_found_whatever_its_phase_in_the_step(backend):
    # guards against: short excursions missed near a step's ends (where no interior sample is the maximum)
    # 46 phases of the same windows, s(0) = -0.9 .. 0: before the fix 1 to 4 runs per
    # solver and tolerance lost their remaining events (a window at theta = 0.94..0.98 of
    # a step; once one is missed, k stops and so do the later ones)
    s0 = -np.linspace(0.0, 0.9, 46)
    x0 = np.stack([s0, np.zeros_like(s0)], axis=1)
    expected = [int(np.sum(P * np.arange(1, 20) - W - s < T_END)) for s in s0]
    sol = solve(windows(), x0, (0.0, T_END), backend=backend)
    missed = [b for b in range(len(s0)) if sol.j_final[b] != expected[b]]
    assert not missed, f"runs {missed} (s(0) = {s0[missed].tolist()}) lost excursions"
