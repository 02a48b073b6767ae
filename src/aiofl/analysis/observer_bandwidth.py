r"""The observer bandwidth a rig allows: an ω0 ceiling from the sample time, the delay and
the sensor's noise.

A linear ESO's bandwidth :math:`\omega_0` cannot be raised at will: three things of the
loop around it cap it.  :func:`omega0_ceiling` returns each cap with its rule and its
source, and the binding (lowest) one; :func:`config_ceiling` reads them from a run
config (what ``aiofl analyze`` prints and ``aiofl tune --omega0-ceiling`` clips
``eso.omega0``'s search bound to).

- **Sampling**: :math:`\omega_0 T_s \le` :data:`MAX_OMEGA0_TS` (= 0.3).  The sampled ESO's
  poles are :math:`e^{-\omega_0T_s}`; the exact-ZOH current observer (Miklosovic, Radke &
  Gao, "Discrete implementation and generalization of the extended state observer", ACC
  2006) keeps the continuous design's behaviour only while they stay near 1 (0.74 here).
  This is the rule ``aiofl design`` already uses (:mod:`aiofl.analysis.first_design`).
- **Delay**: :math:`\omega_0\tau \le` :data:`DELAY_PRODUCT` (= 0.3) for a loop delay τ
  (measurement + actuation + one sample of computation delay when the command is applied
  a sample late).  The delay costs the observer :math:`\omega_0\tau` rad of phase at its
  own bandwidth (the phase of :math:`e^{-s\tau}`; 0.3 rad = 17°), which its chain model
  does not have.  The number is this project's rule of thumb, in the range the ADRC delay
  studies work in (the observer kept well below :math:`1/\tau`; Zheng & Gao, "Predictive
  active disturbance rejection control for processes with time delay", ISA Trans. 53,
  2014, treat longer delays with a predictor).  A controller told about the delay
  (``eso.delay``) keeps its observer consistent, but the loop still carries the delay:
  the cap is reported all the same, labelled.
- **Noise**: the command's noise the measurement noise causes must stay within
  :data:`NOISE_FRACTION` (5 %) of the actuator's half-range
  :math:`(u_{max} - u_{min})/2`, or, with no actuator limit, of the input that holds the
  plant at its operating point :math:`|u^*|` (:func:`aiofl.plants.operating_point.trim`).
  The measurement noise per sample has variance :math:`R_d = \sigma^2 + \Delta^2/12`
  (a Gaussian noise σ held at most one sample, a quantiser of step Δ as Widrow's uniform
  white noise; :func:`aiofl.components.kalman.measurement_noise_intensity`).  The command's
  standard deviation is :math:`\sqrt{R_d}\,\lVert T_{nu}\rVert_2`, with :math:`T_{nu}`
  the transfer from the measurement noise n to the command u of the *exact discrete LADRC*
  (exact-ZOH current-observer ESO with the config's α, linear SEF with ω_c = ω0/ratio at
  the config's ratio, law :math:`u = (\sum k_i(r_i - \hat\xi_i) - \hat\xi_{\rho+1})/b_0`)
  closing the loop on its own design model, the chain :math:`y^{(\rho)} = b_0u` under a
  zero-order hold (:func:`noise_loop`; the controller alone has an integrator, so its own
  H2 norm is infinite, and the loop's sensitivity is what a rig sees: Herbst, "Transfer
  function analysis and implementation of active disturbance rejection control", Control
  Theory Technol. 19, 2021, reads the noise sensitivity off the same loop).
  :math:`\lVert T_{nu}\rVert_2^2 = D^2 + CWC^T` with W the discrete controllability
  Gramian (:func:`scipy.linalg.solve_discrete_lyapunov`).  The largest ω0 meeting the
  budget is found by :func:`scipy.optimize.brentq` in :math:`\log\omega_0` (the noise grows
  with ω0, as :math:`\omega_0^{\rho+1}` at small :math:`\omega_0T_s`).
  :func:`noise_gain` gives the other classical measure, the command change per unit of
  measurement at the same sample, :math:`|FL|` (the controller's high-frequency gain), the
  one :mod:`aiofl.identification.first_config` bounds against a log's noise.

``tests/test_observer_bandwidth.py`` checks each cap's closed form and that the noise
cap's ω0 gives the stated command noise in a simulated sampled loop
(:class:`aiofl.discrete_controller.DiscreteController` on the ZOH chain).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aiofl.analysis.first_design import MAX_OMEGA0_TS, OBSERVER_RATIO
from aiofl.components.discrete import current_observer_gain, eso_continuous_poles, eso_zoh
from aiofl.components.fastmath import binomial_power
from aiofl.components.observers import binomial_alphas

__all__ = [
    "DELAY_PRODUCT",
    "MAX_OMEGA0_TS",
    "NOISE_FRACTION",
    "Cap",
    "Ceiling",
    "config_ceiling",
    "delay_cap",
    "largest_omega0",
    "noise_cap",
    "noise_gain",
    "noise_loop",
    "noise_rms_gain",
    "omega0_ceiling",
    "sampling_cap",
]

#: the largest ω0·τ (rad of phase the delay costs the observer at its bandwidth)
DELAY_PRODUCT = 0.3
#: the largest command noise (standard deviation), as a fraction of the input's scale
NOISE_FRACTION = 0.05
#: the lowest ω0·Ts the noise cap searches down to
_LOWEST_OMEGA0_TS = 1e-4


@dataclass(frozen=True)
class Cap:
    """One cap on ω0.

    Attributes
    ----------
    name
        ``"sampling"``, ``"delay"`` or ``"noise"``.
    omega0
        The largest ω0 it allows [rad/s] (``inf``: it does not cap; ``nan``: not computed).
    rule
        The rule with its numbers, one line.
    source
        Where the rule comes from (the module notes).
    """

    name: str
    omega0: float
    rule: str
    source: str

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (``omega0`` None when it does not cap or was not computed)."""
        w = self.omega0 if math.isfinite(self.omega0) else None
        return {"name": self.name, "omega0": w, "rule": self.rule, "source": self.source}


