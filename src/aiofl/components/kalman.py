r"""Kalman-optimal gains of the linear ESO: steady-state Kalman–Bucy and discrete Kalman filters.

The linear ESO (eqs. 5/16) is a Luenberger observer of the chain of integrators (6),

.. math::
    \dot\xi = A\xi + B b_0 u + G w,\qquad y = C\xi + v,

with A the (ρ+1)×(ρ+1) shift matrix, :math:`C = e_1^T` and the total disturbance's
derivative entering the extended state, :math:`G = e_{\rho+1}`.  If w and v are white
noises of intensities (power spectral densities) q and r, the observer gain that
minimises the steady-state estimation error covariance is the Kalman–Bucy gain
(Kalman & Bucy, "New results in linear filtering and prediction theory", J. Basic Eng.
83, 1961):

.. math::
    L = P C^T r^{-1},\qquad A P + P A^T - P C^T r^{-1} C P + G q G^T = 0

(the continuous algebraic Riccati equation, solved by
:func:`scipy.linalg.solve_continuous_are`).

**Butterworth property.**  With :math:`\omega = (q/r)^{1/(2\rho+2)}` the scaling
:math:`P_{ij} = r\,\omega^{i+j-1}\tilde P_{ij}` turns the equation into the one with
:math:`q = r = 1` (every term of entry (i, j) carries :math:`r\omega^{i+j}`), so
:math:`L_i = \omega^i \tilde P_{i1}`: the gains are :math:`\beta_i = \alpha_i\omega^i`
with :math:`\alpha_i = \tilde P_{i1}` independent of q and r, i.e. exactly the ESO's
bandwidth form with :math:`\omega_0 = (q/r)^{1/(2\rho+2)}`.  The return-difference
identity of the filter,
:math:`r\,|1 + C(sI - A)^{-1}L|^2 = r + q\,|C(sI - A)^{-1}G|^2` on the imaginary axis with
:math:`C(sI - A)^{-1}G = s^{-n}` (n = ρ+1), gives the observer's characteristic
polynomial D(s) as the stable factor of :math:`D(s)D(-s) = (-1)^n s^{2n} + \omega^{2n}`:
its roots are the Butterworth pattern :math:`s_k = \omega\,e^{i\pi(2k+n-1)/(2n)}`,
k = 1..n (Anderson & Moore, *Optimal Filtering*, 1979; the dual LQR result is in
Kwakernaak & Sivan, *Linear Optimal Control Systems*, 1972, Sec. 3.8): the α are the
coefficients of the normalised Butterworth polynomial of order ρ+1.
:func:`kalman_alphas` gets them from one Riccati solve (q = r = 1) per order;
:func:`continuous_kalman_gain` scales it.

**Sampled observer.**  The sampled ESO (:mod:`aiofl.components.discrete`) is the exact
ZOH model :math:`\xi_{k+1} = \Phi\xi_k + \Gamma u_k + w_k`, :math:`\Phi = e^{AT}`, in
current-observer form :math:`\hat\xi_k = p_k + L(y_k - p_{1,k})`,
:math:`p_{k+1} = \Phi\hat\xi_k + \Gamma u_k`.  The sampled process noise
:math:`w_k = \int_0^T e^{A(T-s)}G\,dw(s)` has covariance
:math:`Q_d = \int_0^T e^{As} G q G^T e^{A^Ts} ds` (:func:`discrete_process_noise`, by
Van Loan's method: Van Loan, "Computing integrals involving the matrix exponential",
IEEE Trans. Autom. Control 23(3), 1978), the measurement noise per sample has variance
:math:`R_d`.  The steady-state Kalman filter's a-priori covariance P solves the discrete
algebraic Riccati equation

.. math::
    P = \Phi P \Phi^T - \Phi P C^T (C P C^T + R_d)^{-1} C P \Phi^T + Q_d

(:func:`scipy.linalg.solve_discrete_are`), and its *current-estimate* (measurement
update) gain :math:`M = P C^T (C P C^T + R_d)^{-1}` is exactly the current observer's L;
the estimate's covariance is :math:`(I - MC)P` and the error map :math:`(I - MC)\Phi`
(Franklin, Powell & Workman, *Digital Control of Dynamic Systems*, 3rd ed., 1998,
Sec. 9.4).  :func:`control.dlqe` returns the predictor gain :math:`\Phi M` of the same P.

**Measurement noise intensity** (:func:`measurement_noise_intensity`): a Gaussian noise
of variance σ² held over h seconds has the low-frequency spectral density σ²h; sampled
every T it is a sequence of variance σ² (independent when h ≤ T), i.e. a held noise of
hold max(h, T); a quantiser of step Δ adds :math:`\Delta^2/12` per sample.
"""

