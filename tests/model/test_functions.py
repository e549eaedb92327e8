import math

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


def test_custom_is_written_for_one_float_and_evaluated_elementwise():
    f = Custom(lambda s: s * math.sqrt(s))  # fn maps a float to a float
    s = np.array([[0.0, 1.0], [4.0, 9.0]])
    out = f(s)
    assert out.shape == (2, 2)
    np.testing.assert_allclose(out, [[0.0, 1.0], [8.0, 27.0]])
    assert as_kfunction("gamma", lambda s: 2.0 * s)(np.array([3.0])).tolist() == [6.0]


def test_custom_written_for_arrays_gets_the_one_value_message():
    with pytest.raises(
        InputError, match=r"`fn` must map a float s >= 0 to a float \(written for one value.*TypeError"
    ):
        Custom(lambda s: s[:2])


def test_custom_that_raises_on_the_probe_names_the_error():
    with pytest.raises(InputError, match=r"raised ZeroDivisionError"):
        Custom(lambda s: 1 / s)


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
