"""Window boundaries of the metrics: a window ``(t_start, t_stop)`` is closed at both ends.

``transmission_counts`` counts the transmissions at times ``t_start <= t <= t_stop``
and ``max_estimation_error`` takes the save-grid points in the same closed window (their
docstrings). Each test puts a transmission or a grid point exactly on an end (the times
are taken from the run's own log, or are grid points that are integers), and one ulp
inside or outside it, on both solvers.
"""

import math

import numpy as np
import pytest

from etobs import EstimationProblem, Node, Observer, Plant, simulate
from etobs.errors import InputError
from etobs.estimation import input_transmission_counts, max_estimation_error, transmission_counts
from etobs.hybrid import SaveAt, SolverOptions
from etobs.model import Constant, InputNode, PeriodicRule

BACKENDS = ("engine", "scipy")
#: These runs take fewer than 200 steps; the bound ends a solver that stalls on the
#: transmission at t0 (its trigger function is exactly 0 there) with max_steps.
BOUNDED = SolverOptions(max_steps=5000)


@pytest.fixture(params=BACKENDS)
def backend(request):
    return request.param


def _clock_problem(slope=0.0, input_rule=None):
    """``x' = slope``, ``y = x``; observer ``z' = 0``; one node sending every 1 s from t = 0."""
    k = float(slope)
    plant = Plant(f_p=lambda t, x, u, v: np.full(1, k), h=lambda x: x.copy(), n_x=1, n_y=1, n_u=1)
    observer = Observer(f_o=lambda t, z, u, ybar, yhat: np.zeros(1), n_z=1)
    inputs = [InputNode((0,), input_rule, name="u")] if input_rule is not None else []
    return EstimationProblem(
        plant=plant,
        observer=observer,
        nodes=[Node((0,), PeriodicRule(period=1.0, first=0.0))],
        input_nodes=inputs,
        u=Constant([0.0]),
    )


def test_a_transmission_at_the_window_start_is_counted(backend):
    # guards against: transmission_counts' lower bound `t >= t_start` made `t > t_start`
    res = simulate(_clock_problem(), [0.0], 10.5, backend=backend, options=BOUNDED)
    t = res.transmissions.t
    assert t[0] == 0.0 and len(t) == 11  # the case: sends at 0, ~1, ..., ~10
    assert transmission_counts(res, (0.0, 10.5)).tolist() == [[11]]
    assert transmission_counts(res).tolist() == [[11]]  # the whole horizon [0, 10.5]
    # one ulp after the start leaves out the transmission at t = 0
    assert transmission_counts(res, (math.nextafter(0.0, 1.0), 10.5)).tolist() == [[10]]
    assert transmission_counts(res, (t[3], 10.5)).tolist() == [[8]]
    assert transmission_counts(res, (math.nextafter(t[3], np.inf), 10.5)).tolist() == [[7]]


def test_a_transmission_at_the_window_end_is_counted(backend):
    # guards against: transmission_counts' upper bound `t <= t_stop` made `t < t_stop`
    res = simulate(_clock_problem(), [0.0], 10.5, backend=backend, options=BOUNDED)
    t = res.transmissions.t
    assert len(t) == 11
    assert transmission_counts(res, (0.5, t[10])).tolist() == [[10]]
    assert transmission_counts(res, (0.5, math.nextafter(t[10], 0.0))).tolist() == [[9]]
    # a window of one instant holds the transmission at that instant
    assert transmission_counts(res, (t[4], t[4])).tolist() == [[1]]
    assert transmission_counts(res, (0.0, 0.0)).tolist() == [[1]]


def test_input_nodes_are_counted_in_the_same_closed_window(backend):
    # guards against: the input nodes' count taking another window than the outputs'
    res = simulate(
        _clock_problem(input_rule=PeriodicRule(period=1.0, first=0.0)),
        [0.0],
        3.5,
        backend=backend,
        options=BOUNDED,
    )
    t_in = res.transmissions.select(rule=1).t
    assert t_in[0] == 0.0 and len(t_in) == 4
    assert input_transmission_counts(res, (0.0, t_in[2])).tolist() == [[3]]
    assert input_transmission_counts(res, (math.nextafter(0.0, 1.0), t_in[2])).tolist() == [[2]]
    assert transmission_counts(res, (0.0, 3.5), nodes="all").tolist() == [[4, 4]]


GRID = np.linspace(0.0, 10.0, 11)  # integers: exact


@pytest.mark.parametrize(("slope", "x0", "expected"), [(-1.0, 10.0, 8.0), (1.0, 0.0, 5.0)])
def test_the_error_window_takes_the_grid_points_on_both_ends(backend, slope, x0, expected):
    # guards against: max_estimation_error's `t >= t_start` / `t <= t_stop` made strict
    # |x - xhat| = |x0 + slope t| (xhat = 0): largest at the window's start when falling
    # (10 - 2 = 8), at its end when rising (5)
    res = simulate(
        _clock_problem(slope),
        [x0],
        10.0,
        backend=backend,
        options=BOUNDED,
        save=SaveAt(steps=False, grid=GRID),
    )
    assert max_estimation_error(res, (2.0, 5.0))[0] == pytest.approx(expected, abs=1e-9)
    inner = (math.nextafter(2.0, np.inf), math.nextafter(5.0, 0.0))  # points 3 and 4 only
    assert max_estimation_error(res, inner)[0] == pytest.approx(expected - 1.0, abs=1e-9)
    assert max_estimation_error(res, (5.0, 5.0))[0] == pytest.approx(abs(x0 + 5.0 * slope), abs=1e-9)


def test_a_kept_maximum_is_read_on_a_window_that_ends_on_its_first_and_last_grid_points(backend):
    # guards against: the kept-maximum check `t_start <= grid <= t_stop` made strict
    save = SaveAt(steps=False, grid=GRID[2:6], max_distance="estimation_error")
    res = simulate(_clock_problem(-1.0), [10.0], 10.0, backend=backend, options=BOUNDED, save=save)
    assert max_estimation_error(res, (2.0, 5.0))[0] == pytest.approx(8.0, abs=1e-9)
    with pytest.raises(InputError, match=r"does not cover whole"):
        max_estimation_error(res, (math.nextafter(2.0, np.inf), 5.0))
