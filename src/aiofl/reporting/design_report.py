"""A report for any design (``aiofl report CONFIG``): the page ``aiofl reproduce`` writes for
the paper, for the user's own config.

:func:`design_report` runs and measures the design and :func:`design_html` renders it:

- the verdict (:mod:`aiofl.engine.kernel.loop`: ok, lost or diverged, with the time and, for a lost
  plant, the bound it left), the integrals of eq. (22), the step metrics and the command's
  figures (peak, noise at steady state, saturation: :mod:`aiofl.engine.response`);
- the trajectory figure (output and reference, error, command);
- the operating point (:func:`aiofl.plants.operating_point.trim` at r(0));
- the margins of the linearised continuous loop
  (:func:`aiofl.analysis.linearize.closed_loop_verdict`) and, for a sampled design, the
  spectral radius of its linearised sampled loop
  (:class:`aiofl.analysis.sampled_loop.SampledLoop`), each labelled: the continuous figures
  of a sampled design are a limit, not what the processor runs;
- the export check, for a sampled design: the exported C against the engine's discrete
  controller in the config's loop, and whether single precision holds
  (:mod:`aiofl.export.c_check`);
- the design with its own sensor beside the ideal one (a limit), and on 16- and 12-bit
  encoders when the output is an angle;
- with an ``[uncertainty]`` table, its draws and box corners
  (:func:`aiofl.analysis.corners.run_box_robustness`, without the worst-case search and
  the β/b0 range, which ``aiofl robustness`` adds).

Every part that cannot be computed for a design says why instead of failing the report.
"""

from __future__ import annotations

import datetime as _dt
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from aiofl import layout as L
from aiofl.reporting.page import details, escape, html_table, img, item_list, page
from aiofl.reporting.section import Section, html_parts, markdown_text, md_table
from aiofl.reporting.verdict import command_text, step_text, verdict_text

__all__ = [
    "DesignReport",
    "OutcomeSection",
    "design_html",
    "design_markdown",
    "design_report",
    "design_sections",
]

#: encoder presets a design whose output is an angle is also measured with
ENCODERS = ("encoder-16bit", "encoder-12bit")


@dataclass
class DesignReport:
    """What :func:`design_report` measured (plain data, ready for JSON but ``figure``)."""

    label: str
    record: dict[str, Any]
    verdict: str
    lines: list[str]
    figure: bytes
    operating_point: dict[str, Any] | None
    operating_text: str
    margins: list[tuple[str, str]]
    export: list[tuple[str, str]]
    sensors: list[list[str]]
    robustness: dict[str, Any] | None
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """The report's numbers (``report.json``)."""
        return {
            "config": self.label,
            "run": self.record,
            "verdict": self.verdict,
            "operating_point": self.operating_point,
            "margins": dict(self.margins),
            "export": dict(self.export),
            "sensors": self.sensors,
            "robustness": self.robustness,
            "notes": self.notes,
        }


def _fmt(x: Any, digits: int = 4) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "—"
    return f"{x:.{digits}g}" if isinstance(x, float) else str(x)


def _margins(cfg: Any) -> tuple[list[tuple[str, str]], list[str]]:
    """The labelled margin rows, and notes on what could not be computed."""
    from aiofl.analysis.linearize import closed_loop_verdict

    rows: list[tuple[str, str]] = []
    notes: list[str] = []
    cont = "continuous loop" + (" (the controller unsampled: a limit)" if cfg.sampling else "")
    lin = None
    try:
        from aiofl.analysis.linearize import linearize_closed_loop

        lin = linearize_closed_loop(cfg)
        v = closed_loop_verdict(cfg, linearization=lin)
        rows += [
            (f"{cont}: verdict", str(v.get("verdict"))),
            (f"{cont}: gain margin [dB]", _fmt(v.get("gain_margin_db"))),
            (f"{cont}: phase margin [deg]", _fmt(v.get("phase_margin_deg"))),
            (f"{cont}: delay margin [s]", _fmt(v.get("delay_margin_s"))),
            (f"{cont}: Ms", _fmt(v.get("ms"))),
        ]
    except Exception as exc:  # a loop the linearisation cannot take: said, not fatal
        notes.append(f"continuous linearisation not computed ({type(exc).__name__}: {exc})")
    if cfg.sampling is not None:
        from aiofl.analysis.sampled_loop import sampled_margins

        at = f"sampled loop at Ts = {cfg.sampling.ts:g} s (what the processor runs)"
        try:
            m = sampled_margins(cfg)
            if "reason" in m:
                notes.append(f"sampled linearisation not computed ({m['reason']})")
            else:
                radius = m["spectral_radius"]
                word = "stable" if radius < 1.0 else "unstable"
                rows += [
                    (f"{at}: spectral radius", f"{_fmt(radius, 6)} ({word})"),
                    (f"{at}: gain margin [dB]", _fmt(m.get("gain_margin_db"))),
                    (f"{at}: phase margin [deg]", _fmt(m.get("phase_margin_deg"))),
                    (f"{at}: delay margin [s]", _fmt(m.get("delay_margin_s"))),
                ]
        except Exception as exc:  # as above
            notes.append(f"sampled linearisation not computed ({type(exc).__name__}: {exc})")
    if lin is not None:
        rows += _loop_view_rows(cfg, lin, notes)
    return rows, notes


