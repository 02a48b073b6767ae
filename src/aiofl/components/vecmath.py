r"""Branch-free exp, log, sin and cos that LLVM can put in SIMD lanes.

The engine's lane kernel (:mod:`aiofl.engine.kernel.loop`) advances eight members at once, one
per lane of an AVX-512 register, and relies on LLVM's loop vectorizer.  A call to libm's
``exp`` or ``sin`` cannot be vectorized (numba's LLVM has no vector math library: Intel's
SVML needs an SVML-patched llvmlite, which PyPI's is not), so the vectorizer would split
every such call into eight scalar calls.  These functions are written in plain arithmetic,
integer/float bit casts and selects, with no branch and no call, so a loop over lanes that
calls them compiles to vector code.

Accuracy (checked in ``tests/test_lanes.py`` against numpy/libm):

* :func:`vexp`: :math:`x = k\ln 2/4 + r`, :math:`|r| \le \ln 2/8` (Cody–Waite, two parts),
  :math:`2^{j/4}` (:math:`j = k \bmod 4`) in a high and a low part chosen by selects,
  :math:`e^r - 1 = r + r^2 q(r)` with q of degree 7 by Estrin's scheme (a short dependency
  chain, for a lone member's latency), and :math:`2^{\lfloor k/4\rfloor}` in two factors,
  so that overflow to inf, underflow to 0 and subnormal results come out of the product
  without a select; within 1 ulp of libm; ``exp(x > 709.78) = inf``,
  ``exp(x < -745.2) = 0``, NaN propagates.
* :func:`vlog`: ARM optimized-routines' ``log.c`` (2018) with FMA: :math:`x = 2^k z`,
  :math:`\log x = k\ln 2 + \log c_i + \log(1 + r)`, :math:`r = z/c_i - 1`, from a
  128-entry table (:mod:`aiofl.components.vecmath_tables`: :math:`1/c_i` chosen so that
  :math:`\log c_i` rounds to within :math:`2^{-68}`), with the rounding errors of
  :math:`z/c_i - 1` and of the sums carried in a low part instead of the reference's
  special polynomial near 1, and :math:`\log(1+r) - r` by a degree-7 polynomial;
  subnormal inputs rescaled first; within 1 ulp; ``log 0 = -inf``, ``log(x < 0) = NaN``,
  ``log inf = inf``.  The table is read by a scalar load in a lone member's code and a
  vector gather in a lane group's.
* :func:`vsin`, :func:`vcos`: reduction by :math:`\pi/2` in three Cody–Waite parts
  (fdlibm's ``__ieee754_rem_pio2`` medium case, exact for :math:`|x| < 2^{20}\pi/2
  \approx 1.6\cdot10^6`), fdlibm's ``__kernel_sin``/``__kernel_cos`` polynomials by
  Estrin's scheme (a lone member's dependency chain: 14 ns against 20 with Horner's, libm
  12) and the quadrant by select; within 2 ulp there.  Beyond that range the reduction loses
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

from aiofl.components import vecmath_tables as _T

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
    FMA, scalar or vector, the same bits either way).

    Parameters
    ----------
    typingctx
        numba's typing context (numba passes it; a caller writes ``fma(a, b, c)``).
    a, b, c
        float64 values.

    Returns
    -------
    tuple
        The signature and code generator numba compiles (float64 only; None otherwise).
    """
    if not all(isinstance(t, types.Float) and t.bitwidth == 64 for t in (a, b, c)):
        return None

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        return builder.fma(*args)

    return types.float64(types.float64, types.float64, types.float64), codegen


_LN2_HI = 6.93147180369123816490e-01  # fdlibm: ln 2 split, the high part has 32 bits
_LN2_LO = 1.90821492927058770002e-10
_SHIFT = 6755399441055744.0  # 1.5 2^52: adding it rounds to an integer, kept in the low bits
_SHIFT_BITS = 0x4338000000000000  # its bits
_EXP_INV_STEP = 5.7707801635558535  # 4/ln 2
_EXP_STEP_HI = _T.EXP_STEP_HI
_EXP_STEP_LO = _T.EXP_STEP_LO
_SB0, _SB1, _SB2, _SB3 = _T.EXP_SCALE_BITS
_TL0, _TL1, _TL2, _TL3 = _T.EXP_SCALE_TAIL
_Q0, _Q1, _Q2, _Q3, _Q4, _Q5, _Q6, _Q7 = _T.EXP_POLY


