"""A report section: one part of a report that computes its rows from what was measured and
renders them as Markdown and as HTML.

Every report of :mod:`aiofl.reporting` is a list of sections: ``aiofl reproduce``'s
``tables.md`` and ``report.html`` (:mod:`aiofl.reporting.reproduction_report`) and a design's
report (:mod:`aiofl.reporting.design_report`).  A :class:`Section` has a :attr:`~Section.title`
and renders itself with :meth:`~Section.markdown` (a block of ``tables.md``; empty when it has
nothing to show) and :meth:`~Section.html` (parts of the page, built from
:mod:`aiofl.reporting.page`).  :class:`TableSection` is the common shape: a titled table with
notes under it (the robustness, sensor, rig and fresh-seed rows, the noise fronts); a
subclass says what its rows and notes are.  :func:`markdown_text` and :func:`html_parts`
assemble a list of sections; :func:`md_table` is the one Markdown table of the package.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from types import MappingProxyType

from aiofl.reporting.page import details, escape, html_table, img, item_list

__all__ = ["Section", "TableSection", "html_parts", "markdown_text", "md_table"]


def md_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A Markdown table (a ``|`` inside a heading or a cell is escaped).

    Parameters
    ----------
    header
        The column headings.
    rows
        The cells, row by row.

    Returns
    -------
    str
        The table's lines, without a trailing newline.
    """
    lines = ["| " + " | ".join(_cell(h) for h in header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


class Section(ABC):
    """One part of a report: its rows computed from what was measured, rendered as Markdown
    and as HTML."""

    #: the section's heading (a class attribute, or a field of a dataclass section)
    title: str

    @abstractmethod
    def markdown(self) -> str:
        """The section as a block of Markdown ("" when it has nothing to show)."""

    @abstractmethod
    def html(self) -> list[str]:
        """The section as parts of an HTML page (none when it has nothing to show)."""


class TableSection(Section):
    """A titled table with notes under it: :meth:`rows` under :attr:`header`, the sentences
    of :meth:`lead` above the table and those of :meth:`notes` below it (in the page, folded
    under :attr:`notes_summary`), then the figure :attr:`figure` (the page only).

    Without rows the section is left out, unless :attr:`shown_without_rows` (its notes then
    say why there are none).
    """

    #: the table's columns
    header: Sequence[str] = ()
    #: the line the notes are folded under in the page
    notes_summary: str = "What these columns are"
    #: show the title and the notes when there are no rows
    shown_without_rows: bool = False
    #: the table's CSS class in the page
    table_class: str = ""
    #: (file name, alternative text) of the figure shown under the section in the page
    figure: tuple[str, str] | None = None
    #: the figures' PNG bytes by file name (see :attr:`figure`)
    figures: Mapping[str, bytes] = MappingProxyType({})

    @abstractmethod
    def rows(self) -> list[list[str]]:
        """The table's rows (cells as text)."""

    def lead(self) -> list[str]:
        """Sentences above the table (default: none)."""
        return []

    def notes(self) -> list[str]:
        """Sentences below the table (default: none)."""
        return []

    def markdown(self) -> str:
        """``## title``, the lead as a list, the table, the notes as a list."""
        rows = self.rows()
        if not rows and not self.shown_without_rows:
            return ""
        out = [f"## {self.title}", ""]
        lead = self.lead()
        if lead:
            out += [*(f"- {t}" for t in lead), ""]
        if rows:
            out += [md_table(self.header, rows), ""]
        out += [f"- {n}" for n in self.notes()]
        return "\n".join(out) + "\n"

    def html(self) -> list[str]:
        """An ``<h2>``, the lead, the table, the folded notes and the figure."""
        rows = self.rows()
        if not rows and not self.shown_without_rows:
            return []
        body = [f"<h2>{escape(self.title)}</h2>"]
        lead = self.lead()
        if lead:
            body.append(item_list(lead, "answers"))
        if rows:
            body.append(html_table(self.header, rows, cls=self.table_class))
        body.append(details(self.notes_summary, [item_list(self.notes(), "notes")]))
        if self.figure is not None:
            body += img(self.figures, *self.figure)
        return body


def markdown_text(sections: Sequence[Section]) -> str:
    """The sections' Markdown blocks, one after the other (a section with nothing to show
    is left out).

    Parameters
    ----------
    sections
        The sections, in order.

    Returns
    -------
    str
    """
    return "\n".join(block for s in sections if (block := s.markdown()))


def html_parts(sections: Sequence[Section]) -> list[str]:
    """The sections' HTML parts, one after the other (for :func:`aiofl.reporting.page.page`).

    Parameters
    ----------
    sections
        The sections, in order.

    Returns
    -------
    list of str
    """
    return [part for s in sections for part in s.html()]
