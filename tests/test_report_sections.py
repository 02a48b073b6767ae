"""Report sections (issue 37): one interface, a section computes its rows and renders its
Markdown and HTML; ``aiofl reproduce``'s tables.md and report.html and a design's report are
lists of sections."""

from __future__ import annotations

import io
import re
from dataclasses import dataclass, fields

import pytest
from PIL import Image

from aiofl.reporting.design_report import DesignReport, design_html, design_markdown
from aiofl.reporting.front_files import FrontFile, ShippedFront
from aiofl.reporting.noise_front import NoiseFront
from aiofl.reporting.page import escape
from aiofl.reporting.section import TableSection, html_parts, markdown_text, md_table


@dataclass
class _Rows(TableSection):
    got: list[list[str]]
    title = "A | table"
    header = ("a", "b|c")

    def rows(self) -> list[list[str]]:
        return self.got

    def notes(self) -> list[str]:
        return ["first note", "second <note>"]


def test_md_table_escapes_pipes_in_headings_and_cells() -> None:
    text = md_table(["x", "peak |u|"], [["1", "|e| < 2"]])
    assert text.split("\n") == ["| x | peak \\|u\\| |", "|---|---|", "| 1 | \\|e\\| < 2 |"]


def test_a_table_section_renders_title_table_and_notes_in_both_formats() -> None:
    sec = _Rows([["1", "2"], ["3", "4|5"]])
    assert sec.markdown() == (
        "## A | table\n\n| a | b\\|c |\n|---|---|\n| 1 | 2 |\n| 3 | 4\\|5 |\n\n"
        "- first note\n- second <note>\n"
    )
    page = "".join(sec.html())
    assert page.startswith("<h2>A | table</h2><table")
    assert "<td>4|5</td>" in page and "<li>second &lt;note&gt;</li>" in page
    assert "<summary>What these columns are</summary>" in page


def test_a_section_without_rows_is_left_out_of_both_documents() -> None:
    empty, full = _Rows([]), _Rows([["1", "2"]])
    assert empty.markdown() == "" and empty.html() == []
    # an absent section adds no blank line between its neighbours
    assert markdown_text([full, empty, full]) == full.markdown() + "\n" + full.markdown()
    assert html_parts([empty, full]) == full.html()
    shown = _Rows([])
    shown.shown_without_rows = True
    assert shown.markdown() == "## A | table\n\n- first note\n- second <note>\n"


def test_the_front_files_share_one_field_list() -> None:
    common = {f.name for f in fields(FrontFile)}
    assert common == {
        "structure",
        "path",
        "names",
        "values",
        "itae",
        "isu",
        "chosen",
        "robust",
        "robust_path",
    }
    own = {cls: {f.name for f in fields(cls)} - common for cls in (ShippedFront, NoiseFront)}
    assert own == {ShippedFront: {"scenario"}, NoiseFront: {"label", "cvar", "stable"}}


def _png() -> bytes:
    buf = io.BytesIO()
    Image.new("RGB", (4, 3), "white").save(buf, format="PNG")
    return buf.getvalue()


def _design(**kw) -> DesignReport:
    base = dict(
        label="my design",
        record={"itae": 0.5, "iae": 0.25, "ise": None, "isu": 2.0, "iau": 1.0, "opi": 0.125},
        verdict="ok (the plant stayed within its envelope)",
        lines=["step: overshoot 1 %"],
        figure=_png(),
        operating_point=None,
        operating_text="operating point: y = 0 rad",
        margins=[("continuous loop: verdict", "stable")],
        export=[],
        sensors=[["its own", "ok", "0.5", "2", "1", "0"]],
        robustness=None,
        notes=["export not checked: continuous"],
    )
    return DesignReport(**{**base, **kw})


def test_a_design_report_is_the_same_sections_in_markdown_and_html() -> None:
    rep = _design()
    md = design_markdown(rep, "A sine.")
    page = design_html(rep, "A sine.")
    titles = [
        "What the plant did",
        "Operating point",
        "Margins (each labelled with the loop it is of)",
        "Export check",
        "Sensors",
        "Notes",
    ]
    assert re.findall(r"^## (.*)$", md, flags=re.M) == titles
    assert re.findall(r"<h2>(.*?)</h2>", page) == titles
    assert "| 0.5 | 0.25 | — | 2 | 1 | 0.125 |" in md  # ise None: a dash
    assert "not checked (see the notes)" in md and "<p>not checked (see the notes)</p>" in page
    assert md.startswith("# Design report: my design\n\nA sine.\n\n## What the plant did")
    assert "Robustness over" not in md + page


def test_a_design_with_draws_has_its_robustness_section() -> None:
    rob = {
        "draws": 4,
        "stable_fraction": 0.75,
        "status_counts": {"ok": 3, "diverged": 1},
        "itae": {"q50": 1.0, "q95": 2.0, "max": None},
        "worst": {"status": "diverged", "stopped_at": 1.5, "itae": None, "factors": {"J": 1.2}},
    }
    rep = _design(robustness=rob, notes=[])
    md = design_markdown(rep)
    assert "## Robustness over the [uncertainty] draws" in md
    assert "| stable (neither lost nor diverged) | 75.0 % |" in md
    assert "| worst draw | diverged at 1.5 s, ITAE —, factors J × 1.2 |" in md
    assert "## Notes" not in md and "<h2>Notes</h2>" not in design_html(rep)


@pytest.mark.slow
def test_tables_md_and_report_html_are_the_reports_sections(reproduced) -> None:
    """The files ``aiofl reproduce`` wrote are the sections of reproduction_report, in its
    orders, rendered from the Reproduction it returned."""
    from aiofl.reporting.reproduction_report import (
        HTML_SECTIONS,
        MARKDOWN_SECTIONS,
        html_report,
        report_markdown,
        report_sections,
    )

    rep = reproduced.reproduction()
    md = (reproduced.out / "tables.md").read_text()
    assert md == report_markdown(rep)
    figures = {p.name: p.read_bytes() for p in reproduced.out.glob("*.png")}
    page = (reproduced.out / "report.html").read_text()

    def undated(text: str) -> str:
        return re.sub(r"on \d{4}-\d\d-\d\d \d\d:\d\d [^<]*<", "on DATE<", text)

    assert undated(page) == undated(html_report(rep, figures))
    sections = report_sections(rep, figures)
    assert set(MARKDOWN_SECTIONS) <= set(HTML_SECTIONS) == set(sections)
    # each section's heading in the documents, in the documents' order (Tables I–III go
    # under the page's own title)
    at = [md.index(f"# {sections[k].title}\n") for k in MARKDOWN_SECTIONS if sections[k].markdown()]
    assert len(at) >= 9 and at == sorted(at)
    shown = [k for k in HTML_SECTIONS if k != "tables" and sections[k].html()]
    at = [page.index(f">{escape(sections[k].title)}</h2>") for k in shown]
    assert len(at) >= 11 and at == sorted(at)