@dataclass(frozen=True)
class Ceiling:
    """Every cap on ω0 and the binding one (:func:`omega0_ceiling`)."""

    caps: tuple[Cap, ...]
    notes: tuple[str, ...] = field(default_factory=tuple)

    @property
    def binding(self) -> Cap | None:
        """The lowest finite cap (None when none caps)."""
        finite = [c for c in self.caps if math.isfinite(c.omega0)]
        return min(finite, key=lambda c: c.omega0) if finite else None

    @property
    def omega0(self) -> float:
        """The ceiling [rad/s]: the binding cap's ω0 (``inf`` when none caps)."""
        b = self.binding
        return b.omega0 if b is not None else math.inf

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the caps, the binding one's name and ω0, the notes."""
        b = self.binding
        return {
            "caps": [c.to_dict() for c in self.caps],
            "binding": None if b is None else b.name,
            "omega0": None if b is None else b.omega0,
            "notes": list(self.notes),
        }

    def format_text(self, omega0: float | None = None) -> str:
        """The section ``aiofl analyze`` prints; ``omega0``: the design's, compared."""
        lines = ["observer bandwidth ceiling (omega0, rad/s):"]
        for c in self.caps:
            val = (
                f"{c.omega0:.4g} rad/s"
                if math.isfinite(c.omega0)
                else ("no cap" if math.isinf(c.omega0) else "not computed")
            )
            lines.append(f"  {c.name:<9} {val:<16} {c.rule}")
            lines.append(f"  {'':<9} {'':<16} [{c.source}]")
        b = self.binding
        if b is None:
            lines.append("  binding: none (no cap applies)")
        else:
            lines.append(f"  binding: {b.name}, omega0 <= {b.omega0:.4g} rad/s")
            if omega0 is not None and math.isfinite(omega0):
                verdict = "within" if omega0 <= b.omega0 * (1 + 1e-9) else "ABOVE"
                lines.append(
                    f"  the design's omega0 = {omega0:.4g} rad/s is {verdict} the ceiling "
                    f"({omega0 / b.omega0:.3g} x)"
                )
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


