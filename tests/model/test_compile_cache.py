"""The compiled-code cache: a damaged entry is discarded once, code it cannot cache is named (issue 23).

Each test has its own ``ETOBS_CACHE_DIR`` under ``tmp_path``, never the shared cache.
"""

import numpy as np
import pytest

from etobs import luenberger
from etobs.compile import FunctionSpec, compile_function
from etobs.compile import functions as fns

SPEC = FunctionSpec("A0", (2,), 2)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("ETOBS_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(fns, "_MEMO", {})  # each compile below goes to the disk cache
    return tmp_path / "cache" / "functions"


def _fresh(memo):
    memo.clear()


def test_a_damaged_cache_entry_is_discarded_and_compiled_again_with_one_warning(cache):
    scale = 2.0009871  # a constant of this test only: a key no other test has

    def h(x):
        return np.sin(x) * scale

    compile_function(h, SPEC, "h")
    (data,) = cache.glob("*.nbc")
    raw = bytearray(data.read_bytes())
    raw[len(raw) // 3 : len(raw) // 3 + 400] = b"A" * 400  # what a torn write or a bad disk leaves
    data.write_bytes(bytes(raw))
    _fresh(fns._MEMO)
    # before: "LLVM bitcode parsing error" on every run until the user deleted the cache
    with pytest.warns(
        RuntimeWarning, match=r"cache file etobs wrapper.* does not match its SHA-256: damaged; discarded it"
    ):
        cf = compile_function(h, SPEC, "h")
    assert cf.address
    _fresh(fns._MEMO)
    compile_function(h, SPEC, "h")  # the new entry loads: no warning (warnings are errors here)
    assert len(list(cache.glob("*.nbc"))) == 1


def test_code_that_cannot_be_cached_says_so_naming_the_function(cache):
    big = np.full(200_000, 0.5)  # 1.6 MB read as a constant: numba cannot cache the code

    def h(x):
        return x * big[0]

    # before: AttributeError "'ContentLocator' object has no attribute '_py_file'" on every run
    with pytest.warns(RuntimeWarning, match=r"machine code of `h` cannot be cached .*pass it in `params`"):
        compile_function(h, SPEC, "h")


def test_luenberger_keeps_its_gain_in_params_not_in_the_compiled_code():
    # a 1000 x 1000 gain in the closure made the 1000-node model uncacheable (see above)
    L = np.arange(6.0).reshape(3, 2)
    obs = luenberger(lambda t, x, u: -x, L=L)
    np.testing.assert_array_equal(obs.params, L.ravel())
    assert not any(isinstance(c.cell_contents, np.ndarray) for c in obs.f_o.__closure__)
    out = obs.call_f_o(0.0, np.ones(3), np.zeros(0), np.array([1.0, 2.0]), np.zeros(2))
    np.testing.assert_array_equal(out, -np.ones(3) + L @ [1.0, 2.0])
