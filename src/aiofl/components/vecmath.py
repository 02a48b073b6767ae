r"""Branch-free exp, log, sin and cos that LLVM can put in SIMD lanes.

The engine's lane kernel (:mod:`aiofl.engine.lanes`) advances eight members at once, one
per lane of an AVX-512 register, and relies on LLVM's loop vectorizer.  A call to libm's
``exp`` or ``sin`` cannot be vectorized (numba's LLVM has no vector math library: Intel's
SVML needs an SVML-patched llvmlite, which PyPI's is not), so the vectorizer would split
every such call into eight scalar calls.  These functions are written in plain arithmetic,
integer/float bit casts and selects, with no branch and no call, so a loop over lanes that
calls them compiles to vector code.

Accuracy (checked in ``tests/test_lanes.py`` against numpy/libm):

* :func:`vexp`: Cody–Waite reduction :math:`x = k\ln 2 + r`, :math:`|r| \le \ln 2/2`, a
  degree-13 Taylor polynomial (:math:`1 + r + r^2 q(r)`, q by Estrin's scheme: a short
  dependency chain, for a lone member's latency), scaling by :math:`2^k` split in two
  factors (correct into the subnormal range); within 1 ulp of libm; ``exp(x > 709.78) = inf``,
  ``exp(x < -745.2) = 0``, NaN propagates.
* :func:`vlog`: fdlibm's ``__ieee754_log`` (reduction to :math:`[\sqrt2/2, \sqrt2)`,
  :math:`\log(1+f) = f - f^2/2 + s(f^2/2 + R(s^2))`, Sun Microsystems 1993), subnormal
  inputs rescaled first; within 1 ulp; ``log 0 = -inf``, ``log(x < 0) = NaN``,
  ``log inf = inf``.
* :func:`vsin`, :func:`vcos`: reduction by :math:`\pi/2` in three Cody–Waite parts
  (fdlibm's ``__ieee754_rem_pio2`` medium case, exact for :math:`|x| < 2^{20}\pi/2
  \approx 1.6\cdot10^6`), fdlibm's ``__kernel_sin``/``__kernel_cos`` polynomials and the
  quadrant by select; within 2 ulp there.  Beyond that range the reduction loses
  :math:`\approx |x|\,2^{-53}` absolutely (libm does a full Payne–Hanek reduction), and
  :math:`|x| > 2^{31}\pi/2 \approx 3.4\cdot10^9`, inf and NaN give NaN (an angle that
  large has diverged).

They are compiled strictly (no fast-math flag: the reductions' cancellations must not be
re-associated away, and vector and scalar code must round alike) and inline into their
callers.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

__all__ = ["VECMATH_OPTIONS", "fma", "vcos", "vexp", "vlog", "vsin"]

VECMATH_OPTIONS = {
    "fastmath": False,
    "error_model": "numpy",
    "inline": "always",
    "cache": True,
}
"""numba options of these functions: strict IEEE 754 arithmetic, inlined."""


@intrinsic
def _as_int(typingctx: Any, x: Any) -> Any:
    """The bits of a float64 as an int64 (a bit cast, no conversion)."""
    if not isinstance(x, types.Float) or x.bitwidth != 64:
        return None

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        return builder.bitcast(args[0], ir.IntType(64))

    return types.int64(types.float64), codegen


@intrinsic
def _as_float(typingctx: Any, k: Any) -> Any:
    """The float64 whose bits are the int64 ``k`` (a bit cast, no conversion)."""
    if not isinstance(k, types.Integer):
        return None

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        v = context.cast(builder, args[0], sig.args[0], types.int64)
        return builder.bitcast(v, ir.DoubleType())

    return types.float64(k), codegen


@intrinsic
def fma(typingctx: Any, a: Any, b: Any, c: Any) -> Any:
    """:math:`a b + c` rounded once (LLVM's ``llvm.fma``: one instruction on a CPU with
    FMA, scalar or vector, the same bits either way)."""
    if not all(isinstance(t, types.Float) and t.bitwidth == 64 for t in (a, b, c)):
        return None

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        return builder.fma(*args)

    return types.float64(types.float64, types.float64, types.float64), codegen


_LOG2E = 1.4426950408889634
_LN2_HI = 6.93147180369123816490e-01  # fdlibm: ln 2 split, the high part has 32 bits
_LN2_LO = 1.90821492927058770002e-10
_EXP_MAX = 709.782712893384  # exp overflows above
_EXP_MIN = -745.1332191019412  # exp underflows to 0 below


@njit(**VECMATH_OPTIONS)
def _pow2(k: float) -> float:
    """:math:`2^k` for an integral float k in [-1022, 1023]."""
    return _as_float((np.int64(k) + 1023) << 52)


@njit(**VECMATH_OPTIONS)
def vexp(x: float) -> float:
    """:math:`e^x`, branch-free (see the module notes for accuracy and special values)."""
    xc = -746.0 if x < -746.0 else x  # keeps k in range; NaN stays NaN
    xc = 710.0 if xc > 710.0 else xc
    k = np.rint(xc * _LOG2E)
    r = (xc - k * _LN2_HI) - k * _LN2_LO
    # e^r = 1 + r + r^2 q(r), the Taylor polynomial q to r^11 by Estrin's scheme (a short
    # dependency chain, which a lone member's step waits on; 1 + r added last, exactly)
    r2 = r * r
    r4 = r2 * r2
    r8 = r4 * r4
    a0 = fma(r, 1.0 / 6.0, 0.5)
    a1 = fma(r, 1.0 / 120.0, 1.0 / 24.0)
    a2 = fma(r, 1.0 / 5040.0, 1.0 / 720.0)
    a3 = fma(r, 1.0 / 362880.0, 1.0 / 40320.0)
    a4 = fma(r, 1.0 / 39916800.0, 1.0 / 3628800.0)
    a5 = fma(r, 1.0 / 6227020800.0, 1.0 / 479001600.0)
    q = fma(r8, fma(r2, a5, a4), fma(r4, fma(r2, a3, a2), fma(r2, a1, a0)))
    p = 1.0 + fma(r2, q, r)
    k = 0.0 if k != k else k  # NaN: any k, the NaN is carried by p
    k1 = np.floor(0.5 * k)  # 2^k = 2^k1 2^(k-k1): both factors stay normal
    y = p * _pow2(k1) * _pow2(k - k1)
    y = np.inf if x > _EXP_MAX else y
    return 0.0 if x < _EXP_MIN else y


_LG1 = 6.666666666666735130e-01  # fdlibm e_log.c
_LG2 = 3.999999999940941908e-01
_LG3 = 2.857142874366239149e-01
_LG4 = 2.222219843214978396e-01
_LG5 = 1.818357216161805012e-01
_LG6 = 1.531383769920937332e-01
_LG7 = 1.479819860511658591e-01
_TWO54 = 1.80143985094819840000e16
_MANT = (1 << 52) - 1


@njit(**VECMATH_OPTIONS)
def vlog(x: float) -> float:
    r""":math:`\ln x`, branch-free (fdlibm's algorithm; see the module notes)."""
    tiny = x < 2.2250738585072014e-308
    xs = x * _TWO54 if tiny else x  # subnormals: scale into the normal range
    bits = _as_int(xs)
    e = ((bits >> 52) & 0x7FF) - 1023
    m = _as_float((bits & _MANT) | 0x3FF0000000000000)  # in [1, 2)
    big = m > 1.4142135623730951
    m = 0.5 * m if big else m
    e = e + 1 if big else e
    dk = float(e) - (54.0 if tiny else 0.0)
    f = m - 1.0
    hfsq = 0.5 * f * f
    s = f / (2.0 + f)
    z = s * s
    w = z * z
    t1 = w * fma(w, fma(w, _LG6, _LG4), _LG2)
    t2 = z * fma(w, fma(w, fma(w, _LG7, _LG5), _LG3), _LG1)
    y = dk * _LN2_HI - ((hfsq - fma(s, hfsq + t1 + t2, dk * _LN2_LO)) - f)
    y = x if x == np.inf else y
    y = -np.inf if x == 0.0 else y
    return np.nan if (x < 0.0 or x != x) else y


_INVPIO2 = 6.36619772367581382433e-01  # fdlibm e_rem_pio2.c
_PIO2_1 = 1.57079632673412561417e00  # first 33 bits of pi/2
_PIO2_2 = 6.07710050630396597660e-11  # next 33 bits
_PIO2_3 = 2.02226624871116645580e-21  # next 33 bits
_S1 = -1.66666666666666324348e-01  # fdlibm k_sin.c
_S2 = 8.33333333332248946124e-03
_S3 = -1.98412698298579493134e-04
_S4 = 2.75573137070700676789e-06
_S5 = -2.50507602534068634195e-08
_S6 = 1.58969099521155010221e-10
_C1 = 4.16666666666666019037e-02  # fdlibm k_cos.c
_C2 = -1.38888888888741095749e-03
_C3 = 2.48015872894767294178e-05
_C4 = -2.75573143513906633035e-07
_C5 = 2.08757232129817482790e-09
_C6 = -1.13596475577881948265e-11


@njit(**VECMATH_OPTIONS)
def _sincos_reduced(x: float) -> tuple[float, float, int]:
    r"""(sin r, cos r, quadrant) with :math:`x = q\pi/2 + r`, :math:`|r| \le \pi/4`."""
    k = np.rint(x * _INVPIO2)
    big = not abs(k) < 2147483648.0  # |x| > 2^31 pi/2, inf or NaN: no reduction here
    k = 0.0 if big else k
    r = ((x - k * _PIO2_1) - k * _PIO2_2) - k * _PIO2_3
    z = r * r
    sp = fma(z, fma(z, fma(z, fma(z, _S6, _S5), _S4), _S3), _S2)
    sn = fma(r * z, fma(z, sp, _S1), r)
    cp = z * fma(z, fma(z, fma(z, fma(z, fma(z, _C6, _C5), _C4), _C3), _C2), _C1)
    hz = 0.5 * z
    w = 1.0 - hz
    cs = w + (((1.0 - w) - hz) + z * cp)
    sn = np.nan if big else sn
    cs = np.nan if big else cs
    return sn, cs, np.int64(k) & 3


@njit(**VECMATH_OPTIONS)
def vsin(x: float) -> float:
    r""":math:`\sin x`, branch-free (see the module notes for the accuracy range)."""
    sn, cs, q = _sincos_reduced(x)
    v = cs if (q & 1) == 1 else sn
    return -v if q >= 2 else v


@njit(**VECMATH_OPTIONS)
def vcos(x: float) -> float:
    r""":math:`\cos x`, branch-free (see the module notes for the accuracy range)."""
    sn, cs, q = _sincos_reduced(x)
    v = sn if (q & 1) == 1 else cs
    return -v if (q == 1 or q == 2) else v
