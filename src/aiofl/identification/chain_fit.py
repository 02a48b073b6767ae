r"""The output-error fit of one chain-plus-delay model to a log (the model-free route's engine).

The model, for a chain order ρ, is the continuous-time process model

.. math::
    y^{(\rho)} + a_{\rho-1}y^{(\rho-1)} + \dots + a_0 y = b_0\,u(t-\tau) + c
    \;[-\;F_c\,\sigma(t)],

with u held over each sample (zero-order hold), a constant c (gravity, an offset) and,
optionally, a Coulomb-friction-like term :math:`F_c\sigma(t)`, :math:`\sigma =
\operatorname{sign}(\dot y)` read from the log (:func:`velocity_sign`).  Its output is fitted
to the measured y by least squares on the *simulation* (output) error — the
prediction-error method with an output-error noise model (Ljung, *System Identification:
Theory for the User*, 2nd ed., 1999, Secs. 4.2, 7.3; what MATLAB's ``procest`` does for a
process model with a transport delay).  For white output noise this is the maximum-likelihood
estimate, the one the SRIVC iterations converge to (Young & Jakeman, "Refined instrumental
variable methods of recursive time-series analysis, Part III: extensions", Int. J. Control
31, 1980; Garnier & Wang (eds.), *Identification of Continuous-time Models from Sampled
Data*, Springer 2008, ch. 4), without SRIVC's need of a stable prefilter 1/A(p) (a chain of
integrators has none).

**Exact sampling.**  Time is measured in samples (:math:`T = 1`; :math:`a'_i = a_iT^{\rho-i}`,
:math:`b'_0 = b_0T^\rho`), where a chain's matrices have entries of order one.  The state
:math:`x = (y, \dot y, \dots)` with the companion matrix A is sampled exactly under the
delayed zero-order hold: with :math:`\tau = (d + f)T`, :math:`0 \le f < 1`, the input over
:math:`[t_k, t_{k+1})` is :math:`u_{k-d-1}` for fT then :math:`u_{k-d}`, so
:math:`x_{k+1} = \Phi x_k + \Phi_2\Gamma_f u_{k-d-1} + \Gamma_{1-f}u_{k-d} + \Gamma_1 c`,
:math:`\Phi_2 = e^{A(1-f)T}`, :math:`\Gamma_h = \int_0^{hT}e^{As}ds\,e_\rho` (Åström &
Wittenmark, *Computer-Controlled Systems*, 3rd ed., 1997, Sec. 2.3, sampling a system
with a time delay; the exponentials by :func:`aiofl.components.discrete.zoh`, delta form).
The recursion runs compiled (:func:`_responses`); a direct-form filter would move a
cluster of ρ poles near z = 1 by :math:`\epsilon^{1/\rho}`.

**Variable projection.**  The output is linear in :math:`b'_0`, c, :math:`F_c` and the
initial state (the free responses of the ρ unit initial states); for given nonlinear
parameters :math:`\theta = (a', \tau)` they are solved by linear least squares and
:func:`scipy.optimize.least_squares` minimises the projected residual over θ alone (Golub &
Pereyra, "The differentiation of pseudo-inverses and nonlinear least squares problems whose
variables separate", SIAM J. Numer. Anal. 10, 1973).

**Covariance.**  At the optimum the full parameter vector :math:`p = (\theta, \beta)` has
the least-squares covariance :math:`\hat P = \hat\sigma^2 (J^TJ)^{-1}`,
:math:`\hat\sigma^2 = \mathrm{RSS}/(N - n_p)`, J the Jacobian of the simulated output
(Ljung 1999, eq. 9.17 for output-error models), when the output error is white.  A
quantised, slowly moving output leaves a *correlated* residual (a sawtooth of the encoder
step), and that formula then gave intervals several times too short (b0 4.5 σ off on a
fourth-order chain with a 12-bit encoder); so the covariance used is Newey & West's
heteroskedasticity-and-autocorrelation-consistent sandwich (:func:`_hac_covariance`),
which reduces to the formula above for white residuals.  The stated assumption: the output
error is stationary and correlated over at most :data:`MAX_HAC_LAG` samples (sensor noise,
quantisation), not unmodelled dynamics, which make every interval too short.  The delay
search allows down to one sample of negative delay so that a plant without delay has its
optimum inside the search box (the reported delay is clipped at 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray
from scipy.optimize import least_squares

from aiofl.components.discrete import zoh

__all__ = ["POLE_MAX", "ChainFit", "fit_chain", "velocity_sign"]

#: the fastest pole a fit may place, in rad per sample (|λ| T); π would be Nyquist
POLE_MAX = 1.0
#: most residual evaluations of one fit's local search
MAX_NFEV = 50
#: longest residual correlation the covariance allows for (samples)
MAX_HAC_LAG = 200


@njit(cache=True, fastmath=True)
def _responses(
    dphi: NDArray[np.float64],
    g_prev: NDArray[np.float64],
    g_cur: NDArray[np.float64],
    g_c: NDArray[np.float64],
    u: NDArray[np.float64],
    w: NDArray[np.float64],
    d: int,
    k0: int,
    use_w: bool,
) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """Outputs y_k, k = k0..N-1, of the sampled chain from x_{k0} for the columns: the
    delayed input u, the constant 1, the undelayed extra input w (friction; zeros unless
    ``use_w``), and the free responses of the unit initial states."""
    n = dphi.shape[0]
    m = n + 3
    big_n = u.shape[0]
    x = np.zeros((m, n))  # one row per column's state
    for j in range(n):
        x[3 + j, j] = 1.0
    out = np.zeros((big_n - k0, m))
    step = np.empty(n)
    for k in range(k0, big_n):
        for j in range(m):
            out[k - k0, j] = x[j, 0]
        if k == big_n - 1:
            break
        u1 = u[k - d - 1] if k - d - 1 >= 0 else 0.0
        u0 = u[k - d] if k - d >= 0 else 0.0
        for j in range(m):
            if j == 2 and not use_w:
                continue
            if j == 0:
                for i in range(n):
                    step[i] = g_prev[i] * u1 + g_cur[i] * u0
            elif j == 1:
                for i in range(n):
                    step[i] = g_c[i]
            elif j == 2:
                for i in range(n):
                    step[i] = g_c[i] * w[k]
            else:
                for i in range(n):
                    step[i] = 0.0
            for i in range(n):
                acc = step[i]
                for l in range(n):
                    acc += dphi[i, l] * x[j, l]
                step[i] = acc
            for i in range(n):
                x[j, i] += step[i]
    return out


def velocity_sign(y: NDArray[np.float64], width: int) -> NDArray[np.float64]:
    r"""sign(ẏ) from the log: the slope of a centred least-squares line over ``2·width + 1``
    samples (a Savitzky–Golay first derivative, :func:`scipy.signal.savgol_filter`), 0 where
    it is below the slope a quantisation step over the window would give."""
    from scipy.signal import savgol_filter

    win = 2 * width + 1
    if y.shape[0] < win + 2:
        return np.zeros_like(y)
    slope = savgol_filter(y, win, 1, deriv=1)
    steps = np.diff(y)
    q = float(np.min(np.abs(steps[steps != 0]))) if np.any(steps != 0) else 0.0
    return np.where(np.abs(slope) > q / win, np.sign(slope), 0.0)


@dataclass(frozen=True)
class ChainFit:
    r"""One fitted chain-plus-delay model (times in seconds, the log's units).

    ``a`` are :math:`a_0 \dots a_{\rho-1}`; ``y_model`` the simulated output on samples
    ``k0..N-1``; ``n_params`` counts every fitted parameter (a, τ, b0, c, F_c, the initial
    state); ``nfev`` the local search's residual evaluations.
    """

    rho: int
    a: tuple[float, ...]
    b0: float
    b0_std: float
    c: float
    friction: float
    delay: float
    delay_std: float
    rss: float
    n_fit: int
    n_params: int
    k0: int
    y_model: NDArray[np.float64]
    nfev: int


def _sampled(a_s: NDArray[np.float64], tau_s: float) -> tuple[NDArray[np.float64], ...]:
    """Φ - I and the input vectors of the scaled chain (T = 1) with companion coefficients
    ``a_s`` and delay ``tau_s`` samples: (dphi, g_prev, g_cur, g_c, d)."""
    rho = a_s.shape[0]
    a_mat = np.eye(rho, k=1)
    a_mat[-1, :] = -a_s
    e = np.zeros(rho)
    e[-1] = 1.0
    _phi, dphi, g_c = zoh(a_mat, e, 1.0)
    d = math.floor(tau_s + 1e-12)
    f = tau_s - d
    if f <= 1e-9:
        return dphi, np.zeros(rho), g_c, g_c, np.array([d])
    phi2, _, g_cur = zoh(a_mat, e, 1.0 - f)
    _, _, g_f = zoh(a_mat, e, f)
    return dphi, phi2 @ g_f, g_cur, g_c, np.array([d])


def _lstsq(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Least squares for a tall, thin ``a`` with columns of unit norm: the normal equations
    by Cholesky (a few columns, ten thousand rows: ten times faster than an orthogonal
    factorisation), LAPACK's ``gelsy`` when they are numerically singular."""
    from scipy.linalg import LinAlgError, cho_factor, cho_solve, lstsq

    gram = a.T @ a
    if np.linalg.cond(gram) < 1e12:
        try:
            return np.asarray(cho_solve(cho_factor(gram), a.T @ b))
        except LinAlgError:
            pass
    return np.asarray(lstsq(a, b, lapack_driver="gelsy", check_finite=False)[0])


class _ChainResidual:
    """The variable-projection residual of one order on one log (scaled units): θ =
    (a'/scales, τ/T)."""

    def __init__(
        self,
        y: NDArray[np.float64],
        u: NDArray[np.float64],
        rho: int,
        k0: int,
        w: NDArray[np.float64] | None,
        scales: NDArray[np.float64],
    ) -> None:
        self.y, self.u, self.rho, self.k0, self.scales = y, u, rho, k0, scales
        self.w = np.zeros_like(u) if w is None else w
        self.use_w = w is not None
        self.target = y[k0:]
        # columns: u, 1, (w), free responses
        self.cols = [0, 1] + ([2] if self.use_w else []) + list(range(3, 3 + rho))
        self.scale = max(float(np.std(self.target)), 1e-300)

    def columns(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        a_s, tau = theta[: self.rho] * self.scales, float(theta[self.rho])
        dphi, g_prev, g_cur, g_c, d = _sampled(a_s, tau)
        out = _responses(dphi, g_prev, g_cur, g_c, self.u, self.w, int(d[0]), self.k0, self.use_w)
        return out[:, self.cols]

    def solve(self, theta: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The columns' least-squares weights and the model output for θ."""
        cols = self.columns(theta)
        with np.errstate(over="ignore", invalid="ignore"):  # an unstable trial's columns
            norms = np.linalg.norm(cols, axis=0)
        if not np.all(np.isfinite(norms)):
            return np.full(cols.shape[1], np.nan), np.full(self.target.shape, np.nan)
        norms[norms == 0] = 1.0
        beta = _lstsq(cols / norms, self.target)
        beta = beta / norms
        return beta, cols @ beta

    def residual(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        _, model = self.solve(theta)
        r = (self.target - model) / self.scale
        if not np.all(np.isfinite(r)):  # an unstable trial: far worse than any fit
            return np.full_like(self.target, 1e6)
        return r


def _stable_start(a_s: NDArray[np.float64], n_fit: int) -> NDArray[np.float64]:
    """``a_s`` with its roots' real parts capped so e^{λN} stays finite (an equation-error
    start can be wildly unstable)."""
    roots = np.roots(np.r_[1.0, a_s[::-1]])
    cap = 5.0 / max(n_fit, 1)
    roots = np.where(roots.real > cap, -roots.real + 1j * roots.imag, roots)
    return np.real(np.poly(roots))[1:][::-1].copy()


def _svf_starts(
    y: NDArray[np.float64],
    u: NDArray[np.float64],
    rho: int,
    lam: float,
    delays: NDArray[np.int64],
    k0: int,
) -> tuple[NDArray[np.float64], int]:
    """Equation-error (LSSVF) start ``(a', d)`` with the filter (λ/(s+λ))^ρ, Tustin-sampled
    first-order sections, the whole-sample delay d of ``delays`` with the least equation
    error (Garnier, Mensler & Richard, "Continuous-time model identification from sampled
    data: implementation issues and performance evaluation", Int. J. Control 76, 2003).
    The filter is linear and time-invariant, so the filtered delayed input is the delayed
    filtered input."""
    from scipy.signal import lfilter

    c1 = lam / 2.0
    low = ([c1, c1], [1.0 + c1, -(1.0 - c1)])  # λ/(s+λ)
    high = ([1.0, -1.0], [1.0 + c1, -(1.0 - c1)])  # s/(s+λ)

    def filt(x: NDArray[np.float64], i: int) -> NDArray[np.float64]:
        # s^i λ^(ρ-i) / (s+λ)^ρ applied to x
        out = x
        for _ in range(rho - i):
            out = lfilter(*low, out)
        for _ in range(i):
            out = lfilter(*high, out)
        return out

    # every term carries λ^ρ/(s+λ)^ρ: z_i = s^i λ^ρ/(s+λ)^ρ y
    yf = [filt(y - y[0], i) * lam**i for i in range(rho + 1)]
    uf = filt(u, 0)
    cf = filt(np.ones_like(y), 0)
    # the normal equations of [-z_0 .. -z_{ρ-1}, 1_f, u_f(k - d)]: only the last column
    # moves with d, so the Gram matrix is updated, not rebuilt
    fixed = np.column_stack([-yf[i] for i in range(rho)] + [cf])[k0:]
    target = yf[rho][k0:]
    norm = np.linalg.norm(fixed, axis=0)
    norm[norm == 0] = 1.0
    fixed = fixed / norm
    gram = np.zeros((rho + 2, rho + 2))
    gram[: rho + 1, : rho + 1] = fixed.T @ fixed
    rhs = np.zeros(rho + 2)
    rhs[: rho + 1] = fixed.T @ target
    tt = float(target @ target)
    best: tuple[float, NDArray[np.float64], int] | None = None
    for d in delays:
        col = uf[k0 - int(d) : uf.shape[0] - int(d)]
        cn = float(np.linalg.norm(col)) or 1.0
        col = col / cn
        gram[rho + 1, : rho + 1] = gram[: rho + 1, rho + 1] = fixed.T @ col
        gram[rho + 1, rho + 1] = 1.0
        rhs[rho + 1] = col @ target
        coef = np.linalg.lstsq(gram, rhs, rcond=1e-12)[0]
        cost = tt - float(coef @ rhs)  # the residual's sum of squares at the LS solution
        if best is None or cost < best[0]:
            best = (cost, coef[:rho] / norm[:rho], int(d))
    assert best is not None
    return best[1], best[2]


def _hac_lag(res: NDArray[np.float64]) -> int:
    """The bandwidth of :func:`_hac_covariance`: the first lag whose residual
    autocorrelation is inside the 95 % band ±1.96/√N of white noise, at most
    :data:`MAX_HAC_LAG` (0 for white residuals)."""
    n = res.shape[0]
    r = res - res.mean()
    spec = np.fft.rfft(r, 2 * n)
    acf = np.fft.irfft(spec * np.conj(spec))[: MAX_HAC_LAG + 2]
    acf = acf / acf[0] if acf[0] > 0 else acf
    inside = np.flatnonzero(np.abs(acf[1:]) < 1.96 / math.sqrt(n))
    return int(inside[0]) if inside.size else MAX_HAC_LAG


def _hac_covariance(
    jac: NDArray[np.float64], res: NDArray[np.float64], n_params: int
) -> NDArray[np.float64]:
    r"""The least-squares covariance, robust to correlated residuals: Newey & West's
    estimator (Econometrica 55, 1987) :math:`(J^TJ)^{-1}\hat S(J^TJ)^{-1}`,
    :math:`\hat S = \sum_{|l|\le L}(1 - |l|/(L+1))\sum_k J_k r_k r_{k+l}J_{k+l}^T`
    (Bartlett weights), scaled by N/(N - n_p).  With L = 0 it is White's
    heteroskedasticity-consistent sandwich; for white residuals of constant variance it
    tends to :math:`\hat\sigma^2(J^TJ)^{-1}`.  Quantisation of a slowly moving output makes
    the residual a correlated sawtooth, which the plain formula would take for white
    noise (too short intervals); L is the residual's correlation length (:func:`_hac_lag`)."""
    n = jac.shape[0]
    norm = np.linalg.norm(jac, axis=0)
    norm[norm == 0] = 1.0
    js = jac / norm
    bread = np.linalg.pinv(js.T @ js)
    score = js * res[:, None]
    lag = _hac_lag(res)
    meat = score.T @ score
    for l in range(1, lag + 1):
        g = score[l:].T @ score[:-l]
        meat += (1.0 - l / (lag + 1.0)) * (g + g.T)
    cov = bread @ meat @ bread * (n / max(n - n_params, 1))
    return cov / np.outer(norm, norm)


def _scales(a_s: NDArray[np.float64], n_fit: int) -> NDArray[np.float64]:
    """Scales of ``a'`` that make the fitted parameters of order one: the coefficients of
    (s + ω)^ρ, ω the start's largest pole magnitude clipped to [10/N, POLE_MAX] (finite
    differences and trust regions then step sensibly in every coefficient)."""
    rho = a_s.shape[0]
    roots = np.roots(np.r_[1.0, a_s[::-1]])
    omega = float(np.clip(np.max(np.abs(roots)) if roots.size else 0.0, 10.0 / n_fit, POLE_MAX))
    return np.array([math.comb(rho, i) * omega ** (rho - i) for i in range(rho)])


def fit_chain(
    y: NDArray[np.float64],
    u: NDArray[np.float64],
    ts: float,
    rho: int,
    *,
    delay_max: float,
    friction: NDArray[np.float64] | None = None,
) -> ChainFit:
    r"""Fit the order-``rho`` chain-plus-delay model to ``(u, y)`` (module notes).

    Parameters
    ----------
    y, u
        Output and input samples (uniform, ``ts`` apart; u held over each sample).
    rho
        The chain order.
    delay_max
        The largest input delay tried [s] (the first ``ceil(delay_max/ts) + 1`` samples only
        feed the delayed input).  The search also allows down to one sample of negative
        delay, so that a plant without delay has its estimate inside the search interval
        (its intervals are then the usual ones); the reported delay is clipped at 0.
    friction
        :math:`-\sigma(t)` samples to include a Coulomb-friction-like term, or None.

    ts
        The sample time [s].

    Returns
    -------
    ChainFit
    """
    tau_max = delay_max / ts
    k0 = math.ceil(tau_max) + 1
    n_fit = y.shape[0] - k0
    # the poles a sampled log can resolve: |λ| <= POLE_MAX/T, so |a'_i| <= C(ρ,i) POLE_MAX^(ρ-i)
    # (a higher order's extra pole otherwise runs off to infinity, where it is a delay)
    box = np.array([math.comb(rho, i) * POLE_MAX ** (rho - i) for i in range(rho)])
    # starts: equation-error fits for a few filter bandwidths (each with its best whole-sample
    # delay); the best of them by the output error
    unit = _ChainResidual(y, u, rho, k0, friction, np.ones(rho))
    best: tuple[float, NDArray[np.float64]] | None = None
    delays = np.arange(0, k0, dtype=np.int64)
    for lam in (0.3, 0.1, 0.03, 0.01):
        a_ee, d = _svf_starts(y, u, rho, lam, delays, k0)
        theta = np.r_[np.clip(_stable_start(a_ee, n_fit), -box, box), min(d, tau_max)]
        cost = float(np.sum(unit.residual(theta) ** 2))
        if best is None or cost < best[0]:
            best = (cost, theta)
    assert best is not None
    scales = _scales(best[1][:rho], n_fit)
    prob = _ChainResidual(y, u, rho, k0, friction, scales)
    theta0 = np.r_[best[1][:rho] / scales, best[1][rho]]
    lower = np.r_[-box / scales, -1.0 + 1e-6]
    upper = np.r_[box / scales, max(tau_max, 1e-6)]
    sol = least_squares(
        prob.residual,
        np.clip(theta0, lower, upper),
        bounds=(lower, upper),
        x_scale="jac",
        method="trf",
        ftol=1e-8,
        xtol=1e-8,
        max_nfev=MAX_NFEV,
    )
    theta = sol.x
    beta, model = prob.solve(theta)
    rss = float(np.sum((prob.target - model) ** 2))
    # the full Jacobian of the simulated output at the optimum: θ by central differences
    # (β held), β exactly (its columns)
    cols = prob.columns(theta)
    jac = np.empty((model.shape[0], rho + 1 + cols.shape[1]))
    for i in range(rho + 1):
        h = 1e-6 * max(abs(theta[i]), 1e-2) if i < rho else 1e-3
        tp, tm = theta.copy(), theta.copy()
        tp[i] += h
        tm[i] -= h
        jac[:, i] = (prob.columns(tp) @ beta - prob.columns(tm) @ beta) / (2 * h)
    jac[:, rho + 1 :] = cols
    n_params = jac.shape[1]
    cov = _hac_covariance(jac, prob.target - model, n_params)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    t_rho = ts**rho
    a_s = theta[:rho] * scales
    return ChainFit(
        rho=rho,
        a=tuple(float(a_s[i]) / ts ** (rho - i) for i in range(rho)),
        b0=float(beta[0]) / t_rho,
        b0_std=float(std[rho + 1]) / t_rho,
        c=float(beta[1]) / t_rho,
        friction=float(beta[2]) / t_rho if friction is not None else 0.0,
        delay=max(float(theta[rho]), 0.0) * ts,
        delay_std=float(std[rho]) * ts,
        rss=rss,
        n_fit=n_fit,
        n_params=n_params,
        k0=k0,
        y_model=model,
        nfev=int(sol.nfev),
    )