from __future__ import annotations

import math
from functools import cache
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "butterworth_poles",
    "continuous_kalman_gain",
    "discrete_kalman_gain",
    "discrete_process_noise",
    "eso_kalman_observer",
    "kalman_alphas",
    "kalman_bandwidth",
    "kalman_gain_parameters",
    "measurement_noise_intensity",
    "noise_chain",
    "van_loan",
]


def noise_chain(rho: int) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    r"""The ESO's noise model: A the (ρ+1)×(ρ+1) shift matrix of the chain (6), the noise
    input :math:`G = e_{\rho+1}` (the derivative of the extended state) and the output
    :math:`C = e_1^T`; returns (A, G, C) as (n, n), (n, 1) and (1, n) arrays."""
    if rho < 1:
        raise ValueError(f"rho = {rho}; allowed: >= 1")
    n = rho + 1
    g = np.zeros((n, 1))
    g[rho, 0] = 1.0
    return np.eye(n, k=1), g, np.eye(1, n)


def _check_intensities(q: float, r: float, r_name: str = "r") -> None:
    for name, val in (("q", q), (r_name, r)):
        if not (math.isfinite(val) and val > 0):
            raise ValueError(f"controller.eso.{name} = {val}; allowed: finite and > 0")


def kalman_bandwidth(rho: int, q: float, r: float) -> float:
    r"""The radius :math:`\omega = (q/r)^{1/(2\rho+2)}` of the Kalman–Bucy observer's
    Butterworth poles: the ESO bandwidth :math:`\omega_0` of its gains (module notes).

    Parameters
    ----------
    rho
        The order ρ.
    q, r
        The process- and measurement-noise intensities, finite and > 0.

    Returns
    -------
    float
        ω [rad/s].
    """
    _check_intensities(q, r)
    # in logarithms: q/r itself may overflow (q = 1e300, r = 1e-300)
    return math.exp((math.log(q) - math.log(r)) / (2 * rho + 2))


