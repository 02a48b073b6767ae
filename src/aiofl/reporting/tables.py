"""Tables I–III of ``aiofl reproduce`` and their notes, the sample-time paragraph and every
case's closed-loop verdict beside its simulation, with the number formatting the report uses.

Every number here is generated from the computed :class:`aiofl.reporting.cases.Reproduction`
(and the paper's values in :data:`aiofl.reporting.paper.PAPER_TABLES`).  Units are the
plant's own (:attr:`aiofl.plants.base.Plant.output_unit`, ``input_unit``).  The report's
sections of them (:class:`PaperTablesSection`, :class:`SamplingSection`,
:class:`VerdictSection`; :mod:`aiofl.reporting.section`) render the same rows as Markdown and
as HTML.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aiofl.components.metrics import opi
from aiofl.plants.base import Plant
from aiofl.reporting.behaviour import analysis_numbers, reconcile, simulation_text
from aiofl.reporting.cases import (
    CaseRun,
    Reproduction,
    controller_access,
    itd_gain,
    model_assistance,
    observer_roots,
    output_ratio,
)
from aiofl.reporting.page import Raw, details, escape, html_table, img, item_list
from aiofl.reporting.paper import PAPER_TABLES, SCENARIOS
from aiofl.reporting.sampling_note import sampling_paragraph, ts_max_cell
from aiofl.reporting.section import Section, md_table

__all__ = [
    "CONTEXT_ROWS",
    "DASH",
    "VERDICT_HEADER",
    "VERDICT_INTRO",
    "PaperTablesSection",
    "SamplingSection",
    "VerdictSection",
    "case_label",
    "fmt",
    "metric_units",
    "sampling_text",
    "scenario_notes",
    "table_header",
    "table_rows",
    "verdict_notes",
    "verdict_rows",
    "word_list",
]

DASH = "—"


# ------------------------------------------------------------------------ formatting
def fmt(x: float | None, digits: int = 6) -> str:
    """A number with ``digits`` significant digits, a dash for None, ∞ for infinity."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return DASH
    if isinstance(x, float) and math.isinf(x):
        return "∞" if x > 0 else "−∞"
    if x == 0:
        return "0"
    return f"{x:.{digits}g}"


def _pct(new: float, ref: float) -> str:
    return f"{100.0 * (new - ref) / ref:+.1f} %"


def _root(z: complex) -> str:
    if abs(z.imag) < 1e-9 * max(1.0, abs(z.real)):
        return f"{z.real:.4g}"
    return f"{z.real:.4g} {'+' if z.imag >= 0 else '−'} {abs(z.imag):.4g}j"


def _cluster_roots(roots: np.ndarray, rtol: float = 1e-2) -> list[tuple[complex, int]]:
    """Group numerically split repeated roots: (mean, multiplicity), largest real part first.

    A root of multiplicity k computed by ``np.roots`` is split by about ε^(1/k) relative
    (e.g. -44.72 ± 0.049j for a 5-fold root at -44.7); roots within ``rtol`` of a group's
    first member, relative to its magnitude, are one group.
    """
    groups: list[list[complex]] = []
    for z in sorted(roots, key=lambda z: (-z.real, -z.imag)):
        for g in groups:
            if abs(z - g[0]) <= rtol * max(abs(g[0]), 1e-300):
                g.append(z)
                break
        else:
            groups.append([z])
    return [(complex(np.mean(g)), len(g)) for g in groups]


def _roots_text(roots: np.ndarray) -> str:
    parts = []
    for z, k in _cluster_roots(roots):
        if z.imag < -1e-9 * max(1.0, abs(z.real)):
            continue  # the conjugate of a pair already shown
        text = (
            _root(z)
            if abs(z.imag) < 1e-9 * max(1.0, abs(z.real))
            else _root(z).replace(" + ", " ± ")
        )
        parts.append(text + (f" (×{k})" if k > 1 else ""))
    return ", ".join(parts)


