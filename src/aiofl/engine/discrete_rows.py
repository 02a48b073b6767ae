r"""Sampled-data controllers as data: the settings, and the per-member coefficient row.

:class:`Sampling` says how a controller runs on a processor: sample time ``ts`` (an integer
multiple of the engine's step), an optional one-sample computation delay, the quanta of
the converters and the discretisation of its dynamic parts.  :func:`sampling_rows` turns a
batch of controllers and their settings into one float row per member holding every
coefficient of the discrete update (:mod:`aiofl.components.discrete`): the ESO's Φ, Γ, K,
L, the prefilter's Φ, Γ, the TD's step and filter factor.  The engine's sampled loop
(:mod:`aiofl.engine.kernel.sampled`) and the C export (:mod:`aiofl.export`) both run the update
from exactly these numbers; a member whose row has ``D_STEPS = 0`` is continuous.

What the engine simulates at :math:`t_k = kT_s` (:mod:`aiofl.engine.kernel.sampled`):

1. the ADC: :math:`y_k = Q_y(h(x(t_k)) + n(t_k))`, :math:`Q_q(v) = q\lfloor v/q + 1/2\rfloor`
   (``y_quantum``; none if 0), the scenario's noise as in the continuous loop;
2. the controller, once: ESO correction, SEF and law from the estimate and the
   differentiator's profile at :math:`t_k`, saturation, ESO prediction, differentiator
   update; it returns :math:`u_k`;
3. the DAC: the plant gets :math:`Q_u(u_k)` (``u_quantum``) held over
   :math:`[t_k, t_{k+1})`, or with ``delay = 1`` the previous sample's
   :math:`Q_u(u_{k-1})` (:math:`u_{-1} = 0`).  The ESO's prediction uses the command that
   is applied over the interval (:math:`u_k`, or :math:`u_{k-1}` with the delay), unquantised:
   the controller knows what it commanded, not what the converter made of it.

A linear ESO with Kalman gains (``eso.gains = "kalman"``) discretised by ZOH gets the
discrete steady-state Kalman gain of the ZOH model instead of the pole-mapped one
(:func:`aiofl.components.kalman.eso_kalman_observer`), with the process-noise intensity
``eso.q`` and the measurement variance per sample :math:`R_d = r/T_s`
(:func:`aiofl.components.kalman.measurement_noise_intensity`); by forward Euler it gets
the continuous Kalman–Bucy gains, as any gains.

The ESO starts at :math:`\hat\xi = (y_0, 0, \dots, 0)` with :math:`y_0` the first
measurement, the differentiator at rest at 0.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.components import discrete as D
from aiofl.components.kalman import eso_kalman_observer
from aiofl.components.model_gains import discrete_model_gain, model_gain
from aiofl.components.observers import eso_gain
from aiofl.controller import Controller, ControllerBatch

__all__ = [
    "ESO_METHODS",
    "H0_RANGE",
    "MIN_SAMPLES",
    "N_DISC",
    "QUANTUM_MIN",
    "TD_METHODS",
    "Sampling",
    "check_h0",
    "sample_steps",
    "sampling_rows",
]

ESO_METHODS = ("zoh", "euler")
"""ESO discretisations: exact ZOH current observer (linear ESO only), forward Euler."""
TD_METHODS = ("fhan", "euler")
"""Discretisations of Han's TD (18): Han's discrete fhan TD, forward Euler."""
QUANTUM_MIN = 1e-12
"""Smallest non-zero ADC/DAC quantum q: Q(v) = q·floor(v/q + 1/2) needs 1/q and v/q finite
(q = 5e-324 gives 1/q = inf and NaN at v = 0); 1e-12 is finer than any converter (a 32-bit
ADC over ±1 has q ≈ 5e-10) and keeps v/q finite for every abs(v) < 1e296."""

MIN_SAMPLES = 10
"""Fewest controller samples over a run's horizon, t_final/Ts: a sampled controller that
acts once or twice in the whole run (``ts = 1.0`` with ``t_final = 0.5``) is a typo, not a
design (its ISU would be 0 and its ITAE that of a loop left open)."""
H0_RANGE = (1e-3, 100.0)
"""fhan's filter factor h0 in units of Ts: 1e-3·Ts <= h0 <= 100·Ts.  A larger h0 freezes
Han's discrete TD (with h0 = 1e300 its output stays 0 and u ≡ 0); h0 of a few Ts filters
noise, h0 = Ts is the default."""


def check_h0(h0: float | None, ts: float) -> None:
    """Raise ValueError unless ``h0`` is None (Ts) or within :data:`H0_RANGE` times ``ts``."""
    lo, hi = H0_RANGE[0] * ts, H0_RANGE[1] * ts
    if h0 is not None and not (math.isfinite(h0) and lo <= h0 <= hi):
        raise ValueError(
            f"controller.discrete.h0 = {h0:g} s; allowed: {H0_RANGE[0]:g}·ts <= h0 <= "
            f"{H0_RANGE[1]:g}·ts, i.e. {lo:g} .. {hi:g} s with ts = {ts:g} s (fhan's filter "
            "factor; a few ts filters noise, a huge one freezes the TD)"
        )


# ----------------------------------------------------------------------------- the row
D_STEPS = 0  #: engine steps per sample N = Ts/dt (0: a continuous member)
D_TS = 1  #: sample time Ts [s]
D_DELAY = 2  #: computation delay in samples (0 or 1)
D_YQ = 3  #: measurement quantum (0: none)
D_UQ = 4  #: command quantum (0: none)
D_ESO = 5  #: 0 = ZOH current observer, 1 = forward Euler
D_TDM = 6  #: Han TD: 0 = fhan, 1 = forward Euler on eq. (18)
D_H0 = 7  #: fhan's filter factor h0
STRIDE = L.RHO_MAX + 1  #: row stride of the ESO's Φ
D_PHI = 8  #: ESO Φ - I (delta form), (ρ+1)×(ρ+1) with row stride STRIDE
D_GAM = D_PHI + STRIDE * STRIDE  #: ESO Γ
D_K = D_GAM + STRIDE  #: ESO K
D_L = D_K + STRIDE  #: ESO L
PF_STRIDE = L.RHO_MAX  #: row stride of the prefilter's Φ
D_PF_PHI = D_L + STRIDE  #: linear prefilter Φ - I, ρ×ρ with row stride PF_STRIDE
D_PF_GAM = D_PF_PHI + PF_STRIDE * PF_STRIDE  #: linear prefilter Γ
D_KDELAY = D_PF_GAM + PF_STRIDE  #: the known measurement delay compensated, in samples
N_DISC = D_KDELAY + 1
ESO_ZOH, ESO_EULER = 0, 1
TDM_FHAN, TDM_EULER = 0, 1


@dataclass(frozen=True)
class Sampling:
    """How a controller runs on a processor (the ``[controller.discrete]`` table).

    Parameters
    ----------
    ts
        Sample time [s]; must be an integer multiple of the engine's step ``dt``.
    delay
        Computation delay in samples, 0 or 1 (u computed at t_k is applied at t_{k+1}).
    y_quantum, u_quantum
        Quanta of the measurement (ADC) and the command (DAC); 0 = not quantised.
    eso
        ``"zoh"`` (exact ZOH current observer, linear ESO only) or ``"euler"``; None picks
        ZOH for the linear ESO and Euler for the INLESO.
    td
        Han's TD (``td = "han"``): ``"fhan"`` (Han's discrete TD) or ``"euler"`` (forward
        Euler on eq. 18).  The ITD is always discretised by Euler, the linear prefilter by
        ZOH.
    h0
        fhan's filter factor h0 [s] (default ``ts``).
    """

    ts: float
    delay: int = 0
    y_quantum: float = 0.0
    u_quantum: float = 0.0
    eso: str | None = None
    td: str = "fhan"
    h0: float | None = None

    def __post_init__(self) -> None:
        if isinstance(self.ts, bool) or not (math.isfinite(self.ts) and self.ts > 0):
            raise ValueError(f"controller.discrete.ts = {self.ts!r}; allowed: a number > 0 [s]")
        if isinstance(self.delay, bool) or self.delay not in (0, 1):
            raise ValueError(
                f"controller.discrete.delay = {self.delay!r}; allowed: the integer 0 or 1"
            )
        for name in ("y_quantum", "u_quantum"):
            val = getattr(self, name)
            if not (math.isfinite(val) and (val == 0 or val >= QUANTUM_MIN)):
                raise ValueError(
                    f"controller.discrete.{name} = {val}; allowed: 0 (none) or a finite "
                    f"quantum >= {QUANTUM_MIN:g}"
                )
        if self.eso is not None and self.eso not in ESO_METHODS:
            raise ValueError(
                f"controller.discrete.eso = {self.eso!r}; allowed: {', '.join(ESO_METHODS)}"
            )
        if self.td not in TD_METHODS:
            raise ValueError(
                f"controller.discrete.td = {self.td!r}; allowed: {', '.join(TD_METHODS)}"
            )
        if self.h0 is not None and not (math.isfinite(self.h0) and self.h0 > 0):
            raise ValueError(f"controller.discrete.h0 = {self.h0}; allowed: > 0 [s]")

    def eso_method(self, controller: Controller) -> str:
        """The ESO discretisation used for ``controller`` (resolving ``eso = None``)."""
        if self.eso is not None:
            return self.eso
        return "zoh" if controller.eso == "linear" else "euler"

    def check_horizon(self, t_final: float) -> None:
        """Raise ValueError unless the horizon holds at least :data:`MIN_SAMPLES` samples."""
        if not t_final >= MIN_SAMPLES * self.ts:
            raise ValueError(
                f"controller.discrete.ts = {self.ts:g} s gives {t_final / self.ts:.3g} "
                f"sample(s) over scenario.t_final = {t_final:g} s; allowed: ts <= "
                f"t_final/{MIN_SAMPLES} = {t_final / MIN_SAMPLES:g} s (at least {MIN_SAMPLES} "
                "controller samples over the horizon)"
            )

    def check(self, controller: Controller) -> None:
        """Raise ValueError if ``controller`` cannot run with these settings."""
        if controller.law == "iofl" and controller.td != "exact":
            raise ValueError(
                f"a sampled IOFL law needs td_kind = 'exact' (got {controller.td!r}): it "
                "reads the reference derivatives at each sample"
            )
        if controller.eso == "improved" and self.eso_method(controller) == "zoh":
            raise ValueError(
                "controller.discrete.eso = 'zoh' needs the linear ESO; the improved ESO "
                "(INLESO) is discretised by forward Euler (allowed: euler)"
            )

    def describe(self, controller: Controller) -> list[str]:
        """The discretisation of each component, one line each (for reports and code)."""
        lines = [f"sample time Ts = {self.ts:g} s, computation delay {self.delay} sample(s)"]
        eso = self.eso_method(controller)
        kalman = controller.eso_gains == "kalman"
        if eso == "zoh" and kalman:
            q, r = controller.value("eso.q"), controller.value("eso.r")
            lines.append(
                "ESO: exact ZOH discretisation, current-observer form, steady-state Kalman "
                f"gain (discrete Riccati equation, q = {q:g}, R_d = r/Ts = {r / self.ts:g})"
            )
        elif eso == "zoh":
            lines.append(
                "ESO: exact ZOH discretisation, current-observer form (Miklosovic, Radke & "
                "Gao 2006), poles z = exp(s_i Ts)"
            )
        else:
            lines.append(
                "ESO: forward Euler" + (" on the continuous Kalman-Bucy gains" if kalman else "")
            )
        td = {
            "exact": "reference derivatives: supplied by the caller (r, r', ..., r^(rho))",
            "han": (
                "TD: Han's discrete TD with fhan (Han 2009), h0 = "
                + ("Ts" if self.h0 is None else f"{self.h0:g} s")
                if self.td == "fhan"
                else "TD: forward Euler on eq. (18)"
            ),
            "improved": "TD: forward Euler on the ITD, eq. (21)",
            "linear": "TD: linear prefilter, exact ZOH discretisation",
        }[controller.td]
        lines.append(td)
        lines.append("SEF, law and saturation: the continuous formulas at each sample")
        if self.y_quantum or self.u_quantum:
            lines.append(
                f"quantisation: y_quantum = {self.y_quantum:g}, u_quantum = {self.u_quantum:g}"
            )
        return lines


def sample_steps(ts: float, dt: float) -> int:
    """Engine steps per sample, N = Ts/dt; ValueError unless Ts is an integer multiple of dt."""
    n = round(ts / dt)
    if n < 1 or abs(n * dt - ts) > 1e-9 * ts:
        raise ValueError(
            f"controller.discrete.ts = {ts:g} s is not an integer multiple of the step "
            f"dt = {dt:g} s; allowed: k·dt for k = 1, 2, ... (e.g. {max(n, 1) * dt:g} s)"
        )
    return n


DELAY_STEPS_MAX = 1 << 16
"""Largest transport delay in engine steps (the loop's ring buffer holds this many + 1
values per lane and delay: 2 × 65537 × 32 doubles = 34 MB at most for a group)."""


def delay_steps(key: str, tau: float, dt: float, sampled: bool) -> int:
    r"""Engine steps of the transport delay ``scenario.<key> = tau``: m = τ/dt.

    The sampled engine holds a delay exactly when it is an integer multiple m of the step:
    the command is piecewise constant with jumps on the step grid, so
    :math:`u(t - m\,dt)` jumps on the grid too, and the sensor reads a stored
    :math:`y(t_k - m\,dt)`.  The continuous controller's observer reads, at every stage
    of the integrator, the output of the same stage m steps back, and the plant gets the
    command of that stage (the method of steps,
    :func:`aiofl.engine.kernel.continuous._tpl_delay_stage_in`).  A delay between grid points
    would put a jump inside an RK4 step: refused (ValueError naming the field), as is a
    delay of more than :data:`DELAY_STEPS_MAX` steps.  ``sampled`` (the controller's
    timing) no longer changes what is held; it is kept for the callers.

    Parameters
    ----------
    key
        The scenario field (``input_delay``, ``output_delay``), for the message.
    tau
        The delay τ [s].
    dt
        The step [s].
    sampled
        Whether the controller is sampled (unused, see above).

    Returns
    -------
    int
        m.
    """
    if tau == 0.0:
        return 0
    m = round(tau / dt)
    if m < 1 or abs(m * dt - tau) > 1e-9 * tau:
        raise ValueError(
            f"scenario.{key} = {tau:g} s is not an integer multiple of the step "
            f"dt = {dt:g} s; allowed: k·dt for k = 0, 1, 2, ... (e.g. {max(m, 1) * dt:g} s)"
        )
    if m > DELAY_STEPS_MAX:
        raise ValueError(
            f"scenario.{key} = {tau:g} s is {m} steps of dt = {dt:g} s; allowed: at most "
            f"{DELAY_STEPS_MAX} steps"
        )
    return m


def known_delay_samples(tau: float, ts: float) -> int:
    """``controller.eso.delay`` (the known measurement delay, [s]) in samples of ``ts``: a
    ValueError naming it unless it is a whole number of samples, at most
    :data:`aiofl.layout.KNOWN_DELAY_MAX`."""
    d = round(tau / ts)
    if abs(tau - d * ts) > 1e-9 * ts or not 0 <= d <= L.KNOWN_DELAY_MAX:
        raise ValueError(
            f"controller.eso.delay = {tau:g} s at ts = {ts:g} s; allowed: a whole number of "
            f"samples, 0 .. {L.KNOWN_DELAY_MAX} ts (0 .. {L.KNOWN_DELAY_MAX * ts:g} s)"
        )
    return d


def check_delays(scen: NDArray[np.float64], disc: NDArray[np.float64] | None, dt: float) -> None:
    """:func:`delay_steps` for every member's scenario row (``scen``, one row per member;
    ``disc`` its discrete rows, None or ``D_STEPS`` 0 for a continuous member).

    Parameters
    ----------
    scen
        The scenario rows, one per member.
    disc
        Their discrete rows (None, or ``D_STEPS`` 0: a continuous member).
    dt
        The step [s].
    """
    cols = [L.S_IN_DELAY, L.S_OUT_DELAY]
    for i in np.nonzero(np.any(scen[:, cols] != 0.0, axis=1))[0]:
        sampled = disc is not None and disc[i, D_STEPS] > 0
        for key, col in (("input_delay", L.S_IN_DELAY), ("output_delay", L.S_OUT_DELAY)):
            delay_steps(key, float(scen[i, col]), dt, sampled)


def _row(
    ints: NDArray[np.int64],
    floats: NDArray[np.float64],
    s: Sampling,
    dt: float,
    jac: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    rho = int(ints[L.I_RHO])
    row = np.zeros(N_DISC)
    row[D_STEPS] = sample_steps(s.ts, dt)
    row[D_TS] = s.ts
    row[D_DELAY] = s.delay
    row[D_YQ] = s.y_quantum
    row[D_UQ] = s.u_quantum
    row[D_TDM] = TDM_FHAN if s.td == "fhan" else TDM_EULER
    row[D_H0] = s.h0 if s.h0 is not None else s.ts
    row[D_KDELAY] = known_delay_samples(float(floats[L.F_ESO_DELAY]), s.ts)
    eso_kind = int(ints[L.I_ESO])
    if int(ints[L.I_LAW]) == L.LAW_IOFL and int(ints[L.I_TD]) != L.TD_EXACT:
        raise ValueError(
            "a sampled IOFL law needs td_kind = 'exact': it reads the reference derivatives "
            "at each sample"
        )
    method = s.eso or ("zoh" if eso_kind == L.ESO_LINEAR else "euler")
    with np.errstate(all="ignore"):  # a Ts too small overflows: refused below, no warning
        _fill_row(row, ints, floats, s, method, eso_kind, rho, jac)
    if not np.all(np.isfinite(row)):
        raise ValueError(
            f"controller.discrete.ts = {s.ts:g} s: the discretisation has non-finite "
            "coefficients (an observer or prefilter bandwidth too large for this sample "
            "time, or Ts too small to represent its powers); allowed: a larger ts"
        )
    check_h0(s.h0, s.ts)  # after ts: an absurd ts is named as such, not through h0
    return row


def _fill_row(
    row: NDArray[np.float64],
    ints: NDArray[np.int64],
    floats: NDArray[np.float64],
    s: Sampling,
    method: str,
    eso_kind: int,
    rho: int,
    jac: NDArray[np.float64] | None = None,
) -> None:
    """Write the ESO and prefilter coefficients of ``s`` into ``row`` (see :func:`_row`);
    ``jac``: the nominal model's Jacobian a model-assisted observer's gain is placed for
    (:mod:`aiofl.components.model_gains`)."""
    n = rho + 1
    w0 = floats[L.F_OMEGA0]
    b0 = floats[L.F_B0]
    alphas = floats[L.F_ESO_ALPHA : L.F_ESO_ALPHA + n]
    if method == "zoh":
        if eso_kind != L.ESO_LINEAR:
            raise ValueError(
                "controller.discrete.eso = 'zoh' needs the linear ESO; the improved ESO "
                "(INLESO) is discretised by forward Euler (allowed: euler)"
            )
        if int(ints[L.I_ESO_GAINS]) == L.ESO_GAINS_KALMAN:
            # the discrete steady-state Kalman gain on the ZOH model, R_d = r/Ts
            q, r = float(floats[L.F_ESO_Q]), float(floats[L.F_ESO_R])
            eso = eso_kalman_observer(rho, q, r / s.ts, b0, s.ts)
        else:
            eso = D.eso_current_observer(rho, alphas, w0, b0, s.ts)
            if jac is not None:  # placed for the model's linearised error map
                eso = replace(eso, l=discrete_model_gain(jac, alphas, w0, s.ts))
        row[D_ESO] = ESO_ZOH
    else:
        betas = [eso_gain(float(alphas[i]), float(w0), i + 1) for i in range(n)]
        if jac is not None:
            betas = list(model_gain(jac, alphas, w0))
        eso = D.eso_forward_euler(rho, betas, b0, s.ts)
        row[D_ESO] = ESO_EULER
    for i in range(n):
        row[D_PHI + i * STRIDE : D_PHI + i * STRIDE + n] = eso.dphi[i]
    row[D_GAM : D_GAM + n] = eso.gamma
    row[D_K : D_K + n] = eso.k
    row[D_L : D_L + n] = eso.l
    if int(ints[L.I_TD]) == L.TD_LINEAR:
        pf_phi, pf_gam = D.linear_prefilter_zoh(rho, floats[L.F_TD_OMEGA], s.ts, delta=True)
        for i in range(rho):
            row[D_PF_PHI + i * PF_STRIDE : D_PF_PHI + i * PF_STRIDE + rho] = pf_phi[i]
        row[D_PF_GAM : D_PF_GAM + rho] = pf_gam


def sampling_rows(
    batch: ControllerBatch,
    samplings: Sequence[Sampling | None],
    dt: float,
    model_jacobians: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """The engine's per-member discrete rows (B, N_DISC); zeros for continuous members.

    Coefficients are computed once per distinct (controller row, settings) pair, from the
    packed rows, so a GA population's tuned ω0, b0, α are always the ones discretised.
    ``model_jacobians`` (:func:`aiofl.engine.observer_gains.model_jacobians`): for a
    model-assisted member with bandwidth gains, the nominal model's Jacobian its observer
    gain is placed for (:mod:`aiofl.components.model_gains`); NaN rows elsewhere.

    Parameters
    ----------
    batch
        The packed controllers.
    samplings
        One sampling setting per member (None: continuous).
    dt
        The engine step [s].
    model_jacobians
        (B, ρ) model Jacobians of the placed members, NaN rows elsewhere (None: none placed).

    Returns
    -------
    ndarray
        Shape (B, N_DISC).
    """
    if len(samplings) != len(batch):
        raise ValueError(f"{len(samplings)} sampling settings for a batch of {len(batch)}")
    out = np.zeros((len(batch), N_DISC))
    memo: dict[tuple[bytes, bytes, Sampling, bytes | None], NDArray[np.float64]] = {}
    for i, s in enumerate(samplings):
        if s is None:
            continue
        jac = None
        if model_jacobians is not None and not np.isnan(model_jacobians[i, 0]):
            jac = model_jacobians[i]
        jkey = None if jac is None else jac.tobytes()
        key = (batch.ints[i].tobytes(), batch.floats[i].tobytes(), s, jkey)
        if key not in memo:
            memo[key] = _row(batch.ints[i], batch.floats[i], s, dt, jac)
        out[i] = memo[key]
    return out
