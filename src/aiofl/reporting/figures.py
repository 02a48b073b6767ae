"""Figures like the paper's Figures 3–5, with the tracking error: one row of panels per run.

Each run gets one row of three panels: (left) the output y against the reference r,
(middle) the tracking error e = y − r, the integrand of ITAE (eq. 22) without its weight t,
and (right) the control signal u, each axis in the plant's own units
(:attr:`aiofl.plants.base.Plant.output_unit`, ``input_unit``).  One legend for the whole
figure, above the panels, says which line is which, so nothing is printed over the curves.
Panels are lettered (a), (b), ... (z), (aa), ... (:func:`panel_letter`); the figure's title,
a run's label and the units are drawn as plain text (a ``$`` in a config's name is no
mathtext).

A run that diverged is drawn up to the divergence time, which is marked (a dotted line and
the time in the panel titles); its output and error panels are clipped to a few reference
amplitudes (the peak is written in the title) and its control panel uses a symmetric-log
scale, so both the early behaviour and the blow-up stay visible.

Scenario events (the disturbance step, a plant change) are drawn as dash-dot lines when
they fall inside the horizon; an event outside it is only listed in the legend, so an
event time of, say, 10⁷ s neither fails nor stretches the figure.

Matplotlib is used through :class:`matplotlib.figure.Figure` with the Agg canvas (no
pyplot state, no display needed).
"""

from __future__ import annotations

import io
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from aiofl.plants.base import unit_label
from aiofl.reporting.paper import SCENARIOS

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from aiofl.engine.simulation import SimulationResult
    from aiofl.reporting.cases import Reproduction
    from aiofl.scenario import Scenario

__all__ = [
    "Panel",
    "config_figure",
    "figure_png",
    "panel_letter",
    "result_figure",
    "runs_figure",
    "scenario_events",
    "scenario_figure",
]

COLORS = {"LESO": "#1f77b4", "INLESO": "#d62728", "LADRC": "#2ca02c", "IOFL": "#9467bd"}
_FALLBACK = ("#ff7f0e", "#8c564b", "#e377c2", "#17becf")
EVENT_STYLE = {"color": "0.45", "ls": "-.", "lw": 0.9}
DIVERGED_STYLE = {"color": "crimson", "ls": ":", "lw": 1.5}


@dataclass(frozen=True)
class Panel:
    """One row of a figure.

    Attributes
    ----------
    label
        Row title (e.g. ``"LESO [paper-s1-leso]"``).
    result
        The run.
    color
        Line colour of y, e and u.
    t_final
        The horizon [s] (the x axis spans it even when the run stopped early).
    reference
        Optional r(t), drawn over the whole horizon.
    events
        Scenario events ``(time [s], label)``; drawn when inside the horizon.
    output_unit, input_unit
        Units of y (and r, e) and of u; no brackets when empty.
    """

    label: str
    result: SimulationResult
    color: str
    t_final: float
    reference: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None = None
    events: tuple[tuple[float, str], ...] = ()
    output_unit: str = ""
    input_unit: str = ""


def _color(structure: str, i: int) -> str:
    return COLORS.get(structure, _FALLBACK[i % len(_FALLBACK)])


def _inside(t: float, t_final: float) -> bool:
    return math.isfinite(t) and 0.0 <= t <= t_final


def _u(unit: str) -> str:
    return f" {unit}" if unit and unit != "-" else ""


def _symlog_ticks(ax: Axes, peak: float) -> None:
    """Symmetric-log y axis (linear within ±1) with ticks 0, ±10^k far enough apart that
    their labels never touch."""
    ax.set_yscale("symlog", linthresh=1.0, linscale=0.5)
    top = max(2, math.ceil(math.log10(peak)))
    step = max(2, math.ceil((top - 1) / 3))
    exps = list(range(top, 1, -step))[::-1]
    ticks = [-(10.0**k) for k in exps[::-1]] + [0.0] + [10.0**k for k in exps]
    ax.set_yticks(ticks)
    ax.set_yticklabels(
        [
            ("−" if v < 0 else "") + f"$10^{{{round(math.log10(abs(v)))}}}$" if v else "0"
            for v in ticks
        ]
    )


