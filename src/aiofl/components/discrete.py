r"""Sampled-data (discrete-time) forms of the controller's dynamic components.

A processor runs the controller once per sample time :math:`T` (``ts``): at
:math:`t_k = kT` it reads :math:`y_k`, updates its states once and outputs :math:`u_k`,
held until :math:`t_{k+1}` (zero-order hold).  The static parts (fal, NLSEF, INLSEF,
linear SEF, the law (14), saturation) are the continuous formulas evaluated at the sample;
only the dynamic parts need a discretisation.  This module gives them, in two halves: the
*coefficients* (host side, numpy/scipy/python-control, computed once per design) and the
*update* that uses them (small compiled functions, called by the engine's sampled loop;
:mod:`aiofl.export` writes the same update in C with the same coefficients).

**ESO, one update form for every discretisation.**  With the predicted state
:math:`p_k`, the injected error :math:`\phi_k = \phi(y_k - p_{1,k})` (:math:`\phi(e) = e`
for the LESO, the INLESO's :math:`g(e)` of eq. (19)) and the plant input :math:`u_k`
applied over :math:`[t_k, t_{k+1})`,

.. math::
    \hat\xi_k = p_k + L\,\phi_k \quad\text{(correction: the estimate used at } t_k),\qquad
    p_{k+1} = \Phi\,\hat\xi_k + \Gamma u_k + K\phi_k \quad\text{(prediction)}.

* *Exact ZOH, current-observer form* (Miklosovic, Radke & Gao, "Discrete implementation
  and generalization of the extended state observer", ACC 2006): the ESO's model
  :math:`\dot\xi = A\xi + B b_0 u` (A the shift matrix of the chain (6), B the ρ-th unit
  vector) discretised exactly under a zero-order hold, :math:`\Phi = e^{AT}`,
  :math:`\Gamma = \int_0^T e^{As}\,ds\,B b_0`, :math:`K = 0`, and the current-observer
  gain L placing the eigenvalues of the estimation error map :math:`(I - LC)\Phi` at
  :math:`z_i = e^{s_i T}`, where :math:`s_i` are the continuous observer's poles (roots of
  :math:`s^{\rho+1} + \beta_1 s^\rho + \dots + \beta_{\rho+1}`).  With Gao's gains
  (:math:`\alpha_i = \binom{\rho+1}{i}`) all ρ+1 of them are :math:`e^{-\omega_0 T}`; for
  ρ = 1, 2 the gain is Miklosovic et al.'s closed form, e.g. for ρ = 1
  :math:`L = [1-\beta^2,\ (1-\beta)^2/T]^T`, :math:`\beta = e^{-\omega_0 T}` (also
  Herbst, "A simulative study on ADRC as a control tool for practitioners",
  Electronics 2013).  Linear ESO only.
* *Forward Euler* (what most firmware does), LESO and INLESO:
  :math:`\hat\xi_{k+1} = \hat\xi_k + T\big(A\hat\xi_k + B b_0 u_k + \beta\,\phi_k\big)`,
  i.e. :math:`\Phi = I + TA`, :math:`\Gamma = T b_0 B`, :math:`K = T\beta`, :math:`L = 0`;
  the linear error map :math:`I + T(A - \beta C)` has eigenvalues :math:`1 + T s_i`
  (:math:`1 - \omega_0 T`, ρ+1 times, with Gao's gains): unstable once
  :math:`\omega_0 T > 2`.

Both Φ are upper triangular (A is strictly upper triangular), which the update uses.  The
update is written in *delta form*, :math:`p^+ = \hat\xi + \big((\Phi - I)\hat\xi + \Gamma u +
K\phi\big)`, with the coefficients :math:`\Phi - I` computed without cancellation
(:func:`zoh`): the small increments are summed before they meet the large state, which in
single precision keeps the command about ten times closer to the double-precision one
(the same form serves the prefilter).  The first state is kept as its change since the
last measurement (:func:`observer_predict`), so the innovation :math:`y_k - p_{1,k}` is
formed from small numbers.

**Differentiators.**  Han's discrete time-optimal TD (Han, "From PID to active disturbance
rejection control", IEEE Trans. Ind. Electron. 56(3), 2009, Sec. III-A):
:math:`r_{1,k+1} = r_{1,k} + T r_{2,k}`,
:math:`r_{2,k+1} = r_{2,k} + T\,\mathrm{fhan}(r_{1,k} - r_k, r_{2,k}, R, h_0)` (:func:`fhan`);
forward Euler on eq. (18) and on the ITD (21); the linear prefilter
:math:`\omega^\rho/(s+\omega)^\rho` discretised exactly under a zero-order hold of r.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from aiofl.components.fastmath import CALLER_JIT_OPTIONS, sign
from aiofl.components.observers import binomial_alphas

__all__ = [
    "DiscreteESO",
    "current_observer_gain",
    "error_map",
    "eso_chain",
    "eso_continuous_poles",
    "eso_current_observer",
    "eso_discrete_poles",
    "eso_forward_euler",
    "eso_zoh",
    "fhan",
    "fhan_td_step",
    "linear_discrete_update",
    "linear_prefilter_zoh",
    "observer_correct",
    "observer_innovation",
    "observer_predict",
    "zoh",
]


# ------------------------------------------------------------------ coefficients (host)
@dataclass(frozen=True)
class DiscreteESO:
    r"""Coefficients of the discrete ESO update (see the module notes):
    :math:`\hat\xi = p + L\phi`, :math:`p^+ = \Phi\hat\xi + \Gamma u + K\phi`.

    ``phi`` is (ρ+1, ρ+1) upper triangular and ``dphi`` is :math:`\Phi - I` (computed
    without cancellation, for the delta-form update); ``gamma``, ``k`` and ``l`` have ρ+1
    entries; ``method`` is ``"zoh"`` or ``"euler"``.
    """

    phi: NDArray[np.float64]
    dphi: NDArray[np.float64]
    gamma: NDArray[np.float64]
    k: NDArray[np.float64]
    l: NDArray[np.float64]
    method: str

    def error_map(self) -> NDArray[np.float64]:
        """The linear ESO's estimation-error map (see :func:`error_map`)."""
        return error_map(self)


