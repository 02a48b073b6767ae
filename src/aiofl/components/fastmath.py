r"""Scalar building blocks shared by the controller components and the compiled engine.

The paper's formulas are implemented once, as small compiled scalar functions in
:mod:`aiofl.components.feedback`, :mod:`aiofl.components.observers`,
:mod:`aiofl.components.differentiators` and :mod:`aiofl.components.law`; the engine's time loop
calls exactly those functions.  This module holds what they share:

* :data:`FASTMATH` and :data:`JIT_OPTIONS` (:data:`CALLER_JIT_OPTIONS` in the modules
  whose functions call one of this module's), the numba options every one of them (and the
  engine's time loop) is compiled with: LLVM fast-math without ``nnan``/``ninf`` (NaN and
  infinity keep their IEEE 754 meaning, divergence detection relies on it) and numpy's
  error model (a division by zero gives inf or NaN instead of raising);
* :func:`abspow`, :math:`x^a` for :math:`x = |e| \ge 0` from a precomputed
  :math:`\log x`, so two powers of one error share one logarithm;
* :func:`fast_tanh`, tanh within 2 ulp of libm at a third of its cost on small
  arguments;
* :func:`sign`, :math:`\operatorname{sign}(x) \in \{-1, 0, 1\}`;
* :func:`binomial_power`, the coefficients of :math:`(s+\omega)^\rho` (linear SEF gains
  and linear prefilter coefficients).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from aiofl.numba_patches import key_helpers_by_fastmath

# numba's lowering helpers compiled per set of fast-math flags, before any component is
# compiled (aiofl.numba_patches)
key_helpers_by_fastmath()

__all__ = [
    "CALLER_JIT_OPTIONS",
    "FASTMATH",
    "JIT_OPTIONS",
    "abspow",
    "binomial_power",
    "fast_tanh",
    "sign",
]

FASTMATH = {"contract", "arcp", "nsz", "afn", "reassoc"}
"""LLVM fast-math flags of the scalar components and the engine's time loop.  ``nnan`` and
``ninf`` are deliberately absent: divergence detection relies on NaN and infinity behaving
as IEEE 754 says."""

JIT_OPTIONS = {"cache": True, "fastmath": FASTMATH, "error_model": "numpy"}
"""numba options of the scalar component functions (the engine's time loop uses the same
``fastmath`` and ``error_model``)."""

CALLER_JIT_OPTIONS = {**JIT_OPTIONS, "cache": False}
"""numba options of the component modules whose functions call a compiled function of
another module (this one's): as :data:`JIT_OPTIONS` but never cached on disk.  numba keys
a function's disk cache on its own source file only, so a cached caller loaded after an
edit of its callee's module would run the callee's old code (numbers stale by ~1e-8 in the
analysis after editing this file).  Compiling them in each process costs a fraction of a
second on first call; the engine's kernels link their own uncached copies anyway
(:func:`aiofl.engine.build.bindings.private_components`) and are cached under a fingerprint of
every source they use."""


@njit(**JIT_OPTIONS)
def abspow(x: float, a: float, log_x: float) -> float:
    r""":math:`x^a` for :math:`x \ge 0` given :math:`\log x`, as :math:`\exp(a \log x)`.

    Cheaper than ``pow`` and lets two powers of the same x share one logarithm; the result
    differs from ``x**a`` by a few ulp (exact for a = 0 and 1).  :math:`0^a = 0` for
    a > 0 (``exp(-inf) = 0``); inf and NaN propagate.

    Parameters
    ----------
    x
        x ≥ 0.
    a
        The exponent.
    log_x
        log x.

    Returns
    -------
    float
    """
    if a == 1.0:
        return x
    if a == 0.0:
        return 1.0
    return np.exp(a * log_x)


# Cephes' rational approximation of tanh on |x| < 0.625: tanh x = x + x z P(z)/Q(z), z = x²
_TANH_P = (-9.64399179425052238628e-1, -9.92877231001918586564e1, -1.61468768441708447952e3)
_TANH_Q = (1.12811678491632931402e2, 2.23548839060100448583e3, 4.84406305325125486048e3)


@njit(**JIT_OPTIONS)
def fast_tanh(x: float) -> float:
    """tanh x within 2 ulp of libm's, at a third of its cost on small arguments.

    A rational approximation for |x| < 0.625 (Cephes), ``1 - 2/(exp(2|x|) + 1)`` up to 20,
    and 1 beyond (tanh 20 rounds to 1); odd; NaN propagates.  Both forms are evaluated and
    the result chosen by plain selects, so a loop over SIMD lanes vectorizes
    (:mod:`aiofl.engine.kernel.loop`); the value is the same as choosing first.
    """
    ax = abs(x)
    p0, p1, p2 = _TANH_P
    q0, q1, q2 = _TANH_Q
    zz = ax * ax
    t = ax + ax * zz * ((p0 * zz + p1) * zz + p2) / (((zz + q0) * zz + q1) * zz + q2)
    t = 1.0 - 2.0 / (np.exp(2.0 * ax) + 1.0) if ax >= 0.625 else t
    t = 1.0 if ax >= 20.0 else t
    return math.copysign(t, x)


@njit(**JIT_OPTIONS)
def sign(x: float) -> float:
    r""":math:`\operatorname{sign}(x)`: 1 for x > 0, -1 for x < 0, 0 for x = 0 (and NaN)."""
    s = 1.0 if x > 0.0 else 0.0  # plain selects: vectorizable in a loop over lanes
    return -1.0 if x < 0.0 else s


@njit(**JIT_OPTIONS)
def binomial_power(rho: int, j: int, omega: float) -> float:
    r""":math:`\binom{\rho}{j}\omega^{\rho-j}`, the coefficient of :math:`s^j` in
    :math:`(s+\omega)^\rho` (0 <= j <= ρ).

    The binomial coefficient is built as a float product,
    :math:`\binom{\rho}{i} = \binom{\rho}{i-1}(\rho-i+1)/i`, exact for the orders used here.

    Parameters
    ----------
    rho
        ρ ≥ 0.
    j
        0 ≤ j ≤ ρ.
    omega
        ω.

    Returns
    -------
    float
    """
    binom = 1.0
    for i in range(1, j + 1):
        binom = binom * (rho - i + 1) / i
    return binom * omega ** (rho - j)