def panel_letter(i: int) -> str:
    """The letter of panel ``i`` (from 0): a..z, then aa, ab, ... (a figure of more than
    eight runs has more than 26 panels; no letter repeats)."""
    out = ""
    i += 1
    while i > 0:
        i, r = divmod(i - 1, 26)
        out = chr(ord("a") + r) + out
    return out


def _draw_row(axes: Sequence[Axes], p: Panel, letters: Sequence[str]) -> None:
    ax_y, ax_e, ax_u = axes
    res = p.result
    t, r, y, u = res.t, res["r"], res["y"], res["u"]
    e = y - r
    if p.reference is not None:
        t_ref = np.linspace(0.0, p.t_final, 4001)
        ax_y.plot(t_ref, p.reference(t_ref), color="0.25", lw=1.0, ls="--")
    else:
        ax_y.plot(t, r, color="0.25", lw=1.0, ls="--")
    ax_y.plot(t, y, color=p.color, lw=1.3)
    ax_e.axhline(0.0, color="0.25", lw=0.8, ls="--")
    ax_e.plot(t, e, color=p.color, lw=1.0)
    ax_u.plot(t, u, color=p.color, lw=0.8)
    # the plant's units and the run's label are user text: plain, never mathtext
    ax_y.set_ylabel(unit_label("y, r", p.output_unit), parse_math=False)
    ax_e.set_ylabel(unit_label("e = y − r", p.output_unit), parse_math=False)
    ax_u.set_ylabel(unit_label("u", p.input_unit), parse_math=False)
    ax_y.set_title(
        f"({letters[0]}) {p.label}", fontsize=9.5, loc="left", fontweight="bold", parse_math=False
    )
    ax_e.set_title(f"({letters[1]}) tracking error", fontsize=9.5, loc="left")
    ax_u.set_title(f"({letters[2]}) control signal", fontsize=9.5, loc="left")
    if res.failed:
        r_amp = float(np.max(np.abs(r))) if r.size else 1.0
        lim = 3.0 * (r_amp if r_amp > 0 else 1.0)
        y_peak = float(np.max(np.abs(y))) if y.size else 0.0
        if y_peak > lim:
            for ax in (ax_y, ax_e):
                ax.set_ylim(-lim, lim)
            ax_y.set_title(
                f"|y| reaches {y_peak:.3g}{_u(p.output_unit)}",
                fontsize=8.5,
                loc="right",
                parse_math=False,
            )
        u_peak = float(np.max(np.abs(u))) if u.size else 0.0
        if u_peak > 100.0:
            _symlog_ticks(ax_u, u_peak)
            ax_u.set_ylabel(unit_label("u", p.input_unit) + " (symlog)", parse_math=False)
        at = res.stopped_at if res.stopped_at is not None else float(t[-1]) if t.size else 0.0
        for ax in (ax_y, ax_e, ax_u):
            ax.axvline(at, **DIVERGED_STYLE)
        for ax in (ax_e, ax_u):
            title = f"{res.status} at t = {at:.2f} s"
            ax.set_title(title, fontsize=8.5, loc="right", color="crimson")
    for t_ev, _text in p.events:
        if _inside(t_ev, p.t_final):
            for ax in (ax_y, ax_e, ax_u):
                ax.axvline(t_ev, **EVENT_STYLE)
    for ax in (ax_y, ax_e, ax_u):
        ax.grid(True, alpha=0.3)
        ax.set_xlim(0.0, p.t_final)  # a diverged run keeps the full axis: the cut shows


def _legend_entries(panels: Sequence[Panel]) -> tuple[list[Any], list[str]]:
    """One figure legend: line styles, scenario events (drawn or not) and divergence."""
    from matplotlib.lines import Line2D

    handles: list[Any] = [
        Line2D([], [], color="0.25", ls="--", lw=1.0),
        Line2D([], [], color="0.1", lw=1.3),
    ]
    labels = ["reference r (and e = 0)", "output y, error e, control u (colour per design)"]
    horizon = max((p.t_final for p in panels), default=0.0)
    seen: dict[str, bool] = {}
    for p in panels:
        for t_ev, text in p.events:
            key = f"{text} at t = {t_ev:g} s"
            seen[key] = seen.get(key, False) or _inside(t_ev, p.t_final)
    for key, drawn in seen.items():
        handles.append(Line2D([], [], **EVENT_STYLE) if drawn else Line2D([], [], lw=0))
        labels.append(key if drawn else f"{key} (outside 0–{horizon:g} s, not drawn)")
    if any(p.result.failed for p in panels):
        handles.append(Line2D([], [], **DIVERGED_STYLE))
        labels.append("divergence (run stops)")
    return handles, labels


