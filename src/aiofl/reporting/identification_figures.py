r"""Figures of an identification (``aiofl identify``): what a control engineer checks.

* :func:`fit_figure` (grey-box route): the measured output against the fitted model's
  simulated output, the residual :math:`\varepsilon_k = y_k - \hat y_k`, and the residual
  tests of MATLAB's ``resid`` (Ljung, *System Identification*, 2nd ed., 1999, §16.6): the
  residual's autocorrelation and its cross-correlation with u over lags :math:`-M \dots M`,
  with the 99 % band :math:`\pm 2.58/\sqrt N` a white, input-independent residual stays in;
* :func:`eso_figure` (model-free route): the extended state observer run offline over the
  logged (u, y) with the estimated ρ and b0; its estimate of the total disturbance
  :math:`\hat\xi_{\rho+1}` stays small and smooth when b0 and ρ are right (a wrong b0 leaves
  :math:`(b - b_0)\,u` in it, which follows u);
* :func:`candidates_figure` (model-free route): each candidate chain's score and fit, the
  chosen one marked.

The results are read by attribute (the model-free estimate, the offline ESO, the grey-box
fit of :mod:`aiofl.identification`), so this module draws whatever those give.  Text from a
log (a file name, a unit) is drawn as plain text (no mathtext).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from aiofl.plants.base import unit_label

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from aiofl.identification.log import Log

__all__ = ["candidates_figure", "eso_figure", "fit_figure"]


def _units(log: Log | None, role: str) -> str:
    return "" if log is None else str(log.units.get(role, ""))


def _lag_axis(lags: np.ndarray, size: int, symmetric: bool) -> np.ndarray:
    """The lags of a correlation of ``size`` values: ``lags`` when they match, else 0..M
    (an autocorrelation) or -M..M (a cross-correlation)."""
    if lags.size == size:
        return lags
    return np.arange(size) - (size // 2 if symmetric else 0)


def fit_figure(fit: Any, log: Log | None = None, title: str = "") -> Figure:
    """Measured vs simulated output, the residual, and the residual tests (2 x 2 panels).

    Parameters
    ----------
    fit
        A grey-box fit: ``t``, ``y_measured``, ``y_simulated``, ``fit_percent``,
        ``validation_fit_percent`` and ``residuals`` (lags, autocorrelation,
        cross_correlation, band, white, independent).
    log
        The log (for its units), or None.
    title
        The figure's title (plain text).

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12.0, 6.5), dpi=100, layout="constrained")
    (a, b), (c, d) = fig.subplots(2, 2)
    t = np.asarray(fit.t)
    y_unit, t_unit = _units(log, "y"), _units(log, "t") or "s"
    a.plot(t, fit.y_measured, color="0.3", lw=1.0, label="measured")
    a.plot(t, fit.y_simulated, color="C0", lw=1.2, label="simulated (fitted model)")
    val = fit.validation_fit_percent
    fits = f"fit {fit.fit_percent:.2f} %" + ("" if val is None else f", validation {val:.2f} %")
    a.set_title(f"(a) output: measured vs simulated ({fits})", fontsize=10)
    a.set_ylabel(unit_label("y", y_unit))
    a.legend(fontsize=8, frameon=False)
    residual = np.asarray(fit.y_measured) - np.asarray(fit.y_simulated)
    c.plot(t, residual, color="C3", lw=0.8)
    c.axhline(0.0, color="0.5", lw=0.6)
    c.set_title(f"(c) residual y - y_sim (rms {np.sqrt(np.mean(residual**2)):.3g})", fontsize=10)
    c.set_ylabel(unit_label("residual", y_unit))
    c.set_xlabel(unit_label("time t", t_unit))
    r = fit.residuals
    for ax, values, what, ok, letter, symmetric in (
        (b, r.autocorrelation, "autocorrelation", r.white, "b", False),
        (d, r.cross_correlation, "cross-correlation with u", r.independent, "d", True),
    ):
        values = np.asarray(values)
        x = _lag_axis(np.asarray(r.lags), values.size, symmetric)
        ax.vlines(x, 0.0, values, color="C0", lw=1.2)
        ax.plot(x, values, "o", color="C0", ms=2.5)
        ax.axhspan(-r.band, r.band, color="C2", alpha=0.15, lw=0, label="99 % band")
        ax.axhline(0.0, color="0.5", lw=0.6)
        verdict = "inside the band" if ok else "leaves the band"
        ax.set_title(f"({letter}) residual {what}: {verdict}", fontsize=10)
        ax.legend(fontsize=8, frameon=False, loc="upper right")
    d.set_xlabel("lag [samples]")
    if title:
        fig.suptitle(title, fontsize=12, fontweight="bold", parse_math=False)
    return fig


