"""The report of ``aiofl reproduce``: its sections, and their order in ``tables.md`` and in
``report.html``.

:func:`report_sections` makes every :class:`~aiofl.reporting.section.Section` of the report
from one :class:`~aiofl.reporting.cases.Reproduction`; :func:`report_markdown` writes those
of :data:`MARKDOWN_SECTIONS` one after the other (``tables.md``) and :func:`html_report` those
of :data:`HTML_SECTIONS` into one self-contained page (inline CSS, figures as base64 PNG,
:mod:`aiofl.reporting.page`).  The page leads with the one-screen summary
(:mod:`aiofl.reporting.summary`), then Tables I–III, the robustness, sensor, rig and
fresh-seed rows, the Pareto and noise fronts and every case's closed-loop verdict beside what
its simulation did; the long parts (the findings of :mod:`aiofl.reporting.findings`, the
notes on each case, Figures 3–5, the linearisation sentences, the settings the paper leaves
open and the engine's settings) are folded in ``<details>`` blocks.  ``tables.md`` puts the
linearisation right after Tables I–III and leaves out the findings and the settings.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Mapping
from dataclasses import dataclass

from aiofl.reporting.cases import Reproduction
from aiofl.reporting.findings import FindingsSection
from aiofl.reporting.fresh_seeds import FreshSeedsSection
from aiofl.reporting.fronts import FrontsSection
from aiofl.reporting.noise_front import NoiseFrontSection
from aiofl.reporting.open_settings import SettingsSection
from aiofl.reporting.page import details, escape, html_table, page
from aiofl.reporting.rig_rows import RigSection
from aiofl.reporting.robust_rows import RobustSection
from aiofl.reporting.section import Section, html_parts, markdown_text, md_table
from aiofl.reporting.sensor_rows import SensorSection
from aiofl.reporting.summary import SummarySection
from aiofl.reporting.tables import PaperTablesSection, SamplingSection, VerdictSection

__all__ = [
    "HTML_SECTIONS",
    "MARKDOWN_SECTIONS",
    "EngineSection",
    "html_report",
    "report_markdown",
    "report_sections",
]

MARKDOWN_SECTIONS = (
    "summary",
    "tables",
    "sampling",
    "verdicts",
    "robust",
    "sensors",
    "rig",
    "fresh",
    "fronts",
    "noise",
)
"""The sections of ``tables.md``, in order (keys of :func:`report_sections`)."""

HTML_SECTIONS = (
    "summary",
    "findings",
    "tables",
    "robust",
    "sensors",
    "rig",
    "fresh",
    "fronts",
    "noise",
    "sampling",
    "verdicts",
    "settings",
    "engine",
)
"""The sections of ``report.html``, in order (keys of :func:`report_sections`)."""

ENGINE_HEADER = ("Setting", "Value")


@dataclass
class EngineSection(Section):
    """The engine's settings of the run and the wall time of each stage."""

    rep: Reproduction
    title = "Engine settings"

    def rows(self) -> list[list[str]]:
        """(setting, value), the last the wall time of each stage."""
        timing = ", ".join(f"{k} {v:.2f} s" for k, v in self.rep.timings.items())
        return [list(r) for r in [*self.rep.engine.items(), ("wall time", timing)]]

    def markdown(self) -> str:
        """``## title`` and the table."""
        return f"## {self.title}\n\n{md_table(ENGINE_HEADER, self.rows())}\n"

    def html(self) -> list[str]:
        """The table, folded under an ``<h2>``."""
        table = html_table(ENGINE_HEADER, self.rows(), cls="settings")
        return [details(self.title, [table], heading=True)]


def report_sections(
    rep: Reproduction, figures: Mapping[str, bytes] | None = None
) -> dict[str, Section]:
    """Every section of the report, by key (:data:`MARKDOWN_SECTIONS`, :data:`HTML_SECTIONS`).

    Parameters
    ----------
    rep
        The reproduction.
    figures
        PNG bytes by file name (``fig3.png`` ...), shown in the page (None: none).

    Returns
    -------
    dict of str to Section
    """
    figs = dict(figures or {})
    return {
        "summary": SummarySection(rep),
        "findings": FindingsSection(rep),
        "tables": PaperTablesSection(rep, figs),
        "robust": RobustSection(rep),
        "sensors": SensorSection(rep),
        "rig": RigSection(rep),
        "fresh": FreshSeedsSection(rep),
        "fronts": FrontsSection(rep, figs),
        "noise": NoiseFrontSection(rep, figs),
        "sampling": SamplingSection(rep),
        "verdicts": VerdictSection(rep),
        "settings": SettingsSection(rep),
        "engine": EngineSection(rep),
    }


def report_markdown(rep: Reproduction) -> str:
    """``tables.md``: the sections of :data:`MARKDOWN_SECTIONS`, one after the other."""
    sections = report_sections(rep)
    return markdown_text([sections[k] for k in MARKDOWN_SECTIONS])


def html_report(rep: Reproduction, figures: Mapping[str, bytes]) -> str:
    """``report.html``: one self-contained page (inline CSS, figures as base64 PNG) of the
    sections of :data:`HTML_SECTIONS` under a title and the paper's reference.

    Figures are embedded as palette PNGs (:func:`aiofl.reporting.page.page_png`).

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
    head = [
        "<h1>AIOFL reproduction report</h1>",
        '<p class="muted">Abdul-Adheem &amp; Ibraheem, <em>On the Active Input-Output '
        "Feedback Linearization of Single-Link Flexible Joint Manipulator: an Extended "
        f"State Observer Approach</em> (arXiv 1805.00222). Generated by "
        f"<code>aiofl reproduce</code> on {escape(now)}.</p>",
    ]
    sections = report_sections(rep, figures)
    body = html_parts([sections[k] for k in HTML_SECTIONS])
    return page("AIOFL reproduction report", head + body)