# ----------------------------------------------------------------- the three rules
_SAMPLING_SOURCE = "Miklosovic, Radke & Gao, ACC 2006; the rule of `aiofl design`"
_DELAY_SOURCE = (
    "phase omega0*tau of e^(-s tau) at the observer's bandwidth; this project's rule of thumb "
    "(cf. Zheng & Gao, ISA Trans. 53, 2014)"
)
_NOISE_SOURCE = (
    "H2 norm of the exact discrete LADRC's noise-to-command loop on its chain model "
    "(Herbst, Control Theory Technol. 19, 2021); the fraction is this project's choice"
)


def sampling_cap(ts: float | None) -> Cap:
    r""":math:`\omega_0 \le` :data:`MAX_OMEGA0_TS`:math:`/T_s` (``inf`` for a continuous
    controller, ``ts`` None)."""
    if ts is None:
        return Cap("sampling", math.inf, "continuous controller: no sampling cap", _SAMPLING_SOURCE)
    _positive("ts", ts)
    return Cap(
        "sampling",
        MAX_OMEGA0_TS / ts,
        f"omega0*Ts <= {MAX_OMEGA0_TS:g} (Ts = {ts:.4g} s; ESO poles e^(-omega0 Ts) >= "
        f"{math.exp(-MAX_OMEGA0_TS):.2f})",
        _SAMPLING_SOURCE,
    )


def delay_cap(delay: float, *, told: bool = False) -> Cap:
    r""":math:`\omega_0 \le` :data:`DELAY_PRODUCT`:math:`/\tau` (``inf`` without delay);
    ``told``: the controller is told about the delay (labelled in the rule)."""
    if not (math.isfinite(delay) and delay >= 0):
        raise ValueError(f"delay = {delay!r}; allowed: a finite number of seconds >= 0")
    if delay == 0:
        return Cap("delay", math.inf, "no loop delay: no delay cap", _DELAY_SOURCE)
    rule = (
        f"omega0*tau <= {DELAY_PRODUCT:g} rad ({math.degrees(DELAY_PRODUCT):.0f} deg of phase; "
        f"tau = {delay:.4g} s)"
    )
    if told:
        rule += "; the ESO is told the delay (eso.delay), the loop still carries it"
    return Cap("delay", DELAY_PRODUCT / delay, rule, _DELAY_SOURCE)


def _positive(name: str, value: float) -> float:
    if isinstance(value, bool) or not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} = {value!r}; allowed: a finite number > 0")
    return float(value)


def _feedback_row(rho: int, b0: float, omega_c: float, n_feedback: int) -> NDArray[np.float64]:
    """F with u = -F ξ̂ at r = 0: (k_1..k_m, 0.., 1)/b0, k_i of (s + ω_c)^ρ."""
    f = np.zeros(rho + 1)
    for i in range(n_feedback):
        f[i] = binomial_power(rho, i, omega_c)
    f[rho] = 1.0
    return f / b0


def _observer_gain(
    rho: int, omega0: float, ts: float, alphas: ArrayLike | None
) -> NDArray[np.float64]:
    a = binomial_alphas(rho) if alphas is None else np.asarray(alphas, dtype=np.float64)
    return current_observer_gain(rho, ts, eso_continuous_poles(a, omega0))


def _check_design(rho: int, b0: float, omega0: float, ts: float, ratio: float) -> None:
    if isinstance(rho, bool) or not isinstance(rho, int | np.integer) or not 1 <= rho <= 8:
        raise ValueError(f"rho = {rho!r}; allowed: an integer 1..8")
    if not (math.isfinite(b0) and b0 != 0):
        raise ValueError(f"b0 = {b0!r}; allowed: finite and non-zero")
    _positive("omega0", omega0)
    _positive("ts", ts)
    _positive("ratio (omega0/omega_c)", ratio)


