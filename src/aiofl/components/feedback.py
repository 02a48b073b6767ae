r"""State error feedbacks: NLSEF with fal (eq. 17), INLSEF (eq. 20), linear full-state.

The errors are :math:`e_i = r_i - \hat\xi_i`, i = 1..m, where m (``n_feedback``) is how
many estimated states are fed back; the paper uses m = 2 (text after eq. 22).

* NLSEF, eq. (17) and the sentence before it, with gains :math:`k_i` (the paper's law is
  :math:`v = \mathrm{fal}(e_1,\alpha_1,\delta_1) + \mathrm{fal}(e_2,\alpha_2,\delta_2)`, i.e.
  :math:`k_i = 1`):

  .. math:: v = \sum_{i=1}^m k_i\,\mathrm{fal}(e_i, \alpha_i, \delta_i)

* INLSEF, eq. (20):

  .. math:: v = \delta \tanh\!\Big(\frac{1}{\delta}\sum_{i=1}^m
            \Big(k_{i1} + \frac{k_{i2}}{1+\exp(\mu_i e_i^2)}\Big)|e_i|^{\alpha_i}
            \operatorname{sign}(e_i)\Big)

* Linear full-state feedback for the chain (14), :math:`\dot\xi_\rho = b_0 v`:

  .. math:: v = \frac{1}{b_0}\Big(\sum_{i=1}^m k_i e_i + r^{(\rho)}\Big),\qquad
            k_i = \binom{\rho}{i-1}\omega_c^{\rho-i+1}

  which places the tracking-error poles at :math:`-\omega_c` when m = ρ.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from aiofl.components.fastmath import CALLER_JIT_OPTIONS, abspow, binomial_power, fast_tanh, sign

__all__ = [
    "fal",
    "fal_inner_slope",
    "fal_linear",
    "fal_power_needed",
    "fal_scaled",
    "improved_sef",
    "inlsef_limit",
    "inlsef_term",
    "linear_sef",
    "linear_sef_gain",
    "linear_sef_gains",
    "nonlinear_sef",
]


@njit(**CALLER_JIT_OPTIONS)
def fal_scaled(e: float, alpha: float, delta: float, inner_slope: float) -> float:
    r"""Han's fal, eq. (17), given its inner slope :math:`\delta^{\alpha-1}`.

    .. math::
        \mathrm{fal}(e,\alpha,\delta) = \begin{cases} e\,\delta^{\alpha-1} & |e|\le\delta\\
        |e|^\alpha \operatorname{sign}(e) & |e|>\delta \end{cases}

    ``inner_slope`` must be :math:`\delta^{\alpha-1}` (:func:`fal_inner_slope`); the engine
    computes it once per member.  :func:`fal` is this function with the slope computed from α and δ.

    Parameters
    ----------
    e
        The error.
    alpha, delta
        α and the linear zone's half-width δ > 0.
    inner_slope
        :math:`\delta^{\alpha-1}`.

    Returns
    -------
    float
    """
    if not fal_power_needed(e, alpha, delta):
        return fal_linear(e, delta, inner_slope)
    ae = abs(e)
    return abspow(ae, alpha, np.log(ae)) * sign(e)


@njit(**CALLER_JIT_OPTIONS)
def fal_power_needed(e: float, alpha: float, delta: float) -> bool:
    r"""Whether :math:`\mathrm{fal}(e,\alpha,\delta)` needs the power :math:`|e|^\alpha`:
    outside the linear zone (:math:`|e| > \delta`, or e NaN) with :math:`\alpha \ne 1`.
    Otherwise :func:`fal_scaled` is :func:`fal_linear`.

    Parameters
    ----------
    e, alpha, delta
        As for :func:`fal`.

    Returns
    -------
    bool
    """
    return not abs(e) <= delta and alpha != 1.0


@njit(**CALLER_JIT_OPTIONS)
def fal_linear(e: float, delta: float, inner_slope: float) -> float:
    r"""fal where it needs no power (:func:`fal_power_needed` false): the inner branch
    :math:`e\,\delta^{\alpha-1}` for :math:`|e| \le \delta`, else :math:`e` (α = 1).

    The engine's SIMD lanes evaluate fal as this alone when no lane of a group needs the
    power (the same value, bit for bit, as :func:`fal_scaled`).

    Parameters
    ----------
    e, delta, inner_slope
        As for :func:`fal_scaled`.

    Returns
    -------
    float
    """
    return e * inner_slope if abs(e) <= delta else e


@njit(**CALLER_JIT_OPTIONS)
def fal_inner_slope(alpha: float, delta: float) -> float:
    r"""The slope :math:`\delta^{\alpha-1} = 1/\delta^{1-\alpha}` of fal's linear inner
    branch (eq. 17, continuous form), for :func:`fal_scaled`."""
    return delta ** (alpha - 1.0)


@njit(**CALLER_JIT_OPTIONS)
def fal(e: float, alpha: float, delta: float) -> float:
    r"""Han's fal function, eq. (17), in its continuous form.

    .. math::
        \mathrm{fal}(e,\alpha,\delta) = \begin{cases} e/\delta^{1-\alpha} & |e|\le\delta\\
        |e|^\alpha \operatorname{sign}(e) & |e|>\delta \end{cases}

    The paper prints :math:`e/\delta^{\alpha-1}` on the inner branch, which is
    discontinuous at :math:`|e| = \delta` (erratum); both branches equal
    :math:`\delta^\alpha\operatorname{sign}(e)` there with the form used here.
    Computed as :func:`fal_scaled` with the slope :math:`\delta^{\alpha-1}`.

    Parameters
    ----------
    e
        The error.
    alpha
        The exponent α.
    delta
        The linear zone's half-width δ > 0.

    Returns
    -------
    float
    """
    return fal_scaled(e, alpha, delta, fal_inner_slope(alpha, delta))


@njit(**CALLER_JIT_OPTIONS)
def nonlinear_sef(
    e: NDArray[np.float64],
    m: int,
    k: NDArray[np.float64],
    alpha: NDArray[np.float64],
    delta: NDArray[np.float64],
) -> float:
    r"""NLSEF :math:`v = \sum_{i\le m} k_i\,\mathrm{fal}(e_i,\alpha_i,\delta_i)`, eq. (17).

    Parameters
    ----------
    e
        The errors :math:`e_i`.
    m
        How many are fed back.
    k, alpha, delta
        The gains, exponents and δ of each.

    Returns
    -------
    float
        v.
    """
    v = 0.0
    for i in range(m):
        v += k[i] * fal(e[i], alpha[i], delta[i])
    return v


@njit(**CALLER_JIT_OPTIONS)
def inlsef_term(e: float, k1: float, k2: float, mu: float, alpha: float) -> float:
    r"""One error's term of the INLSEF, eq. (20):

    .. math:: v_i = \Big(k_{i1} + \frac{k_{i2}}{1+\exp(\mu_i e_i^2)}\Big)
              |e_i|^{\alpha_i}\operatorname{sign}(e_i)

    (the exponential is skipped when :math:`k_{i2} = 0`).

    Parameters
    ----------
    e
        The error :math:`e_i`.
    k1, k2, mu, alpha
        :math:`k_{i1}`, :math:`k_{i2}`, :math:`\mu_i` and :math:`\alpha_i`.

    Returns
    -------
    float
    """
    gain = k1
    if k2 != 0.0:
        gain += k2 / (1.0 + np.exp(mu * e * e))
    ae = abs(e)
    return gain * abspow(ae, alpha, np.log(ae)) * sign(e)


@njit(**CALLER_JIT_OPTIONS)
def inlsef_limit(s: float, v_limit: float) -> float:
    r"""The INLSEF's smooth limit, eq. (20): :math:`v = \delta\tanh(s/\delta)` of the sum
    :math:`s = v_1 + \dots + v_m` of :func:`inlsef_term`, with :math:`\delta` =
    ``v_limit``."""
    return v_limit * fast_tanh(s / v_limit)


@njit(**CALLER_JIT_OPTIONS)
def improved_sef(
    e: NDArray[np.float64],
    m: int,
    k1: NDArray[np.float64],
    k2: NDArray[np.float64],
    mu: NDArray[np.float64],
    alpha: NDArray[np.float64],
    delta: float,
) -> float:
    r"""INLSEF, eq. (20): :math:`v = \delta\tanh((v_1+\dots+v_m)/\delta)` with the terms
    :math:`v_i` of :func:`inlsef_term`.

    Parameters
    ----------
    e, m
        The errors and how many are fed back.
    k1, k2, mu, alpha
        The terms' constants, one each per error (:func:`inlsef_term`).
    delta
        The limit δ > 0.

    Returns
    -------
    float
        v.
    """
    s = 0.0
    for i in range(m):
        s += inlsef_term(e[i], k1[i], k2[i], mu[i], alpha[i])
    return inlsef_limit(s, delta)


@njit(**CALLER_JIT_OPTIONS)
def linear_sef(weighted_errors: float, r_rho: float, b0: float) -> float:
    r"""Linear full-state feedback for the chain (14),
    :math:`v = \big(\sum_{i=1}^m k_i e_i + r^{(\rho)}\big)/b_0`, given the weighted sum
    :math:`\sum k_i e_i` (gains from :func:`linear_sef_gains`) and the feed-forward
    :math:`r^{(\rho)}`.

    Parameters
    ----------
    weighted_errors
        :math:`\sum k_i e_i`.
    r_rho
        :math:`r^{(\rho)}`.
    b0
        b₀ ≠ 0.

    Returns
    -------
    float
        v.
    """
    return (weighted_errors + r_rho) / b0


@njit(**CALLER_JIT_OPTIONS)
def linear_sef_gain(rho: int, i: int, omega_c: float) -> float:
    r"""Gain :math:`k_i = \binom{\rho}{i-1}\omega_c^{\rho-i+1}` (i = 1..ρ) of the linear SEF:
    the coefficient of :math:`s^{i-1}` in :math:`(s+\omega_c)^\rho`
    (:func:`aiofl.components.fastmath.binomial_power`).

    Parameters
    ----------
    rho, i, omega_c
        ρ, the index 1..ρ and :math:`\omega_c` [rad/s].

    Returns
    -------
    float
    """
    return binomial_power(rho, i - 1, omega_c)


def linear_sef_gains(rho: int, omega_c: float) -> NDArray[np.float64]:
    r"""Gains :math:`k_i = \binom{\rho}{i-1}\omega_c^{\rho-i+1}`, i = 1..ρ, so that
    :math:`s^\rho + k_\rho s^{\rho-1} + \dots + k_1 = (s+\omega_c)^\rho`
    (:func:`linear_sef_gain` for each i)."""
    return np.array([linear_sef_gain(rho, i, float(omega_c)) for i in range(1, rho + 1)])
