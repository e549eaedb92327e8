"""Each Runge--Kutta pair as the engine runs it: its order, its dense output, its error norm.

The engine compiles its own stages, error norm and dense output from the coefficients of
:mod:`etobs.hybrid.tableau`, so these tests run the engine (``backend="engine"``), over
exactly one step where they measure a local error, against closed-form solutions.
"""

import numpy as np
import pytest

from etobs.hybrid import HybridSystem, SaveAt, SolverOptions, solve
from etobs.hybrid.tableau import TABLEAUS

#: Order of each pair and of its dense output: Dormand & Prince (1980) with Shampine's
#: interpolant, and DOP853 (Hairer, Nørsett & Wanner 1993, II.10).
ORDERS = {"dopri5": (5, 4), "dop853": (8, 7)}
#: Step sizes of the order tests: large enough that DOP853's local error at the smaller
#: one (2e-13) stays far above rounding, small enough for the asymptotic rate (measured:
#: 6.08 and 8.89 for the local error, 5.04 and 7.98 for the dense output).
STEPS = (0.5, 0.25)
#: Start of the step; with a power-of-two ``h`` the end ``T0 + h`` is exact, so the step
#: the engine takes is ``h`` itself.
T0 = 0.25


def _rotation(t, x):
    return np.array([x[1], -x[0]])


def _no_guard(t, x):
    return np.zeros(0)


def _keep(k, t, x):
    return x


#: y' = (y_1, -y_0), no jump rule: y(t) = (sin t, cos t).
ROTATION = HybridSystem(n=2, n_rules=0, flow=_rotation, guard=_no_guard, jump=_keep)


def exact(t):
    """The rotation's solution through (sin T0, cos T0) at ``t``: shape (..., 2)."""
    t = np.asarray(t, dtype=float)
    return np.stack([np.sin(t), np.cos(t)], axis=-1)


def one_step(method, h, theta=()):
    """Solve over ``[T0, T0 + h]`` in one step of size ``h``, keeping the state at ``T0 + theta h``.

    ``rtol = atol = 1`` accepts the step whatever its error estimate; the solution says
    the run took one accepted step, none rejected, and its arc has the two step ends.
    """
    options = SolverOptions(method=method, first_step=h, max_step=h, rtol=1.0, atol=1.0)
    grid = T0 + np.asarray(theta, dtype=float) * h if len(theta) else None
    sol = solve(ROTATION, exact(T0), (T0, T0 + h), options=options, save=SaveAt(grid=grid), backend="engine")
    assert sol.ok
    assert (sol.n_steps.tolist(), sol.n_rejected.tolist()) == ([1], [0])
    np.testing.assert_array_equal(sol.arcs[0].t, [T0, T0 + h])
    return sol


@pytest.mark.parametrize("method", ORDERS)
def test_local_error_has_the_method_order(method):
    # Local error of an order-p method is O(h^(p+1)): halving h divides it by 2^(p+1).
    order, _ = ORDERS[method]
    errs = [np.abs(one_step(method, h).x_final[0] - exact(T0 + h)).max() for h in STEPS]
    rate = np.log2(errs[0] / errs[1])
    assert rate == pytest.approx(order + 1, abs=0.6)


@pytest.mark.parametrize("method", ORDERS)
def test_dense_output_has_its_order(method):
    # The dense output of order q inside the step is off by O(h^(q+1)).
    _, dense_order = ORDERS[method]
    theta = np.linspace(0.05, 0.95, 7)
    errs = []
    for h in STEPS:
        sol = one_step(method, h, theta)
        errs.append(np.abs(sol.grid.x[0] - exact(T0 + theta * h)).max())
    rate = np.log2(errs[0] / errs[1])
    assert rate >= dense_order + 1 - 0.6


@pytest.mark.parametrize("method", ORDERS)
def test_dense_output_matches_step_ends(method):
    # At theta = 1 the interpolant is the step's end; near theta = 0 it leaves the start
    # with the start's slope: y(theta) = y0 + theta h f(y0) + O(theta^2).
    h, small = 0.25, 1e-9
    sol = one_step(method, h, (small, 1.0))
    y0 = exact(T0)
    np.testing.assert_allclose(sol.grid.x[0, 0], y0 + small * h * _rotation(T0, y0), rtol=0, atol=1e-15)
    np.testing.assert_allclose(sol.grid.x[0, 1], sol.x_final[0], rtol=0, atol=1e-14)


# ---- the error norm ------------------------------------------------------------------


def _t4(t, x):
    return np.array([t**4])


def _t7(t, x):
    return np.array([t**7])


#: y' = t^d, y(0) = 0, with d = order - 1: the pair's quadrature of order p is exact, so
#: every accepted step ends on y = t^(d+1) / (d+1), while its lower-order estimate is not
#: (the error estimate is not zero). The stages do not depend on y: K_i = (c_i h)^d.
QUADRATURES = {
    "dopri5": (4, HybridSystem(n=1, n_rules=0, flow=_t4, guard=_no_guard, jump=_keep)),
    "dop853": (7, HybridSystem(n=1, n_rules=0, flow=_t7, guard=_no_guard, jump=_keep)),
}


def error_norm(method, h, atol, rtol):
    """The error norm of the first step of size ``h`` of ``y' = t^d`` from ``(0, 0)``, in closed form.

    Hairer, Nørsett & Wanner (1993), II.4 (4.11): ``err = |h sum_k e_k K_k| / sc`` with
    ``sc = atol + rtol max(|y0|, |y1|)`` (one component); DOP853 corrects its 5th-order
    estimate ``e5`` by the 3rd-order one ``e3``: ``err = |h| e5^2 / sqrt(e5^2 + 0.01 e3^2)``.
    The step is accepted where ``err <= 1``.
    """
    tab = TABLEAUS[method]
    d, _ = QUADRATURES[method]
    K = np.append(tab.c, 1.0) ** d * h**d  # the FSAL stage K_s = f(h) (node 1)
    y1 = h ** (d + 1) / (d + 1)
    sc = atol + rtol * abs(y1)
    e5 = abs(tab.e @ K) / sc
    if tab.e_low is None:
        return abs(h) * e5
    e3 = abs(tab.e_low @ K) / sc
    return abs(h) * e5**2 / np.sqrt(e5**2 + 0.01 * e3**2)


@pytest.mark.parametrize("method", ORDERS)
@pytest.mark.parametrize("margin", [1e-6, -1e-6])
def test_step_is_accepted_exactly_when_its_error_norm_is_at_most_one(method, margin):
    # The norm is inversely proportional to the scale: the atol at which it equals 1,
    # give or take a relative margin, puts the first step on either side of the limit.
    d, system = QUADRATURES[method]
    h, rtol = 0.5, 1e-14
    atol = error_norm(method, h, 1.0, 0.0) * (1.0 + margin)
    norm = error_norm(method, h, atol, rtol)
    assert (norm <= 1.0) == (margin > 0) and abs(norm - 1.0) < 2e-6
    options = SolverOptions(method=method, first_step=h, max_step=h, rtol=rtol, atol=atol)
    sol = solve(system, [0.0], (0.0, h), options=options, backend="engine")
    assert sol.ok
    if margin > 0:
        assert (sol.n_steps.tolist(), sol.n_rejected.tolist()) == ([1], [0])
    else:  # rejected, then accepted in smaller steps
        assert sol.n_rejected[0] >= 1 and sol.n_steps[0] >= 2
    np.testing.assert_allclose(sol.x_final[0], [h ** (d + 1) / (d + 1)], rtol=1e-13)