def noise_gain(
    rho: int,
    b0: float,
    omega0: float,
    ts: float,
    *,
    ratio: float = OBSERVER_RATIO,
    omega_c: float | None = None,
    alphas: ArrayLike | None = None,
    n_feedback: int | None = None,
) -> float:
    r""":math:`|FL|`: the LADRC's command change per unit of measurement at the same sample
    (its high-frequency gain), L the exact-ZOH current observer's gain
    (:func:`aiofl.components.discrete.current_observer_gain`), F the law's gains on
    :math:`\hat\xi` with :math:`\omega_c = \omega_0/` ``ratio`` (or ``omega_c`` held
    fixed when given, as in every function here).

    Parameters
    ----------
    rho, b0, omega0, ts
        ρ (1..8) and b₀ ≠ 0 of the chain, ω₀ [rad/s] and the sample time Ts [s].
    ratio, omega_c, alphas, n_feedback
        ω₀/ω_c (default :data:`OBSERVER_RATIO`), or ω_c [rad/s] held when given; the ρ + 1
        observer coefficients α (None: binomial); the estimates fed back (None: ρ).

    Returns
    -------
    float
    """
    _check_design(rho, b0, omega0, ts, ratio)
    gain = _observer_gain(rho, omega0, ts, alphas)
    wc = omega0 / ratio if omega_c is None else _positive("omega_c", omega_c)
    f = _feedback_row(rho, b0, wc, rho if n_feedback is None else n_feedback)
    return abs(float(f @ gain))


def noise_loop(
    rho: int,
    b0: float,
    omega0: float,
    ts: float,
    *,
    ratio: float = OBSERVER_RATIO,
    omega_c: float | None = None,
    alphas: ArrayLike | None = None,
    n_feedback: int | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], float]:
    r"""(A, B, C, D) of :math:`T_{nu}`, measurement noise n to command u, of the exact
    discrete LADRC on the ZOH chain :math:`y^{(\rho)} = b_0u` (module notes), r = 0.

    Plant :math:`x_{k+1} = \Phi_\rho x_k + \Gamma_\rho u_k`, :math:`y_k = x_{1,k} + n_k`;
    controller (current observer) :math:`\hat\xi_k = Mp_k + Ly_k` with
    :math:`M = I - Lc`, :math:`u_k = -F\hat\xi_k`, :math:`p_{k+1} = (\Phi - \Gamma F)\hat\xi_k`.
    In the state :math:`(x, p)`:

    .. math::
        A = \begin{bmatrix}\Phi_\rho - \Gamma_\rho FLc_\rho & -\Gamma_\rho FM\\
            GLc_\rho & GM\end{bmatrix},\quad
        B = \begin{bmatrix}-\Gamma_\rho FL\\ GL\end{bmatrix},\quad
        C = [-FLc_\rho,\ -FM],\quad D = -FL,

    :math:`G = \Phi - \Gamma F`.
    """
    _check_design(rho, b0, omega0, ts, ratio)
    phi, gam = eso_zoh(rho, b0, ts)
    el = _observer_gain(rho, omega0, ts, alphas)
    wc = omega0 / ratio if omega_c is None else _positive("omega_c", omega_c)
    f = _feedback_row(rho, b0, wc, rho if n_feedback is None else n_feedback)
    n = rho + 1
    c = np.eye(1, n)[0]
    m = np.eye(n) - np.outer(el, c)
    g = phi - np.outer(gam, f)
    phi_r, gam_r, c_r = phi[:rho, :rho], gam[:rho], np.eye(1, rho)[0]
    fl = float(f @ el)
    a = np.block(
        [
            [phi_r - fl * np.outer(gam_r, c_r), -np.outer(gam_r, f @ m)],
            [np.outer(g @ el, c_r), g @ m],
        ]
    )
    b = np.concatenate([-fl * gam_r, g @ el])
    cc = np.concatenate([-fl * c_r, -(f @ m)])
    return a, b, cc, -fl