def eso_chain(rho: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    r"""The ESO's model, eq. (6): :math:`\dot\xi = A\xi + B\,(b_0u)`, A the (ρ+1)×(ρ+1)
    shift matrix (ones on the super-diagonal), B the ρ-th unit vector."""
    if rho < 1:
        raise ValueError(f"rho = {rho}; allowed: >= 1")
    n = rho + 1
    b = np.zeros(n)
    b[rho - 1] = 1.0
    return np.eye(n, k=1), b


def zoh(
    a: ArrayLike, b: ArrayLike, ts: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    r"""Exact zero-order-hold discretisation of :math:`\dot x = Ax + bw` (w held over a
    sample): returns :math:`\Phi = e^{AT}`, :math:`\Phi - I` and
    :math:`\Gamma = \int_0^T e^{As}\,ds\,b`.

    One exponential (:func:`scipy.linalg.expm`) of the augmented matrix
    :math:`\begin{bmatrix}AT & I & bT\\ 0 & 0 & 0\\ 0 & 0 & 0\end{bmatrix}`, whose top
    blocks are :math:`e^{AT}`, :math:`\Psi = \int_0^1 e^{ATs}ds` and :math:`\Psi bT = \Gamma`;
    :math:`\Phi - I = AT\,\Psi` then has no cancellation (:math:`e^{AT} - I` computed by
    subtraction loses the relative precision of entries near 0).

    The exponential is taken in the scaled coordinates :math:`\tilde x_i = T^{i-1}x_i`
    (and a scaled input), where a chain of integrators has entries of order 1 whatever T
    is; unscaling multiplies by powers of T exactly.  Unscaled (as
    :func:`scipy.signal.cont2discrete` does it) the entries :math:`T^j/j!` of a long chain
    lose their relative precision: at ρ = 8, T = 3 ms, :math:`T^8/8!` came out 40 % off.

    Parameters
    ----------
    a, b
        A (n × n) and b (n,).
    ts
        The sample time T [s].

    Returns
    -------
    Phi, Phi_minus_I, Gamma : ndarray
    """
    from scipy.linalg import expm

    a = np.asarray(a, dtype=np.float64)
    bv = np.asarray(b, dtype=np.float64).reshape(-1)
    n = a.shape[0]
    d = ts ** np.arange(n, dtype=np.float64)
    bt = bv * ts * d
    d_in = float(np.max(np.abs(bt))) or 1.0
    m_s = a * ts * d[:, None] / d[None, :]
    big = np.zeros((2 * n + 1, 2 * n + 1))
    big[:n, :n] = m_s
    big[:n, n : 2 * n] = np.eye(n)
    big[:n, 2 * n] = bt / d_in
    e = expm(big)
    unscale = d[None, :] / d[:, None]
    phi = e[:n, :n] * unscale
    dphi = (m_s @ e[:n, n : 2 * n]) * unscale
    return phi, dphi, e[:n, 2 * n] * d_in / d


def eso_zoh(rho: int, b0: float, ts: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    r"""Exact zero-order-hold discretisation of the ESO's model (6) (:func:`zoh`):
    :math:`\Phi = e^{AT}` (entries :math:`T^{j-i}/(j-i)!`), :math:`\Gamma = \int_0^T e^{As}
    ds\,B b_0` (:math:`b_0 T^{\rho-i+1}/(\rho-i+1)!` for i ≤ ρ, 0 for the extended state).

    Parameters
    ----------
    rho
        The order ρ (the observer has ρ + 1 states).
    b0
        The input gain b₀.
    ts
        The sample time T [s].

    Returns
    -------
    Phi, Gamma : ndarray
    """
    a, b = eso_chain(rho)
    phi, _, gam = zoh(a, b * b0, ts)
    return np.triu(phi), gam


def eso_continuous_poles(alphas: ArrayLike, omega0: float) -> NDArray[np.complex128]:
    r"""The continuous ESO's poles :math:`s_i = \omega_0\lambda_i`, :math:`\lambda_i` the roots
    of :math:`\lambda^{\rho+1} + \alpha_1\lambda^\rho + \dots + \alpha_{\rho+1}` (eq. 9 with
    :math:`\beta_i = \alpha_i\omega_0^i`).  Gao's binomial α give exactly :math:`-\omega_0`,
    ρ+1 times (no root finding)."""
    a = np.asarray(alphas, dtype=np.float64)
    rho = a.size - 1
    if rho >= 1 and np.allclose(a, binomial_alphas(rho), rtol=1e-12, atol=0.0):
        return np.full(rho + 1, -float(omega0), dtype=np.complex128)
    return (np.roots(np.r_[1.0, a]) * omega0).astype(np.complex128)


def eso_discrete_poles(alphas: ArrayLike, omega0: float, ts: float) -> NDArray[np.complex128]:
    r"""The discrete observer poles :math:`z_i = e^{s_i T}` of the continuous ESO's poles
    :math:`s_i` (:func:`eso_continuous_poles`): :math:`e^{-\omega_0 T}`, ρ+1 times, with
    Gao's gains.

    Parameters
    ----------
    alphas
        The ρ + 1 coefficients α.
    omega0
        ω₀ [rad/s].
    ts
        The sample time T [s].

    Returns
    -------
    ndarray
    """
    return np.exp(eso_continuous_poles(alphas, omega0) * ts)


def current_observer_gain(rho: int, ts: float, s_poles: ArrayLike) -> NDArray[np.float64]:
    r"""Current-observer gain L with :math:`\operatorname{eig}((I - LC)\Phi) = e^{s_i T}`,
    :math:`\Phi = e^{AT}` of the chain (6), :math:`C = [1, 0, \dots, 0]`, for the continuous
    poles ``s_poles``.

    Since :math:`(I - LC)\Phi` and :math:`\Phi - (\Phi L)C` have the same eigenvalues, the
    predictor gain :math:`L_p = \Phi L` is placed by Ackermann's formula
    (:func:`control.acker` on the dual pair) and :math:`L = \Phi^{-1}L_p`.  For accuracy at
    any :math:`\omega_0 T` this is done (a) in the scaled coordinates
    :math:`\tilde\xi_i = T^{i-1}\xi_i`, where :math:`\tilde\Phi_{ij} = 1/(j-i)!` does not
    depend on T, and (b) in delta form, placing the eigenvalues
    :math:`z_i - 1 = \operatorname{expm1}(s_i T)` of :math:`\tilde\Phi - I - L_pC` (the same
    L_p), so the small gains :math:`\tilde L_i \sim (1 - e^{-\omega_0 T})^i` keep their
    relative precision; then :math:`L_i = \tilde L_i / T^{i-1}`.

    Parameters
    ----------
    rho
        The order ρ.
    ts
        The sample time T [s].
    s_poles
        The ρ + 1 continuous poles.

    Returns
    -------
    ndarray
        L, ρ + 1 entries.
    """
    import control
    from scipy.linalg import expm

    n = rho + 1
    a, _ = eso_chain(rho)
    phi_s = np.triu(expm(a))  # scaled Φ: 1/(j-i)!
    c = np.eye(1, n)
    s = np.asarray(s_poles, dtype=np.complex128)
    if s.size != n:
        raise ValueError(f"{s.size} poles for an observer of order {n}")
    delta = np.expm1(s * ts)
    lp = np.asarray(control.acker((phi_s - np.eye(n)).T, c.T, delta), dtype=np.float64)
    l_scaled = np.linalg.solve(phi_s, lp.reshape(n))
    return l_scaled / ts ** np.arange(n)


def eso_current_observer(
    rho: int, alphas: ArrayLike, omega0: float, b0: float, ts: float
) -> DiscreteESO:
    """The linear ESO discretised exactly (ZOH) in current-observer form (Miklosovic et al.
    2006): Φ, Γ of :func:`eso_zoh`, K = 0, L of :func:`current_observer_gain` at the
    continuous poles :func:`eso_continuous_poles`.

    Parameters
    ----------
    rho, alphas, omega0, b0, ts
        ρ, the ρ + 1 coefficients α, ω₀ [rad/s], b₀ and T [s].

    Returns
    -------
    DiscreteESO
    """
    a, b = eso_chain(rho)
    phi, dphi, gam = zoh(a, b * b0, ts)
    l = current_observer_gain(rho, ts, eso_continuous_poles(alphas, omega0))
    return DiscreteESO(np.triu(phi), np.triu(dphi), gam, np.zeros(rho + 1), l, "zoh")


def eso_forward_euler(rho: int, betas: ArrayLike, b0: float, ts: float) -> DiscreteESO:
    r"""The ESO (5)/(16)/(19) by forward Euler: :math:`\Phi = I + TA`,
    :math:`\Gamma = T b_0 B`, :math:`K = T\beta`, :math:`L = 0` (see the module notes).

    Parameters
    ----------
    rho
        The order ρ.
    betas
        The ρ + 1 observer gains β.
    b0, ts
        b₀ and T [s].

    Returns
    -------
    DiscreteESO
    """
    a, b = eso_chain(rho)
    beta = np.asarray(betas, dtype=np.float64)
    if beta.size != rho + 1:
        raise ValueError(f"{beta.size} observer gains for an observer of order {rho + 1}")
    n = rho + 1
    return DiscreteESO(np.eye(n) + ts * a, ts * a, ts * b0 * b, ts * beta, np.zeros(n), "euler")


def error_map(eso: DiscreteESO) -> NDArray[np.float64]:
    r"""Estimation-error map of a *linear* discrete ESO: with :math:`\tilde p = \xi - p`
    (and :math:`\phi = C\tilde p`), :math:`\tilde p_{k+1} = (\Phi(I - LC) - KC)\,\tilde p_k`
    for a constant total disturbance.  Its eigenvalues are the discrete observer poles."""
    n = eso.phi.shape[0]
    c = np.eye(1, n)
    return eso.phi @ (np.eye(n) - np.outer(eso.l, c)) - np.outer(eso.k, c)


def linear_prefilter_zoh(
    rho: int, omega: float, ts: float, *, delta: bool = False
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    r"""The linear prefilter :math:`\omega^\rho/(s+\omega)^\rho` in the controllable form of
    :func:`aiofl.components.differentiators.linear_prefilter_update`, discretised exactly
    under a zero-order hold of r (:func:`zoh`): returns :math:`(\Phi, \Gamma)` with
    :math:`r_{k+1} = \Phi r_k + \Gamma r(t_k)`, or :math:`(\Phi - I, \Gamma)` with
    ``delta``.

    Parameters
    ----------
    rho, omega, ts
        The order ρ, the bandwidth ω [rad/s] and T [s].
    delta
        Return Φ − I instead of Φ.

    Returns
    -------
    Phi, Gamma : ndarray
    """
    from aiofl.components.differentiators import linear_prefilter_coefficients

    c = linear_prefilter_coefficients(rho, omega)
    a = np.eye(rho, k=1)
    a[rho - 1, :] = -c
    b = np.zeros(rho)
    b[rho - 1] = c[0]
    phi, dphi, gam = zoh(a, b, ts)
    return (dphi if delta else phi), gam


# ------------------------------------------------------------------ updates (compiled)
@njit(**CALLER_JIT_OPTIONS)
def fhan(x1: float, x2: float, r: float, h: float) -> float:
    r"""Han's time-optimal synthesis function fhan (Han 2009, Sec. III-A).

    With :math:`d = rh`, :math:`d_0 = hd`, :math:`y = x_1 + hx_2`,
    :math:`a_0 = \sqrt{d^2 + 8r|y|}`,

    .. math::
        a = \begin{cases} x_2 + \tfrac12(a_0 - d)\operatorname{sign}(y) & |y| > d_0\\
            x_2 + y/h & |y| \le d_0\end{cases},\qquad
        \mathrm{fhan} = \begin{cases} -r\operatorname{sign}(a) & |a| > d\\ -r\,a/d & |a|\le d
        \end{cases}

    the form of Han's book; Han (2009) prints the same function branch-free,
    :math:`d = rh^2`, :math:`a_0 = hx_2`, :math:`y = x_1 + a_0`,
    :math:`a_1 = \sqrt{d(d + 8|y|)}`, :math:`a_2 = a_0 + \operatorname{sign}(y)(a_1-d)/2`,
    :math:`a = (a_0 + y)\,\mathrm{fsg}(y,d) + a_2(1 - \mathrm{fsg}(y,d))`,
    :math:`\mathrm{fhan} = -r(a/d)\,\mathrm{fsg}(a,d)
    - r\operatorname{sign}(a)(1-\mathrm{fsg}(a,d))`,
    :math:`\mathrm{fsg}(x,d) = (\operatorname{sign}(x+d) - \operatorname{sign}(x-d))/2`
    (h times this a; the tests check both agree).  r is the speed factor (``td.R``), h the
    filter factor :math:`h_0`.

    Parameters
    ----------
    x1, x2
        The position error and the velocity.
    r
        The speed factor R.
    h
        The filter factor :math:`h_0` > 0.

    Returns
    -------
    float
    """
    d = r * h
    d0 = h * d
    y = x1 + h * x2
    ay = abs(y)
    a = x2 + 0.5 * (math.sqrt(d * d + 8.0 * r * ay) - d) * sign(y) if ay > d0 else x2 + y / h
    if abs(a) > d:
        return -r * sign(a)
    return -r * a / d


@njit(**CALLER_JIT_OPTIONS)
def fhan_td_step(
    r1: float, r2: float, r: float, big_r: float, ts: float, h0: float
) -> tuple[float, float]:
    r"""One sample of Han's discrete TD (Han 2009, Sec. III-A):
    :math:`r_1^+ = r_1 + T r_2`, :math:`r_2^+ = r_2 + T\,\mathrm{fhan}(r_1 - r, r_2, R, h_0)`.

    Parameters
    ----------
    r1, r2
        The TD's states.
    r
        The reference at the sample.
    big_r, ts, h0
        R, the sample time T [s] and :math:`h_0`.

    Returns
    -------
    tuple of (float, float)
        :math:`(r_1^+, r_2^+)`.
    """
    fh = fhan(r1 - r, r2, big_r, h0)
    return r1 + ts * r2, r2 + ts * fh


@njit(inline="always", **CALLER_JIT_OPTIONS)  # inlined where called: no array arguments
def observer_innovation(state: NDArray[np.float64], o_p: int, o_y: int, y: float) -> float:
    r"""The innovation :math:`e_k = y_k - p_{1,k}` in increment form,
    :math:`e_k = (y_k - y_{k-1}) - q_k` with :math:`q_k = p_{1,k} - y_{k-1}` at
    ``state[o_p]`` and :math:`y_{k-1}` at ``state[o_y]`` (see :func:`observer_predict`).

    Parameters
    ----------
    state
        The engine's state vector.
    o_p, o_y
        The offsets of :math:`q_k` and :math:`y_{k-1}`.
    y
        :math:`y_k`.

    Returns
    -------
    float
    """
    return (y - state[o_y]) - state[o_p]


@njit(inline="always", **CALLER_JIT_OPTIONS)  # inlined where called: no array arguments
def observer_correct(
    state: NDArray[np.float64],
    o_p: int,
    o_x: int,
    n: int,
    coef: NDArray[np.float64],
    o_l: int,
    y: float,
    e: float,
    phi: float,
) -> float:
    r"""Correction :math:`\hat\xi = p + L\phi`, with :math:`\hat\xi_1 = y_k + d_k`,
    :math:`d_k = L_1\phi_k - e_k` (:math:`= \hat\xi_1 - y_k`, returned): :math:`p_i` at
    ``state[o_p + i]`` (i ≥ 1), :math:`\hat\xi_i` to ``state[o_x + i]``, :math:`L_i` at
    ``coef[o_l + i]``, i < n.

    Parameters
    ----------
    state
        The engine's state vector.
    o_p, o_x
        The offsets of p and of :math:`\hat\xi`.
    n
        The observer's order ρ + 1.
    coef, o_l
        The coefficients and the offset of :math:`L_1`.
    y, e
        :math:`y_k` and the innovation :math:`e_k`.
    phi
        φ: the innovation the gain acts on (:math:`e_k`, or a nonlinear function of it).

    Returns
    -------
    float
        :math:`d_k`.
    """
    d = coef[o_l] * phi - e
    state[o_x] = y + d
    for i in range(1, n):
        state[o_x + i] = state[o_p + i] + coef[o_l + i] * phi
    return d


@njit(inline="always", **CALLER_JIT_OPTIONS)  # inlined where called: no array arguments
def observer_predict(
    state: NDArray[np.float64],
    o_p: int,
    o_x: int,
    o_y: int,
    n: int,
    coef: NDArray[np.float64],
    o_phi: int,
    stride: int,
    o_g: int,
    o_k: int,
    u: float,
    phi: float,
    y: float,
    d: float,
) -> None:
    r"""Prediction in delta and increment form: with
    :math:`\Delta_i = ((\Phi - I)\hat\xi + \Gamma u + K\phi)_i` (Φ upper triangular),
    :math:`p^+_i = \hat\xi_i + \Delta_i` for i ≥ 2 and, for the first state, its change
    since the measurement, :math:`q^+ = p^+_1 - y_k = d_k + \Delta_1`
    (:func:`observer_correct`); then :math:`y_k` is kept for the next innovation.

    :math:`(\Phi - I)_{ij}` at ``coef[o_phi + i*stride + j]``, :math:`\Gamma_i`,
    :math:`K_i` at ``coef[o_g + i]``, ``coef[o_k + i]``; reads :math:`\hat\xi` at
    ``state[o_x:]``, writes q, p_2.. at ``state[o_p:]`` and :math:`y_k` at ``state[o_y]``.
    Only small quantities meet in the innovation, so the observer does not lose the
    precision of :math:`\hat\xi_1 \approx y` (one unit in the last place of y, amplified
    by the gains :math:`L_i \sim T^{1-i}`, was the largest error of single-precision code).

    Parameters
    ----------
    state, coef
        The engine's state vector and coefficients.
    o_p, o_x, o_y
        The offsets of p (q first), :math:`\hat\xi` and :math:`y_k` in ``state``.
    n
        The observer's order ρ + 1.
    o_phi, stride, o_g, o_k
        The offsets of Φ − I (row stride ``stride``), Γ and K in ``coef``.
    u
        The command :math:`u_k`.
    phi
        φ of the innovation (as for :func:`observer_correct`).
    y
        :math:`y_k`.
    d
        :math:`d_k` of :func:`observer_correct`.
    """
    for i in range(n):
        acc = coef[o_g + i] * u + coef[o_k + i] * phi
        for j in range(i, n):
            acc += coef[o_phi + i * stride + j] * state[o_x + j]
        state[o_p + i] = (d if i == 0 else state[o_x + i]) + acc
    state[o_y] = y


@njit(inline="always", **CALLER_JIT_OPTIONS)  # inlined where called: no array arguments
def linear_discrete_update(
    state: NDArray[np.float64],
    o: int,
    n: int,
    coef: NDArray[np.float64],
    o_phi: int,
    stride: int,
    o_g: int,
    w: float,
    scratch: NDArray[np.float64],
    o_s: int,
) -> None:
    r"""A linear discrete state update in delta form, :math:`s^+ = s + ((\Phi - I)s +
    \Gamma w)` (full Φ), in place: s at ``state[o:o+n]``, :math:`(\Phi - I)_{ij}` at
    ``coef[o_phi + i*stride + j]``, :math:`\Gamma_i` at ``coef[o_g + i]``;
    ``scratch[o_s:o_s+n]`` holds the new state until all of it is computed.

    Parameters
    ----------
    state, o, n
        The engine's state vector, the offset of s and its length n.
    coef, o_phi, stride, o_g
        The coefficients, the offsets of Φ − I (row stride ``stride``) and of Γ.
    w
        The held input.
    scratch, o_s
        A scratch vector and the offset of the n entries used.
    """
    for i in range(n):
        acc = coef[o_g + i] * w
        for j in range(n):
            acc += coef[o_phi + i * stride + j] * state[o + j]
        scratch[o_s + i] = state[o + i] + acc
    for i in range(n):
        state[o + i] = scratch[o_s + i]