def word_list(items: Sequence[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def _pow(unit: str, k: int) -> str:
    """``unit`` to the power k (parenthesised when compound): V² , (m^3/s)²."""
    if k == 1:
        return unit
    base = f"({unit})" if any(c in unit for c in "/·^ *") else unit
    return base + {2: "²", 3: "³"}.get(k, f"^{k}")


def metric_units(plant: Plant) -> dict[str, str]:
    """Units of the metrics of eq. (22) for a plant: ITAE = ∫ t|e| dt in [y]·s², ISU = ∫ u² dt
    in [u]²·s, IAU = ∫ |u| dt in [u]·s (empty where the plant declares no unit)."""
    y, u = plant.output_unit, plant.input_unit
    known = {"y": bool(y and y != "-"), "u": bool(u and u != "-")}
    return {
        "itae": f"{y}·s²" if known["y"] else "",
        "isu": f"{_pow(u, 2)}·s" if known["u"] else "",
        "iau": f"{u}·s" if known["u"] else "",
    }


def _with_unit(text: str, unit: str) -> str:
    return f"{text} [{unit}]" if unit else text


def case_label(run: CaseRun) -> str:
    """Row label; an IOFL or model-assisted row says what its law is given."""
    given = controller_access(run.case.config) or model_assistance(run.case.config)
    return run.case.label + (f"; {given}" if given else "")


# ---------------------------------------------------------------------------- tables
CONTEXT_ROWS = (
    "y ≡ 0 (no control, for context)",
    "y ≡ r exactly (least ISU: model inversion from x*(0), for context)",
)
"""Labels of the rows that end every table (references, not results)."""


def table_header(rep: Reproduction, scenario: int) -> list[str]:
    """Columns of Table I/II/III, with the metrics' units from the scenario's plant."""
    units = metric_units(rep.scenario_runs(scenario)[0].case.config.plant)
    return [
        "Structure",
        "Preset",
        _with_unit("ITAE paper", units["itae"]),
        _with_unit("ITAE computed", units["itae"]),
        _with_unit("ISU paper", units["isu"]),
        _with_unit("ISU computed", units["isu"]),
        _with_unit("IAU computed", units["iau"]),
        "OPI computed",
        "ts_max [ms]",
    ]


def table_rows(rep: Reproduction, scenario: int) -> list[list[str]]:
    """Rows of Table I/II/III (scenario 1/2/3): paper vs computed, plus context rows."""
    rows = []
    for run in rep.scenario_runs(scenario):
        rec = run.record
        paper = (
            PAPER_TABLES[scenario].get(run.case.structure, {})
            if run.case.source == "printed"
            else {}
        )
        itae = (
            f"{rec['status']} at t = {rec['stopped_at']:.2f} s"
            if rec["failed"]
            else fmt(rec["itae"])
        )
        rows.append(
            [
                case_label(run),
                run.case.preset,
                fmt(paper.get("itae"), 9),
                itae,
                fmt(paper.get("isu"), 9),
                fmt(rec["isu"]),
                fmt(rec["iau"]),
                fmt(rec["opi"]),
                ts_max_cell(rep.sampling.get(run.case.preset)),
            ]
        )
    triv = rep.trivial[scenario]
    w = rep.scenario_runs(scenario)[0].case.config.weights
    rows.append(
        [CONTEXT_ROWS[0], DASH, DASH, fmt(triv), DASH, "0", "0", fmt(opi(triv, 0, 0, w)), DASH]
    )
    # the least ISU any controller needs to keep y = r (aiofl.analysis.exact_tracking)
    from aiofl.analysis.exact_tracking import exact_tracking_cost

    ex = exact_tracking_cost(rep.scenario_runs(scenario)[0].case.config)
    rows.append(
        [
            CONTEXT_ROWS[1],
            DASH,
            DASH,
            "0",
            DASH,
            fmt(ex["isu"]),
            fmt(ex["iau"]),
            fmt(opi(0.0, ex["isu"], ex["iau"], w)),
            DASH,
        ]
    )
    return rows


def _observer_note(run: CaseRun) -> str | None:
    """The ESO's error polynomial (eq. 9) of a printed case, or of any case with a root in
    the right half-plane."""
    cfg = run.case.config
    if cfg.controller.law != "aiofl":
        return None
    roots = observer_roots(cfg)
    n_rhp = int(np.sum(roots.real > 0))
    if run.case.source != "printed" and not n_rhp:
        return None
    linear = cfg.controller.eso == "linear"
    what = (
        "linear-ESO error polynomial s^(ρ+1) + β1 s^ρ + … + β(ρ+1) (eq. 9)"
        if linear
        else "INLESO β-polynomial with unit injection gain (g(e) is nonlinear: indicative only)"
    )
    verdict = (
        f"{n_rhp} root(s) in the right half-plane"
        + (": the observer error is unstable on its own" if linear else "")
        if n_rhp
        else "all roots in the left half-plane"
    )
    return f"roots of its {what}: {_roots_text(roots)}; {verdict}"


def _itd_note(run: CaseRun) -> str | None:
    gain = itd_gain(run.case.config)
    if gain is None or abs(gain - 1.0) < 1e-3:
        return None
    c = run.case.config.controller
    return (
        f"its improved TD (21) with a = {c.value('td.a'):g}, b = {c.value('td.b'):g} settles "
        f"at (1 − a) r / b = {gain:.4f} r, so the loop is asked to track {100 * gain:.2g} % "
        "of the reference"
    )


def scenario_notes(rep: Reproduction, scenario: int) -> list[str]:
    """Short notes under a table, generated from the numbers in it."""
    notes = []
    triv = rep.trivial[scenario]
    paper = PAPER_TABLES[scenario]
    for run in rep.scenario_runs(scenario):
        rec = run.record
        name = f"{run.case.label} [{run.case.preset}]"
        p = paper.get(run.case.structure) if run.case.source == "printed" else None
        extra = [n for n in (_itd_note(run), _observer_note(run)) if n]
        if rec["failed"]:
            tail = f" The paper reports ITAE {fmt(p['itae'])}." if p else ""
            more = "".join(f" {n[0].upper()}{n[1:]}." for n in extra)
            at = f"{rec['stopped_at']:.2f}"
            what = "the plant is lost" if rec["status"] == "lost" else "the loop diverges"
            notes.append(f"{name}: {what} at t = {at} s.{tail}{more}")
            continue
        parts = [f"{name}: ITAE {fmt(rec['itae'], 5)}"]
        if p:
            parts.append(
                f"vs the paper's {fmt(p['itae'], 5)} ({_pct(rec['itae'], p['itae'])}); "
                f"ISU {fmt(rec['isu'], 4)} vs {fmt(p['isu'], 5)}"
            )
        ratio = output_ratio(run)
        rel = (rec["itae"] - triv) / triv
        if ratio is not None and ratio < 0.1:
            parts.append(
                f"the output barely moves (peak |y| over the last 5 s is {100 * ratio:.2g} % "
                "of the reference's), so its ITAE is essentially that of y ≡ 0"
            )
        elif rel >= 0:
            parts.append(f"worse than y ≡ 0 ({_pct(rec['itae'], triv)} in ITAE)")
        parts.append(simulation_text(run.behaviour, run.unit))
        parts += extra
        notes.append("; ".join(parts) + ".")
    rel_paper = ", ".join(f"{k} {_pct(v['itae'], triv)}" for k, v in paper.items())
    notes.append(
        f"y ≡ 0 scores ITAE {fmt(triv, 5)} (∫ t|r| dt over {_horizon(rep, scenario)} s); "
        f"the paper's own ITAE values relative to it: {rel_paper}."
    )
    # how the re-tuned rows were tuned, from their [tune] tables; one note per recipe
    from aiofl.tuning.search import describe_tuning

    recipes: dict[tuple[str, str], list[str]] = {}
    for run in rep.scenario_runs(scenario):
        tuned = run.case.source in ("retuned", "robust")
        how = describe_tuning(run.case.config) if tuned else None
        if how:
            what = "re-tuned" if run.case.source == "retuned" else "tuned"
            recipes.setdefault((how, what), []).append(f"{run.case.label} [{run.case.preset}]")
    for (how, what), rows in recipes.items():
        verb = "was" if len(rows) == 1 else "were"
        notes.append(f"{word_list(rows)} {verb} {what} with {how}.")
    return notes


def _horizon(rep: Reproduction, scenario: int) -> str:
    return fmt(rep.scenario_runs(scenario)[0].case.config.scenario.t_final, 4)


# ----------------------------------------------------------------- verdict vs run
VERDICT_HEADER = (
    "Case",
    "Verdict (tracking orbit; equilibrium)",
    "max Re λ [1/s]",
    "min ζ",
    "GM [dB]",
    "PM [°]",
    "DM [s]",
    "Ms",
    "Reconciled verdict beside the simulation (measured from the trajectory)",
)


def verdict_rows(rep: Reproduction) -> list[list[str]]:
    """One row per case: the closed-loop verdict, damping and margins (a dash where the
    analysis gives none), and the sentence reconciling it with the simulation."""
    rows = []
    for run in rep.runs:
        v = rep.verdicts.get(run.case.preset, {})
        n = analysis_numbers(v)
        verdict = n["verdict"] if n["verdict"] in ("stable", "unstable", "marginal") else "—"
        short = (v.get("orbit") or {}).get("short")
        if short and verdict != "—":
            verdict = f"{short} (equilibrium {verdict})" if "equilibrium" not in short else short
        elif short:
            verdict = short
        given = controller_access(run.case.config)
        rows.append(
            [
                run.case.preset + (f" ({given})" if given else ""),
                verdict,
                fmt(n["max_real"], 4),
                fmt(n["min_damping"], 3),
                fmt(_raw(v, "gain_margin_db"), 3),
                fmt(_raw(v, "phase_margin_deg"), 3),
                fmt(_raw(v, "delay_margin_s"), 3),
                fmt(_raw(v, "ms"), 3),
                reconcile(v, run.behaviour, run.unit),
            ]
        )
    return rows


def _raw(v: Mapping[str, Any], key: str) -> float | None:
    """A margin as the analysis gave it (infinity kept, shown as ∞)."""
    val = v.get(key)
    return None if val is None else float(val)


def verdict_notes(rep: Reproduction) -> list[tuple[str, str]]:
    """(case, how the non-smooth elements were linearised and the ε sweep) per case."""
    out = []
    for preset, v in rep.verdicts.items():
        notes = [str(x) for x in v.get("notes") or []]
        sweep = v.get("verdicts_by_amplitude") or {}
        if sweep:
            notes.append("by amplitude ε: " + ", ".join(f"{k}: {w}" for k, w in sweep.items()))
        if notes:
            out.append((preset, "; ".join(notes)))
    return out


# ------------------------------------------------------------------------- sections
MARKDOWN_INTRO = (
    "ITAE = ∫ t|y − r| dt and ISU = ∫ u² dt over the horizon (eq. 22); IAU = ∫ |u| dt and "
    "OPI (eq. 22, printed weights) are computed here only (the paper gives none). "
    "'paper' columns are the printed Tables I–III; 'computed' columns come from "
    "simulating the paper's printed parameters (presets `paper-s*-*`). Metrics of a run "
    "that diverged are not defined; the divergence time is given instead. The row "
    "y ≡ 0 is the trivial controller that never moves the output, for context."
)
"""What the columns of Tables I–III are, in ``tables.md``."""

HTML_INTRO = (
    "<p>Each table puts the paper's printed ITAE and ISU beside what this code computes "
    "from the paper's printed parameters (presets <code>paper-s*-*</code>, shown with "
    "<code>aiofl show NAME</code>). A run that diverged has no metrics; its divergence "
    "time is shown. The row <em>y ≡ 0</em> is the trivial controller that never moves "
    "the output, for context. The ESO-based designs (LESO, INLESO, LADRC) see only the "
    "measured output, ρ and b0; an IOFL row says what the model-based law is given. "
    "The run-level numbers (metrics, divergence times, tracking errors, verdicts) are "
    "those of <code>metrics.json</code>.</p>"
)
"""What the columns of Tables I–III are, in the page (HTML)."""


@dataclass
class PaperTablesSection(Section):
    """Tables I–III, paper vs computed (:func:`table_rows`), each with its notes
    (:func:`scenario_notes`) and, in the page, its figure (``fig3.png`` ...)."""

    rep: Reproduction
    figures: Mapping[str, bytes] = field(default_factory=dict)
    title = "Tables I–III: paper vs this code"

    def markdown(self) -> str:
        """A level-1 heading, what the columns are, then each table and its notes."""
        rep = self.rep
        out = [f"# {self.title}", "", MARKDOWN_INTRO, ""]
        for s, info in SCENARIOS.items():
            out += [f"## Table {info.table}: scenario {s}, {info.title}", ""]
            out += [md_table(table_header(rep, s), table_rows(rep, s)), ""]
            out += [f"- {n}" for n in scenario_notes(rep, s)]
            out += [""]
        return "\n".join(out)

    def html(self) -> list[str]:
        """What the columns are, then each table with its notes and figure folded."""
        rep = self.rep
        body = [HTML_INTRO]
        for s, info in SCENARIOS.items():
            body.append(f"<h2>Table {info.table}: scenario {s}, {escape(info.title)}</h2>")
            rows = table_rows(rep, s)
            body.append(html_table(table_header(rep, s), rows, context_rows=len(CONTEXT_ROWS)))
            notes = scenario_notes(rep, s)
            what = f"Notes on the rows of Table {info.table} ({len(notes)})"
            body.append(details(what, [item_list(notes, "notes")]))
            name = f"fig{info.figure}.png"
            figure = img(self.figures, name, f"Figure {info.figure}: scenario {s}")
            if figure:
                n = len(rep.scenario_runs(s))
                what = f"Figure {info.figure} (reproduced): output, tracking error and control of "
                body.append(details(what + f"the {n} designs ({name})", figure))
        return body


@dataclass
class SamplingSection(Section):
    """The paragraph on the designs' sample-time limits (:func:`sampling_text`; left out
    when none were computed)."""

    rep: Reproduction
    title = "What the sample-time limits mean"

    def markdown(self) -> str:
        """``## title`` and the paragraph."""
        para = sampling_text(self.rep)
        return f"## {self.title}\n\n{para}\n" if para else ""

    def html(self) -> list[str]:
        """The paragraph, folded under an ``<h2>``."""
        para = sampling_text(self.rep)
        return [details(self.title, [f"<p>{escape(para)}</p>"], heading=True)] if para else []


@dataclass
class VerdictSection(Section):
    """Every case's closed-loop verdict beside what its simulation did
    (:func:`verdict_rows`), and how each loop was linearised (:func:`verdict_notes`, the
    page only)."""

    rep: Reproduction
    title = "Closed-loop linearisation beside the simulation"

    def markdown(self) -> str:
        """``## title``, what the columns mean, the table."""
        table = md_table(VERDICT_HEADER, verdict_rows(self.rep))
        return f"## {self.title}\n\n{VERDICT_INTRO}\n\n{table}\n"

    def html(self) -> list[str]:
        """The table, its long sentences folded under a short summary per row."""
        rep = self.rep
        body = [
            f"<h2>{escape(self.title)}</h2>",
            details("What the columns mean", [f"<p>{escape(VERDICT_INTRO)}</p>"]),
        ]
        rows: list[list[str]] = verdict_rows(rep)
        for run, row in zip(rep.runs, rows, strict=True):
            row[-1] = _verdict_cell(run, row[-1])
        header = [*VERDICT_HEADER[:-1], "The simulation (open a row for the sentence)"]
        body.append(html_table(header, rows, cls="verdicts"))
        how = verdict_notes(rep)
        if how:
            table = html_table(["Case", "Linearisation notes"], how, cls="settings")
            body.append(
                details("How each loop was linearised (non-smooth elements, ε sweep)", [table])
            )
        return body


def _verdict_cell(run: CaseRun, sentence: str) -> Raw:
    """The long linearisation-vs-simulation sentence folded under a short summary: what the
    run did and whether the two agree."""
    kind = run.behaviour.kind
    verb = {"diverged": "diverges", "lost": "loses the plant"}
    did = (
        f"{verb[kind]} at t = {run.behaviour.stopped_at:.2f} s"
        if kind in verb and run.behaviour.stopped_at is not None
        else kind
    )
    tail = sentence.rsplit(" — ", 1)[1] if " — " in sentence else ""
    short = did + (f"; {tail.split(':')[0].rstrip('.')}" if tail else "")
    return Raw(details(short, [escape(sentence)]))


def sampling_text(rep: Reproduction) -> str:
    """The paragraph on the designs' sample-time limits (empty when none were computed)."""
    rows = [(r.case.label, r.case.preset, r.case.source, r.case.scenario) for r in rep.runs]
    return " ".join(sampling_paragraph(rows, rep.sampling))


VERDICT_INTRO = (
    "One reconciled verdict per design (aiofl.analysis.orbit): the tracking orbit's largest "
    "Floquet multiplier μ over one reference period (variational equation along the periodic "
    "steady state; stable when |μ| < 1), and the equilibrium with the reference held: stable, "
    "or unstable and then the limit cycle it settles on (amplitude of y and frequency from a "
    "simulation, cross-checked by the describing functions of its nonlinearities). "
    "The equilibrium's verdict is that of the whole closed loop linearised at its operating "
    "point (the "
    "reference held constant, the disturbance at its final value; aiofl.analysis.linearize); "
    "min ζ is the least damping ratio −Re λ/|λ| of its eigenvalues; GM, PM, DM (gain, phase "
    "and delay margins, loop broken at the plant input) and Ms (sensitivity peak) are shown "
    "where the analysis provides them. The last column states what the simulation did, "
    "measured from its trajectory over its last seconds (e = y − r, in the plant's output "
    "unit), and whether the two agree."
)
