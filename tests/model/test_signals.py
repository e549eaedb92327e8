import numpy as np
import pytest

from etobs.errors import InputError, ModelError
from etobs.model import Constant, FunctionSignal, Sinusoid, Zero
from etobs.model.signals import as_signal


def test_sinusoid_values_and_bound():
    s = Sinusoid(amplitude=[0.0, 0.01], omega=0.3)
    t = np.array([0.0, np.pi / 0.6])
    np.testing.assert_allclose(s(t), [[0, 0], [0, 0.01]], atol=1e-15)
    assert s.bound == pytest.approx(0.01)


def test_as_signal():
    assert isinstance(as_signal("u", None, 2), Zero)
    c = as_signal("u", [1.0, 2.0], 2)
    assert isinstance(c, Constant)
    np.testing.assert_allclose(c(np.zeros(3)), [[1, 2]] * 3)
    f = as_signal("u", lambda t: np.array([t, 2.0 * t]), 2)  # one time t (a float) -> (dim,)
    assert isinstance(f, FunctionSignal)
    np.testing.assert_allclose(f(np.array([1.0, 3.0])), [[1, 2], [3, 6]])  # a time vector -> (B, dim)


def test_bad_signals():
    with pytest.raises(InputError, match=r"`m` has dimension 3; expected 2"):
        as_signal("m", [1.0, 2.0, 3.0], 2)
    with pytest.raises(
        ModelError,
        match=r"signal function `fn` returned shape \(\) for t = 0.0; expected \(1,\): write it for one time t",
    ):
        FunctionSignal(lambda t: t, 1)
    with pytest.raises(ModelError, match=r"returned shape \(3,\) for t = 0.0; expected \(2,\)"):
        as_signal("u", lambda t: np.array([t, t, t]), 2)
