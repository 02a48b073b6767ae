r"""The ADRC check of an identified (ρ, b0): the ESO run offline over the logged (u, y).

The linear ESO of order ρ+1 sees the plant as :math:`y^{(\rho)} = \xi_{\rho+1} + b_0 u`
and estimates the total disturbance :math:`\xi_{\rho+1} = f + (b - b_0)u`.  Run over the
log with the identified b0 it shows what a controller would have to cancel:

* with the right ρ and b0 it is f, the dynamics and disturbances the data contain — smooth
  (it moves with y and its derivatives), and small next to :math:`b_0u`;
* a wrong b0 adds :math:`(b - b_0)u`: the estimate then jumps with every step of u
  (b0 three times too large or too small makes it as large as :math:`b_0u` itself);
* a ρ too low leaves a derivative of u in it, a ρ too high a derivative of the noise:
  large, or rough.

The observer is the project's discrete ESO: the chain (6) sampled exactly under the
zero-order hold, current-observer form, gains placing all ρ+1 discrete poles at
:math:`e^{-\omega_0T}` (Miklosovic, Radke & Gao, "Discrete implementation and
generalization of the extended state observer", ACC 2006;
:func:`aiofl.components.discrete.eso_current_observer`), started at :math:`\hat\xi =
(y_0, 0, \dots)`; the first :data:`SETTLE_TIMES` observer time constants
:math:`1/\omega_0` are left out of the figures (the start-up transient).

Figures: ``rms`` is :math:`\mathrm{RMS}(\hat\xi_{\rho+1} - \overline{\hat\xi_{\rho+1}}) /
\mathrm{RMS}(b_0u - \overline{b_0u})` (a constant disturbance — gravity, an offset — is
what an ESO cancels best and is not counted); ``roughness`` is
:math:`\mathrm{RMS}(\Delta^2\hat\xi)/(\sqrt6\,\mathrm{RMS}(\hat\xi))` of the same
detrended estimate, 1 for white noise and near 0 for a signal smooth at the sample time
(the measurement noise reaches the estimate amplified by about
:math:`\omega_0^{\rho+1}`); ``u_share`` the correlation of the estimate with the
observer's own response to u (its disturbance estimate from u alone, about
:math:`-\mathrm{lowpass}(b_0u)`), the signature of a wrong b0: positive when b0 is too
large in magnitude, negative when too small.  The observer is affine in b0 (b0 enters only
through :math:`\Gamma = b_0\Gamma_1`), so ``b0_best``, the b0 with the least disturbance
RMS, is one linear least-squares step.  The verdict is "small and smooth" when
``rms`` ≤ :data:`RMS_MAX`, ``roughness`` ≤ :data:`ROUGHNESS_MAX` (or the rough part,
``rms · roughness``, ≤ :data:`NOISE_PART_MAX`) and ``|u_share|`` ≤ :data:`U_SHARE_MAX`;
otherwise it gives the reasons.  The figures discriminate a wrong b0
best with ω0 above the input's switching rate; below it the observer cannot follow u and
a wrong b0 shows mostly in ``rms``.  The thresholds are this project's (a
disturbance half as large as the control it would cancel is no longer "small"), not a
published rule.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from aiofl.components.discrete import eso_current_observer
from aiofl.components.observers import binomial_alphas
from aiofl.identification.log import Log, LogError

__all__ = ["RMS_MAX", "ROUGHNESS_MAX", "U_SHARE_MAX", "OfflineESO", "offline_eso"]

#: the largest disturbance RMS, relative to b0·u's, still called small
RMS_MAX = 0.5
#: the largest roughness (1: white noise) still called smooth
ROUGHNESS_MAX = 0.3
#: a rough disturbance whose rough part is below this fraction of b0·u's RMS (rms ×
#: roughness) is still called smooth: a plant with almost no disturbance leaves only the
#: noise in the estimate, rough but negligible
NOISE_PART_MAX = 0.05
#: the largest correlation of the disturbance with the observer's response to u before b0
#: is called wrong (a slow observer sees the plant's own dynamics, driven by u, correlate
#: with u too: 0.82 on a fourth-order chain with the right b0 and omega0 = 15 rad/s)
U_SHARE_MAX = 0.9
#: observer time constants left out at the start
SETTLE_TIMES = 10.0
#: the highest order the offline observer runs
MAX_RHO = 6


@dataclass(frozen=True)
class OfflineESO:
    """The offline ESO's run over a log (module notes).

    Attributes
    ----------
    t, y
        The log's time and measured output.
    y_hat
        The observer's output estimate :math:`\\hat\\xi_1`.
    disturbance
        The total-disturbance estimate :math:`\\hat\\xi_{\\rho+1}` over the log.
    omega0
        The observer bandwidth used [rad/s].
    rms, roughness, u_share
        The figures (module notes); computed after the start-up transient.
    b0_best
        The b0 whose disturbance estimate has the least RMS over the log (the observer is
        affine in b0, so this is one linear least-squares step).
    verdict
        ``"small and smooth"``, or the reason it is not.
    """

    t: NDArray[np.float64]
    y: NDArray[np.float64]
    y_hat: NDArray[np.float64]
    disturbance: NDArray[np.float64]
    omega0: float
    rms: float
    roughness: float
    u_share: float
    b0_best: float
    verdict: str

    def to_record(self) -> dict[str, object]:
        """JSON-ready figures (no time series): omega0, rms, roughness, u_share, verdict."""
        return {
            "omega0": self.omega0,
            "rms": self.rms,
            "roughness": self.roughness,
            "u_share": self.u_share,
            "b0_best": self.b0_best,
            "verdict": self.verdict,
        }


def _run(
    u: NDArray[np.float64], y: NDArray[np.float64], rho: int, b0: float, omega0: float, ts: float
) -> NDArray[np.float64]:
    """ξ̂ (N x (ρ+1)) of the current observer over (u, y), started at (y_0, 0, ...)."""
    eso = eso_current_observer(rho, binomial_alphas(rho), omega0, b0, ts)
    n = y.shape[0]
    xi = np.empty((n, rho + 1))
    p = np.zeros(rho + 1)
    p[0] = y[0]
    phi, gam, gain = eso.phi, eso.gamma, eso.l
    for k in range(n):
        est = p + gain * (y[k] - p[0])
        xi[k] = est
        p = phi @ est + gam * u[k]
    return xi


def _verdict(rms: float, roughness: float, u_share: float, b0_best: float) -> str:
    reasons = []
    if abs(u_share) > U_SHARE_MAX or (rms > RMS_MAX and abs(u_share) > 0.5):
        reasons.append(
            f"it follows u (correlation {u_share:+.2f}): b0 looks too "
            f"{'large' if u_share > 0 else 'small'} in magnitude (the disturbance is least "
            f"with b0 = {b0_best:.4g})"
        )
    if roughness > ROUGHNESS_MAX and rms * roughness > NOISE_PART_MAX:
        reasons.append(
            f"noisy (roughness {roughness:.2f}, white noise 1, allowed {ROUGHNESS_MAX:g}): "
            "omega0 too high for the noise, or rho too high"
        )
    if rms > RMS_MAX:
        reasons.append(
            f"large: its RMS is {rms:.2g} x b0·u's (allowed {RMS_MAX:g})"
            + ("" if reasons else ": rho too low, or dynamics a chain does not explain")
        )
    return "; ".join(reasons) if reasons else "small and smooth"


def offline_eso(log: Log, rho: int, b0: float, omega0: float) -> OfflineESO:
    """Run the discrete linear ESO of order ρ+1 with gain ``b0`` and bandwidth ``omega0``
    [rad/s] over the log and judge its total-disturbance estimate (module notes).

    Raises ValueError naming ``rho``, ``b0`` or ``omega0`` when out of range (ρ in
    1..:data:`MAX_RHO`; b0 finite and non-zero; 0 < ω0·T ≤ π, the observer's poles inside
    the band the samples resolve), and :class:`LogError` for a log too short to leave the
    start-up transient behind.

    Parameters
    ----------
    log
        The log (uniformly sampled, Ts its sample time).
    rho
        The chain order ρ, an integer 1..:data:`MAX_RHO`.
    b0
        The input gain b0, finite and non-zero.
    omega0
        The observer bandwidth ω0 [rad/s], 0 < ω0·Ts ≤ π.

    Returns
    -------
    OfflineESO
    """
    if not isinstance(rho, int) or isinstance(rho, bool) or not 1 <= rho <= MAX_RHO:
        raise ValueError(f"rho = {rho!r}; allowed: an integer 1..{MAX_RHO}")
    if not math.isfinite(b0) or b0 == 0.0:
        raise ValueError(f"b0 = {b0!r}; allowed: finite and non-zero")
    ts = log.ts
    if not math.isfinite(omega0) or not 0.0 < omega0 * ts <= math.pi:
        raise ValueError(
            f"omega0 = {omega0!r} rad/s; allowed: 0 < omega0 <= pi/Ts = {math.pi / ts:.4g}"
        )
    skip = math.ceil(SETTLE_TIMES / (omega0 * ts))
    if log.n_samples < skip + 20:
        raise LogError(
            f"log has {log.n_samples} samples; allowed: at least {skip + 20} (the observer "
            f"settles over {SETTLE_TIMES:g}/omega0 = {skip} samples)"
        )
    # the observer is linear and b0 enters only through Γ = b0 Γ_1: ξ̂ = ξ̂(0, y) + b0 ξ̂_1(u, 0)
    y, u = np.asarray(log.y, dtype=np.float64), np.asarray(log.u, dtype=np.float64)
    from_y = _run(np.zeros_like(u), y, rho, 1.0, omega0, ts)
    from_u = _run(u, np.zeros_like(y), rho, 1.0, omega0, ts)
    xi = from_y + b0 * from_u
    dist = xi[:, rho]
    d = dist[skip:] - dist[skip:].mean()
    du = from_u[skip:, rho] - from_u[skip:, rho].mean()
    dy = from_y[skip:, rho] - from_y[skip:, rho].mean()
    bu = b0 * u[skip:]
    bu = bu - bu.mean()
    ref = float(np.sqrt(np.mean(bu**2)))
    d_rms = float(np.sqrt(np.mean(d**2)))
    rms = d_rms / ref if ref > 0 else math.inf
    second = np.diff(d, 2)
    roughness = float(np.sqrt(np.mean(second**2))) / (math.sqrt(6.0) * d_rms) if d_rms else 0.0
    # the observer's own view of u: its disturbance estimate from u alone (y = 0) is about
    # -lowpass(b0 u); a b0 too large leaves (b - b0)u, the same shape, in the estimate
    du_rms = float(np.sqrt(np.mean(du**2)))
    u_share = float(np.corrcoef(d, du)[0, 1]) * math.copysign(1.0, b0) if d_rms and du_rms else 0.0
    b0_best = -float(dy @ du) / float(du @ du) if du_rms else math.nan
    return OfflineESO(
        t=np.asarray(log.t, dtype=np.float64).copy(),
        y=np.asarray(log.y, dtype=np.float64).copy(),
        y_hat=xi[:, 0].copy(),
        disturbance=dist,
        omega0=float(omega0),
        rms=rms,
        roughness=roughness,
        u_share=u_share,
        b0_best=b0_best,
        verdict=_verdict(rms, roughness, u_share, b0_best),
    )