def _loop_view_rows(cfg: Any, lin: Any, notes: list[str]) -> list[tuple[str, str]]:
    """Disk margins and the noise in u of each loop-view row, labelled with what the row
    includes (:mod:`aiofl.analysis.loop_view`)."""
    from aiofl.analysis.loop_view import loop_view

    out: list[tuple[str, str]] = []
    try:
        view = loop_view(cfg, linearization=lin)
    except Exception as exc:  # as above
        notes.append(f"disk margins not computed ({type(exc).__name__}: {exc})")
        return out
    unit = cfg.plant.input_unit or ""
    for row in view["rows"]:
        if "reason" in row or not row.get("stable"):
            continue
        lab = row["label"]
        out.append(
            (
                f"{lab}: disk margin α (gain ±dB, phase ±deg)",
                f"{_fmt(row['disk_margin'])} ({_fmt(row['disk_gain_margin_db'])} dB, "
                f"{_fmt(row['disk_phase_margin_deg'])}°)",
            )
        )
        nz = row.get("noise_to_u")
        if nz is not None and nz.get("u_rms") is not None:
            out.append(
                (
                    f"{lab}: RMS of u from the measurement noise ({view['noise_source']})",
                    f"{_fmt(nz['u_rms'])} {unit}".strip(),
                )
            )
    return out


def _export_check(cfg: Any) -> tuple[list[tuple[str, str]], list[str]]:
    """The exported C against the engine's discrete controller in the config's loop, and
    whether single precision holds (:mod:`aiofl.export.c_check`); notes when not checked."""
    if cfg.sampling is None:
        return [], [
            "export not checked: a continuous design has no sample time (aiofl export CONFIG "
            "--ts TS samples it, checks it and writes the C)"
        ]
    if cfg.controller.law != "aiofl":
        return [], ["export not checked: the classical IOFL law is not exported"]
    from aiofl.export import ExportError, export_c
    from aiofl.export.c_check import engine_agreement, float_holds

    try:
        files = {
            prec: dict(
                export_c(
                    cfg.controller,
                    cfg.sampling,
                    precision=prec,
                    title=cfg.name,
                    plant=cfg.plant,
                    plant_source=cfg.plant_source,
                    x0=cfg.scenario.x0,
                )
            )
            for prec in ("double", "float")
        }
        agree = engine_agreement(cfg, cfg.sampling, files["double"])
        why = float_holds(cfg, cfg.sampling, files)
    except (ExportError, RuntimeError, ValueError) as exc:
        return [], [f"export not checked ({exc})"]
    n = int(agree["samples"])
    return [
        (
            "exported C (double) vs the engine's discrete controller: max |u_C - u|",
            f"{agree['max_abs_du']:.3g} over {n} samples ({agree['relative']:.2g} of max |u|)",
        ),
        ("exported C in float", "holds (ITAE, ISU as in double)" if why is None else why),
    ], []


def _sensor_rows(cfg: Any) -> list[list[str]]:
    """The design with its own sensor, the ideal one and, for an angle, the encoders."""
    from dataclasses import replace

    runs: list[tuple[str, Any]] = [(f"its own: {cfg.sensor.describe()}", cfg)]
    if not cfg.sensor.is_ideal or cfg.sampling is not None:
        # no sampling, quantum, noise or transport delay: nothing left to tell the ESO
        ideal = replace(
            cfg, sampling=None, controller=cfg.controller.with_values(**{"eso.delay": 0.0})
        )
        ideal = replace(
            ideal,
            scenario=replace(ideal.scenario, noise_variance=0.0, output_delay=0.0, input_delay=0.0),
        )
        runs.append(("ideal sensor, continuous controller (a limit)", ideal))
    if cfg.plant.output_unit == "rad":
        for preset in ENCODERS:
            try:
                runs.append((preset, cfg.with_sensor(preset)))
            except Exception:  # a config the preset contradicts: left out
                continue
    rows = []
    for label, c in runs:
        r = c.simulate(store=False)
        m = r.metrics or {}
        resp = r.response
        rows.append(
            [
                label,
                r.status + (f" at {r.stopped_at:.3g} s" if r.failed else ""),
                _fmt(m.get("itae")),
                _fmt(m.get("isu")),
                _fmt(resp.get("u_peak")),
                _fmt(resp.get("u_noise")),
            ]
        )
    return rows


