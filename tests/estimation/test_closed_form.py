import numpy as np
import pytest

from etobs import PeriodicRule, SaveAt, SolverOptions, StaticRule, simulate
from etobs.estimation import transmission_counts

from . import scalar


@pytest.mark.parametrize("backend", ["engine", "scipy"])
def test_dynamic_rule_event_times_match_closed_form(backend):
    expected = scalar.event_times(6)
    res = simulate(scalar.problem(), [0.0], expected[-1] + 0.01, backend=backend)
    assert res.backend == backend
    np.testing.assert_allclose(res.transmission_times(0, 0), expected, rtol=0, atol=1e-9)


@pytest.mark.parametrize("backend", ["engine", "scipy"])
def test_eta_follows_its_closed_form_between_events(backend):
    times = scalar.event_times(2)
    grid = np.linspace(0.0, times[0], 7)[1:-1]
    res = simulate(scalar.problem(), [0.0], times[0] - 1e-6, save=SaveAt(grid=grid), backend=backend)
    np.testing.assert_allclose(res.on_grid().eta[0, :, 0], scalar.eta(grid, scalar.ETA0), rtol=1e-9)


def test_static_rule_fires_every_sqrt_eps_over_ell_over_k():
    # Static rule: transmit when ell (k tau)^2 = eps, i.e. every tau = sqrt(eps/ell)/k.
    pb = scalar.problem()
    rule = StaticRule(gamma=pb.nodes[0].rule.gamma, eps=scalar.EPS)
    pb = type(pb)(plant=pb.plant, observer=pb.observer, nodes=[type(pb.nodes[0])((0,), rule)])
    tau = np.sqrt(scalar.EPS / scalar.ELL) / scalar.K
    res = simulate(pb, [0.0], 10 * tau + tau / 2)
    np.testing.assert_allclose(res.transmission_times(0, 0), tau * np.arange(1, 11), atol=1e-10)


def test_dynamic_rule_with_sigma_zero_transmits_like_the_static_rule():
    pb_dyn = scalar.problem(sigma=0.0)
    node = pb_dyn.nodes[0]
    pb_sta = type(pb_dyn)(
        plant=pb_dyn.plant,
        observer=pb_dyn.observer,
        nodes=[type(node)((0,), StaticRule(gamma=node.rule.gamma, eps=scalar.EPS))],
    )
    a = simulate(pb_dyn, [0.0], 3.0).transmission_times(0, 0)
    b = simulate(pb_sta, [0.0], 3.0).transmission_times(0, 0)
    assert a.size == b.size > 5
    np.testing.assert_allclose(a, b, atol=1e-10)


def test_periodic_rule_transmits_on_its_clock():
    pb = scalar.problem()
    pb = type(pb)(
        plant=pb.plant, observer=pb.observer, nodes=[type(pb.nodes[0])((0,), PeriodicRule(period=0.1))]
    )
    res = simulate(pb, [0.0], 1.05, options=SolverOptions())
    np.testing.assert_allclose(res.transmission_times(0, 0), 0.1 * np.arange(1, 11), atol=1e-12)
    assert transmission_counts(res, window=(0.0, 0.55)).tolist() == [[5]]
