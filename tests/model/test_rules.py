import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from etobs.errors import InputError, InputTypeError
from etobs.model import DynamicRule, Linear, Node, PeriodicRule, Quadratic, StaticRule

reals = st.floats(-100, 100)


def paper_rule(**kw):
    base = dict(gamma=Quadratic(5), alpha=Linear(2), sigma=600, c=0.001, b=1, eps=10, eta0=10)
    return DynamicRule(**(base | kw))


def test_dynamic_rule_matches_eq_14_and_15():
    r = paper_rule()
    t = np.zeros(2)
    e = np.array([[3.0], [-1.0]])
    s = np.array([[10.0], [0.5]])
    # eq. (14): eta' = -a*eta + c*ell*e^2
    np.testing.assert_allclose(r.derivative(t, e, s)[:, 0], [-20 + 0.001 * 45, -1 + 0.001 * 5])
    # eq. (15): g = ell*e^2 - sigma*a*eta - eps
    np.testing.assert_allclose(r.trigger(t, e, s), [45 - 12000 - 10, 5 - 600 - 10])
    np.testing.assert_allclose(paper_rule(b=0.25).reset(t, s), 0.25 * s)


def test_norm_of_a_multi_output_node():
    r = StaticRule(gamma=Linear(1.0), eps=1.0)
    g = r.trigger(np.zeros(1), np.array([[3.0, 4.0]]), np.empty((1, 0)))
    assert g.tolist() == [4.0]


@given(e=st.lists(reals, min_size=1, max_size=3), eps=st.floats(1e-3, 100), ell=st.floats(1e-3, 100))
def test_static_rule_is_the_dynamic_rule_with_sigma_zero(e, eps, ell):
    e_arr = np.array([e])
    t = np.zeros(1)
    dyn = DynamicRule(gamma=Quadratic(ell), sigma=0.0, eps=eps, eta0=3.0)
    sta = StaticRule(gamma=Quadratic(ell), eps=eps)
    assert dyn.trigger(t, e_arr, np.array([[3.0]])) == pytest.approx(sta.trigger(t, e_arr, np.empty((1, 0))))


@given(eta=st.floats(0, 1e3), e=reals, b=st.floats(0, 1))
def test_trigger_is_negative_right_after_a_transmission(eta, e, b):
    # After a jump e = 0, so g = -sigma*alpha(b*eta) - eps < 0 (eps > 0).
    r = paper_rule(b=b)
    s = r.reset(np.zeros(1), np.array([[eta]]))
    assert r.trigger(np.zeros(1), np.zeros((1, 1)), s)[0] < 0


def test_periodic_rule_clock():
    r = PeriodicRule(period=0.1)
    s0 = r.initial_state()
    assert r.trigger(np.zeros(1), np.zeros((1, 1)), s0[None])[0] == pytest.approx(-0.1)
    assert PeriodicRule(period=0.1, first=0.0).trigger(np.zeros(1), np.zeros((1, 1)), np.zeros((1, 1)))[0] < 0
    assert PeriodicRule(period=0.1, first=0.0).initial_state().tolist() == [0.1]


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"eps": 0.0}, r"`eps` must be > 0; got 0"),
        ({"eps": -1.0}, r"`eps` must be > 0; got -1"),
        ({"b": 1.5}, r"`b` must be <= 1; got 1.5"),
        ({"b": -0.1}, r"`b` must be >= 0; got -0.1"),
        ({"sigma": -1}, r"`sigma` must be >= 0; got -1"),
        ({"c": -1}, r"`c` must be >= 0; got -1"),
        ({"eta0": -1}, r"`eta0` must be >= 0; got -1"),
        ({"eps": float("nan")}, r"`eps` must be a finite real number; got nan"),
    ],
)
def test_bad_dynamic_rule(kw, match):
    with pytest.raises(InputError, match=match):
        paper_rule(**kw)


def test_bad_periodic_and_static_rules():
    with pytest.raises(InputError, match=r"`period` must be > 0; got 0"):
        PeriodicRule(period=0.0)
    with pytest.raises(InputError, match=r"`first` must be >= 0; got -1"):
        PeriodicRule(period=1.0, first=-1.0)
    with pytest.raises(InputError, match=r"`eps` must be > 0; got 0"):
        StaticRule(gamma=Linear(1), eps=0)


def test_bad_nodes():
    with pytest.raises(InputTypeError, match=r"`rule` must be a TriggerRule .*; got str"):
        Node(outputs=(0,), rule="dynamic")  # type: ignore[arg-type]
    with pytest.raises(InputError, match=r"`outputs` must not repeat an index; got \[0, 0\]"):
        Node(outputs=(0, 0), rule=StaticRule(gamma=Linear(1), eps=1))
    with pytest.raises(InputError, match=r"`outputs` must name at least one output index"):
        Node(outputs=(), rule=StaticRule(gamma=Linear(1), eps=1))
    with pytest.raises(InputError, match=r"`outputs\[0\]` must be an integer >= 0; got -1"):
        Node(outputs=(-1,), rule=StaticRule(gamma=Linear(1), eps=1))


def test_rules_are_frozen():
    r = paper_rule()
    with pytest.raises(AttributeError):
        r.sigma = 1.0  # type: ignore[misc]
