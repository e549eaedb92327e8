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
    f = as_signal("u", lambda t: np.stack([t, t], 1), 2)
    np.testing.assert_allclose(f(np.array([1.0])), [[1, 1]])


def test_bad_signals():
    with pytest.raises(InputError, match=r"`m` has dimension 3; expected 2"):
        as_signal("m", [1.0, 2.0, 3.0], 2)
    with pytest.raises(
        ModelError, match=r"signal function returned shape \(2,\) for t of shape \(2,\); expected \(2, 1\)"
    ):
        FunctionSignal(lambda t: t, 1)
