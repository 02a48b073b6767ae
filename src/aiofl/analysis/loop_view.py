r"""The loop as an engineer reads it: margins of the loop as it runs, disk margins, noise in u.

Each row is the loop broken at the plant input, linearised at the operating point, with
what it includes said in its label:

* ``"continuous, ideal"``: :math:`L(s)` of :mod:`aiofl.analysis.frequency` (the continuous
  controller, no converter);
* ``"sampled at Ts = 1 ms: ZOH + 1-sample computation delay"``: :math:`L(z)` of
  :meth:`aiofl.analysis.sampled_loop.SampledLoop.broken_loop` (the ZOH plant and the
  engine's own discrete update, with its computation delay);
* ``"... + 1 ms actuator lag"``: a first-order lag :math:`1/(\tau s + 1)` between the DAC
  and the plant, discretised with the plant (one exact ZOH of the plant augmented with the
  lag's state: :math:`\dot a = (u_p - a)/\tau`, the plant driven by a);
* ``"... + 1 sample measurement delay"``: :math:`z^{-d}` between the plant's output and the
  controller (a shift register of d states).

For each: closed-loop stability (spectral radius, or eigenvalues), the classical gain and
phase margins at the crossings (:func:`aiofl.analysis.sampled_loop.unit_circle_margins`,
:func:`aiofl.analysis.frequency.loop_margins`), the delay margin :math:`\min_i
\varphi_i/\omega_{gc,i}` and the **disk margin** (python-control's
:func:`control.disk_margins`, balanced skew σ = 0: the largest α such that every
simultaneous gain and phase change in the disk :math:`D(\alpha, 0)` keeps the loop stable,
with its gain margin :math:`(1+\alpha/2)/(1-\alpha/2)` and phase margin
:math:`2\arctan(\alpha/2)`; Seiler, Packard & Gahinet, "An introduction to disk margins",
IEEE Control Systems Magazine 40(5), 2020, eqs. 6–10).  It is computed on the frequency
grid of :func:`aiofl.analysis.frequency.frequency_grid` (up to the Nyquist frequency
:math:`\pi/T_s` for a sampled loop), refined around its minimum.

**Noise in u.**  Measurement noise n reaches the command through
:math:`T_{nu} = -C/(1 + CP)` (the loop's input sensitivity times the controller).  For the
sampled loop with white noise of variance :math:`\sigma^2` per sample (an ADC quantum q:
:math:`\sigma^2 = q^2/12`, the uniform-quantisation model; Widrow & Kollár, *Quantization
Noise*, 2008, ch. 4), the command's stationary RMS is :math:`\sigma\|T_{nu}\|_2`, the
discrete H2 norm :math:`\|T\|_2^2 = \sum_k h_k^2 = CPC^T + DD^T` with P the
controllability Gramian (:func:`scipy.linalg.solve_discrete_lyapunov`).  Also printed:
:math:`|T_{nu}|` at the Nyquist frequency (each sample's noise times this reaches u at the
highest frequency) and its peak.  For the continuous loop, :math:`\max_\omega|T_{nu}|`
and the H2 norm (continuous Gramian) for noise of spectral density :math:`\sigma^2 h`
(noise held over h s: the scenario's ``noise_hold``; valid while :math:`T_{nu}` is flat
beyond 1/h, as a ZOH'd white sequence's spectrum is).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl.analysis.sampled_loop import SampledLoop, unit_circle_margins, zoh

__all__ = [
    "LAG_MAX",
    "MEASUREMENT_DELAY_MAX",
    "RigLoop",
    "check_loop_options",
    "continuous_disk_margin",
    "disk_margin",
    "format_loop_view_text",
    "loop_view",
    "rig_loop",
]

LAG_MAX = 10.0
"""Largest actuator lag [s] the analysis takes (a lag longer than 10 s is not an actuator)."""
MEASUREMENT_DELAY_MAX = 1000
"""Most samples of measurement delay (one state each in the analysed loop)."""


def check_loop_options(lag: float, delay_samples: int, noise_std: float | None = None) -> None:
    """Raise ValueError naming the option unless ``lag``, ``delay_samples`` and
    ``noise_std`` are in range (for a CLI that checks before any work).

    Parameters
    ----------
    lag
        The actuator lag [s], finite and ≥ 0.
    delay_samples
        The measurement delay in samples, an integer ≥ 0.
    noise_std
        The measurement noise's standard deviation, finite and ≥ 0 (None: not given).
    """
    _check_options(lag, delay_samples)
    if noise_std is not None and not (math.isfinite(noise_std) and noise_std >= 0.0):
        raise ValueError(f"noise_std = {noise_std!r}; allowed: a finite number >= 0")


def _check_options(lag: float, delay_samples: int) -> None:
    if isinstance(lag, bool) or not (math.isfinite(lag) and 0.0 <= lag <= LAG_MAX):
        raise ValueError(f"lag = {lag!r} s; allowed: 0 <= lag <= {LAG_MAX:g} s")
    if (
        isinstance(delay_samples, bool)
        or not isinstance(delay_samples, int | np.integer)
        or not 0 <= delay_samples <= MEASUREMENT_DELAY_MAX
    ):
        raise ValueError(
            f"delay_samples = {delay_samples!r}; allowed: an integer, "
            f"0 <= delay_samples <= {MEASUREMENT_DELAY_MAX}"
        )


# ------------------------------------------------------------------ the rig's loop
@dataclass(frozen=True)
class RigLoop:
    r"""The sampled loop with the rig's lag and measurement delay (module docstring).

    ``a, b, c``: broken at the plant input, :math:`L(z) = -c(zI - a)^{-1}b` (input the
    held command, output the command the DAC applies).  ``a_cl, b_n, c_u, d_u``: the closed
    loop driven by measurement noise n (added to the measurement the controller reads),
    output the command computed at the sample.  ``ts``: the sample time.
    """

    a: NDArray[np.float64]
    b: NDArray[np.float64]
    c: NDArray[np.float64]
    a_cl: NDArray[np.float64]
    b_n: NDArray[np.float64]
    c_u: NDArray[np.float64]
    d_u: float
    ts: float

    @property
    def spectral_radius(self) -> float:
        """:math:`\\max|\\lambda(a_{cl})|` (the loop is stable iff < 1)."""
        return float(np.max(np.abs(np.linalg.eigvals(self.a_cl))))

    def loop_transfer(self) -> Any:
        """:math:`L(z)` as a discrete ``control.StateSpace`` (dt = Ts)."""
        import control

        return control.ss(self.a, self.b, -self.c, 0.0, self.ts)

    def noise_transfer(self) -> Any:
        """n → u as a discrete ``control.StateSpace`` (dt = Ts)."""
        import control

        return control.ss(self.a_cl, self.b_n, self.c_u, self.d_u, self.ts)


def rig_loop(loop: SampledLoop, ts: float, lag: float = 0.0, delay_samples: int = 0) -> RigLoop:
    r"""The sampled loop of ``loop`` at ``ts`` with an actuator lag ``lag`` [s] (0: none)
    and ``delay_samples`` samples of measurement delay (module docstring).

    With ``lag = 0`` and ``delay_samples = 0`` its broken loop is
    :meth:`SampledLoop.broken_loop` and its closed loop :meth:`SampledLoop.matrix`.

    Parameters
    ----------
    loop
        The linearised sampled loop (:class:`SampledLoop`); refused when it has none.
    ts
        The sample time [s].
    lag
        The actuator's first-order lag τ [s] (0, the default: none).
    delay_samples
        Samples of measurement delay (0, the default: none).

    Returns
    -------
    RigLoop
    """
    _check_options(lag, delay_samples)
    if not loop.available:
        raise ValueError(loop.reason)
    jcc, jcy, juc, juy, keep, i_up = loop._controller_pieces(ts)
    ap, bp, cp = loop.ap, loop.bp, loop.cp[0]
    if lag > 0.0:  # the plant driven by the lag's state a, a' = (u_p - a)/τ
        n0 = ap.shape[0]
        ap2 = np.zeros((n0 + 1, n0 + 1))
        ap2[:n0, :n0], ap2[:n0, n0] = ap, bp[:, 0]
        ap2[n0, n0] = -1.0 / lag
        bp = np.zeros((n0 + 1, 1))
        bp[n0, 0] = 1.0 / lag
        ap, cp = ap2, np.append(cp, 0.0)
    phi, gam = zoh(ap, bp, ts)
    n, nk, d = phi.shape[0], keep.size, int(delay_samples)
    nt = n + nk + d
    ym = np.zeros(nt)  # the measurement the controller reads, as a row of the state
    if d:
        ym[n + nk + d - 1] = 1.0
    else:
        ym[:n] = cp
    a = np.zeros((nt, nt))
    a[:n, :n] = phi
    a[n : n + nk, :] += np.outer(jcy, ym)
    a[n : n + nk, n : n + nk] += jcc
    if d:
        a[n + nk, :n] = cp
        for j in range(1, d):
            a[n + nk + j, n + nk + j - 1] = 1.0
    b = np.zeros((nt, 1))
    b[:n, 0] = gam[:, 0]
    u_now = np.zeros(nt)  # the command computed at the sample
    u_now[n : n + nk] = juc
    u_now += juy * ym
    c = np.zeros((1, nt))
    if loop.base.delay:
        c[0, n + i_up] = 1.0
    else:
        c[0] = u_now
    a_cl = a + b @ c
    b_n = np.zeros(nt)
    b_n[n : n + nk] = jcy
    if not loop.base.delay:
        b_n[:n] += gam[:, 0] * juy
    return RigLoop(a, b, c, a_cl, b_n[:, None], u_now[None, :], float(juy), float(ts))


# ------------------------------------------------------------------ disk margins
def disk_margin(
    loop: Any, omega: NDArray[np.float64], *, skew: float = 0.0
) -> tuple[float, float, float, float]:
    r"""``(α, gain margin [dB], phase margin [°], ω)`` of the disk margin of a SISO loop
    (:func:`control.disk_margins` on ``omega``, its minimum refined on 401 points between
    the grid's neighbours); ω where the worst case is.  The loop's closed loop must be
    stable (not checked here).

    Parameters
    ----------
    loop
        The loop transfer function, a ``control`` system.
    omega
        The frequency grid [rad/s].
    skew
        The disk's skew σ of :func:`control.disk_margins` (0: the symmetric disk).

    Returns
    -------
    alpha, gain_margin_db, phase_margin_deg, omega : float
    """
    import control

    w = np.asarray(omega, dtype=np.float64)
    dm, _, _ = control.disk_margins(loop, w, skew=skew, returnall=True)
    i = int(np.argmin(dm))
    lo, hi = w[max(i - 1, 0)], w[min(i + 1, w.size - 1)]
    fine = np.linspace(lo, hi, 401)
    dm2, dgm2, dpm2 = control.disk_margins(loop, fine, skew=skew, returnall=True)
    j = int(np.argmin(dm2))
    if dm2[j] <= dm[i]:
        return float(dm2[j]), float(dgm2[j]), float(dpm2[j]), float(fine[j])
    _, dgm, dpm = control.disk_margins(loop, w[i : i + 1], skew=skew, returnall=True)
    return float(dm[i]), float(dgm[0]), float(dpm[0]), float(w[i])


def _discrete_grid(a: NDArray[np.float64], ts: float) -> NDArray[np.float64]:
    """A log grid up to π/Ts from the continuous equivalents :math:`\\log z / T_s` of the
    eigenvalues (:func:`aiofl.analysis.frequency.frequency_grid`), with π/Ts itself."""
    from aiofl.analysis.frequency import frequency_grid

    z = np.linalg.eigvals(a)
    z = z[np.abs(z) > 1e-12]
    nyq = math.pi / ts
    grid = frequency_grid(np.log(z.astype(np.complex128)) / ts)
    grid = grid[grid < nyq]
    return np.unique(np.r_[np.logspace(math.log10(nyq) - 5, math.log10(nyq), 600), grid, nyq])


# ------------------------------------------------------------------ H2 norms
def _h2_discrete(a: Any, b: Any, c: Any, d: float) -> float:
    from scipy.linalg import solve_discrete_lyapunov

    p = solve_discrete_lyapunov(a, b @ b.T)
    return float(math.sqrt(max(float((c @ p @ c.T)[0, 0]) + d * d, 0.0)))


def _h2_continuous(a: Any, b: Any, c: Any, d: float) -> float:
    from scipy.linalg import matrix_balance, solve_continuous_lyapunov

    if d != 0.0:
        return math.inf
    # balanced first: the solver judges "λ_i + λ_j close to 0" relative to ‖A‖, which a
    # closed loop with b0-scaled entries (‖A‖ ~ 1e7) makes look singular
    a, (sc, _) = matrix_balance(a, separate=True, permute=False)
    b, c = b / sc[:, None], c * sc[None, :]
    p = solve_continuous_lyapunov(a, -b @ b.T)
    return float(math.sqrt(max(float((c @ p @ c.T)[0, 0]), 0.0)))


def _peak(sys: Any, w: NDArray[np.float64]) -> tuple[float, float]:
    mag = np.abs(np.asarray(sys(1j * w if sys.dt == 0 else np.exp(1j * w * sys.dt))).ravel())
    i = int(np.argmax(mag))
    return float(mag[i]), float(w[i])


# ------------------------------------------------------------------ the rows
def _fmt_ms(v: float) -> str:
    return f"{v * 1e3:g} ms"


def _labels(ts: float, delay: int, lag: float, d: int) -> str:
    base = f"sampled at Ts = {_fmt_ms(ts)}: ZOH + {delay}-sample computation delay"
    if lag > 0.0:
        base += f" + {_fmt_ms(lag)} actuator lag"
    if d:
        base += f" + {d} sample{'s' if d > 1 else ''} measurement delay"
    return base


def _continuous_rows(
    config: Any, lag: float, lin: Any, noise_std: float | None
) -> list[dict[str, Any]]:
    import control

    from aiofl.analysis.frequency import frequency_grid, loop_margins
    from aiofl.analysis.linearize import linearize_closed_loop

    lin = lin or linearize_closed_loop(config)
    a, b, c, d = (np.asarray(m, dtype=np.float64) for m in lin.loop)
    rows = []
    for lg in (0.0, lag) if lag > 0.0 else (0.0,):
        if lg > 0.0:
            n = a.shape[0]
            a2 = np.zeros((n + 1, n + 1))
            a2[:n, :n], a2[:n, n] = a, b[:, 0]
            a2[n, n] = -1.0 / lg
            b2 = np.zeros((n + 1, 1))
            b2[n, 0] = 1.0 / lg
            c2, d2 = np.hstack([c, d]), np.zeros_like(d)
        else:
            a2, b2, c2, d2 = a, b, c, d
        loop = control.ss(a2, b2, -c2, -d2)
        # closing u_p = u: a + b (1 - d)^-1 c
        a_cl = a2 + b2 @ np.linalg.solve(np.eye(1) - d2, c2)
        eig = np.linalg.eigvals(a_cl)
        m = loop_margins(loop, eig)
        stable = bool(np.all(eig.real < 0.0))
        row: dict[str, Any] = {
            "label": "continuous, ideal"
            if lg == 0.0
            else f"continuous + {_fmt_ms(lg)} actuator lag",
            "stable": stable,
            "max_real": float(np.max(eig.real)),
            **{k: v for k, v in m.to_dict().items() if k != "margin_notes"},
        }
        grid = frequency_grid(eig, np.linalg.eigvals(a2))
        row.update(_disk_row(loop, grid, stable))
        if lg == 0.0 and stable:  # n -> u of the continuous loop (the input "n")
            j = lin.input_names.index("n")
            an, bn = lin.a, lin.b[:, [j]]
            cn, dn = lin.c[[1], :], float(lin.d[1, j])
            tn = control.ss(an, bn, cn, dn)
            peak, w_peak = _peak(tn, grid)
            h2 = _h2_continuous(an, bn, cn, dn)
            hold = float(config.scenario.noise_hold)
            row["noise_to_u"] = {
                "h2_per_unit_std": h2 * math.sqrt(hold),
                "peak_gain": peak,
                "peak_frequency": w_peak,
                "high_frequency_gain": abs(dn),
                "noise_hold": hold,
                "u_rms": None if noise_std is None else h2 * math.sqrt(hold) * noise_std,
            }
        rows.append(row)
    return rows


def continuous_disk_margin(lin: Any) -> dict[str, Any]:
    """The disk margin of a :class:`aiofl.analysis.linearize.Linearization`'s loop broken at
    the plant input: ``{"disk_margin", "disk_gain_margin_db", "disk_phase_margin_deg",
    "disk_frequency"}`` (None values when the closed loop is not stable)."""
    from aiofl.analysis.frequency import frequency_grid

    loop = lin.loop_transfer()
    stable = lin.verdict() == "stable"
    return _disk_row(loop, frequency_grid(lin.eigenvalues, np.linalg.eigvals(loop.A)), stable)


def _disk_row(loop: Any, grid: NDArray[np.float64], stable: bool) -> dict[str, Any]:
    if not stable:
        return {"disk_margin": None, "disk_gain_margin_db": None, "disk_phase_margin_deg": None}
    alpha, dgm, dpm, w = disk_margin(loop, grid)

    def num(v: float) -> float | None:
        return float(v) if math.isfinite(v) else None

    return {
        "disk_margin": num(alpha),
        "disk_gain_margin_db": num(dgm),
        "disk_phase_margin_deg": num(dpm),
        "disk_frequency": w,
    }


def _sampled_row(
    loop: SampledLoop, ts: float, lag: float, d: int, noise_std: float | None
) -> dict[str, Any]:
    rig = rig_loop(loop, ts, lag, d)
    radius = rig.spectral_radius
    stable = radius < 1.0
    row: dict[str, Any] = {
        "label": _labels(ts, loop.base.delay, lag, d),
        "stable": stable,
        "spectral_radius": radius,
        **unit_circle_margins(rig.a, rig.b, rig.c, ts),
    }
    grid = _discrete_grid(rig.a_cl, ts)
    row.update(_disk_row(rig.loop_transfer(), grid, stable))
    if stable:
        tn = rig.noise_transfer()
        h2 = _h2_discrete(rig.a_cl, rig.b_n, rig.c_u, rig.d_u)
        peak, w_peak = _peak(tn, grid)
        nyq = abs(complex(np.asarray(tn(-1.0)).ravel()[0]))
        row["noise_to_u"] = {
            "h2_per_unit_std": h2,
            "peak_gain": peak,
            "peak_frequency": w_peak,
            "nyquist_gain": nyq,
            "u_rms": None if noise_std is None else h2 * noise_std,
        }
    return row


def loop_view(
    config: Any,
    *,
    ts: float | None = None,
    lag: float = 0.0,
    delay_samples: int = 0,
    noise_std: float | None = None,
    linearization: Any = None,
) -> dict[str, Any]:
    r"""Margins (classical and disk) and noise-to-u of a config's loop, one row per
    variant, each labelled with what it includes (module docstring).

    Parameters
    ----------
    config
        A :class:`aiofl.config.RunConfig`.
    ts
        Sample time of the sampled rows (default: the config's own; none when the config
        is continuous and ``ts`` is None).
    lag
        Actuator lag τ [s] (first order), 0: none; 0 ≤ τ ≤ :data:`LAG_MAX`.
    delay_samples
        Measurement delay in samples, 0 ≤ d ≤ :data:`MEASUREMENT_DELAY_MAX`.
    noise_std
        Standard deviation σ of the measurement noise per sample (e.g. ``q/√12`` for an
        ADC quantum q); None: the config's own (scenario noise plus the ADC quantum's
        :math:`q^2/12`), or only the gains when it has none.
    linearization
        A :func:`aiofl.analysis.linearize.linearize_closed_loop` result to reuse.

    Returns
    -------
    dict
        ``{"rows": [{"label", "stable", "gain_margin_db", "phase_margin_deg",
        "delay_margin_s", "disk_margin", "disk_gain_margin_db", "disk_phase_margin_deg",
        "noise_to_u": {...}, ...}, ...], "noise_std", "noise_source"}``; a row that could
        not be computed has ``"reason"``.
    """
    check_loop_options(lag, delay_samples, noise_std)
    source = "given"
    if noise_std is None:
        var = float(config.scenario.noise_variance)
        q = float(config.sampling.y_quantum) if config.sampling is not None else 0.0
        var += q * q / 12.0
        if var > 0.0:
            noise_std = math.sqrt(var)
            parts = []
            if config.scenario.noise_variance > 0:
                parts.append(f"scenario noise σ² = {config.scenario.noise_variance:g}")
            if q > 0:
                parts.append(f"ADC quantum q = {q:g} (q²/12)")
            source = " + ".join(parts)
        else:
            source = "none"
    rows: list[dict[str, Any]] = []
    try:
        rows += _continuous_rows(config, lag, linearization, noise_std)
    except ValueError as exc:
        rows.append({"label": "continuous, ideal", "reason": str(exc)})
    if ts is None and config.sampling is not None:
        ts = float(config.sampling.ts)
    if ts is not None:
        loop = SampledLoop(config)
        variants = [(0.0, 0)]
        if lag > 0.0:
            variants.append((lag, 0))
        if delay_samples:
            variants.append((0.0, int(delay_samples)))
        if lag > 0.0 and delay_samples:
            variants.append((lag, int(delay_samples)))
        for lg, d in variants:
            label = _labels(ts, loop.base.delay, lg, d)
            if not loop.available or loop.spectral_radius(ts) is None:
                rows.append({"label": label, "reason": loop.reason or "no linearisation"})
                continue
            rows.append(_sampled_row(loop, ts, lg, d, noise_std))
    return {"rows": rows, "noise_std": noise_std, "noise_source": source}


def _g(v: Any, unit: str = "", none: str = "∞") -> str:
    return none if v is None else f"{v:.4g}{unit}"


def format_loop_view_text(view: dict[str, Any], unit: str = "", u_unit: str = "") -> list[str]:
    """Text lines of :func:`loop_view` (``aiofl analyze --closed-loop``).

    Parameters
    ----------
    view
        A :func:`loop_view` result.
    unit, u_unit
        The output's and the input's units, for the noise lines (``""``: undeclared).

    Returns
    -------
    list of str
    """
    out = ["Margins of the loop broken at the plant input, each with what it includes:"]
    for row in view["rows"]:
        out.append(f"  {row['label']}:")
        if "reason" in row:
            out.append(f"    not analysed: {row['reason']}")
            continue
        if not row["stable"]:
            out.append("    UNSTABLE (no margins)")
            continue
        out.append(
            f"    gain margin {_g(row.get('gain_margin_db'), ' dB')}, phase margin "
            f"{_g(row.get('phase_margin_deg'), '°')}, delay margin "
            f"{_g(row.get('delay_margin_s'), ' s')}"
        )
        out.append(
            f"    disk margin α = {_g(row['disk_margin'])}: gain ×/÷ "
            f"{_g(row['disk_gain_margin_db'], ' dB')} and phase ± "
            f"{_g(row['disk_phase_margin_deg'], '°')} at once"
            + (f" (worst at {row['disk_frequency']:.4g} rad/s)" if "disk_frequency" in row else "")
        )
        nz = row.get("noise_to_u")
        if nz is not None:
            if "nyquist_gain" in nz:
                edge = f"|T_nu| {nz['nyquist_gain']:.4g} at Nyquist"
                white = "white measurement noise per sample"
            else:
                edge = f"|T_nu(∞)| {nz['high_frequency_gain']:.4g}"
                white = f"white noise held over {nz['noise_hold']:g} s"
            line = (
                f"    noise → u: {nz['h2_per_unit_std']:.4g} {u_unit}RMS per unit RMS of "
                f"{white}; {edge}, peak {nz['peak_gain']:.4g} at "
                f"{nz['peak_frequency']:.4g} rad/s"
            )
            out.append(line)
            if nz["u_rms"] is not None:
                sig = f"{view['noise_std']:.4g}" + (f" {unit}" if unit else "")
                out.append(
                    f"    the measurement's noise (σ = {sig}, "
                    f"{view['noise_source']}) moves u by {nz['u_rms']:.4g} {u_unit}RMS"
                )
    return out
