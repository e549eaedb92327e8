"""``sin`` and ``cos`` as straight-line arithmetic that LLVM vectorizes: the lane engine's (issue 26).

A loop over lanes that calls libm's ``sin`` is not vectorized (numba 0.68 has no usable
SVML here), and a libm call costs 9-15 ns; these are plain arithmetic, inlined by numba,
and a loop over 16 lanes of them becomes vector instructions (``tests/compile/test_vecmath.py``
checks the LLVM IR). Written as scalar Python (standard library only), so that the same
text runs in Python, in numba and in the generated model.

**Method.** One polynomial for both (the form of SLEEF's vector ``sin``, written here from
the identities, not copied): Cody--Waite reduction ``r = x - k pi`` with ``k = round(x/pi)``
for ``sin`` (``sin x = (-1)^k sin r``), and ``r = x - q pi/2`` with the odd
``q = 2 round(x/pi - 1/2) + 1`` for ``cos`` (``cos x = (-1)^((q+1)/2) sin r``), with ``pi/2``
split in three doubles, the first two of 33 significant bits (so ``q * PIO2_1`` and
``q * PIO2_2``, and ``k`` times their doubles, are exact for ``|k|, |q| < 2^20``); then the
Taylor polynomial of ``sin`` to ``r^21`` on ``|r| <= pi/2``, whose truncation error there is
below ``2e-18`` (``(pi/2)^23 / 23!``), evaluated by Horner in ``r^2``, and the sign chosen
without a branch. One polynomial of ten terms instead of the two of ``sin`` and ``cos`` that
a reduction by ``pi/2`` needs: a third less arithmetic (1.4 against 2.1 ns a value in a
loop over 16 lanes here). The parts of ``pi/2`` were computed from ``pi`` by Machin's
formula in 80 digits (``decimal``; the test recomputes and checks them), the polynomial
coefficients are ``1/n!`` computed here; nothing is copied from a library.

**Accuracy** (tested against ``math.sin``/``math.cos`` on 2·10^5 points a range): at most
2 ulp for ``|x| <= 2^20 pi/2`` (about 1.6e6, :data:`EXACT_UP_TO`); beyond that the
reduction loses bits and the error grows with ``|x|`` (measured in the test); from
``|x| = 2^50`` (:data:`HUGE`, where an ulp of ``x`` is a quarter) the result is ``nan``, which
the engine reports as a ``nonfinite`` run rather than a silent value. ``sin(-0.0) = -0.0``;
``nan`` and ``±inf`` give ``nan`` as libm does.
"""

from __future__ import annotations

import functools
import math
from typing import Any

#: ``pi/2`` in three parts (the first two with 33 significant bits, the third the rest).
PIO2_1 = float.fromhex("0x1.921fb54400000p+0")
PIO2_2 = float.fromhex("0x1.0b4611a600000p-34")
PIO2_3 = float.fromhex("0x1.3198a2e037073p-69")
#: ``pi`` in three parts: those of ``pi/2`` doubled (exactly: the same significant bits).
PI_1, PI_2, PI_3 = 2.0 * PIO2_1, 2.0 * PIO2_2, 2.0 * PIO2_3
ONE_OVER_PI = 0.3183098861837907
#: Below this ``|x|`` the reduction is exact to the last bit (``|k| < 2^20``).
EXACT_UP_TO = 2.0**20 * PIO2_1
#: At and beyond this ``|x|`` (``2^50``, where one ulp of ``x`` is 0.25) the result is ``nan``.
HUGE = 2.0**50
#: Adding and subtracting it rounds a float below ``2^51`` to the nearest integer (ties to even).
_ROUND = 1.5 * 2.0**52

# (-1)^n / (2n+1)! rounded to double: sin r = r + r^3 (S1 + r^2 (S2 + ... + r^2 S10))
S1, S2, S3, S4, S5, S6, S7, S8, S9, S10 = ((-1) ** n / math.factorial(2 * n + 1) for n in range(1, 11))


def _round(v: float) -> float:
    """``v`` rounded to the nearest integer (``|v| < 2^51``), without a call: vectorizable."""
    return (v + _ROUND) - _ROUND


def _sin_poly(r: float) -> float:
    """``sin r`` for ``|r| <= pi/2`` (Taylor to ``r^21``, Horner in ``r^2``)."""
    z = r * r
    return r + r * z * (
        S1 + z * (S2 + z * (S3 + z * (S4 + z * (S5 + z * (S6 + z * (S7 + z * (S8 + z * (S9 + z * S10))))))))
    )


def _odd(m: float) -> float:
    """1 when the integer ``m`` (a float, ``|m| < 2^51``) is odd, else 0: without a branch."""
    return m - 2.0 * _round(m * 0.5 - 0.25)  # the rounded value is floor(m / 2)


