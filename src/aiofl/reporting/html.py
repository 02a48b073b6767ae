"""The self-contained HTML report of ``aiofl reproduce`` (inline CSS, figures as base64 PNG).

The page leads with a one-screen summary (:mod:`aiofl.reporting.summary`: the paper's
question answered per scenario, the best design per structure, what the printed parameter
sets do), then Tables I–III, the robustness rows, the Pareto fronts and every case's
closed-loop verdict beside what its simulation did.  The long parts (the findings of
:mod:`aiofl.reporting.findings`, the notes on each case, Figures 3–5, the linearisation
sentences, the settings the paper leaves open and the engine's settings) are folded in
``<details>`` blocks.  The rows are those of :mod:`aiofl.reporting.tables`.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Mapping

from aiofl.reporting.cases import CaseRun, Reproduction
from aiofl.reporting.findings import findings
from aiofl.reporting.fresh_seeds import FRESH_HEADER, FRESH_TITLE, fresh_notes, fresh_rows
from aiofl.reporting.fronts import (
    ISU_BUDGET,
    front_header,
    front_notes,
    front_rows,
    front_scenarios,
    has_front_content,
)
from aiofl.reporting.noise_front import (
    NOISE_HEADER,
    NOISE_TITLE,
    noise_answer,
    noise_notes,
    noise_rows,
)
from aiofl.reporting.page import PAGE_COLOURS, page, page_png
from aiofl.reporting.page import Raw as _Raw
from aiofl.reporting.page import details as _details
from aiofl.reporting.page import escape as _e
from aiofl.reporting.page import html_table as _html_table
from aiofl.reporting.page import img as _img
from aiofl.reporting.page import item_list as _list
from aiofl.reporting.paper import SCENARIOS
from aiofl.reporting.rig_rows import RIG_HEADER, RIG_TITLE, rig_notes, rig_rows
from aiofl.reporting.robust_rows import ROBUST_HEADER, robust_notes, robust_rows
from aiofl.reporting.sensor_rows import SENSOR_HEADER, SENSOR_TITLE, sensor_notes, sensor_rows
from aiofl.reporting.summary import (
    structure_header,
    structure_rows,
    summary_header,
    summary_intro,
    summary_rows,
)
from aiofl.reporting.tables import (
    CONTEXT_ROWS,
    VERDICT_HEADER,
    VERDICT_INTRO,
    open_settings,
    sampling_text,
    scenario_notes,
    table_header,
    table_rows,
    verdict_notes,
    verdict_rows,
)

__all__ = ["PAGE_COLOURS", "html_report", "page_png"]


def _summary_section(rep: Reproduction) -> list[str]:
    """The one-screen summary (:mod:`aiofl.reporting.summary`)."""
    return [
        '<section class="summary"><h2 id="summary">Summary</h2>',
        f"<p>{_e(summary_intro(rep))}</p>",
        _html_table(summary_header(rep), summary_rows(rep), cls="summary"),
        _html_table(structure_header(rep), structure_rows(rep), cls="summary"),
        '<p class="muted">Below: Tables I–III, robustness, Pareto fronts and the '
        "linearisation; the notes on each case, Figures 3–5 and the long explanations are "
        "folded (click a ▸ line to open it).</p></section>",
    ]


def _verdict_cell(run: CaseRun, sentence: str) -> _Raw:
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
    return _Raw(_details(short, [_e(sentence)]))


def _robust_sections(rep: Reproduction, figures: Mapping[str, bytes]) -> list[str]:
    """The robustness table and the Pareto-front section (with ``fronts-s{N}.png``)."""
    body = ["<h2>Robustness: every design over the same ±20 % model errors</h2>"]
    rows = robust_rows(rep)
    if rows:
        body.append(_html_table(ROBUST_HEADER, rows))
    body.append(
        _details("How these rows were computed, per scenario", [_list(robust_notes(rep), "notes")])
    )
    rows = sensor_rows(rep)
    if rows:
        body.append(f"<h2>{_e(SENSOR_TITLE)}</h2>")
        body.append(_html_table(SENSOR_HEADER, rows))
        body.append(_details("What these columns are", [_list(sensor_notes(rep), "notes")]))
    rows = rig_rows(rep)
    if rows:
        body.append(f"<h2>{_e(RIG_TITLE)}</h2>")
        body.append(_html_table(RIG_HEADER, rows))
        body.append(_details("What these columns are", [_list(rig_notes(rep), "notes")]))
    rows = fresh_rows(rep)
    if rows:
        body.append(f"<h2>{_e(FRESH_TITLE)}</h2>")
        body.append(_html_table(FRESH_HEADER, rows))
        body.append(_details("How these rows were computed", [_list(fresh_notes(rep), "notes")]))
    body.append("<h2>Pareto fronts: which structure tracks best at equal control energy?</h2>")
    body.append(_details("Where the fronts come from", [_list(front_notes(rep), "notes")]))
    for s, sentences in front_scenarios(rep).items():
        body.append(f"<h3>Scenario {s} (ISU ≤ {ISU_BUDGET[s]:g})</h3>")
        if has_front_content(rep, s):
            body.append(_html_table(front_header(s), front_rows(rep, s), cls="settings"))
        body.append(_list(sentences, "answers"))
        body += _img(figures, f"fronts-s{s}.png", f"Pareto fronts, scenario {s}")
    body.append(f"<h2>{_e(NOISE_TITLE)}</h2>")
    body.append(_list(noise_answer(getattr(rep, "noise_fronts", None)), "answers"))
    body.append(_html_table(NOISE_HEADER, noise_rows(rep), cls="settings"))
    body.append(_details("Where the noise fronts come from", [_list(noise_notes(rep), "notes")]))
    body += _img(figures, "noise-front-s3.png", "Noise fronts, scenario 3")
    return body


def html_report(rep: Reproduction, figures: Mapping[str, bytes]) -> str:
    """``report.html``: one self-contained page (inline CSS, figures as base64 PNG).

    The page leads with a one-screen summary (:mod:`aiofl.reporting.summary`), then Tables
    I–III, the robustness rows, the Pareto fronts and the linearisation; the notes on each
    case, Figures 3–5, the linearisation sentences and the settings are folded in
    ``<details>`` blocks.  Figures are embedded as palette PNGs (:func:`page_png`).

    Parameters
    ----------
    rep
        The reproduction.
    figures
        PNG bytes by file name (``fig3.png`` ...).

    Returns
    -------
    str
        The page.
    """
    now = _dt.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z")
    body = [
        "<h1>AIOFL reproduction report</h1>",
        '<p class="muted">Abdul-Adheem &amp; Ibraheem, <em>On the Active Input-Output '
        "Feedback Linearization of Single-Link Flexible Joint Manipulator: an Extended "
        f"State Observer Approach</em> (arXiv 1805.00222). Generated by "
        f"<code>aiofl reproduce</code> on {_e(now)}.</p>",
        *_summary_section(rep),
        _details("What we found", [_list(findings(rep), "findings")], heading=True),
        "<p>Each table puts the paper's printed ITAE and ISU beside what this code computes "
        "from the paper's printed parameters (presets <code>paper-s*-*</code>, shown with "
        "<code>aiofl show NAME</code>). A run that diverged has no metrics; its divergence "
        "time is shown. The row <em>y ≡ 0</em> is the trivial controller that never moves "
        "the output, for context. The ESO-based designs (LESO, INLESO, LADRC) see only the "
        "measured output, ρ and b0; an IOFL row says what the model-based law is given. "
        "The run-level numbers (metrics, divergence times, tracking errors, verdicts) are "
        "those of <code>metrics.json</code>.</p>",
    ]
    for s, info in SCENARIOS.items():
        body.append(f"<h2>Table {info.table}: scenario {s}, {_e(info.title)}</h2>")
        body.append(
            _html_table(table_header(rep, s), table_rows(rep, s), context_rows=len(CONTEXT_ROWS))
        )
        notes = scenario_notes(rep, s)
        what = f"Notes on the rows of Table {info.table} ({len(notes)})"
        body.append(_details(what, [_list(notes, "notes")]))
        name = f"fig{info.figure}.png"
        img = _img(figures, name, f"Figure {info.figure}: scenario {s}")
        if img:
            n = len(rep.scenario_runs(s))
            what = f"Figure {info.figure} (reproduced): output, tracking error and control of "
            body.append(_details(what + f"the {n} designs ({name})", img))
    body += _robust_sections(rep, figures)
    para = sampling_text(rep)
    if para:
        body.append(
            _details("What the sample-time limits mean", [f"<p>{_e(para)}</p>"], heading=True)
        )
    body.append("<h2>Closed-loop linearisation beside the simulation</h2>")
    body.append(_details("What the columns mean", [f"<p>{_e(VERDICT_INTRO)}</p>"]))
    rows = verdict_rows(rep)
    for run, row in zip(rep.runs, rows, strict=True):
        row[-1] = _verdict_cell(run, row[-1])
    header = [*VERDICT_HEADER[:-1], "The simulation (open a row for the sentence)"]
    body.append(_html_table(header, rows, cls="verdicts"))
    how = verdict_notes(rep)
    if how:
        table = _html_table(["Case", "Linearisation notes"], how, cls="settings")
        body.append(
            _details("How each loop was linearised (non-smooth elements, ε sweep)", [table])
        )
    settings = _html_table(
        ["Setting", "The paper", "Choice made"],
        [list(t) for t in open_settings(rep)],
        cls="settings",
    )
    body.append(
        _details("Settings the paper leaves open and the choice made", [settings], heading=True)
    )
    timing = ", ".join(f"{k} {v:.2f} s" for k, v in rep.timings.items())
    eng = [*rep.engine.items(), ("wall time", timing)]
    engine = _html_table(["Setting", "Value"], [list(r) for r in eng], cls="settings")
    body.append(_details("Engine settings", [engine], heading=True))
    return page("AIOFL reproduction report", body)
