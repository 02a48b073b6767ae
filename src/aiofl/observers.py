r"""Extended state observers of any order ρ+1: linear (LESO) and improved nonlinear (INLESO).

For a plant of relative degree ρ written as a chain of integrators with the total
disturbance as an extra state, eq. (6),

.. math::
    \dot\xi_i = \xi_{i+1}\ (i<\rho),\quad \dot\xi_\rho = \xi_{\rho+1} + b_0 u,\quad
    \dot\xi_{\rho+1} = \dot f_T ,

the ESO of eqs. (5)/(16) (linear) and (19) (improved nonlinear) is

.. math::
    \dot{\hat\xi}_i = \hat\xi_{i+1} + \beta_i\,\phi(y-\hat\xi_1)\quad (i<\rho),\qquad
    \dot{\hat\xi}_\rho = \hat\xi_{\rho+1} + \beta_\rho\,\phi(y-\hat\xi_1) + b_0 u,\qquad
    \dot{\hat\xi}_{\rho+1} = \beta_{\rho+1}\,\phi(y-\hat\xi_1),

with :math:`\phi(e) = e` for the LESO and
:math:`\phi(e) = k_\alpha |e|^\alpha \operatorname{sign}(e) + k_\beta |e|^\beta e`
for the INLESO (eq. 19).  Gains are :math:`\beta_i = \alpha_i\,\omega_0^i` (text after
eq. 16).  Gao's bandwidth parameterisation is :math:`\alpha_i = \binom{\rho+1}{i}`, which
puts all ρ+1 observer poles at :math:`-\omega_0`.
"""

from __future__ import annotations

from math import comb

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "binomial_alphas",
    "eso_error_matrix",
    "eso_gains",
    "eso_rhs",
    "inleso_injection",
]


def eso_gains(omega0: float, alphas: ArrayLike) -> NDArray[np.float64]:
    r"""Observer gains :math:`\beta_i = \alpha_i\,\omega_0^i`, i = 1..ρ+1 (text after eq. 16)."""
    a = np.asarray(alphas, dtype=np.float64)
    return a * float(omega0) ** np.arange(1, a.size + 1)


def binomial_alphas(rho: int) -> NDArray[np.float64]:
    r"""Gao's bandwidth choice :math:`\alpha_i = \binom{\rho+1}{i}`, i = 1..ρ+1.

    With these the characteristic polynomial of the linear ESO error is
    :math:`(s+\omega_0)^{\rho+1}`.
    """
    if rho < 1:
        raise ValueError(f"rho must be >= 1, got {rho}")
    return np.array([comb(rho + 1, i) for i in range(1, rho + 2)], dtype=np.float64)


def eso_error_matrix(betas: ArrayLike) -> NDArray[np.float64]:
    r"""State matrix of the linear ESO estimation error, eq. (9).

    With :math:`e = \xi - \hat\xi`, :math:`\dot e = A_e e + [0,\dots,0,\Delta]^T` where
    :math:`A_e` has ones on the super-diagonal and :math:`-\beta` in the first column.  Its
    characteristic polynomial is :math:`s^{\rho+1} + \beta_1 s^\rho + \dots + \beta_{\rho+1}`.
    """
    b = np.asarray(betas, dtype=np.float64)
    m = b.size
    a = np.eye(m, k=1)
    a[:, 0] = -b
    return a


@njit(cache=True)
def inleso_injection(e: float, k_alpha: float, k_beta: float, a: float, b: float) -> float:
    r"""Nonlinear error injection of the INLESO, eq. (19).

    .. math:: g(e) = k_\alpha |e|^\alpha \operatorname{sign}(e) + k_\beta |e|^\beta e
    """
    ae = abs(e)
    s = 1.0 if e > 0.0 else (-1.0 if e < 0.0 else 0.0)
    return k_alpha * ae**a * s + k_beta * ae**b * e


@njit(cache=True)
def eso_rhs(
    xi_hat: NDArray[np.float64],
    d_xi_hat: NDArray[np.float64],
    rho: int,
    betas: NDArray[np.float64],
    b0: float,
    y: float,
    u: float,
    improved: bool,
    k_alpha: float,
    k_beta: float,
    a: float,
    b: float,
) -> None:
    r"""Right-hand side of the ESO of order ρ+1, eqs. (5), (16) and (19).

    Writes :math:`\dot{\hat\xi}` into ``d_xi_hat[:rho+1]``.  ``improved`` selects the
    INLESO injection :math:`g(e)` of eq. (19) instead of the linear :math:`e`.
    """
    e = y - xi_hat[0]
    if improved:
        e = inleso_injection(e, k_alpha, k_beta, a, b)
    for i in range(rho):
        d_xi_hat[i] = xi_hat[i + 1] + betas[i] * e
    d_xi_hat[rho - 1] += b0 * u
    d_xi_hat[rho] = betas[rho] * e
