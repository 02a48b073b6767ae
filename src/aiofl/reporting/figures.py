"""Figures like the paper's Figures 3–5: output vs reference and control signal per run.

Each run gets one row of two panels: (left) the output y [rad] against the reference r,
(right) the control signal u [V].  A run that diverged is drawn up to the divergence time,
which is marked; its output panel is clipped to a few reference amplitudes (the peak is
written on the panel) and its control panel uses a symmetric-log scale, so both the early
behaviour and the blow-up stay visible.

Matplotlib is used through :class:`matplotlib.figure.Figure` with the Agg canvas (no
pyplot state, no display needed).
"""

from __future__ import annotations

import io
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from aiofl.reporting.paper import SCENARIOS

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from aiofl.engine.simulation import SimulationResult
    from aiofl.reporting.cases import Reproduction
    from aiofl.scenario import Scenario

__all__ = [
    "Panel",
    "figure_png",
    "result_figure",
    "runs_figure",
    "scenario_events",
    "scenario_figure",
]

COLORS = {"LESO": "#1f77b4", "INLESO": "#d62728", "LADRC": "#2ca02c", "IOFL": "#9467bd"}
_FALLBACK = ("#ff7f0e", "#8c564b", "#e377c2", "#17becf")


@dataclass(frozen=True)
class Panel:
    """One row of a figure: a label, the run, a line colour, the horizon [s] and
    optionally r(t), drawn over the whole horizon even when the run stopped early, and
    scenario events ``(time, label)`` marked on both panels."""

    label: str
    result: SimulationResult
    color: str
    t_final: float
    reference: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None = None
    events: tuple[tuple[float, str], ...] = ()


def _color(structure: str, i: int) -> str:
    return COLORS.get(structure, _FALLBACK[i % len(_FALLBACK)])