def noise_rms_gain(
    rho: int,
    b0: float,
    omega0: float,
    ts: float,
    *,
    ratio: float = OBSERVER_RATIO,
    omega_c: float | None = None,
    alphas: ArrayLike | None = None,
    n_feedback: int | None = None,
) -> float:
    r""":math:`\lVert T_{nu}\rVert_2 = \sqrt{D^2 + CWC^T}`, :math:`W = AWA^T + BB^T`
    (:func:`noise_loop`): the command's standard deviation per unit standard deviation of
    a white measurement noise.  ``inf`` when the loop is not stable (spectral radius >= 1)."""
    from scipy.linalg import solve_discrete_lyapunov

    a, b, c, d = noise_loop(
        rho, b0, omega0, ts, ratio=ratio, omega_c=omega_c, alphas=alphas, n_feedback=n_feedback
    )
    if not np.all(np.isfinite(a)) or np.max(np.abs(np.linalg.eigvals(a))) >= 1.0 - 1e-12:
        return math.inf
    # in the scaled coordinates t^(i-1) x_i, t^(i-1) p_i (t = 1/max(omega0, omega_c), or
    # Ts when that is shorter) the entries are of order one
    fastest = max(omega0, omega0 / ratio if omega_c is None else omega_c)
    unit = ts / min(fastest * ts, 1.0)
    scale = unit ** np.concatenate([np.arange(rho), np.arange(rho + 1)], dtype=np.float64)
    a_s = a * scale[:, None] / scale[None, :]
    b_s, c_s = b * scale, c / scale
    w = solve_discrete_lyapunov(a_s, np.outer(b_s, b_s))
    return math.sqrt(max(d * d + float(c_s @ w @ c_s), 0.0))


def largest_omega0(
    noise_of: Callable[[float], float], budget: float, lo: float, hi: float
) -> tuple[float, str]:
    r"""The largest :math:`\omega_0 \in [lo, hi]` with ``noise_of(ω0) <= budget`` for a
    noise that grows with ω0: :func:`scipy.optimize.brentq` on
    :math:`\log(\text{noise}/\text{budget})` in :math:`\log\omega_0`.  Returns (ω0, how):
    ``hi`` with how ``"not binding"`` when even hi meets it, ``lo`` with how
    ``"exceeded"`` when even lo does not, else how ``"solved"``.

    Parameters
    ----------
    noise_of, budget, lo, hi
        ω₀ -> the noise (growing with ω₀), its budget, and the range of ω₀ searched [rad/s].

    Returns
    -------
    tuple of (float, str)
    """
    from scipy.optimize import brentq

    def excess(log_w: float) -> float:
        val = noise_of(math.exp(log_w))
        return math.log(val / budget) if math.isfinite(val) and val > 0 else 700.0

    if excess(math.log(hi)) <= 0:
        return hi, "not binding"
    if excess(math.log(lo)) > 0:
        return lo, "exceeded"
    root = brentq(excess, math.log(lo), math.log(hi), xtol=1e-12, rtol=1e-12)
    return math.exp(root), "solved"


def noise_cap(
    rho: int,
    b0: float,
    ts: float,
    *,
    noise_variance: float,
    u_scale: float,
    scale_label: str = "the input's scale",
    ratio: float = OBSERVER_RATIO,
    omega_c: float | None = None,
    alphas: ArrayLike | None = None,
    n_feedback: int | None = None,
    upper: float | None = None,
) -> Cap:
    r"""The largest ω0 with :math:`\sqrt{R_d}\lVert T_{nu}\rVert_2 \le`
    :data:`NOISE_FRACTION` · ``u_scale`` (module notes), searched over
    :math:`[\max(10^{-4}/T_s, \omega_c),` ``upper`` :math:`]` (default :math:`\pi/T_s`;
    :math:`\omega_c` only when held).  ``inf`` for a
    noise-free measurement.

    Parameters
    ----------
    rho, b0, ts, ratio, omega_c, alphas, n_feedback
        As for :func:`noise_gain`.
    noise_variance, u_scale, scale_label, upper
        :math:`R_d` per sample (≥ 0), the input's scale (> 0), how the cap names it, and
        the top of the search [rad/s].

    Returns
    -------
    Cap
    """
    _positive("ts", ts)
    if not (math.isfinite(noise_variance) and noise_variance >= 0):
        raise ValueError(f"noise variance = {noise_variance!r}; allowed: finite and >= 0")
    if noise_variance == 0:
        return Cap("noise", math.inf, "noise-free measurement: no noise cap", _NOISE_SOURCE)
    _positive("u_scale", u_scale)
    sigma = math.sqrt(noise_variance)
    budget = NOISE_FRACTION * u_scale
    hi = math.pi / ts if upper is None else float(upper)
    # the floor: ω0 Ts = 1e-4, and with ω_c held no observer slower than the loop
    lo = max(_LOWEST_OMEGA0_TS / ts, omega_c or 0.0)

    def std_u(w0: float) -> float:
        return sigma * noise_rms_gain(
            rho, b0, w0, ts, ratio=ratio, omega_c=omega_c, alphas=alphas, n_feedback=n_feedback
        )

    w, how = largest_omega0(std_u, budget, lo, min(hi, math.pi / ts))
    rule = (
        f"std(u) = sqrt(R_d)*||T_nu||_2 <= {NOISE_FRACTION:g} x {u_scale:.4g} ({scale_label}), "
        f"sqrt(R_d) = {sigma:.3g}"
    )
    if how == "not binding":
        return Cap("noise", math.inf, rule + f"; met up to omega0 = {w:.4g}", _NOISE_SOURCE)
    if how == "exceeded":
        floor = "omega_c" if omega_c and w == omega_c else f"{_LOWEST_OMEGA0_TS:g}/Ts"
        rule += f"; exceeded already at omega0 = {w:.3g} rad/s ({floor}, the search's floor)"
    return Cap("noise", w, rule, _NOISE_SOURCE)


