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

from aiofl.components.fastmath import CALLER_JIT_OPTIONS, abspow, sign

__all__ = [
    "binomial_alphas",
    "eso_error_matrix",
    "eso_gain",
    "eso_gains",
    "eso_rhs",
    "eso_update",
    "inleso_injection",
]


@njit(**CALLER_JIT_OPTIONS)
def eso_gain(alpha_i: float, omega0: float, i: int) -> float:
    r"""Observer gain :math:`\beta_i = \alpha_i\,\omega_0^i` (text after eq. 16).

    Parameters
    ----------
    alpha_i
        :math:`\alpha_i`.
    omega0
        ω₀ [rad/s].
    i
        The index i, 1..ρ+1.

    Returns
    -------
    float
    """
    return alpha_i * omega0**i


def eso_gains(omega0: float, alphas: ArrayLike) -> NDArray[np.float64]:
    r"""Observer gains :math:`\beta_i = \alpha_i\,\omega_0^i`, i = 1..ρ+1 (text after eq. 16)."""
    a = np.asarray(alphas, dtype=np.float64)
    return np.array([eso_gain(float(a[i]), float(omega0), i + 1) for i in range(a.size)])


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


@njit(**CALLER_JIT_OPTIONS)
def inleso_injection(e: float, k_alpha: float, k_beta: float, a: float, b: float) -> float:
    r"""Nonlinear error injection of the INLESO, eq. (19).

    .. math:: g(e) = k_\alpha |e|^\alpha \operatorname{sign}(e) + k_\beta |e|^\beta e

    Both powers share one :math:`\log|e|`; the second term is skipped when
    :math:`k_\beta = 0`.

    Parameters
    ----------
    e
        The error :math:`y - \hat\xi_1`.
    k_alpha, k_beta
        :math:`k_\alpha` and :math:`k_\beta`.
    a, b
        The exponents α and β.

    Returns
    -------
    float
        g(e).
    """
    ae = abs(e)
    la = np.log(ae)
    g = k_alpha * abspow(ae, a, la) * sign(e)
    if k_beta != 0.0:
        g += k_beta * abspow(ae, b, la) * e
    return g


@njit(inline="always", **CALLER_JIT_OPTIONS)  # inlined where called: no array arguments
def eso_update(
    xi_hat: NDArray[np.float64],
    d_xi_hat: NDArray[np.float64],
    o: int,
    rho: int,
    betas: NDArray[np.float64],
    ob: int,
    b0: float,
    u: float,
    phi: float,
) -> None:
    r"""The ESO of eqs. (5)/(16)/(19) given the injected error :math:`\phi` =
    :math:`\phi(y - \hat\xi_1)`:

    .. math::
        \dot{\hat\xi}_i = \hat\xi_{i+1} + \beta_i\phi\ (i<\rho),\quad
        \dot{\hat\xi}_\rho = \hat\xi_{\rho+1} + \beta_\rho\phi + b_0 u,\quad
        \dot{\hat\xi}_{\rho+1} = \beta_{\rho+1}\phi .

    :math:`\hat\xi_i` is ``xi_hat[o + i - 1]``, its derivative goes to
    ``d_xi_hat[o + i - 1]`` and :math:`\beta_i` is ``betas[ob + i - 1]`` (offsets, so the
    engine passes its state vector without slicing it).  :math:`\phi = e` for the LESO,
    :func:`inleso_injection` for the INLESO.

    Parameters
    ----------
    xi_hat, d_xi_hat
        The engine's state and derivative vectors.
    o
        The offset of :math:`\hat\xi_1` in both.
    rho
        The order ρ.
    betas, ob
        The gains and the offset of :math:`\beta_1`.
    b0
        b₀.
    u
        The command.
    phi
        The injected error φ.
    """
    for i in range(rho):
        d_xi_hat[o + i] = xi_hat[o + i + 1] + betas[ob + i] * phi
    d_xi_hat[o + rho - 1] += b0 * u
    d_xi_hat[o + rho] = betas[ob + rho] * phi


@njit(**CALLER_JIT_OPTIONS)
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
    INLESO injection :math:`g(e)` of eq. (19) instead of the linear :math:`e`
    (:func:`inleso_injection`, then :func:`eso_update`).

    Parameters
    ----------
    xi_hat, d_xi_hat
        :math:`\hat\xi` and its derivative (written), ρ + 1 entries each.
    rho
        The order ρ.
    betas
        The ρ + 1 gains β.
    b0
        b₀.
    y, u
        The measurement and the command.
    improved
        The INLESO's injection instead of the linear one.
    k_alpha, k_beta, a, b
        The INLESO's constants (:func:`inleso_injection`).
    """
    e = y - xi_hat[0]
    if improved:
        e = inleso_injection(e, k_alpha, k_beta, a, b)
    eso_update(xi_hat, d_xi_hat, 0, rho, betas, 0, b0, u, e)