def eso_figure(eso: Any, log: Log, title: str = "") -> Figure:
    r"""The offline ESO: the logged input and output, and the total-disturbance estimate.

    Parameters
    ----------
    eso
        The offline observer run: ``t``, ``disturbance`` (:math:`\hat\xi_{\rho+1}` over the
        log), ``omega0``, ``rms``, ``roughness`` and ``verdict``.
    log
        The log it ran over.
    title
        The figure's title (plain text).

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11.0, 7.0), dpi=100, layout="constrained")
    a, b, c = fig.subplots(3, 1, sharex=True)
    t_unit = _units(log, "t") or "s"
    a.plot(log.t, log.u, color="C1", lw=0.9, drawstyle="steps-post")
    a.set_ylabel(unit_label("u", _units(log, "u")))
    a.set_title("(a) logged input", fontsize=10)
    b.plot(log.t, log.y, color="0.3", lw=0.9, label="measured")
    y_eso = getattr(eso, "y", None)
    if y_eso is not None and np.shape(y_eso) == np.shape(eso.t):
        b.plot(eso.t, y_eso, color="C0", lw=0.9, label="ESO's estimate")
    b.set_ylabel(unit_label("y", _units(log, "y")))
    b.set_title("(b) logged output", fontsize=10)
    b.legend(fontsize=8, frameon=False)
    c.plot(eso.t, eso.disturbance, color="C3", lw=0.9)
    c.axhline(0.0, color="0.5", lw=0.6)
    c.set_title(
        f"(c) total-disturbance estimate (omega0 = {eso.omega0:.4g} rad/s; rms {eso.rms:.3g}, "
        f"roughness {eso.roughness:.3g}): {eso.verdict}",
        fontsize=10,
    )
    c.set_ylabel("xi_rho+1 estimate")
    c.set_xlabel(unit_label("time t", t_unit))
    if title:
        fig.suptitle(title, fontsize=12, fontweight="bold", parse_math=False)
    return fig


def candidates_figure(estimate: Any, title: str = "") -> Figure:
    """Each candidate chain's score (left) and fit percentage (right); the chosen one red.

    Parameters
    ----------
    estimate
        The model-free estimate: ``rho``, ``delay``, ``criterion`` and ``candidates`` (each
        with ``rho``, ``delay``, ``b0``, ``score``, ``fit_percent``).
    title
        The figure's title (plain text).
    """
    from matplotlib.figure import Figure

    cands = list(estimate.candidates)
    fig = Figure(figsize=(10.0, 3.8), dpi=100, layout="constrained")
    a, b = fig.subplots(1, 2)
    labels = [f"rho={c.rho}\ndelay={c.delay:.3g}" for c in cands]
    x = np.arange(len(cands))
    chosen = [c.rho == estimate.rho and c.delay == estimate.delay for c in cands]
    colors = ["C3" if ch else "C0" for ch in chosen]
    a.bar(x, [c.score for c in cands], color=colors)
    a.set_title(f"(a) score ({estimate.criterion}; lower is better)", fontsize=10)
    b.bar(x, [c.fit_percent for c in cands], color=colors)
    b.set_title("(b) fit [%] (100 (1 - |y - y_sim| / |y - mean y|))", fontsize=10)
    for ax in (a, b):
        ax.set_xticks(x, labels, fontsize=8)
    if title:
        fig.suptitle(title, fontsize=12, fontweight="bold", parse_math=False)
    return fig