def omega0_ceiling(
    *,
    rho: int,
    b0: float,
    ts: float | None,
    delay: float = 0.0,
    noise_variance: float = 0.0,
    u_scale: float | None = None,
    scale_label: str = "the input's scale",
    ratio: float = OBSERVER_RATIO,
    omega_c: float | None = None,
    alphas: ArrayLike | None = None,
    n_feedback: int | None = None,
    told: bool = False,
    notes: Sequence[str] = (),
) -> Ceiling:
    """The three caps (module notes) and the binding one.  The noise cap needs a sampled
    controller (``ts``) and ``u_scale``; without them it is reported as not computed.

    Parameters
    ----------
    rho, b0, ts, ratio, omega_c, alphas, n_feedback, noise_variance, u_scale, scale_label
        As for :func:`noise_cap`; ``ts`` None: a continuous controller.
    delay, told, notes
        The loop's delay [s], whether the observer is told it, sentences to report.

    Returns
    -------
    Ceiling
    """
    caps = [sampling_cap(ts), delay_cap(delay, told=told)]
    extra = list(notes)
    if noise_variance > 0 and ts is not None and u_scale:
        caps.append(
            noise_cap(
                rho,
                b0,
                ts,
                noise_variance=noise_variance,
                u_scale=u_scale,
                scale_label=scale_label,
                ratio=ratio,
                omega_c=omega_c,
                alphas=alphas,
                n_feedback=n_feedback,
            )
        )
    elif noise_variance > 0:
        why = "a continuous controller" if ts is None else (scale_label or "no input scale")
        caps.append(Cap("noise", math.nan, f"not computed: {why}", _NOISE_SOURCE))
    else:
        caps.append(Cap("noise", math.inf, "noise-free measurement: no noise cap", _NOISE_SOURCE))
    return Ceiling(tuple(caps), tuple(extra))


# ----------------------------------------------------------------- from a run config
def _loop_delay(cfg: Any) -> float:
    """τ: the scenario's input and output delays, plus one sample of computation delay."""
    tau = float(cfg.scenario.input_delay) + float(cfg.scenario.output_delay)
    if cfg.sampling is not None and int(cfg.sampling.delay) == 1:
        tau += float(cfg.sampling.ts)
    return tau


def _input_scale(cfg: Any) -> tuple[float | None, str]:
    """The actuator's half-range, else |u*| holding the reference's operating value."""
    lo, hi = cfg.controller.u_range()
    if math.isfinite(lo) and math.isfinite(hi):
        return 0.5 * (hi - lo), f"actuator half-range ({lo:g} .. {hi:g})"
    from aiofl.analysis.closed_loop import reference_operating_value
    from aiofl.plants.operating_point import trim

    try:
        y_op = reference_operating_value(cfg.scenario.reference)
        u_op = float(trim(cfg.plant, y_op).u)
    except Exception:  # no equilibrium there: no scale to compare the noise with
        return None, (
            "no actuator limit (law.u_max) and no operating point: no scale for the "
            "command's noise (give u_scale)"
        )
    if not math.isfinite(u_op) or u_op == 0.0:
        return None, (
            f"no actuator limit (law.u_max) and a zero holding input at y = {y_op:g}: "
            "no scale for the command's noise (give u_scale)"
        )
    return abs(u_op), f"|u*| = {abs(u_op):.4g}, the input holding y = {y_op:g}"