@njit(**VECMATH_OPTIONS)
def vexp(x: float) -> float:
    """:math:`e^x`, branch-free (see the module notes for accuracy and special values)."""
    xc = -746.0 if x < -746.0 else x  # keeps k in range; NaN stays NaN
    xc = 710.0 if xc > 710.0 else xc
    kd = fma(xc, _EXP_INV_STEP, _SHIFT)  # k = round(4x/ln 2) in the low bits
    # k, |k| <= 4305, kept in [-2^17, 2^17) so that a NaN's bits overflow nothing below
    k = ((_as_int(kd) - _SHIFT_BITS + 0x20000) & 0x3FFFF) - 0x20000
    kd = kd - _SHIFT
    r = fma(kd, -_EXP_STEP_LO, fma(kd, -_EXP_STEP_HI, xc))  # x - k ln2/4, |r| <= ln2/8
    # 2^(j/4) = h_j (1 + t_j), j = k mod 4, chosen by selects (no table load: a vector
    # gather costs more than the polynomial it would save)
    odd, upper = (k & 1) != 0, (k & 2) != 0
    sbits = (_SB3 if odd else _SB2) if upper else (_SB1 if odd else _SB0)
    tail = (_TL3 if odd else _TL2) if upper else (_TL1 if odd else _TL0)
    # e^r - 1 = r + r^2 q(r), q by Estrin's scheme (a short dependency chain)
    r2 = r * r
    r4 = r2 * r2
    q = fma(
        r4,
        fma(r2, fma(r, _Q7, _Q6), fma(r, _Q5, _Q4)),
        fma(r2, fma(r, _Q3, _Q2), fma(r, _Q1, _Q0)),
    )
    tmp = fma(r2, q, r + tail)  # 2^(j/4) e^r = h_j (1 + tmp)
    # 2^(k div 4) in two factors, both normal for every clamped x: the product overflows
    # to inf, underflows to 0 or rounds into the subnormals by itself (no select)
    e = k >> 2
    e1 = e >> 1
    s = _as_float(sbits + ((e - e1) << 52))
    return fma(s, tmp, s) * _as_float((e1 + 1023) << 52)


_TWO54 = 1.80143985094819840000e16
_LOG_OFF = _T.LOG_OFF
_LOG_MASK = _T.LOG_N - 1
_LOG_INVC = _T.LOG_INVC
_LOG_LOGC = _T.LOG_LOGC
_A0, _A1, _A2, _A3, _A4, _A5 = _T.LOG_POLY


@njit(**VECMATH_OPTIONS)
def vlog(x: float) -> float:
    r""":math:`\ln x`, branch-free (table-driven; see the module notes)."""
    xa = abs(x)  # x < 0 gives NaN below; the bits of |x| overflow no integer operation
    ix = _as_int(xa)
    ixs = _as_int(xa * _TWO54)  # a subnormal x, scaled into the normal range
    tiny = ix < 0x0010000000000000
    ix = ixs if tiny else ix
    tmp = ix - _LOG_OFF
    i = (tmp >> 45) & _LOG_MASK
    k = (tmp >> 52) - (54 if tiny else 0)
    z = _as_float(ix - (tmp & (0xFFF << 52)))  # x = 2^k z
    invc = _LOG_INVC[i]
    logc = _LOG_LOGC[i]
    r = fma(z, invc, -1.0)  # z/c - 1, rounded once ...
    p = z * invc
    r_lo = ((p - 1.0) - r) + fma(z, invc, -p)  # ... and what the rounding dropped
    kd = float(k)
    w = fma(kd, _LN2_HI, logc)  # k ln2_hi + log c, and its rounding error (Fast2Sum)
    w_lo = (kd * _LN2_HI - w) + logc
    hi = w + r
    hi_lo = (w - hi) + r  # exact: |w| >= |r| or w = 0
    r2 = r * r
    poly = fma(r2, fma(r2, fma(r, _A5, _A4), fma(r, _A3, _A2)), fma(r, _A1, _A0))
    lo = hi_lo + (w_lo + fma(kd, _LN2_LO, r_lo))
    y = hi + fma(r2, poly, lo)
    # the special values by an addition (a select here would lengthen a lone member's
    # dependency chain): the main path is finite for |x| = 0 and inf
    finite = x > 0.0 and x < np.inf
    special = np.inf if x == np.inf else (-np.inf if x == 0.0 else np.nan)
    return y + (0.0 if finite else special)


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
    q = np.int64(0.0 if big else k) & 3
    # k pio2_1 is exact for |k| < 2^20, so the FMA rounds x - k pio2_1 as fdlibm's
    # subtraction does, one rounding shorter in the dependency chain
    r = (fma(-k, _PIO2_1, x) - k * _PIO2_2) - k * _PIO2_3
    # fdlibm's polynomials by Estrin's scheme: from z, four dependent operations to sin and
    # six to cos (Horner's: six and nine, 20 ns of latency against libm's 12)
    z = r * r
    z2 = z * z
    z4 = z2 * z2
    ps = fma(z4, fma(z, _S6, _S5), fma(z2, fma(z, _S4, _S3), fma(z, _S2, _S1)))
    sn = fma(r * z, ps, r)  # r + r^3 (S1 + S2 z + ... + S6 z^5)
    pc = fma(z4, fma(z, _C6, _C5), fma(z2, fma(z, _C4, _C3), fma(z, _C2, _C1)))
    hz = 0.5 * z
    w = 1.0 - hz
    cs = w + (((1.0 - w) - hz) + z2 * pc)  # 1 - z/2 + z^2 (C1 + ... + C6 z^5)
    sn = np.nan if big else sn
    cs = np.nan if big else cs
    return sn, cs, q


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
