"""The lane engine's sin and cos (etobs.compile.vecmath): accuracy against libm, limits, vectorization."""

import math
import re

import numba
import numpy as np
import pytest

from etobs.compile import vecmath as vm

JITTED = vm.jitted()
SIN, COS = JITTED["sin"], JITTED["cos"]  # numba needs the dispatchers as globals


def _many(fn):
    """``fn`` of every entry of an array, in a compiled loop."""

    @numba.njit
    def many(x):
        out = np.empty_like(x)
        for i in range(x.size):
            out[i] = fn(x[i])
        return out

    return many


many_sin, many_cos = _many(SIN), _many(COS)


@numba.njit
def sixteen_lanes(x, out):
    for i in range(16):
        out[i] = SIN(x[i])


def ulps(got, want):
    """``|got - want|`` in units of the last place of ``want`` (of the smallest normal at 0)."""
    return np.abs(got - want) / np.spacing(np.maximum(np.abs(want), np.finfo(float).tiny))


@pytest.mark.parametrize("limit", [math.pi / 4, math.pi, 100.0, 1e4, vm.EXACT_UP_TO])
def test_within_two_ulp_of_libm_up_to_the_exact_reduction_limit(limit):
    x = np.random.default_rng(int(limit)).uniform(-limit, limit, 200_000)
    assert ulps(many_sin(x), np.sin(x)).max() <= 2.0
    assert ulps(many_cos(x), np.cos(x)).max() <= 2.0


@pytest.mark.parametrize("limit", [1e9, 1e12, vm.HUGE])
def test_beyond_it_the_error_is_below_half_an_ulp_of_the_argument(limit):
    # the reduction loses bits: the result is that of an argument within its own rounding
    x = np.random.default_rng(7).uniform(limit / 2, limit, 50_000) * np.sign(np.arange(50_000) % 2 - 0.5)
    x = x[np.abs(x) < vm.HUGE]
    for ours, libm in ((many_sin, np.sin), (many_cos, np.cos)):
        want = libm(x)
        assert np.all(np.abs(ours(x) - want) <= 0.5 * np.spacing(np.abs(x)) + 2 * np.spacing(np.abs(want)))


def test_the_limits_on_both_sides():
    below, above = np.nextafter(vm.EXACT_UP_TO, 0.0), np.nextafter(vm.EXACT_UP_TO, np.inf)
    assert ulps(many_sin(np.array([below])), np.sin([below]))[0] <= 2.0
    assert ulps(many_cos(np.array([below, -below])), np.cos([below, -below])).max() <= 2.0
    assert abs(vm.sin(above) - math.sin(above)) <= 0.5 * math.ulp(above)
    assert abs(vm.cos(above) - math.cos(above)) <= 0.5 * math.ulp(above)
    last = np.nextafter(vm.HUGE, 0.0)
    assert math.isfinite(vm.sin(last)) and math.isfinite(vm.cos(-last))
    assert math.isnan(vm.sin(vm.HUGE)) and math.isnan(vm.cos(-vm.HUGE))


def test_special_values_are_libms():
    assert math.copysign(1.0, vm.sin(-0.0)) == -1.0 and vm.sin(0.0) == 0.0 and vm.cos(0.0) == 1.0
    for v in (math.nan, math.inf, -math.inf):
        assert math.isnan(vm.sin(v)) and math.isnan(vm.cos(v))


@pytest.mark.parametrize("k", range(-8, 9))
def test_every_quadrant_and_its_edges(k):
    # at and around k pi/2 (where the reduction picks the neighbouring k) and at (2k+1) pi/4
    base = k * math.pi / 2
    x = np.array([base, np.nextafter(base, -np.inf), np.nextafter(base, np.inf), base + math.pi / 4])
    x = np.concatenate([x, x + 1e-9, x - 1e-9])
    assert np.all(np.abs(many_sin(x) - np.sin(x)) <= 2 * np.spacing(1.0))
    assert np.all(np.abs(many_cos(x) - np.cos(x)) <= 2 * np.spacing(1.0))


def test_compiled_and_python_give_the_same_bits():
    x = np.random.default_rng(3).uniform(-1e3, 1e3, 2_000)
    assert many_sin(x).tolist() == [vm.sin(float(v)) for v in x]
    assert many_cos(x).tolist() == [vm.cos(float(v)) for v in x]


def test_a_loop_over_sixteen_lanes_is_vector_code_without_a_call_to_libm():
    x, out = np.linspace(-3.0, 3.0, 16), np.empty(16)
    sixteen_lanes(x, out)
    np.testing.assert_array_equal(out, [vm.sin(float(v)) for v in x])
    ir = "\n".join(sixteen_lanes.inspect_llvm().values())
    assert re.search(r"<\d+ x double>", ir), "the lane loop was not vectorized"
    assert not re.search(r"call [^\n]*@(llvm\.)?sin", ir)


def test_the_constants_are_pi_and_the_factorials():
    # pi by Machin's formula in 80 digits: pi/2 = PIO2_1 + PIO2_2 + PIO2_3 to 1e-36, the first
    # two with 33 significant bits (k * PIO2_i exact for |k| < 2^20), and 2/pi rounded
    from decimal import Decimal, getcontext

    getcontext().prec = 80

    def atan_inv(n):
        x, total, k = Decimal(1) / n, Decimal(0), 0
        term = x
        while abs(term) > Decimal(10) ** -79:
            total += term / (2 * k + 1)
            term *= -x * x
            k += 1
        return total

    pi = 16 * atan_inv(5) - 4 * atan_inv(239)
    assert abs(pi / 2 - Decimal(vm.PIO2_1) - Decimal(vm.PIO2_2) - Decimal(vm.PIO2_3)) < Decimal(10) ** -36
    for part in (vm.PIO2_1, vm.PIO2_2):
        mantissa = int(math.frexp(part)[0] * 2**53)
        assert mantissa % 2**20 == 0  # at most 33 significant bits
    assert vm.ONE_OVER_PI == float(1 / pi)
    assert (vm.PI_1, vm.PI_2, vm.PI_3) == (2 * vm.PIO2_1, 2 * vm.PIO2_2, 2 * vm.PIO2_3)
    assert [vm.S1, vm.S2, vm.S10] == [-1 / 6, 1 / 120, 1 / math.factorial(21)]
