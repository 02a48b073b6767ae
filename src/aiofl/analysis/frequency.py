r"""Frequency-domain analysis of the loop broken at the plant input (python-control).

Breaking the closed loop at the plant input — the plant driven by an external
:math:`u_p`, the controller (ESO, TD, SEF, law) computing its own u from the plant's y —
gives a single-input single-output system :math:`u_p \mapsto u`,
:math:`G(s) = C(sI - A)^{-1}B + D`, linearised at the operating point
(:meth:`aiofl.analysis.closed_loop.ClosedLoop.linear_model` with ``broken=True``).
Closing it with :math:`u_p = u` is positive feedback, so the loop transfer function in
the usual negative-feedback convention is

.. math:: L(s) = -G(s),\qquad S(s) = \frac{1}{1 + L(s)},\qquad
          T(s) = \frac{L(s)}{1 + L(s)}

(Åström & Murray, *Feedback Systems*, 2nd ed., ch. 10: stability margins and the
sensitivity peak).  From :math:`L(j\omega)`:

* gain margin :math:`g_m = 1/|L(j\omega_{pc})|` at a phase crossover
  (:math:`\angle L = -180°`), in dB :math:`20\log_{10} g_m`; infinite without one;
* phase margin :math:`\varphi_m = 180° + \angle L(j\omega_{gc})` at a gain crossover
  (:math:`|L| = 1`); infinite without one;
* delay margin :math:`\tau_m = \min_i \varphi_{m,i}/\omega_{gc,i}` over the gain
  crossovers (:math:`\varphi` in rad, taken in :math:`[0, 2\pi)`): the smallest delay
  :math:`e^{-s\tau}` in the loop that puts a crossing on −1 (defined for a stable loop);
* sensitivity peak :math:`M_s = \max_\omega |S(j\omega)| = 1/\min_\omega|1 + L(j\omega)|`;
* least damping ratio of the closed-loop eigenvalues,
  :math:`\zeta = -\operatorname{Re}\lambda/|\lambda|`.

How they are computed.  L is evaluated exactly from its state-space model (python-control,
one linear solve per frequency) on a logarithmic grid refined around every lightly damped
eigenvalue (:func:`frequency_grid`); each crossing bracketed by a sign change on the grid
(:math:`\log|L|` for the gain crossovers, :math:`\operatorname{Im}L/|L|` with
:math:`\operatorname{Re}L < 0` for the phase crossovers) is refined by
:func:`scipy.optimize.brentq` on the exact response, and each local maximum of
:math:`|S|` by :func:`scipy.optimize.minimize_scalar`; the headline margins are chosen as
:func:`control.stability_margins` chooses them (the gain margin closest to 0 dB, the
smallest absolute phase margin).  :func:`control.stability_margins` itself is not used on these
loops: on a state-space model it first converts to a transfer function, whose polynomial
coefficients for the 10–13 states of a closed loop with :math:`\omega_0 \approx 10^3` span
40 orders of magnitude; on sampled data it interpolates a spline between grid points,
which on the paper's LESO loop (a pole pair 0.14 ± 149j) reported a phase crossover that
the exact response does not have and, on a denser grid, failed to bracket a minimum.  The
tests compare both on low-order loops where it is exact.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "FIGURE_FORMATS",
    "POINTS_PER_DECADE",
    "LoopMargins",
    "frequency_grid",
    "least_damping",
    "loop_figure",
    "loop_figure_bytes",
    "loop_margins",
    "loop_transfer",
]

POINTS_PER_DECADE = 150
"""Density of the frequency grid of :func:`frequency_grid`."""

_MAX_POINTS = 3000


def loop_transfer(
    a: ArrayLike, b: ArrayLike, c: ArrayLike, d: ArrayLike, *, name: str = "L"
) -> Any:
    r"""The loop transfer function :math:`L(s) = -(C(sI-A)^{-1}B + D)` as a
    ``control.StateSpace``, from the loop broken at the plant input (input :math:`u_p`,
    output the controller's u; module docstring).

    Parameters
    ----------
    a, b, c, d
        The state-space matrices of the loop broken at the plant input.
    name
        The system's name (default ``"L"``).

    Returns
    -------
    control.StateSpace
    """
    import control

    return control.ss(
        np.asarray(a, dtype=np.float64),
        np.asarray(b, dtype=np.float64),
        -np.asarray(c, dtype=np.float64),
        -np.asarray(d, dtype=np.float64),
        inputs=["u_p"],
        outputs=["-u"],
        name=name,
    )


def frequency_grid(*eigenvalue_sets: ArrayLike) -> NDArray[np.float64]:
    r"""A logarithmic grid three decades either side of the eigenvalue magnitudes given,
    refined around lightly damped eigenvalues.

    :data:`POINTS_PER_DECADE` points per decade (at most 3000); magnitudes below 1e-9 of
    the largest count as 0 (rounding); 1e-3…1e3 rad/s when every eigenvalue is 0.  Around
    each eigenvalue λ with :math:`|\operatorname{Re}\lambda| < 0.2|\lambda|` (a resonance
    of half-width :math:`|\operatorname{Re}\lambda|` at :math:`\omega = |\operatorname{Im}
    \lambda|`) 201 more points span :math:`|\operatorname{Im}\lambda| \pm
    20|\operatorname{Re}\lambda|`, so the sharp phase turn is resolved wherever it is.
    """
    eig = np.concatenate(
        [np.asarray(e, dtype=np.complex128).ravel() for e in eigenvalue_sets] or [np.zeros(0)]
    )
    eig = eig[np.isfinite(eig)]
    mags = np.abs(eig)
    # magnitudes below 1e-9 of the largest are zero up to rounding (an integrator's pole)
    tiny = 1e-9 * float(np.max(mags, initial=0.0))
    keep = mags > tiny
    eig, mags = eig[keep], mags[keep]
    lo, hi = (float(mags.min()), float(mags.max())) if mags.size else (1.0, 1.0)
    lo_dec, hi_dec = math.floor(math.log10(lo)) - 3, math.ceil(math.log10(hi)) + 3
    n = int(min(_MAX_POINTS, max(200, POINTS_PER_DECADE * (hi_dec - lo_dec))))
    parts = [np.logspace(lo_dec, hi_dec, n)]
    for lam in eig[np.abs(eig.real) < 0.2 * mags]:
        centre, half = abs(lam.imag), max(20.0 * abs(lam.real), 1e-6 * abs(lam))
        if centre > 0.0:
            parts.append(np.linspace(max(centre - half, 0.5 * centre), centre + half, 201))
    grid = np.unique(np.concatenate(parts))
    return grid[(grid >= 10.0**lo_dec) & (grid <= 10.0**hi_dec)]


def least_damping(eigenvalues: ArrayLike) -> tuple[float | None, complex | None]:
    r"""The least damping ratio :math:`\zeta = -\operatorname{Re}\lambda/|\lambda|` of the
    eigenvalues and the eigenvalue it belongs to (None, None if every eigenvalue is 0).

    ζ = 1 for a stable real eigenvalue, −1 for an unstable one, between for a complex pair
    (:func:`control.damp` computes the same from a system's poles)."""
    eig = np.asarray(eigenvalues, dtype=np.complex128).ravel()
    eig = eig[np.abs(eig) > 0.0]
    if eig.size == 0:
        return None, None
    zeta = -eig.real / np.abs(eig)
    i = int(np.argmin(zeta))
    return float(zeta[i]), complex(eig[i])


@dataclass(frozen=True)
class LoopMargins:
    """Stability margins of the loop broken at the plant input (module docstring).

    Attributes
    ----------
    gain_margin
        :math:`g_m` as a ratio (``inf``: no phase crossover).
    phase_margin_deg
        :math:`\\varphi_m` in degrees (``inf``: no gain crossover).
    delay_margin_s
        :math:`\\tau_m` in seconds (``inf``: no gain crossover; ``nan``: the closed loop is
        not stable, so there is none).
    ms, ms_frequency
        Sensitivity peak :math:`M_s` and where it occurs [rad/s] (``inf`` frequency: the
        supremum is approached as ω → ∞).
    phase_crossover, gain_crossover
        :math:`\\omega_{pc}`, :math:`\\omega_{gc}` [rad/s] of the reported margins (nan if none).
    min_damping, least_damped
        Least damping ratio of the closed-loop eigenvalues and that eigenvalue.
    open_loop_rhp_poles
        Poles of L in the open right half plane (the Nyquist criterion needs that many
        counter-clockwise encirclements of −1).
    notes
        Remarks (RHP poles of L, no crossings, ...).
    """

    gain_margin: float
    phase_margin_deg: float
    delay_margin_s: float
    ms: float
    ms_frequency: float
    phase_crossover: float
    gain_crossover: float
    min_damping: float | None
    least_damped: complex | None
    open_loop_rhp_poles: int
    notes: tuple[str, ...]

    @property
    def gain_margin_db(self) -> float:
        """:math:`20\\log_{10} g_m` (``inf`` without a phase crossover)."""
        if self.gain_margin <= 0.0:
            return -math.inf
        return 20.0 * math.log10(self.gain_margin) if math.isfinite(self.gain_margin) else math.inf

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``gain_margin_db``, ``phase_margin_deg``, ``delay_margin_s``, ``ms``,
        ``min_damping`` (None where undefined or infinite; ``notes`` says which) and the
        crossover frequencies."""

        def num(v: float | None) -> float | None:
            return float(v) if v is not None and math.isfinite(v) else None

        return {
            "gain_margin_db": num(self.gain_margin_db),
            "phase_margin_deg": num(self.phase_margin_deg),
            "delay_margin_s": num(self.delay_margin_s),
            "ms": num(self.ms),
            "min_damping": num(self.min_damping),
            "least_damped": (
                None
                if self.least_damped is None
                else [self.least_damped.real, self.least_damped.imag]
            ),
            "phase_crossover_rad_s": num(self.phase_crossover),
            "gain_crossover_rad_s": num(self.gain_crossover),
            "ms_frequency_rad_s": num(self.ms_frequency),
            "open_loop_rhp_poles": self.open_loop_rhp_poles,
            "margin_notes": list(self.notes),
        }


def _delay_margin(pm_deg: NDArray[np.float64], w_gc: NDArray[np.float64]) -> float:
    if w_gc.size == 0:
        return math.inf
    phi = np.deg2rad(np.mod(pm_deg, 360.0))  # the delay rotates L clockwise by ωτ
    return float(np.min(phi / w_gc))


def _roots(fun: Any, w: NDArray[np.float64], fw: NDArray[np.float64]) -> NDArray[np.float64]:
    """Zeros of ``fun`` bracketed by sign changes of its samples ``fw`` on the grid ``w``,
    each refined by :func:`scipy.optimize.brentq` on the exact function."""
    from scipy.optimize import brentq

    ok = np.isfinite(fw)
    out = [float(x) for x in w[ok & (fw == 0.0)]]
    idx = np.nonzero(ok[:-1] & ok[1:] & (np.sign(fw[:-1]) * np.sign(fw[1:]) < 0))[0]
    for i in idx:
        out.append(brentq(fun, w[i], w[i + 1], xtol=1e-15 * w[i], rtol=1e-14))
    return np.array(sorted(out), dtype=np.float64)


def _sensitivity_peak(
    at: Any, w: NDArray[np.float64], lw: NDArray[np.complex128]
) -> tuple[float, float]:
    r""":math:`M_s = \max_\omega |1/(1 + L(j\omega))|` and where: the grid's largest
    samples, each interior local maximum (above half the largest sample) refined by
    :func:`scipy.optimize.minimize_scalar` on the exact response; the grid's ends stand for
    ω → 0 and ω → ∞ (frequency ``inf`` when the supremum is approached as ω → ∞, e.g.
    L = k/s)."""
    from scipy.optimize import minimize_scalar

    s = 1.0 / np.abs(1.0 + lw)
    best, best_w = float(np.max(s)), float(w[int(np.argmax(s))])
    peaks = np.nonzero((s[1:-1] >= s[:-2]) & (s[1:-1] >= s[2:]) & (s[1:-1] >= 0.5 * best))[0] + 1
    for i in peaks:
        res = minimize_scalar(
            lambda lx: -1.0 / abs(1.0 + at(math.exp(lx))),
            bounds=(math.log(w[i - 1]), math.log(w[i + 1])),
            method="bounded",
            options={"xatol": 1e-12},
        )
        if -res.fun > best:
            best, best_w = float(-res.fun), float(math.exp(res.x))
    if best_w == w[-1]:
        best_w = math.inf
    return best, best_w


def loop_margins(
    loop: Any,
    closed_loop_eigenvalues: ArrayLike,
    *,
    omega: ArrayLike | None = None,
    rtol: float = 1e-6,
) -> LoopMargins:
    r"""Gain, phase and delay margins, :math:`M_s` and least damping (module docstring).

    Parameters
    ----------
    loop
        :math:`L(s)` as a ``control.StateSpace`` (:func:`loop_transfer`).
    closed_loop_eigenvalues
        Eigenvalues of the closed loop (for the damping and whether the loop is stable).
    omega
        Frequency grid [rad/s]; default :func:`frequency_grid` of the poles of L and the
        closed-loop eigenvalues.
    rtol
        Relative tolerance for "on the imaginary axis" when counting RHP poles and deciding
        stability.

    Returns
    -------
    LoopMargins
    """
    cl = np.asarray(closed_loop_eigenvalues, dtype=np.complex128).ravel()
    ol = np.asarray(loop.poles(), dtype=np.complex128)
    w = frequency_grid(ol, cl) if omega is None else np.asarray(omega, dtype=np.float64)
    scale_ol = max(1.0, float(np.max(np.abs(ol), initial=0.0)))
    scale_cl = max(1.0, float(np.max(np.abs(cl), initial=0.0)))
    rhp = int(np.sum(ol.real > rtol * scale_ol))
    stable = bool(cl.size == 0 or np.all(cl.real < -rtol * scale_cl))

    a, b, c, d = (np.asarray(m, dtype=np.float64) for m in (loop.A, loop.B, loop.C, loop.D))
    eye = np.eye(a.shape[0])

    def at(wi: float) -> complex:
        """L(jω) = C (jωI − A)⁻¹ B + D, exact (one linear solve)."""
        if a.shape[0] == 0:
            return complex(d[0, 0])
        return complex((c @ np.linalg.solve(1j * wi * eye - a, b))[0, 0] + d[0, 0])

    lw = np.array([at(x) for x in w], dtype=np.complex128)
    with np.errstate(divide="ignore", invalid="ignore"):
        # gain crossovers |L| = 1 (log|L| changes sign); phase crossovers: L on the
        # negative real axis (Im L / |L| changes sign where Re L < 0)
        w_gc = _roots(lambda x: math.log(abs(at(x))), w, np.log(np.abs(lw)))
        w_pc = _roots(lambda x: at(x).imag / abs(at(x)), w, lw.imag / np.abs(lw))
    l_pc = np.array([at(x) for x in w_pc], dtype=np.complex128)
    w_pc, l_pc = w_pc[l_pc.real < 0], l_pc[l_pc.real < 0]
    pms = np.array([np.remainder(np.angle(at(x), deg=True), 360.0) - 180.0 for x in w_gc])
    # the headline margins as python-control's stability_margins picks them: the gain
    # margin closest to 0 dB, the phase margin smallest in magnitude
    gm, wpc = math.inf, math.nan
    if w_pc.size:
        gms = 1.0 / np.abs(l_pc)
        i = int(np.argmin(np.abs(np.log(gms))))
        gm, wpc = float(gms[i]), float(w_pc[i])
    pm, wgc = math.inf, math.nan
    if pms.size:
        i = int(np.argmin(np.abs(pms)))
        pm, wgc = float(pms[i]), float(w_gc[i])
    ms, ms_w = _sensitivity_peak(at, w, lw)
    notes: list[str] = []
    if rhp:
        notes.append(
            f"L has {rhp} pole(s) in the right half plane: the closed loop is stable only "
            f"if the Nyquist plot encircles −1 {rhp} time(s) counter-clockwise; the margins "
            "are distances at the crossings"
        )
    if not np.isfinite(gm):
        notes.append("gain margin infinite: the phase of L never crosses −180°")
    if not np.isfinite(pm):
        notes.append("phase and delay margins infinite: |L| never crosses 1")
    dm = _delay_margin(pms, w_gc)
    if not stable:
        dm = math.nan
        notes.append("delay margin undefined: the closed loop is not stable")
    zeta, lam = least_damping(cl)
    return LoopMargins(
        gain_margin=gm,
        phase_margin_deg=pm,
        delay_margin_s=dm,
        ms=ms,
        ms_frequency=ms_w,
        phase_crossover=wpc,
        gain_crossover=wgc,
        min_damping=zeta,
        least_damped=lam,
        open_loop_rhp_poles=rhp,
        notes=tuple(notes),
    )


# ------------------------------------------------------------------------ figure
def loop_figure(
    loop: Any, margins: LoopMargins, title: str, omega: ArrayLike | None = None
) -> Figure:
    """Bode plot (:math:`|L|`, :math:`|S|` in dB, ∠L in degrees) and Nyquist plot of L near −1.

    The crossovers of the reported margins are marked; the Nyquist panel shows L(jω) for
    ω > 0 (solid) and its mirror ω < 0 (dashed) within a window around −1, with the circle
    of radius :math:`1/M_s` about −1 that the curve touches.  ``title`` (it holds a
    config's name) is drawn as plain text: a ``$`` in it is no mathtext.

    Parameters
    ----------
    loop
        L(s), a ``control`` system (:func:`loop_transfer`).
    margins
        The margins to mark.
    title
        The figure's title, plain text.
    omega
        The frequencies [rad/s] (default: a grid from the open- and closed-loop poles).

    Returns
    -------
    matplotlib.figure.Figure
    """
    import control
    from matplotlib.figure import Figure

    if omega is None:
        closed = control.feedback(loop, 1).poles()
        w = frequency_grid(loop.poles(), closed)
    else:
        w = np.asarray(omega, dtype=np.float64)
    lw = np.asarray(loop(1j * w), dtype=np.complex128).ravel()
    sw = 1.0 / (1.0 + lw)
    fig = Figure(figsize=(11.0, 6.0))
    grid = fig.add_gridspec(2, 2, width_ratios=(1.5, 1.0), left=0.07, right=0.98, wspace=0.25)
    ax_mag, ax_ph = fig.add_subplot(grid[0, 0]), fig.add_subplot(grid[1, 0])
    ax_ny = fig.add_subplot(grid[:, 1])
    with np.errstate(divide="ignore"):
        ax_mag.semilogx(w, 20 * np.log10(np.abs(lw)), label="|L|")
        ax_mag.semilogx(w, 20 * np.log10(np.abs(sw)), "--", label="|S| = |1/(1+L)|")
    ax_mag.axhline(0.0, color="0.5", lw=0.8)
    ax_mag.set_ylabel("magnitude [dB]")
    ax_mag.legend(loc="best", fontsize=8)
    phase = np.rad2deg(np.unwrap(np.angle(lw)))
    ax_ph.semilogx(w, phase)
    for k in range(-4, 2):
        if phase.min() - 90 < -180 + 360 * k < phase.max() + 90:
            ax_ph.axhline(-180 + 360 * k, color="0.5", lw=0.8)
    ax_ph.set_ylabel("phase of L [deg]")
    ax_ph.set_xlabel("ω [rad/s]")
    if math.isfinite(margins.gain_crossover):
        for ax in (ax_mag, ax_ph):
            ax.axvline(margins.gain_crossover, color="C2", ls=":", lw=1)
        ax_ph.annotate(
            f"PM {margins.phase_margin_deg:.3g}° at {margins.gain_crossover:.3g} rad/s",
            (0.02, 0.05), xycoords="axes fraction", fontsize=8, color="C2",
        )  # fmt: skip
    if math.isfinite(margins.phase_crossover):
        for ax in (ax_mag, ax_ph):
            ax.axvline(margins.phase_crossover, color="C3", ls=":", lw=1)
        ax_mag.annotate(
            f"GM {margins.gain_margin_db:.3g} dB at {margins.phase_crossover:.3g} rad/s",
            (0.02, 0.05), xycoords="axes fraction", fontsize=8, color="C3",
        )  # fmt: skip
    radius = 3.0
    inside = np.abs(lw + 1.0) < radius
    ny_re, ny_im = np.where(inside, lw.real, np.nan), np.where(inside, lw.imag, np.nan)
    ax_ny.plot(ny_re, ny_im, "C0", label="L(jω), ω > 0")
    ax_ny.plot(ny_re, -ny_im, "C0--", lw=0.8, label="ω < 0")
    ax_ny.plot([-1.0], [0.0], "r+", ms=10)
    t = np.linspace(0, 2 * np.pi, 200)
    if math.isfinite(margins.ms) and margins.ms > 0:
        rr = 1.0 / margins.ms
        ax_ny.plot(
            -1 + rr * np.cos(t), rr * np.sin(t), color="C1", lw=0.8, label=f"1/Ms = {rr:.3g}"
        )
    ax_ny.plot(np.cos(t), np.sin(t), color="0.7", lw=0.6)
    ax_ny.set_xlim(-1 - radius, -1 + radius)
    ax_ny.set_ylim(-radius, radius)
    ax_ny.set_aspect("equal")
    ax_ny.set_xlabel("Re L")
    ax_ny.set_ylabel("Im L")
    ax_ny.legend(loc="upper right", fontsize=8)
    ax_ny.set_title("Nyquist (window around −1)", fontsize=10)
    fig.suptitle(title, fontsize=11, parse_math=False)  # holds the config's name: plain text
    return fig


FIGURE_FORMATS = ("png", "pdf", "svg")
"""File formats :func:`loop_figure_bytes` writes."""


def loop_figure_bytes(loop: Any, margins: LoopMargins, title: str, fmt: str = "png") -> bytes:
    """:func:`loop_figure` rendered to bytes in ``fmt`` (one of :data:`FIGURE_FORMATS`;
    Agg canvas, no pyplot state).

    Parameters
    ----------
    loop, margins, title
        As for :func:`loop_figure`.
    fmt
        An image format of :data:`FIGURE_FORMATS` (default ``"png"``).

    Returns
    -------
    bytes
        The image file's content.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    if fmt not in FIGURE_FORMATS:
        raise ValueError(f"figure format {fmt!r}; allowed: {', '.join(FIGURE_FORMATS)}")
    fig = loop_figure(loop, margins, title)
    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=110)
    return buf.getvalue()