def sin(x: float) -> float:
    """``sin x`` to 2 ulp for ``|x| <= EXACT_UP_TO`` (module docstring); vectorizable.

    Everything is computed, then the special cases are selected (no early return: a
    branch around the polynomial keeps a loop over lanes from becoming vector code).
    """
    k = _round(x * ONE_OVER_PI)
    r = ((x - k * PI_1) - k * PI_2) - k * PI_3
    v = (1.0 - 2.0 * _odd(k)) * _sin_poly(r)
    v = x if x == 0.0 else v  # keeps the sign of -0.0
    return v if abs(x) < HUGE else math.nan  # also nan and inf


def cos(x: float) -> float:
    """``cos x`` to 2 ulp for ``|x| <= EXACT_UP_TO`` (module docstring); vectorizable."""
    m = _round(x * ONE_OVER_PI - 0.5)
    q = 2.0 * m + 1.0  # cos x = cos(q pi/2 + r) = (-1)^(m+1) sin r
    r = ((x - q * PIO2_1) - q * PIO2_2) - q * PIO2_3
    v = (2.0 * _odd(m) - 1.0) * _sin_poly(r)
    return v if abs(x) < HUGE else math.nan  # also nan and inf


@functools.cache
def jitted(inline: bool = True) -> dict[str, object]:
    """``sin`` and ``cos`` compiled by numba, as numba dispatchers other numba code may call.

    With ``inline`` numba inlines them where they are called (``inline="always"``: a loop
    over lanes around them becomes vector code), else LLVM does once the code is linked (a
    faster compile, the same arithmetic). Each function of this module is compiled in a
    namespace where the helpers it calls are compiled too (inlined into it).
    """
    import types

    import numba

    namespace = dict(globals())
    for name in ("_round", "_sin_poly", "_odd", "sin", "cos"):
        fn = globals()[name]
        how: dict[str, Any] = {"inline": "always"}
        if name in ("sin", "cos") and not inline:
            how = {"forceinline": True}
        namespace[name] = numba.njit(**how)(types.FunctionType(fn.__code__, namespace, name))
    return {"sin": namespace["sin"], "cos": namespace["cos"]}


def _generic(name: str, inline: bool) -> Any:
    """A function numba compiles by the overload :func:`replacements` registers (``np.sin`` in Python)."""

    def generic(x: object) -> object:
        import numpy as np

        return getattr(np, name)(x)

    generic.__name__ = generic.__qualname__ = f"{name}_{'inline' if inline else 'call'}"
    return generic


@functools.cache
def replacements(inline: bool = True) -> dict[int, object]:
    """What the engine compiles in a user's function in place of libm's ``sin`` and ``cos``.

    By ``id`` of what a function's global names may refer to: the modules ``numpy`` and
    ``math`` become modules that forward every attribute but ``sin`` and ``cos``, and
    ``np.sin``, ``np.cos``, ``math.sin``, ``math.cos`` (imported by name) the functions of
    this module, for floats and for arrays (element by element), inlined by numba or not
    (:func:`jitted`). Anything else (complex numbers) is left to numba's ``np.sin``.
    """
    import types as pytypes

    import numpy as np
    from numba.core import types
    from numba.extending import overload

    fns = jitted(inline)

    def typer(scalar: Any, libm: Any) -> Any:
        # no annotations: numba requires the implementations' signature to be the typer's
        def typed(x):  # type: ignore[no-untyped-def]
            if isinstance(x, types.Float | types.Integer | types.Boolean):
                return lambda x: scalar(float(x))
            if isinstance(x, types.Array) and isinstance(x.dtype, types.Float | types.Integer):

                def each(x):  # type: ignore[no-untyped-def]
                    out = np.empty(x.shape)
                    for idx in np.ndindex(x.shape):
                        out[idx] = scalar(float(x[idx]))
                    return out

                return each
            return lambda x: libm(x)

        return typed

    how: dict[str, Any] = {"inline": "always"} if inline else {"jit_options": {"forceinline": True}}
    # numba compiles a call of these by their overloads; Python never calls them there
    sin_any, cos_any = _generic("sin", inline), _generic("cos", inline)
    overload(sin_any, **how)(typer(fns["sin"], np.sin))
    overload(cos_any, **how)(typer(fns["cos"], np.cos))
    out: dict[int, object] = {
        id(np.sin): sin_any,
        id(np.cos): cos_any,
        id(math.sin): sin_any,
        id(math.cos): cos_any,
    }
    for mod in (np, math):
        proxy = pytypes.ModuleType(f"etobs_vecmath_{mod.__name__}")
        proxy.__getattr__ = functools.partial(getattr, mod)  # type: ignore[method-assign]  # PEP 562
        proxy.sin = sin_any  # type: ignore[attr-defined]
        proxy.cos = cos_any  # type: ignore[attr-defined]
        out[id(mod)] = proxy
    return out