def runs_figure(panels: Sequence[Panel], title: str) -> Figure:
    """A figure with one row per run: output vs reference, and control signal.

    Parameters
    ----------
    panels
        The runs to draw, top to bottom.
    title
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.figure import Figure

    n = max(len(panels), 1)
    # fixed margins in inches (much faster than constrained layout, same look)
    row, top, bottom, gap = 2.35, 0.62, 0.55, 0.55
    height = top + bottom + n * row
    fig = Figure(figsize=(11.0, height), dpi=100)
    axes = fig.subplots(
        n,
        2,
        squeeze=False,
        sharex=True,
        gridspec_kw={
            "left": 0.075,
            "right": 0.985,
            "top": 1.0 - top / height,
            "bottom": bottom / height,
            "wspace": 0.2,
            "hspace": gap / (row - gap),
        },
    )
    fig.suptitle(title, fontsize=12, fontweight="bold", y=1.0 - 0.12 / height, va="top")
    letters = "abcdefghijklmnopqrstuvwxyz"
    for i, p in enumerate(panels):
        ax_y, ax_u = axes[i]
        res = p.result
        t = res.t
        r, y, u = res["r"], res["y"], res["u"]
        if p.reference is not None:
            t_ref = np.linspace(0.0, p.t_final, 4001)
            ax_y.plot(t_ref, p.reference(t_ref), color="0.25", lw=1.0, ls="--", label="reference r")
        else:
            ax_y.plot(t, r, color="0.25", lw=1.0, ls="--", label="reference r")
        ax_y.plot(t, y, color=p.color, lw=1.3, label="output y")
        ax_u.plot(t, u, color=p.color, lw=0.8, label="control u")
        ax_y.set_ylabel("angle [rad]")
        ax_u.set_ylabel("u [V]")
        ax_y.set_title(f"({letters[2 * i % 26]}) output: {p.label}", fontsize=10, loc="left")
        ax_u.set_title(
            f"({letters[(2 * i + 1) % 26]}) control signal: {p.label}", fontsize=10, loc="left"
        )
        if res.diverged:
            r_amp = float(np.max(np.abs(r))) if r.size else 1.0
            lim = 3.0 * (r_amp if r_amp > 0 else 1.0)
            y_peak = float(np.max(np.abs(y))) if y.size else 0.0
            if y_peak > lim:
                ax_y.set_ylim(-lim, lim)
                ax_y.text(
                    0.01,
                    0.96,
                    f"off scale: |y| reaches {y_peak:.3g} rad",
                    transform=ax_y.transAxes,
                    va="top",
                    fontsize=8,
                    color="0.3",
                )
            if u.size and float(np.max(np.abs(u))) > 100.0:
                from matplotlib.ticker import SymmetricalLogLocator

                ax_u.set_yscale("symlog", linthresh=1.0)  # linear within ±1 V, log beyond
                ax_u.yaxis.set_major_locator(SymmetricalLogLocator(linthresh=1.0, base=100.0))
                ax_u.set_ylabel("u [V] (symlog)")
            for ax in (ax_y, ax_u):
                ax.axvline(res.diverged_at, color="crimson", ls=":", lw=1.5)
                ax.text(
                    0.99,
                    0.93,
                    f"diverged at t = {res.diverged_at:.2f} s",
                    transform=ax.transAxes,
                    ha="right",
                    va="top",
                    fontsize=9,
                    color="crimson",
                    bbox={"facecolor": "white", "edgecolor": "crimson", "alpha": 0.85},
                )
        for t_ev, text in p.events:
            for ax in (ax_y, ax_u):
                ax.axvline(t_ev, color="0.45", ls="-.", lw=0.9)
            ax_u.annotate(
                text,
                (t_ev, 0.02),
                xycoords=("data", "axes fraction"),
                xytext=(3, 0),
                textcoords="offset points",
                fontsize=8,
                color="0.35",
            )
        for ax in (ax_y, ax_u):
            ax.grid(True, alpha=0.3)
            ax.set_xlim(0.0, p.t_final)  # a diverged run keeps the full axis: the cut shows
        ax_y.legend(loc="lower left", fontsize=8, ncols=2, framealpha=0.85)
    for ax in axes[-1]:
        ax.set_xlabel("time t [s]")
    return fig


def scenario_events(scenario: Scenario) -> tuple[tuple[float, str], ...]:
    """Events worth marking on a time axis: the disturbance step, a late parameter change."""
    events = []
    if scenario.disturbance_amplitude != 0.0:
        events.append(
            (scenario.disturbance_time, f"$\\tau_d$ = {scenario.disturbance_amplitude:g} step")
        )
    if (scenario.plant_scale or scenario.plant_overrides) and scenario.parameter_change_time > 0:
        events.append((scenario.parameter_change_time, "plant change"))
    return tuple(events)


def scenario_figure(rep: Reproduction, scenario: int) -> Figure:
    """Figure 3, 4 or 5 of the reproduction: every run of one scenario.

    Parameters
    ----------
    rep
        The reproduction (see :func:`aiofl.reporting.cases.compute`).
    scenario
        1, 2 or 3.
    """
    info = SCENARIOS[scenario]
    runs = rep.scenario_runs(scenario)
    panels = [
        Panel(
            f"{r.case.label} [{r.case.preset}]",
            r.result,
            _color(r.case.structure, i),
            r.case.config.scenario.t_final,
            r.case.config.scenario.reference.evaluate,
            scenario_events(r.case.config.scenario),
        )
        for i, r in enumerate(runs)
    ]
    return runs_figure(
        panels, f"Figure {info.figure} (reproduced): scenario {scenario}, {info.title}"
    )


def result_figure(
    result: SimulationResult,
    title: str,
    t_final: float,
    structure: str = "",
    reference: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None = None,
    events: tuple[tuple[float, str], ...] = (),
) -> Figure:
    """The figure of one simulation (``aiofl simulate``): output vs reference and control."""
    panel = Panel(structure or "run", result, _color(structure, 0), t_final, reference, events)
    return runs_figure([panel], title)


def figure_png(fig: Figure, dpi: int = 100) -> bytes:
    """Render a figure to PNG bytes (Agg)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()