def config_ceiling(
    cfg: Any, *, u_scale: float | None = None, hold_omega_c: bool = False
) -> Ceiling:
    """:func:`omega0_ceiling` for a run config (:class:`aiofl.config.RunConfig`): ρ, b0,
    α, ω0/ω_c and the feedback count from its controller, Ts and the computation delay
    from ``[controller.discrete]``, the measurement noise per sample from its sensor
    (:func:`aiofl.components.kalman.measurement_noise_intensity` / Ts), the loop delay from
    the scenario, the input's scale ``u_scale`` if given, else from ``law.u_max``/``u_min``
    or the trim.  The noise cap needs a linear ESO and a linear SEF (it is reported as not
    computed otherwise); it scans ω0 at the design's ratio ω0/ω_c, or with ``hold_omega_c``
    at the design's ω_c (a search that tunes ω0 alone); a model-assisted observer
    (``eso.model = "nominal"``) is taken as the model-free one of the same ω0 (noted).

    Parameters
    ----------
    cfg, u_scale, hold_omega_c
        The run config, the input's scale (None: as above) and whether ω_c is held.

    Returns
    -------
    Ceiling
    """
    from aiofl.components.kalman import measurement_noise_intensity

    ctl = cfg.controller
    rho = int(ctl.rho)
    ts = None if cfg.sampling is None else float(cfg.sampling.ts)
    notes: list[str] = []
    told = bool(ctl.value("eso.delay"))
    tau = _loop_delay(cfg)
    var = 0.0
    if ts is not None:
        var = measurement_noise_intensity(cfg.scenario, cfg.sampling) / ts
    elif float(cfg.scenario.noise_variance) > 0:
        var = float(cfg.scenario.noise_variance)
    kwargs: dict[str, Any] = {}
    scale, label = None, ""
    if ctl.eso != "linear" or ctl.sef != "linear" or ctl.law != "aiofl":
        if var > 0:
            notes.append(
                f"noise cap not computed: it needs a linear ESO and linear SEF (this config: "
                f"eso = {ctl.eso}, sef = {ctl.sef}, law = {ctl.law})"
            )
        var_for_cap = 0.0
    else:
        var_for_cap = var
        w0 = float(ctl.value("eso.omega0"))
        wc = float(ctl.value("sef.omega_c"))
        kwargs = {
            "ratio": w0 / wc,
            "omega_c": wc if hold_omega_c else None,
            "alphas": [float(ctl.value(f"eso.alpha{i}")) for i in range(1, rho + 2)],
            "n_feedback": int(ctl.n_feedback) if ctl.n_feedback is not None else rho,
        }
        if var > 0:
            if u_scale is not None:
                _positive("u_scale", u_scale)
                scale, label = float(u_scale), "the given input scale"
            else:
                scale, label = _input_scale(cfg)
            if ctl.eso_model != "none":
                notes.append(
                    "model-assisted observer: the noise cap is the model-free ESO's of the "
                    "same omega0 (its gains differ by the nominal model's Jacobian)"
                )
            if scale is not None:
                notes.append(
                    (
                        f"noise cap at the design's omega_c = {wc:.4g} rad/s, b0 = "
                        if hold_omega_c
                        else f"noise cap at the design's omega0/omega_c = {w0 / wc:.3g}, b0 = "
                    )
                    + f"{float(ctl.value('law.b0')):.4g}, R_d = {var:.3g} per sample"
                )
    ceiling = omega0_ceiling(
        rho=rho,
        b0=float(ctl.value("law.b0")),
        ts=ts,
        delay=tau,
        noise_variance=var_for_cap,
        u_scale=scale,
        scale_label=label,
        told=told,
        notes=notes,
        **kwargs,
    )
    if var_for_cap == 0.0 and var > 0:  # a nonlinear design: say the cap is not computed
        caps = tuple(
            Cap("noise", math.nan, "not computed (nonlinear ESO or SEF)", _NOISE_SOURCE)
            if c.name == "noise"
            else c
            for c in ceiling.caps
        )
        ceiling = Ceiling(caps, ceiling.notes)
    return ceiling
