"""Properties of the vectorized bracketing root finder."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from etobs.hybrid.rootfind import bracket_root


@given(
    roots=st.lists(st.floats(0.001, 0.999), min_size=1, max_size=6),
    power=st.sampled_from([1, 3, 5]),
    xtol=st.sampled_from([1e-6, 1e-10, 1e-13]),
)
def test_brackets_shrink_around_the_root(roots, power, xtol):
    r = np.array(roots)

    def fun(rows, x):
        return np.sign(x - r[rows]) * np.abs(x - r[rows]) ** power

    n = r.size
    lo, hi = np.zeros(n), np.ones(n)
    lo_f, hi_f = fun(np.arange(n), lo), fun(np.arange(n), hi)
    a, b = bracket_root(fun, lo, hi, lo_f, hi_f, np.full(n, xtol))
    assert np.all(b - a <= xtol * (1 + 1e-9))
    assert np.all(fun(np.arange(n), a) < 0)
    assert np.all(fun(np.arange(n), b) >= 0)
    assert np.all((a <= r + 1e-15) & (r <= b + 1e-15))


def test_root_at_the_right_end_closes_at_once():
    def fun(rows, x):
        return x - 1.0

    a, b = bracket_root(
        fun, np.array([0.0]), np.array([1.0]), np.array([-1.0]), np.array([0.0]), np.array([1e-12])
    )
    assert b[0] == 1.0
    assert 1.0 - a[0] <= 1e-12
