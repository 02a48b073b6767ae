r"""What a simulation did, measured from its trajectory, set beside the linearisation verdict.

The closed-loop linearisation (:func:`aiofl.analysis.linearize.closed_loop_verdict`) judges
the loop near one operating point: the reference held constant at :math:`r^*`, the secant
gains of the non-smooth elements taken at a small error amplitude ε.  A run tracks a
time-varying reference with larger errors, so the two can disagree.  This module measures
the run (:func:`measure`) and writes one sentence per case that states both and says
whether they agree (:func:`reconcile`).

Measured over the last ``window`` seconds of the stored trajectory, with the tracking error
:math:`e = y - r` (the sign of the ITAE integrand of eq. 22):

* :math:`\max|e|`, the peak error;
* the oscillation amplitude :math:`A = (\max e - \min e)/2` and its centre
  :math:`(\max e + \min e)/2`;
* the growth :math:`\max_{\text{last window}}|e| / \max_{\text{window before}}|e|`.

A run *tracks* when :math:`\max|e| \le` ``tolerance`` × the reference's peak
:math:`\max|r|` over the same window; it is *growing* when it does not track and its peak
error more than doubled from one window to the next; otherwise it is *bounded* (it stays
near the reference's scale without tracking it).  A run that left the divergence threshold
is *diverged*, with its time.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:
    from aiofl.engine.simulation import SimulationResult

__all__ = [
    "ANALYSIS_KEYS",
    "Behaviour",
    "analysis_numbers",
    "measure",
    "measure_result",
    "min_damping",
    "orbit_numbers",
    "orbit_stable",
    "reconcile",
    "window_for",
]

Kind = Literal["lost", "diverged", "tracks", "bounded", "growing"]

WINDOW = 5.0
"""Default measurement window [s]: the last 5 s of the run."""
TOLERANCE = 0.05
"""A run tracks when max |e| over the window is at most this share of the reference peak."""
GROWTH = 2.0
"""A non-tracking run whose peak error grows by more than this factor per window grows."""

ANALYSIS_KEYS = (
    "max_real",
    "min_damping",
    "gain_margin_db",
    "phase_margin_deg",
    "delay_margin_s",
    "ms",
)
"""Numbers read from a verdict (with ``.get``: the margins exist only when the analysis
provides them)."""


@dataclass(frozen=True)
class Behaviour:
    """What one run did, measured from its trajectory (see the module docstring).

    All errors are in the plant's output unit; ``None`` where not defined (a diverged run
    has no window).
    """

    kind: Kind
    window: float
    stopped_at: float | None = None
    max_abs_error: float | None = None
    error_amplitude: float | None = None
    error_offset: float | None = None
    reference_peak: float | None = None
    growth: float | None = None

    @property
    def relative_error(self) -> float | None:
        """max |e| / max |r| over the window (None when undefined)."""
        if self.max_abs_error is None or not self.reference_peak:
            return None
        return self.max_abs_error / self.reference_peak

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready record (finite floats or null), as written to ``metrics.json``."""
        return {
            "behaviour": self.kind,
            "window_s": self.window,
            "max_abs_error": _finite(self.max_abs_error),
            "error_amplitude": _finite(self.error_amplitude),
            "error_offset": _finite(self.error_offset),
            "reference_peak": _finite(self.reference_peak),
            "growth": _finite(self.growth),
        }