def design_report(cfg: Any, label: str, *, draws: int | None = None) -> DesignReport:
    """Run and measure ``cfg`` (a :class:`~aiofl.config.RunConfig`) for its report.

    Parameters
    ----------
    cfg
        The run config.
    label
        How the report names it.
    draws
        Draws of its ``[uncertainty]`` table to run (None: the table's; without one, none).

    Returns
    -------
    DesignReport
    """
    from aiofl.plants.operating_point import trim
    from aiofl.reporting.cases import computed_record
    from aiofl.reporting.figures import config_figure, figure_png

    result = cfg.simulate(store=True)
    record = computed_record(
        result,
        scenario=None,
        structure=cfg.controller.structure,
        source="config",
        opi=result.opi(cfg.weights),
        extra=True,
    )
    lines = [
        t
        for t in (
            step_text(result, cfg.plant.output_unit),
            command_text(result, cfg.scenario.t_final, cfg.plant.input_unit),
        )
        if t
    ]
    fig = config_figure(
        cfg, result, f"{label}: output vs reference, tracking error and control signal"
    )
    notes: list[str] = []
    try:
        point = trim(cfg.plant, cfg.scenario.initial_value(), x_guess=cfg.scenario.x0 or None)
        op, op_text = point.to_dict(), point.text(cfg.plant.output_unit, cfg.plant.input_unit)
    except ValueError as exc:
        op, op_text = None, f"no operating point: {exc}"
    margins, why = _margins(cfg)
    notes += why
    exported, why = _export_check(cfg)
    notes += why
    robust = None
    if cfg.uncertainty is not None:
        from aiofl.analysis.corners import run_box_robustness

        res = run_box_robustness(cfg, draws=draws, search=False, beta=False)
        robust = res.to_dict()
    return DesignReport(
        label=label,
        record=record,
        verdict=verdict_text(cfg, result),
        lines=lines,
        figure=figure_png(fig),
        operating_point=op,
        operating_text=op_text,
        margins=margins,
        export=exported,
        sensors=_sensor_rows(cfg),
        robustness=robust,
        notes=notes,
    )


def _robust_rows(rob: dict[str, Any]) -> list[list[str]]:
    """The robustness table's rows: draws, stable share, statuses, ITAE, worst draw, corners."""
    counts = rob.get("status_counts", {})
    q = rob["itae"]
    rows = [
        ["draws", str(rob["draws"])],
        ["stable (neither lost nor diverged)", f"{100 * rob['stable_fraction']:.1f} %"],
        [
            "ok / lost / diverged",
            " / ".join(str(counts.get(k, 0)) for k in L.STATUS_NAMES.values()),
        ],
        ["ITAE q50 / q95 / max", " / ".join(_fmt(q[k]) for k in ("q50", "q95", "max"))],
    ]
    w = rob["worst"]
    rows.append(
        [
            "worst draw",
            f"{w['status']}"
            + (f" at {w['stopped_at']:.3g} s" if w.get("stopped_at") is not None else "")
            + f", ITAE {_fmt(w['itae'])}, factors "
            + ", ".join(f"{k} × {v:.3g}" for k, v in w["factors"].items()),
        ]
    )
    c = rob.get("corners")
    if c is not None:
        rows.append(["box corners stable", f"{c['stable']} of {c['count']} ({c['design']})"])
    return rows


METRICS = ("itae", "iae", "ise", "isu", "iau", "opi")
"""The integrals of eq. (22) and the OPI, as the report's first table shows them."""


