r"""Tracking differentiators: Han's TD (eq. 18), the improved TD (eq. 21), a linear prefilter.

Each produces a transient profile :math:`r_1 \approx r` and derivatives
:math:`r_2 \approx \dot r, \dots` that the state error feedback compares with the ESO
estimates, :math:`e_i = r_i - \hat\xi_i`.

* Han's TD, eq. (18) with the erratum corrected (the switching curve divides by
  :math:`2R`, not by :math:`2r`):

  .. math:: \dot r_1 = r_2,\qquad
            \dot r_2 = -R\,\operatorname{sign}\!\Big(r_1 - r + \frac{r_2|r_2|}{2R}\Big)

* Improved TD (ITD), eq. (21):

  .. math:: \dot r_1 = r_2,\qquad
            \dot r_2 = -\varrho^2 \tanh\!\Big(\frac{b r_1 - (1-a) r}{c}\Big) - \varrho r_2

  Its equilibrium for a constant r is :math:`r_1 = (1-a)\,r/b`, so it tracks r itself only
  when :math:`1-a = b`.  The paper's printed set (a = 0.9153, b = 8.7141) gives
  :math:`r_1 \to 0.0097\,r`; we implement eq. (21) as printed and report what it does.

* Linear prefilter of order ρ, :math:`R(s)/r(s) = \omega_r^\rho/(s+\omega_r)^\rho`, whose
  states are :math:`r_1, \dots, r_\rho = r_1^{(\rho-1)}` and whose last state derivative
  supplies :math:`r_1^{(\rho)}` for the feed-forward of a full-state linear feedback.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from aiofl.components.fastmath import CALLER_JIT_OPTIONS, binomial_power, fast_tanh

__all__ = [
    "han_td_rhs",
    "improved_td_constants",
    "improved_td_rhs",
    "improved_td_rhs_scaled",
    "itd_steady_state",
    "linear_prefilter_coefficient",
    "linear_prefilter_coefficients",
    "linear_prefilter_rhs",
    "linear_prefilter_update",
]


@njit(cache=True)
def han_td_rhs(r1: float, r2: float, r: float, big_r: float) -> tuple[float, float]:
    r"""Han's tracking differentiator, eq. (18) with the :math:`2R` correction.

    Returns :math:`(\dot r_1, \dot r_2)`.

    Parameters
    ----------
    r1, r2
        The TD's states (the tracked reference and its derivative).
    r
        The reference.
    big_r
        The speed factor R > 0 (``td.R``).

    Returns
    -------
    tuple of (float, float)
    """
    s = r1 - r + r2 * abs(r2) / (2.0 * big_r)
    sgn = 1.0 if s > 0.0 else 0.0  # sign(s); plain selects vectorize over lanes
    sgn = -1.0 if s < 0.0 else sgn
    return r2, -big_r * sgn


@njit(**CALLER_JIT_OPTIONS)
def improved_td_rhs_scaled(
    r1: float, r2: float, r: float, b_over_c: float, gain: float, rho: float
) -> tuple[float, float]:
    r"""Improved tracking differentiator (ITD), eq. (21), with the constants divided out:

    .. math:: \dot r_1 = r_2,\qquad
              \dot r_2 = -\varrho^2\tanh\big(\tfrac{b}{c}\,r_1 - \tfrac{1-a}{c}\,r\big)
              - \varrho r_2

    ``b_over_c`` = :math:`b/c` and ``gain`` = :math:`(1-a)/c` (:func:`improved_td_constants`;
    the engine computes them once per member).  Returns :math:`(\dot r_1, \dot r_2)`.

    Parameters
    ----------
    r1, r2
        The TD's states.
    r
        The reference.
    b_over_c, gain
        b/c and (1 - a)/c.
    rho
        ϱ (``td.rho``).

    Returns
    -------
    tuple of (float, float)
    """
    return r2, -rho * rho * fast_tanh(b_over_c * r1 - gain * r) - rho * r2


@njit(**CALLER_JIT_OPTIONS)
def improved_td_constants(a: float, b: float, c: float) -> tuple[float, float]:
    r"""The ITD's constants :math:`(b/c,\ (1-a)/c)` for :func:`improved_td_rhs_scaled`.

    Parameters
    ----------
    a, b, c
        The ITD's constants (``td.a``, ``td.b``, ``td.c``; c ≠ 0).

    Returns
    -------
    tuple of (float, float)
    """
    return b / c, (1.0 - a) / c


@njit(**CALLER_JIT_OPTIONS)
def improved_td_rhs(
    r1: float, r2: float, r: float, a: float, b: float, c: float, rho: float
) -> tuple[float, float]:
    r"""Improved tracking differentiator (ITD), eq. (21). Returns :math:`(\dot r_1, \dot r_2)`.

    .. math:: \dot r_2 = -\varrho^2 \tanh\!\Big(\frac{b r_1 - (1-a) r}{c}\Big)
              - \varrho r_2

    Computed as :func:`improved_td_rhs_scaled` with :math:`b/c` and :math:`(1-a)/c`.

    Parameters
    ----------
    r1, r2
        The TD's states.
    r
        The reference.
    a, b, c, rho
        The ITD's constants a, b, c (c ≠ 0) and ϱ.

    Returns
    -------
    tuple of (float, float)
    """
    b_over_c, gain = improved_td_constants(a, b, c)
    return improved_td_rhs_scaled(r1, r2, r, b_over_c, gain, rho)


def itd_steady_state(r: float, a: float, b: float) -> float:
    r"""Equilibrium :math:`r_1 = (1-a)\,r/b` of the ITD (eq. 21) for a constant input r.

    Parameters
    ----------
    r
        The constant input.
    a, b
        The ITD's constants (b ≠ 0).

    Returns
    -------
    float
    """
    return (1.0 - a) * r / b


@njit(**CALLER_JIT_OPTIONS)
def linear_prefilter_coefficient(rho: int, i: int, omega: float) -> float:
    r"""Coefficient :math:`c_i = \binom{\rho}{i-1}\omega^{\rho-i+1}` (i = 1..ρ) of
    :math:`(s+\omega)^\rho` (:func:`aiofl.components.fastmath.binomial_power`).

    Parameters
    ----------
    rho
        The order ρ.
    i
        The index, 1..ρ.
    omega
        The prefilter's bandwidth ω [rad/s].

    Returns
    -------
    float
    """
    return binomial_power(rho, i - 1, omega)


def linear_prefilter_coefficients(rho: int, omega: float) -> NDArray[np.float64]:
    r"""Coefficients :math:`c_i = \binom{\rho}{i-1}\omega^{\rho-i+1}`, i = 1..ρ, of
    :math:`(s+\omega)^\rho = s^\rho + c_\rho s^{\rho-1} + \dots + c_1`."""
    return np.array([linear_prefilter_coefficient(rho, i, float(omega)) for i in range(1, rho + 1)])


@njit(inline="always", **CALLER_JIT_OPTIONS)  # inlined where called: no array arguments
def linear_prefilter_update(
    state: NDArray[np.float64],
    d_state: NDArray[np.float64],
    o: int,
    rho: int,
    r: float,
    coeffs: NDArray[np.float64],
    oc: int,
) -> float:
    r"""Linear prefilter :math:`\omega^\rho/(s+\omega)^\rho` in controllable form:

    .. math:: \dot r_i = r_{i+1}\ (i<\rho),\qquad
              \dot r_\rho = c_1 (r - r_1) - \sum_{i=2}^{\rho} c_i r_i

    with :math:`c_i` from :func:`linear_prefilter_coefficients` at ``coeffs[oc + i - 1]``,
    :math:`r_i` at ``state[o + i - 1]`` and :math:`\dot r_i` written to
    ``d_state[o + i - 1]`` (offsets, so the engine passes its state vector without slicing
    it).  Returns :math:`r_1^{(\rho)} = \dot r_\rho`.

    Parameters
    ----------
    state, d_state
        The engine's state and derivative vectors.
    o
        The offset of :math:`r_1` in both.
    rho
        The order ρ.
    r
        The reference.
    coeffs, oc
        The coefficients and the offset of :math:`c_1` in them.

    Returns
    -------
    float
    """
    acc = coeffs[oc] * (r - state[o])
    for i in range(1, rho):
        d_state[o + i - 1] = state[o + i]
        acc -= coeffs[oc + i] * state[o + i]
    d_state[o + rho - 1] = acc
    return acc


@njit(**CALLER_JIT_OPTIONS)
def linear_prefilter_rhs(
    state: NDArray[np.float64], d_state: NDArray[np.float64], rho: int, r: float, omega: float
) -> float:
    r"""Linear prefilter :math:`\omega^\rho/(s+\omega)^\rho` in controllable form.

    Writes :math:`\dot r_1..\dot r_\rho` into ``d_state`` and returns
    :math:`r_1^{(\rho)} = \dot r_\rho` (:func:`linear_prefilter_update` with the
    coefficients of :func:`linear_prefilter_coefficient`).

    Parameters
    ----------
    state, d_state
        :math:`r_1..r_\rho` and their derivatives (written), ρ entries each.
    rho
        The order ρ.
    r
        The reference.
    omega
        The bandwidth ω [rad/s].

    Returns
    -------
    float
    """
    coeffs = np.empty(rho)
    for i in range(rho):
        coeffs[i] = linear_prefilter_coefficient(rho, i + 1, omega)
    return linear_prefilter_update(state, d_state, 0, rho, r, coeffs, 0)