def _finite(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(float(x)) else float(x)


def window_for(t_final: float, window: float = WINDOW) -> float:
    """The measurement window for a horizon: ``window``, at most a quarter of the horizon
    (so a window before it exists for the growth ratio)."""
    return min(window, 0.25 * t_final)


def measure(
    t: ArrayLike,
    y: ArrayLike,
    r: ArrayLike,
    *,
    failed: bool = False,
    stopped_at: float | None = None,
    status: str = "diverged",
    window: float = WINDOW,
    tolerance: float = TOLERANCE,
) -> Behaviour:
    """Measure a run from its trajectory (module docstring for the definitions).

    Parameters
    ----------
    t, y, r
        Stored time points [s], output and reference (same length).
    failed, stopped_at, status
        Whether the engine stopped the run, when [s], and why (``"lost"``: the plant left
        its envelope; ``"diverged"``: the numbers blew up).
    window
        Length of the final window [s].
    tolerance
        Share of the reference peak within which the run tracks.

    Returns
    -------
    Behaviour
    """
    if failed:
        return Behaviour("lost" if status == "lost" else "diverged", window, stopped_at=stopped_at)
    t = np.asarray(t, dtype=np.float64)
    e = np.asarray(y, dtype=np.float64) - np.asarray(r, dtype=np.float64)
    r_abs = np.abs(np.asarray(r, dtype=np.float64))
    if t.size == 0:
        raise ValueError("measure: the run stored no trajectory (simulate with store=True)")
    last = t >= t[-1] - window
    before = (t >= t[-1] - 2 * window) & ~last
    e_last = e[last]
    peak = float(np.max(np.abs(e_last)))
    r_peak = float(np.max(r_abs[last]))
    scale = r_peak or float(np.max(r_abs)) or 1.0  # a zero reference: the unit itself
    prev = float(np.max(np.abs(e[before]))) if before.any() else math.nan
    growth = peak / prev if prev > 0 else math.nan
    hi, lo = float(np.max(e_last)), float(np.min(e_last))
    if peak <= tolerance * scale:
        kind: Kind = "tracks"
    elif math.isfinite(growth) and growth > GROWTH:
        kind = "growing"
    else:
        kind = "bounded"
    return Behaviour(
        kind,
        window,
        max_abs_error=peak,
        error_amplitude=0.5 * (hi - lo),
        error_offset=0.5 * (hi + lo),
        reference_peak=r_peak,
        growth=growth if math.isfinite(growth) else None,
    )


def measure_result(result: SimulationResult, t_final: float) -> Behaviour:
    """:func:`measure` on an engine result (window :func:`window_for` the horizon)."""
    return measure(
        result.t,
        result["y"] if result.t.size else (),
        result["r"] if result.t.size else (),
        failed=result.failed,
        stopped_at=result.stopped_at,
        status=result.status,
        window=window_for(t_final),
    )


# ------------------------------------------------------------------------- verdicts
def min_damping(verdict: Mapping[str, Any]) -> float | None:
    r"""The least damping ratio of the linearised loop.

    The analysis' own ``min_damping`` when it provides one; otherwise computed from its
    eigenvalues, :math:`\zeta_{\min} = \min_k -\mathrm{Re}\,\lambda_k / |\lambda_k|` over the
    eigenvalues :math:`\lambda_k \ne 0` (negative for a mode that grows).
    """
    if verdict.get("min_damping") is not None:
        return float(verdict["min_damping"])
    eig = [complex(re, im) for re, im in verdict.get("eigenvalues") or []]
    zetas = [-z.real / abs(z) for z in eig if abs(z) > 0]
    return min(zetas) if zetas else None


def analysis_numbers(verdict: Mapping[str, Any]) -> dict[str, Any]:
    """The verdict and its numbers (:data:`ANALYSIS_KEYS`) for ``metrics.json``.

    Keys the analysis does not provide are null; a non-finite value (an infinite gain
    margin) is null too, as JSON has no infinity.
    """
    out: dict[str, Any] = {"verdict": str(verdict.get("verdict", "not analysed"))}
    eig = verdict.get("eigenvalues") or []
    max_real = verdict.get("max_real")
    if max_real is None and eig:
        max_real = max(float(re) for re, _ in eig)
    for key in ANALYSIS_KEYS:
        val = max_real if key == "max_real" else verdict.get(key)
        if key == "min_damping":
            val = min_damping(verdict)
        out[key] = _finite(float(val)) if val is not None else None
    out.update(orbit_numbers(verdict))
    return out


def orbit_numbers(verdict: Mapping[str, Any]) -> dict[str, Any]:
    """The reconciled verdict's numbers for ``metrics.json`` (null where not analysed):
    ``reconciled`` (the sentence), ``tracking_orbit`` (``"stable"``, ``"unstable"`` or
    ``"not determined"``: :func:`aiofl.analysis.orbit.floquet_word`; sine references),
    ``largest_multiplier`` (Floquet, sine references),
    ``ftle`` (largest finite-time Lyapunov exponent, other references), the limit cycle's
    ``limit_cycle_amplitude_y``, ``limit_cycle_amplitude_u``, ``limit_cycle_frequency``."""
    orb = verdict.get("orbit") or {}
    lc = orb.get("limit_cycle") or {}
    bounded = bool(lc.get("bounded"))
    fl = orb.get("floquet")
    from aiofl.analysis.orbit import floquet_word

    return {
        "reconciled": orb.get("verdict"),
        "tracking_orbit": floquet_word(fl) if fl else None,
        "largest_multiplier": _finite((orb.get("floquet") or {}).get("largest")),
        "ftle": _finite((orb.get("ftle") or {}).get("largest")),
        "limit_cycle_amplitude_y": _finite(lc.get("amplitude_y")) if bounded else None,
        "limit_cycle_amplitude_u": _finite(lc.get("amplitude_u")) if bounded else None,
        "limit_cycle_frequency": _finite(lc.get("frequency")) if bounded else None,
    }


def _not_determined() -> str:
    from aiofl.analysis.orbit import NOT_DETERMINED

    return NOT_DETERMINED


def orbit_stable(verdict: Mapping[str, Any]) -> bool | None:
    """Whether the tracking orbit is stable (largest Floquet multiplier < 1, or largest
    finite-time Lyapunov exponent < 0); None where it was not analysed or the analysis
    decided nothing (:data:`aiofl.analysis.orbit.NOT_DETERMINED`)."""
    nums = orbit_numbers(verdict)
    if (verdict.get("orbit") or {}).get("orbit_diverges"):
        return False
    if nums["tracking_orbit"] == _not_determined():
        return None
    if nums["largest_multiplier"] is not None:
        return bool(nums["largest_multiplier"] < 1.0)
    if nums["ftle"] is not None:
        return bool(nums["ftle"] < 0.0)
    return None


def _g(x: float, digits: int = 3) -> str:
    return f"{x:.{digits}g}"


def _sweep_text(verdict: Mapping[str, Any]) -> str:
    """``"; its verdict depends on ε: stable for ε = 0.01, 0.1"`` when the sweep differs."""
    sweep = verdict.get("verdicts_by_amplitude") or {}
    base = verdict.get("verdict")
    other = [eps for eps, v in sweep.items() if isinstance(v, str) and v != base]
    if not other:
        return ""
    kinds = {sweep[eps] for eps in other}
    what = next(iter(kinds)) if len(kinds) == 1 else "different"
    return f"; with the secant gains taken at ε = {', '.join(other)} it is {what}"


def _pct(share: float) -> str:
    """A share as a percentage: 2 significant digits below 10 %, whole percent above."""
    x = 100.0 * share
    return f"{x:.2g} %" if abs(x) < 10 else f"{x:.0f} %"


def simulation_text(b: Behaviour, unit: str, tolerance: float = TOLERANCE) -> str:
    """What the run did, as a clause (``"the simulation tracks: max |e| ... = 0.01 rad"``).

    Parameters
    ----------
    b
        The measured run (:func:`measure`).
    unit
        The output's unit (``""`` or ``"-"``: none).
    tolerance
        The tracking tolerance named for a bounded run (default :data:`TOLERANCE`).

    Returns
    -------
    str
    """
    u = f" {unit}" if unit and unit != "-" else ""
    w = f"over the last {_g(b.window)} s"
    if b.kind in ("lost", "diverged"):
        at = f" at t = {b.stopped_at:.2f} s" if b.stopped_at is not None else ""
        what = "loses the plant" if b.kind == "lost" else "diverges"
        return f"the simulation {what}{at}"
    assert b.max_abs_error is not None and b.error_amplitude is not None
    rel = b.relative_error
    share = f", {_pct(rel)} of the reference peak" if rel is not None else ""
    if b.kind == "tracks":
        return f"the simulation tracks: max |e| {w} = {_g(b.max_abs_error)}{u}{share}"
    if b.kind == "growing":
        return (
            f"the simulation's error is still growing: max |e| {w} = {_g(b.max_abs_error)}{u}, "
            f"{_g(b.growth or math.nan, 2)} times that of the {_g(b.window)} s before"
        )
    return (
        f"the simulation stays bounded, its error above the {_pct(tolerance)} tracking "
        f"tolerance: {w} e = y − r oscillates with amplitude {_g(b.error_amplitude)}{u} "
        f"about {_g(b.error_offset or 0.0)}{u} (max |e| = {_g(b.max_abs_error)}{u}{share})"
    )


def verdict_text(verdict: Mapping[str, Any], unit: str) -> str:
    """The linearisation verdict as a clause, with where it was taken."""
    v = str(verdict.get("verdict", "not analysed"))
    if v not in ("stable", "unstable", "marginal"):
        return f"no linearisation verdict ({v})"
    nums = analysis_numbers(verdict)
    op = verdict.get("operating_point") or {}
    where = (
        f" (r held at {_g(float(op['r']))}" + (f" {unit}" if unit and unit != "-" else "") + ")"
        if op.get("r") is not None
        else ""
    )
    mr = nums["max_real"]
    tail = f", max Re λ = {_g(mr)} 1/s" if mr is not None else ""
    return f"linearisation {v} at the operating point{where}{tail}{_sweep_text(verdict)}"


def reconcile(verdict: Mapping[str, Any], behaviour: Behaviour, unit: str = "") -> str:
    """One sentence: the linearisation verdict, what the simulation did, and whether they agree.

    Parameters
    ----------
    verdict
        A :func:`aiofl.analysis.linearize.closed_loop_verdict` dict (or an ``analysis
        failed`` one).
    behaviour
        The measured run (:func:`measure`).
    unit
        The plant's output unit, for the error values.

    Returns
    -------
    str
    """
    v = str(verdict.get("verdict", ""))
    first = verdict_text(verdict, unit)
    second = simulation_text(behaviour, unit)
    k = behaviour.kind
    stable_orbit = orbit_stable(verdict)
    if orbit_numbers(verdict)["tracking_orbit"] == _not_determined():
        first = str(verdict["orbit"]["verdict"])
        why = (
            "the orbit analysis decides neither way: the orbit did not settle over the "
            "periods analysed"
        )
        return f"{first[:1].upper()}{first[1:]}; {second} — {why}."
    if stable_orbit is not None:  # the reconciled verdict (aiofl.analysis.orbit)
        first = str(verdict["orbit"]["verdict"])
        if stable_orbit and k == "tracks":
            why = "they agree: the run follows the stable orbit"
        elif not stable_orbit and k in ("lost", "diverged", "growing"):
            why = "they agree"
        elif stable_orbit and k == "bounded":
            why = "no contradiction: a stable orbit need not be within the tracking tolerance"
        elif stable_orbit:
            why = (
                "they differ: the orbit is stable to small perturbations; the run's start "
                "lies outside its basin"
            )
        else:
            why = "they differ: the run stays near an orbit the analysis finds unstable"
        return f"{first[:1].upper()}{first[1:]}; {second} — {why}."
    eps = verdict.get("amplitude") if verdict.get("verdicts_by_amplitude") else None
    near = "near the operating point (constant r" + (
        f", secant gains at error amplitude ε = {_g(float(eps))})" if eps is not None else ")"
    )
    agree = (v == "unstable" and k in ("lost", "diverged", "growing")) or (
        v == "stable" and k == "tracks"
    )
    if agree:
        why = "they agree"
    elif v == "unstable":
        why = f"they differ: the verdict holds {near}; the run follows a moving reference"
    elif v == "stable" and k in ("lost", "diverged", "growing"):
        why = f"they differ: the verdict holds {near}; the run leaves that neighbourhood"
    elif v == "stable":
        why = "no contradiction: a loop stable near its operating point need not track"
    else:
        why = ""
    return f"{first[:1].upper()}{first[1:]}; {second}" + (f" — {why}." if why else ".")