@cache
def _normalised(rho: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(α, P̃) of the Riccati equation with q = r = 1 (one solve per order)."""
    from scipy.linalg import solve_continuous_are

    a, g, c = noise_chain(rho)
    # the filter Riccati equation is the control one of the dual pair (Aᵀ, Cᵀ)
    p = solve_continuous_are(a.T, c.T, g @ g.T, np.eye(1))
    p = 0.5 * (p + p.T)
    p.setflags(write=False)
    alphas = p[:, 0].copy()
    alphas.setflags(write=False)
    return alphas, p


def kalman_alphas(rho: int) -> NDArray[np.float64]:
    r"""The ESO's :math:`\alpha_i` of the Kalman–Bucy gains, i = 1..ρ+1: the first column
    of the Riccati solution for q = r = 1 (:func:`scipy.linalg.solve_continuous_are`),
    which are the coefficients of the normalised Butterworth polynomial of order ρ+1
    (e.g. :math:`\sqrt2, 1` for ρ = 1; :math:`2, 2, 1` for ρ = 2); the gains for any q, r
    are :math:`\beta_i = \alpha_i\omega_0^i`, :math:`\omega_0` from :func:`kalman_bandwidth`."""
    return _normalised(rho)[0].copy()


def kalman_gain_parameters(rho: int, q: float, r: float) -> tuple[NDArray[np.float64], float]:
    r"""The Kalman–Bucy gains of the ESO in its bandwidth form: returns
    :math:`(\alpha, \omega_0)` with :math:`\beta_i = \alpha_i\omega_0^i` the gain
    :func:`continuous_kalman_gain` computes (:func:`kalman_alphas`,
    :func:`kalman_bandwidth`).  ``ValueError`` naming ``controller.eso.q`` if q or r is not
    finite and positive, or if the gains overflow (:math:`\omega_0^{\rho+1} = \sqrt{q/r}`
    beyond the largest double).

    Parameters
    ----------
    rho, q, r
        As for :func:`kalman_bandwidth`.

    Returns
    -------
    alphas : ndarray
    omega0 : float
    """
    w0 = kalman_bandwidth(rho, q, r)
    alphas = kalman_alphas(rho)
    if (rho + 1) * math.log(w0) + math.log(float(np.max(alphas))) > 700.0:
        raise ValueError(
            f"controller.eso.q = {q:g} with eso.r = {r:g}: the Kalman gains "
            f"beta_i = alpha_i*omega0^i overflow (omega0 = (q/r)^(1/(2rho+2)) = {w0:.4g}); "
            "allowed: a smaller q/r"
        )
    return alphas, w0


def butterworth_poles(rho: int, omega: float) -> NDArray[np.complex128]:
    r"""The Butterworth pattern of order n = ρ+1 on the circle of radius ω:
    :math:`s_k = \omega\,e^{i\pi(2k + n - 1)/(2n)}`, k = 1..n (all in the open left half-plane)."""
    n = rho + 1
    k = np.arange(1, n + 1)
    return omega * np.exp(1j * np.pi * (2 * k + n - 1) / (2 * n))


def continuous_kalman_gain(
    rho: int, q: float, r: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    r"""Steady-state Kalman–Bucy gain of the ESO's chain: returns (L, P) with
    :math:`A P + P A^T - P C^T r^{-1} C P + G q G^T = 0`, :math:`L = P C^T/r` (module
    notes; what :func:`control.lqe` (A, G, C, q, r) returns).

    Solved once for q = r = 1 (:func:`scipy.linalg.solve_continuous_are`) and scaled,
    :math:`P_{ij} = r\,\omega^{i+j-1}\tilde P_{ij}`, :math:`L_i = \omega^i\tilde P_{i1}`,
    :math:`\omega = (q/r)^{1/(2\rho+2)}`: exact, and accurate for any ratio q/r (a direct
    solve of the unscaled equation has entries from r ω to r ω^{2ρ+1}).

    Parameters
    ----------
    rho, q, r
        As for :func:`kalman_bandwidth`.

    Returns
    -------
    L, P : ndarray
    """
    w = kalman_bandwidth(rho, q, r)
    _, p = _normalised(rho)
    powers = w ** np.arange(1, rho + 2, dtype=np.float64)
    pw = r * np.outer(powers, powers) / w * p
    return powers * p[:, 0], pw


def van_loan(
    a: ArrayLike, qc: ArrayLike, ts: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    r"""Van Loan's method (Van Loan 1978, Thm. 1): returns :math:`\Phi = e^{AT}` and
    :math:`Q_d = \int_0^T e^{As} Q_c e^{A^Ts} ds` from one exponential,

    .. math::
        \exp\left(\begin{bmatrix}-A & Q_c\\ 0 & A^T\end{bmatrix}T\right)
        = \begin{bmatrix}F_{11} & F_{12}\\ 0 & F_{22}\end{bmatrix},\qquad
        \Phi = F_{22}^T,\quad Q_d = F_{22}^T F_{12}.

    Parameters
    ----------
    a
        A (n × n).
    qc
        :math:`Q_c` (n × n).
    ts
        The sample time T [s].

    Returns
    -------
    Phi, Qd : ndarray
    """
    from scipy.linalg import expm

    a = np.asarray(a, dtype=np.float64)
    qc = np.asarray(qc, dtype=np.float64)
    n = a.shape[0]
    m = np.zeros((2 * n, 2 * n))
    m[:n, :n] = -a
    m[:n, n:] = qc
    m[n:, n:] = a.T
    f = expm(m * ts)
    phi = f[n:, n:].T
    qd = phi @ f[:n, n:]
    return phi, 0.5 * (qd + qd.T)


@cache
def _unit_process_noise(rho: int) -> NDArray[np.float64]:
    """Q̂ = ∫_0^1 e^{As} G Gᵀ e^{Aᵀs} ds of the chain (unit time, unit intensity)."""
    a, g, _ = noise_chain(rho)
    _, qd = van_loan(a, g @ g.T, 1.0)
    qd.setflags(write=False)
    return qd


def discrete_process_noise(rho: int, q: float, ts: float) -> NDArray[np.float64]:
    r"""Covariance of the ESO's sampled process noise,
    :math:`Q_d = \int_0^T e^{As} G q G^T e^{A^Ts} ds` (Van Loan's method, :func:`van_loan`).

    Taken in the scaled coordinates :math:`\tilde\xi_i = T^{i-1}\xi_i`, where the chain
    over one sample is the chain over unit time with intensity :math:`qT^{2\rho+1}`; so
    :math:`Q_{d,ij} = q\,T^{2\rho+3-i-j}\hat Q_{ij}` with :math:`\hat Q` Van Loan's integral
    over unit time (:math:`\hat Q_{ij} = 1/((n-i)!\,(n-j)!\,(2n+1-i-j))`, n = ρ+1): every
    entry keeps its relative precision for any T (cf. :func:`aiofl.components.discrete.zoh`).

    Parameters
    ----------
    rho
        The order ρ.
    q
        The process-noise intensity, finite and > 0.
    ts
        The sample time T [s] > 0.

    Returns
    -------
    ndarray
        :math:`Q_d`, (ρ + 1) × (ρ + 1).
    """
    if not (math.isfinite(q) and q > 0):
        raise ValueError(f"controller.eso.q = {q}; allowed: finite and > 0")
    if not (math.isfinite(ts) and ts > 0):
        raise ValueError(f"ts = {ts}; allowed: > 0")
    n = rho + 1
    k = np.arange(1, n + 1, dtype=np.float64)
    scale = ts ** (2 * n + 1 - k[:, None] - k[None, :])
    return q * scale * _unit_process_noise(rho)


def discrete_kalman_gain(
    rho: int, q: float, r_d: float, ts: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    r"""Steady-state Kalman gain of the sampled ESO in *current-estimate* form: returns
    (M, P) with P the a-priori covariance solving the discrete Riccati equation of the
    module notes on :math:`(\Phi = e^{AT}, C, Q_d, R_d)` and
    :math:`M = P C^T (C P C^T + R_d)^{-1}`, the gain L of the current observer
    :math:`\hat\xi_k = p_k + M(y_k - p_{1,k})` (:func:`control.dlqe` returns
    :math:`\Phi M`).

    ``q`` is the process-noise intensity, ``r_d`` the measurement noise variance per
    sample.  In units of :math:`R_d` the problem has one parameter,
    :math:`\lambda = qT^{2\rho+1}/R_d = h^{2\rho+2}` (:math:`h = \omega_0T` for
    :math:`R_d = r/T`, :math:`\omega_0` of :func:`kalman_bandwidth`).  It is solved
    (:func:`scipy.linalg.solve_discrete_are`) in the scaled coordinates
    :math:`\bar\xi_i = \tau^{i-1}\xi_i` with the time unit :math:`\tau = T/\min(h, 1)`
    (:math:`1/\omega_0` for :math:`h < 1`, T otherwise), where
    :math:`\bar\Phi = e^{A\min(h,1)}`, :math:`\bar Q_{d,ij} = \lambda
    \min(h,1)^{2-i-j}\hat Q_{ij}` (:func:`discrete_process_noise`) and the solution
    have entries of order one: the gains keep their relative precision down to
    :math:`h \approx 10^{-4}` (the unscaled equation loses it from
    :math:`h \approx 10^{-2}` at ρ = 4 and fails at large ρ).  Then
    :math:`M_i = \bar M_i/\tau^{i-1}`, :math:`P_{ij} = R_d\bar P_{ij}/\tau^{i+j-2}`.
    Raises ``ValueError`` if the solver finds no stabilising solution (h far above 1
    for a long chain).

    Parameters
    ----------
    rho
        The order ρ.
    q, r_d
        The process-noise intensity and the measurement variance per sample, finite, > 0.
    ts
        The sample time T [s] > 0.

    Returns
    -------
    M, P : ndarray
    """
    from numpy.linalg import LinAlgError
    from scipy.linalg import expm, solve_discrete_are

    for name, val in (("q", q), ("r", r_d), ("ts", ts)):
        if not (math.isfinite(val) and val > 0):
            raise ValueError(f"{name} = {val}; allowed: finite and > 0")
    n = rho + 1
    a, _, c = noise_chain(rho)
    log_lam = math.log(q) + (2 * n - 1) * math.log(ts) - math.log(r_d)
    log_s = min(log_lam / (2 * n), 0.0)  # log min(h, 1)
    k = np.arange(n, dtype=np.float64)
    qbar = np.exp(log_lam - log_s * (k[:, None] + k[None, :])) * _unit_process_noise(rho)
    phi_bar = np.triu(expm(a * math.exp(log_s)))
    try:
        p = solve_discrete_are(phi_bar.T, c.T, qbar, np.eye(1))
    except (LinAlgError, ValueError) as exc:
        raise ValueError(
            f"the discrete Riccati equation has no stabilising solution for q = {q:g}, "
            f"R_d = {r_d:g}, ts = {ts:g} (omega0*ts = {math.exp(log_lam / (2 * n)):.3g}): "
            f"{exc}; allowed: a smaller q/r or ts"
        ) from None
    p = 0.5 * (p + p.T)
    m = p[:, 0] / (p[0, 0] + 1.0)
    d = np.exp(k * (math.log(ts) - log_s))  # tau^(i-1)
    return m / d, r_d * p / np.outer(d, d)


def measurement_noise_intensity(scenario: Any, sampling: Any = None) -> float:
    r"""The measurement noise intensity r (spectral density, [y]²·s) a run's sensor gives.

    From ``scenario.noise_variance`` σ² and ``scenario.noise_hold`` h (Gaussian noise held
    over h seconds) and, for a sampled controller, ``sampling.ts`` T and
    ``sampling.y_quantum`` Δ:

    .. math::
        r = \sigma^2 h \ \text{(continuous)},\qquad
        r = \sigma^2\max(h, T) + \frac{\Delta^2}{12}T \ \text{(sampled)}.

    A held noise of variance σ² has the low-frequency spectral density σ²h.  Sampled every
    T, it is a sequence of variance σ² — independent samples when h ≤ T, i.e. a noise held
    over T — and a quantiser adds an independent :math:`\Delta^2/12` per sample (Widrow's
    model); the sampled observer's measurement variance per sample is then
    :math:`R_d = r/T` (:math:`= \sigma^2 + \Delta^2/12` for h ≤ T).  0 for an ideal sensor.
    """
    var = float(scenario.noise_variance)
    hold = float(scenario.noise_hold)
    if sampling is None:
        return var * hold
    ts = float(sampling.ts)
    yq = float(sampling.y_quantum)
    return var * max(hold, ts) + yq * yq / 12.0 * ts


def eso_kalman_observer(rho: int, q: float, r_d: float, b0: float, ts: float) -> Any:
    r"""The linear ESO discretised exactly (ZOH) in current-observer form with the
    steady-state Kalman gain: Φ, Φ − I, Γ of :func:`aiofl.components.discrete.zoh`,
    K = 0, L = M of :func:`discrete_kalman_gain` (q the process-noise intensity, ``r_d``
    the measurement variance per sample); a
    :class:`~aiofl.components.discrete.DiscreteESO`.

    Parameters
    ----------
    rho, q, r_d, ts
        As for :func:`discrete_kalman_gain`.
    b0
        The input gain b₀.

    Returns
    -------
    DiscreteESO
    """
    from aiofl.components.discrete import DiscreteESO, eso_chain, zoh

    a, b = eso_chain(rho)
    phi, dphi, gam = zoh(a, b * b0, ts)
    m, _ = discrete_kalman_gain(rho, q, r_d, ts)
    return DiscreteESO(np.triu(phi), np.triu(dphi), gam, np.zeros(rho + 1), m, "zoh")