def runs_figure(panels: Sequence[Panel], title: str) -> Figure:
    """A figure with one row per run: output vs reference, tracking error, control signal.

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
    handles, labels = _legend_entries(panels)
    ncols = 3
    legend_rows = math.ceil(len(labels) / ncols)
    # fixed margins in inches (much faster than constrained layout, same look)
    row, bottom, gap = 2.3, 0.55, 0.55
    top = 0.45 + 0.22 * legend_rows + 0.35
    height = top + bottom + n * row
    fig = Figure(figsize=(13.0, height), dpi=100)
    axes = fig.subplots(
        n,
        3,
        squeeze=False,
        sharex=True,
        gridspec_kw={
            "left": 0.06,
            "right": 0.99,
            "top": 1.0 - top / height,
            "bottom": bottom / height,
            "wspace": 0.26,
            "hspace": gap / (row - gap),
        },
    )
    fig.suptitle(  # a config's name or path: plain text
        title, fontsize=12, fontweight="bold", y=1.0 - 0.1 / height, va="top", parse_math=False
    )
    fig.legend(
        handles,
        labels,
        loc="upper center",
        bbox_to_anchor=(0.5, 1.0 - 0.42 / height),
        ncols=ncols,
        fontsize=8.5,
        frameon=False,
    )
    for i, p in enumerate(panels):
        _draw_row(axes[i], p, [panel_letter(3 * i + k) for k in range(3)])
    for ax in axes[-1]:
        ax.set_xlabel("time t [s]")
    return fig


def scenario_events(
    scenario: Scenario, disturbance_unit: str = ""
) -> tuple[tuple[float, str], ...]:
    """Events worth marking on a time axis: the disturbance step, a late parameter change."""
    events = []
    if scenario.disturbance_amplitude != 0.0:
        amp = f"{scenario.disturbance_amplitude:g}{_u(disturbance_unit)}"
        events.append((scenario.disturbance_time, f"$\\tau_d$ = {amp} step"))
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
    panels = []
    for i, r in enumerate(runs):
        cfg = r.case.config
        panels.append(
            Panel(
                f"{r.case.label} [{r.case.preset}]",
                r.result,
                _color(r.case.structure, i),
                cfg.scenario.t_final,
                cfg.scenario.reference.evaluate,
                scenario_events(cfg.scenario, cfg.plant.disturbance_unit),
                cfg.plant.output_unit,
                cfg.plant.input_unit,
            )
        )
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
    *,
    output_unit: str = "",
    input_unit: str = "",
) -> Figure:
    """The figure of one simulation (``aiofl simulate``): output vs reference, tracking
    error and control, in the plant's units.

    Parameters
    ----------
    result
        The run (with stored trajectories).
    title
        The figure's title.
    t_final
        The horizon [s].
    structure
        The controller's structure (its colour and label).
    reference
        t -> r(t), drawn with the output (None: not drawn).
    events
        ``(time, label)`` marks (disturbance, parameter change).
    output_unit, input_unit
        The plant's units.

    Returns
    -------
    matplotlib.figure.Figure
    """
    panel = Panel(
        structure or "run",
        result,
        _color(structure, 0),
        t_final,
        reference,
        events,
        output_unit,
        input_unit,
    )
    return runs_figure([panel], title)


def config_figure(cfg: Any, result: SimulationResult, title: str) -> Figure:
    """:func:`result_figure` of a run config's run: its horizon, structure, reference,
    events and the plant's units (``aiofl simulate``'s and ``aiofl report``'s figure).

    Parameters
    ----------
    cfg
        The run config.
    result
        Its run (with stored trajectories).
    title
        The figure's title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    return result_figure(
        result,
        title,
        cfg.scenario.t_final,
        cfg.controller.structure,
        cfg.scenario.reference.evaluate,
        scenario_events(cfg.scenario, cfg.plant.disturbance_unit),
        output_unit=cfg.plant.output_unit,
        input_unit=cfg.plant.input_unit,
    )


def figure_png(fig: Figure, dpi: int = 100) -> bytes:
    """Render a figure to PNG bytes (Agg)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()
