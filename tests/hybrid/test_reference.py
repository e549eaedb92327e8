"""The reference backend evaluates the guard once per point, whatever the number of rules."""

import numpy as np
import pytest

from etobs.errors import ModelError
from etobs.hybrid import HybridSystem, reference, solve_reference

from .systems import bouncing_ball


def _with_idle_rules(system, extra):
    """``system`` plus ``extra`` rules that never fire; counts the one-run guard calls.

    ``solve_reference`` calls a HybridSystem's Python functions as they are, one row at
    a time, so every call counted here is one point of one run.
    """
    calls = [0]

    def guard(t, x, p):
        calls[0] += 1
        return np.concatenate([system.guard(t, x, p), np.full(extra, -1.0)])

    wide = HybridSystem(
        n=system.n,
        n_rules=system.n_rules + extra,
        flow=system.flow,
        guard=guard,
        jump=system.jump,
        params=system.params,
    )
    return wide, calls


def test_guard_calls_do_not_grow_with_the_number_of_rules():
    # solve_ivp calls its m event functions one by one at the same point; the
    # reference answers the m - 1 others from the one guard evaluation.
    ball = bouncing_ball()
    one, calls_one = _with_idle_rules(ball, 0)
    many, calls_many = _with_idle_rules(ball, 7)
    a = solve_reference(one, [1.0, 0.0], (0.0, 1.2))
    b = solve_reference(many, [1.0, 0.0], (0.0, 1.2))
    assert calls_one[0] > 0
    assert calls_many[0] == calls_one[0]
    np.testing.assert_array_equal(a.jumps.t, b.jumps.t)
    np.testing.assert_array_equal(a.x_final, b.x_final)
    # and the wrapped system gives the ball's own results
    np.testing.assert_array_equal(a.jumps.t, solve_reference(ball, [1.0, 0.0], (0.0, 1.2)).jumps.t)


def test_a_nan_guard_is_the_states_failure_at_an_overflowed_state_and_the_guards_at_a_finite_one():
    # the reference's rule (the engine draws the same line in _locate): before, a blow-up
    # ended model_error ("`guard` returned NaN") or nonfinite by the machine's
    # floating-point path for huge arguments
    nan = np.array([[np.nan, -1.0]])
    with pytest.raises(reference._Overflowed):
        reference._event_values(nan, np.array([[1.0, np.inf]]), 2)
    with pytest.raises(ModelError, match="`guard` returned NaN"):
        reference._event_values(nan, np.array([[1.0, 1e300]]), 2)
    # only the rows where the guard is NaN count: a finite row there is the guard's fault
    two = np.array([[np.nan, -1.0], [-1.0, -1.0]])
    with pytest.raises(ModelError, match="`guard` returned NaN"):
        reference._event_values(two, np.array([[1.0, 2.0], [np.inf, 0.0]]), 2)
    np.testing.assert_array_equal(reference._event_values(-np.ones((1, 2)), np.array([[np.inf, 0.0]]), 2), -1)


@pytest.mark.parametrize("roots", [(1.0, 1.0001), (1.0001, 1.0), (1.3, 0.7, 1.0)])
def test_a_bracket_holding_several_entries_is_located_at_the_earliest(roots):
    # guards against: the later of several roots in one bracket taken. The solver's own
    # brackets seldom hold two (its event stops at the earliest, the peak probes split
    # excursions), so a planted "take the latest" passed every run-level test; here the
    # bracket [0, 2] holds one entry per guard tau - r_k, on the dense output tau = t.
    from etobs.hybrid.options import SolverOptions

    run = object.__new__(reference._Run)  # only what locate reads
    run.opts, run.t_end, run.on_dense = SolverOptions(event_xtol=1e-12), 10.0, {}
    run.g1 = lambda t, x: x[0] - np.array(roots)
    t_in = run.locate(lambda t: np.array([t]), 0.0, 2.0)
    assert min(roots) <= t_in <= min(roots) + 1e-12  # in the jump set, within event_xtol
