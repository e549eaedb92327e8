"""Order of each Runge--Kutta pair and of its dense output, against closed forms."""

import numpy as np
import pytest

from etobs.hybrid.tableau import TABLEAUS


def rotation(t, y):
    return np.stack([y[:, 1], -y[:, 0]], axis=1)


def exact(t):
    return np.stack([np.sin(t), np.cos(t)], axis=1)


def one_step(tab, h):
    t0 = np.array([0.3])
    y0 = exact(t0)
    K, y1 = tab.step(rotation, t0, y0, rotation(t0, y0), np.array([h]))
    return t0, y0, K, y1


@pytest.mark.parametrize(("name", "order"), [("dopri5", 5), ("dop853", 8)])
def test_local_error_has_the_method_order(name, order):
    # Local error of an order-p method is O(h^(p+1)): halving h divides it by 2^(p+1).
    tab = TABLEAUS[name]
    errs = []
    for h in (0.4, 0.2):
        t0, _, _, y1 = one_step(tab, h)
        errs.append(np.abs(y1 - exact(t0 + h)).max())
    rate = np.log2(errs[0] / errs[1])
    assert rate == pytest.approx(order + 1, abs=0.6)


@pytest.mark.parametrize(("name", "dense_order"), [("dopri5", 4), ("dop853", 7)])
def test_dense_output_has_its_order(name, dense_order):
    tab = TABLEAUS[name]
    errs = []
    for h in (0.4, 0.2):
        t0, y0, K, y1 = one_step(tab, h)
        Q = tab.dense(rotation, t0, y0, y1, K, np.array([h]))
        worst = 0.0
        for th in np.linspace(0.05, 0.95, 7):
            y = tab.evaluate(Q, y0, np.array([th]))
            worst = max(worst, np.abs(y - exact(t0 + th * h)).max())
        errs.append(worst)
    rate = np.log2(errs[0] / errs[1])
    assert rate >= dense_order + 1 - 0.6


@pytest.mark.parametrize("name", ["dopri5", "dop853"])
def test_dense_output_matches_step_ends(name):
    tab = TABLEAUS[name]
    t0, y0, K, y1 = one_step(tab, 0.3)
    Q = tab.dense(rotation, t0, y0, y1, K, np.array([0.3]))
    np.testing.assert_allclose(tab.evaluate(Q, y0, np.array([0.0])), y0, atol=1e-15)
    np.testing.assert_allclose(tab.evaluate(Q, y0, np.array([1.0])), y1, atol=1e-14)