@dataclass
class OutcomeSection(Section):
    """What the plant did: the verdict, the metrics, the step and command figures and the
    trajectory figure (``figure.png``)."""

    rep: DesignReport
    title = "What the plant did"

    def _metrics(self) -> list[list[str]]:
        return [[_fmt(self.rep.record.get(k)) for k in METRICS]]

    def markdown(self) -> str:
        """``## title``, the verdict, the metrics, the lines and the figure file."""
        header = [k.upper() for k in METRICS]
        lines = "".join(f"- {t}\n" for t in self.rep.lines)
        return (
            f"## {self.title}\n\n**{self.rep.verdict}**\n\n"
            f"{md_table(header, self._metrics())}\n\n{lines}"
            "\n![output, error and command](figure.png)\n"
        )

    def html(self) -> list[str]:
        """The verdict, the metrics, the lines and the figure inlined."""
        return [
            f"<h2>{escape(self.title)}</h2>",
            f"<p><strong>{escape(self.rep.verdict)}</strong></p>",
            html_table([k.upper() for k in METRICS], self._metrics()),
            item_list(self.rep.lines, "notes"),
            *img({"figure.png": self.rep.figure}, "figure.png", "output, error and command"),
        ]


@dataclass
class TextSection(Section):
    """A titled block of preformatted text (the operating point)."""

    title: str
    text: str

    def markdown(self) -> str:
        """``## title`` and the text as a code block."""
        return f"## {self.title}\n\n```\n{self.text}\n```\n"

    def html(self) -> list[str]:
        """An ``<h2>`` and the text in ``<pre>``."""
        return [f"<h2>{escape(self.title)}</h2>", f"<pre>{escape(self.text)}</pre>"]


@dataclass
class RowsSection(Section):
    """A titled table of a design's report (``empty`` said instead when it has no rows)."""

    title: str
    header: Sequence[str]
    rows: list[list[str]]
    empty: str = ""
    table_class: str = "settings"

    def markdown(self) -> str:
        """``## title`` and the table (or ``empty``)."""
        body = md_table(self.header, self.rows) if self.rows else self.empty
        return f"## {self.title}\n\n{body}\n"

    def html(self) -> list[str]:
        """An ``<h2>`` and the table (or ``empty``)."""
        body = (
            html_table(self.header, self.rows, cls=self.table_class)
            if self.rows
            else f"<p>{escape(self.empty)}</p>"
        )
        return [f"<h2>{escape(self.title)}</h2>", body]


@dataclass
class NotesSection(Section):
    """What could not be computed, and why (left out when nothing)."""

    notes: list[str]
    title = "Notes"

    def markdown(self) -> str:
        """``## title`` and the notes as a list."""
        if not self.notes:
            return ""
        return f"## {self.title}\n\n" + "".join(f"- {n}\n" for n in self.notes)

    def html(self) -> list[str]:
        """The notes, folded under an ``<h2>``."""
        if not self.notes:
            return []
        return [details(self.title, [item_list(self.notes, "notes")], heading=True)]


def design_sections(rep: DesignReport) -> list[Section]:
    """The sections of a design's report, in order."""
    sections: list[Section] = [
        OutcomeSection(rep),
        TextSection("Operating point", rep.operating_text),
        RowsSection(
            "Margins (each labelled with the loop it is of)",
            ["Loop and figure", "Value"],
            [list(r) for r in rep.margins],
            empty="none computed",
        ),
        RowsSection(
            "Export check",
            ["Check", "Result"],
            [list(r) for r in rep.export],
            empty="not checked (see the notes)",
        ),
        RowsSection(
            "Sensors", ["Sensor", "Verdict", "ITAE", "ISU", "peak |u|", "noise in u"], rep.sensors
        ),
    ]
    if rep.robustness is not None:
        sections.append(
            RowsSection(
                "Robustness over the [uncertainty] draws", ["", ""], _robust_rows(rep.robustness)
            )
        )
    return [*sections, NotesSection(rep.notes)]


def design_html(rep: DesignReport, description: str = "") -> str:
    """``report.html`` of a design (one self-contained page, :mod:`aiofl.reporting.page`):
    the sections of :func:`design_sections`."""
    now = _dt.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z")
    head = [
        f"<h1>Design report: {escape(rep.label)}</h1>",
        f'<p class="muted">{escape(description)} Generated by <code>aiofl report</code> on '
        f"{escape(now)}.</p>",
    ]
    return page(f"aiofl design report: {rep.label}", head + html_parts(design_sections(rep)))


def design_markdown(rep: DesignReport, description: str = "") -> str:
    """A design's report in Markdown: the sections of :func:`design_sections` (the figure
    is referred to as ``figure.png``, the file written beside the report)."""
    head = f"# Design report: {rep.label}\n\n" + (f"{description}\n\n" if description else "")
    return head + markdown_text(design_sections(rep))
