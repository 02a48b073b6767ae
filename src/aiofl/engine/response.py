r"""What the time loop watched, as an engineer reads it: the verdict, step metrics, noise in u.

The loop (:func:`aiofl.engine.kernel.loop._tpl_watch`) keeps a few numbers per member at every
step :math:`t_k` (:data:`aiofl.layout.ST_U_PEAK` ..); :func:`response_figures` turns them
into the figures a user asks of a run:

- ``overshoot`` [%], ``rise_time`` [s] (10 % to 90 %), ``settling_time`` [s] (2 % band,
  from the step), for a step reference :math:`r = r_0 + A\,1(t \ge t_s)`, measured on the
  plant's output relative to the step: the definitions of python-control's
  ``step_info`` applied to :math:`y - r_0` from :math:`t_s` on with the final value
  :math:`A` (the reference's, not the last sample's: a design that never settles has no
  settling time, NaN).  NaN for other references;
- ``steady_error``: :math:`|\overline{y - r}|` over the steady-state window (the scenario's
  :attr:`~aiofl.scenario.Scenario.steady_start` to the end: the bias, the noise averaged
  out), ``u_std``, the standard deviation of u there, and ``u_noise``, the part of it that
  changes from one update of u to the next like white noise,
  :math:`\sqrt{\overline{\Delta u^2}/2}` over the updates where u changed (for a white
  sequence :math:`E[\Delta u^2] = 2\sigma^2`; a smooth command's updates are small): how much
  of the sensor's noise and quantum reaches the actuator.  A command whose ``u_noise`` is
  most of its RMS at steady state is *screaming* (:func:`screaming`);
- ``u_peak`` (max :math:`|u|`), ``e_peak`` (max :math:`|y - r|`) and ``saturated_time``
  [s], the time u spent at the actuator's limit.

A member that was lost or diverged keeps its figures up to that time (its steady-state
window may then be empty: NaN).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L

__all__ = ["RESPONSE_NAMES", "SCREAMING_SHARE", "response_figures", "screaming", "status_names"]

SCREAMING_SHARE = 0.5
"""A command is screaming when its white-noise part ``u_noise`` is more than this share of
its RMS at steady state: most of what reaches the actuator is the sensor's noise or quantum,
not control."""

RESPONSE_NAMES = L.RESPONSE_NAMES
"""The figures of :func:`response_figures`, in order (:data:`aiofl.layout.RESPONSE_NAMES`)."""


def screaming(figures: dict[str, float]) -> bool:
    """Whether one run's command is mostly noise at steady state (:data:`SCREAMING_SHARE`)."""
    noise, rms = figures.get("u_noise", math.nan), figures.get("u_rms", math.nan)
    return bool(rms > 0.0 and noise > SCREAMING_SHARE * rms)


def status_names(status: NDArray[np.int64]) -> list[str]:
    """``"ok"``, ``"lost"`` or ``"diverged"`` per member (:data:`aiofl.layout.STATUS_NAMES`)."""
    return [L.STATUS_NAMES[int(v)] for v in status]


def response_figures(
    stats: NDArray[np.float64],
    scen: NDArray[np.float64],
    status: NDArray[np.int64],
    t_stop: NDArray[np.float64],
    dt: float,
    t_final: float,
) -> dict[str, NDArray[np.float64]]:
    """The figures of :data:`RESPONSE_NAMES` per member, from the loop's statistics
    ``stats`` (B, :data:`aiofl.layout.N_STAT`) and scenario rows ``scen`` (B,
    :data:`aiofl.layout.N_SCEN`); ``status``, ``t_stop`` tell where a member stopped.

    Parameters
    ----------
    stats, scen
        The loop's statistics (B, N_STAT) and scenario rows (B, N_SCEN).
    status, t_stop
        Each member's status and when it stopped [s].
    dt, t_final
        The step and the horizon [s].

    Returns
    -------
    dict of str to ndarray
    """
    st = np.asarray(stats, dtype=np.float64)
    b = st.shape[0]
    step = scen[:, L.S_REF_KIND] == L.REF_STEP
    amp = np.abs(scen[:, L.S_REF_A])
    stepped = step & (amp > 0.0) & np.isfinite(st[:, L.ST_STEP_PEAK])
    nan = np.full(b, np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        over = np.where(stepped, np.maximum(0.0, 100.0 * (st[:, L.ST_STEP_PEAK] - amp) / amp), nan)
        rise = np.where(stepped, st[:, L.ST_T90] - st[:, L.ST_T10], nan)
        # settled after the last sample out of the 2 % band; never out: at the step itself
        end = np.where(status == L.STATUS_OK, t_final, t_stop)
        t_out = st[:, L.ST_T_OUT]
        t_step = scen[:, L.S_REF_TSTEP]
        settled_at = np.where(np.isnan(t_out), t_step, t_out + dt)
        unsettled = (status != L.STATUS_OK) | (~np.isnan(t_out) & (t_out >= end - 0.5 * dt))
        settle = np.where(stepped & ~unsettled, settled_at - t_step, nan)
        n_ss = st[:, L.ST_SS_N]
        have = n_ss > 0
        mean_du = np.where(have, st[:, L.ST_SS_SU] / n_ss, nan)
        var = np.where(have, st[:, L.ST_SS_SU2] / n_ss - mean_du**2, nan)
        u_std = np.sqrt(np.maximum(var, 0.0))
        steady = np.where(have, np.abs(st[:, L.ST_SS_SE] / n_ss), nan)
        n_du = st[:, L.ST_SS_NDU]
        u_noise = np.where(n_du > 0, np.sqrt(st[:, L.ST_SS_DU2] / (2.0 * n_du)), 0.0)
        u_noise = np.where(have, u_noise, nan)
        mean_u = st[:, L.ST_SS_U0] + mean_du
        u_rms = np.sqrt(np.maximum(var, 0.0) + mean_u**2)
    return {
        "overshoot": over,
        "rise_time": rise,
        "settling_time": settle,
        "steady_error": steady,
        "u_std": u_std,
        "u_noise": u_noise,
        "u_rms": u_rms,
        "u_peak": st[:, L.ST_U_PEAK].copy(),
        "e_peak": st[:, L.ST_E_PEAK].copy(),
        "saturated_time": st[:, L.ST_T_SAT].copy(),
    }
