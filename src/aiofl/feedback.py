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

from math import comb

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["fal", "improved_sef", "linear_sef_gains", "nonlinear_sef"]


@njit(cache=True)
def fal(e: float, alpha: float, delta: float) -> float:
    r"""Han's fal function, eq. (17), in its continuous form.

    .. math::
        \mathrm{fal}(e,\alpha,\delta) = \begin{cases} e/\delta^{1-\alpha} & |e|\le\delta\\
        |e|^\alpha \operatorname{sign}(e) & |e|>\delta \end{cases}

    The paper prints :math:`e/\delta^{\alpha-1}` on the inner branch, which is
    discontinuous at :math:`|e| = \delta` (erratum); both branches equal
    :math:`\delta^\alpha\operatorname{sign}(e)` there with the form used here.
    """
    ae = abs(e)
    if ae <= delta:
        return e / delta ** (1.0 - alpha)
    return ae**alpha * (1.0 if e > 0.0 else -1.0)


@njit(cache=True)
def nonlinear_sef(
    e: NDArray[np.float64],
    m: int,
    k: NDArray[np.float64],
    alpha: NDArray[np.float64],
    delta: NDArray[np.float64],
) -> float:
    r"""NLSEF :math:`v = \sum_{i\le m} k_i\,\mathrm{fal}(e_i,\alpha_i,\delta_i)`, eq. (17)."""
    v = 0.0
    for i in range(m):
        v += k[i] * fal(e[i], alpha[i], delta[i])
    return v


@njit(cache=True)
def improved_sef(
    e: NDArray[np.float64],
    m: int,
    k1: NDArray[np.float64],
    k2: NDArray[np.float64],
    mu: NDArray[np.float64],
    alpha: NDArray[np.float64],
    delta: float,
) -> float:
    r"""INLSEF, eq. (20): :math:`v = \delta\tanh((v_1+\dots+v_m)/\delta)`."""
    s = 0.0
    for i in range(m):
        ei = e[i]
        ae = abs(ei)
        sgn = 1.0 if ei > 0.0 else (-1.0 if ei < 0.0 else 0.0)
        s += (k1[i] + k2[i] / (1.0 + np.exp(mu[i] * ei * ei))) * ae ** alpha[i] * sgn
    return delta * np.tanh(s / delta)


def linear_sef_gains(rho: int, omega_c: float) -> NDArray[np.float64]:
    r"""Gains :math:`k_i = \binom{\rho}{i-1}\omega_c^{\rho-i+1}`, i = 1..ρ, so that
    :math:`s^\rho + k_\rho s^{\rho-1} + \dots + k_1 = (s+\omega_c)^\rho`."""
    return np.array([comb(rho, i - 1) * omega_c ** (rho - i + 1) for i in range(1, rho + 1)])
