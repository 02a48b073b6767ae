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

from math import comb

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = [
    "han_td_rhs",
    "improved_td_rhs",
    "itd_steady_state",
    "linear_prefilter_coefficients",
    "linear_prefilter_rhs",
]


@njit(cache=True)
def han_td_rhs(r1: float, r2: float, r: float, big_r: float) -> tuple[float, float]:
    r"""Han's tracking differentiator, eq. (18) with the :math:`2R` correction.

    Returns :math:`(\dot r_1, \dot r_2)`.
    """
    s = r1 - r + r2 * abs(r2) / (2.0 * big_r)
    sgn = 1.0 if s > 0.0 else (-1.0 if s < 0.0 else 0.0)
    return r2, -big_r * sgn


@njit(cache=True)
def improved_td_rhs(
    r1: float, r2: float, r: float, a: float, b: float, c: float, rho: float
) -> tuple[float, float]:
    r"""Improved tracking differentiator (ITD), eq. (21). Returns :math:`(\dot r_1, \dot r_2)`."""
    return r2, -rho * rho * np.tanh((b * r1 - (1.0 - a) * r) / c) - rho * r2


def itd_steady_state(r: float, a: float, b: float) -> float:
    r"""Equilibrium :math:`r_1 = (1-a)\,r/b` of the ITD (eq. 21) for a constant input r."""
    return (1.0 - a) * r / b


def linear_prefilter_coefficients(rho: int, omega: float) -> NDArray[np.float64]:
    r"""Coefficients :math:`c_i = \binom{\rho}{i-1}\omega^{\rho-i+1}`, i = 1..ρ, of
    :math:`(s+\omega)^\rho = s^\rho + c_\rho s^{\rho-1} + \dots + c_1`."""
    return np.array([comb(rho, i - 1) * omega ** (rho - i + 1) for i in range(1, rho + 1)])


@njit(cache=True)
def linear_prefilter_rhs(
    state: NDArray[np.float64], d_state: NDArray[np.float64], rho: int, r: float, omega: float
) -> float:
    r"""Linear prefilter :math:`\omega^\rho/(s+\omega)^\rho` in controllable form.

    Writes :math:`\dot r_1..\dot r_\rho` into ``d_state`` and returns
    :math:`r_1^{(\rho)} = \dot r_\rho`.
    """
    for i in range(rho - 1):
        d_state[i] = state[i + 1]
    # c_i = C(rho, i-1) * omega^(rho-i+1), built incrementally to stay in nopython mode.
    acc = omega**rho * (r - state[0])
    binom = 1.0
    for i in range(1, rho):  # state index i -> coefficient C(rho, i) * omega^(rho-i)
        binom = binom * (rho - i + 1) / i
        acc -= binom * omega ** (rho - i) * state[i]
    d_state[rho - 1] = acc
    return acc
