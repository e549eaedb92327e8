import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from etobs.errors import InputError, InputTypeError
from etobs.model import Custom, Linear, Power, Quadratic
from etobs.model.functions import as_kfunction

positive = st.floats(1e-3, 1e3)


@given(k=positive, s=st.floats(0.0, 1e3))
def test_inverse_undoes_each_function(k, s):
    for f in (Linear(k), Quadratic(k), Power(k, 1.5)):
        assert float(f.inverse(f(np.array(s)))) == pytest.approx(s, rel=1e-9, abs=1e-12)


@given(s=st.floats(0.0, 50.0))
def test_custom_numeric_inverse(s):
    f = Custom(lambda x: x + x**3)
    assert float(f.inverse(np.array(f(np.array(s))))) == pytest.approx(s, rel=1e-9, abs=1e-12)


def test_values():
    s = np.array([0.0, 2.0])
    np.testing.assert_allclose(Linear(2.0)(s), [0.0, 4.0])
    np.testing.assert_allclose(Quadratic(5.0)(s), [0.0, 20.0])


@pytest.mark.parametrize(
    ("make", "exc", "match"),
    [
        (lambda: Linear(0.0), InputError, r"`a` must be > 0; got 0"),
        (lambda: Quadratic(-5.0), InputError, r"`ell` must be > 0; got -5"),
        (lambda: Linear("2"), InputTypeError, r"`a` must be a real number; got '2' \(str\)"),
        (lambda: Custom(lambda s: s + 1.0), InputError, r"class-K∞ function \(zero at 0, increasing\)"),
        (lambda: Custom(lambda s: -s), InputError, r"class-K∞ function"),
        (lambda: as_kfunction("gamma", 3.0), InputError, r"`gamma` must be a KFunction"),
    ],
)
def test_bad_functions(make, exc, match):
    with pytest.raises(exc, match=match):
        make()
