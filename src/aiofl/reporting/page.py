"""The pieces every aiofl HTML page is built from: its style, tables, folded blocks,
embedded figures and the page itself (one self-contained file: inline CSS, figures as
base64 palette PNG).  ``aiofl reproduce``'s report
(:mod:`aiofl.reporting.reproduction_report`) and a design's report
(:mod:`aiofl.reporting.design_report`) are made of them, section by section
(:mod:`aiofl.reporting.section`).
"""

from __future__ import annotations

import base64
import html
from collections.abc import Mapping, Sequence

__all__ = [
    "CSS",
    "PAGE_COLOURS",
    "Raw",
    "details",
    "escape",
    "html_table",
    "img",
    "item_list",
    "page",
    "page_png",
]

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;max-width:1180px;
margin:2em auto;padding:0 1em;color:#1b1f24;line-height:1.45}
h1{font-size:1.6em;margin-bottom:.2em}h2{margin-top:1.8em;border-bottom:1px solid #ddd}
table{border-collapse:collapse;margin:.8em 0;font-size:.92em}
th,td{border:1px solid #ccd;padding:.3em .6em;text-align:right;vertical-align:top}
th{background:#eef2f7}td:first-child,td:nth-child(2),th:first-child{text-align:left}
tr.context td{color:#555;font-style:italic;background:#fafafa}
td.div{color:#b00020;font-weight:600}
.settings td,.summary td,.summary th{text-align:left}
.verdicts td:last-child{text-align:left;min-width:16em}
.muted{color:#666;font-size:.9em}
img{max-width:100%;border:1px solid #eee;margin:.5em 0}
ul.notes li,ul.findings li{margin:.3em 0}code{background:#f3f3f3;padding:0 .2em}
details{margin:.4em 0}summary{cursor:pointer;color:#1a4f8a}
summary h2{display:inline-block;margin:1em 0 .2em;border:0}
section.summary{border:1px solid #ccd;background:#f7f9fc;padding:0 1em .4em;margin:1em 0}
section.summary h2{margin-top:.6em}
"""

#: colours of a PNG embedded in the page (the files beside it keep every colour)
PAGE_COLOURS = 256


class Raw(str):
    """Text that is already HTML (not escaped again by :func:`_e`)."""


def escape(s: object) -> str:
    """Text as HTML (a :class:`Raw` is already HTML)."""
    return s if isinstance(s, Raw) else html.escape(str(s))


def html_table(
    header: Sequence[str], rows: Sequence[Sequence[str]], *, cls: str = "", context_rows: int = 0
) -> str:
    """An HTML table; the last ``context_rows`` rows are styled as context (not results).
    A cell that is :class:`Raw` is inserted as HTML.

    Parameters
    ----------
    header
        The column headings (plain text).
    rows
        The cells (plain text, or :class:`Raw` HTML).
    cls
        The table's CSS class.
    context_rows
        How many of the last rows are context.

    Returns
    -------
    str
    """
    parts = [f'<table class="{cls}"><thead><tr>']
    parts += [f"<th>{escape(h)}</th>" for h in header]
    parts.append("</tr></thead><tbody>")
    for i, row in enumerate(rows):
        ctx = ' class="context"' if i >= len(rows) - context_rows else ""
        parts.append(f"<tr{ctx}>")
        for cell in row:
            div = cell.startswith(("diverged", "lost")) and not isinstance(cell, Raw)
            attr = ' class="div"' if div else ""
            parts.append(f"<td{attr}>{escape(cell)}</td>")
        parts.append("</tr>")
    parts.append("</tbody></table>")
    return "".join(parts)


def item_list(items: Sequence[str], cls: str) -> str:
    return f'<ul class="{cls}">' + "".join(f"<li>{escape(i)}</li>" for i in items) + "</ul>"


def details(summary: str, body: Sequence[str], *, heading: bool = False) -> str:
    """A collapsed ``<details>`` block; ``summary`` is plain text (an ``<h2>`` when
    ``heading``), ``body`` HTML.

    Parameters
    ----------
    summary
        The summary line (plain text).
    body
        The content (HTML).
    heading
        Show the summary as an ``<h2>``.

    Returns
    -------
    str
    """
    head = f"<h2>{escape(summary)}</h2>" if heading else escape(summary)
    return f"<details><summary>{head}</summary>" + "".join(body) + "</details>"


def page_png(data: bytes, colours: int = PAGE_COLOURS) -> bytes:
    """A figure's PNG as embedded in the page: flattened on white and reduced to a palette
    of ``colours`` (median cut, no dithering; line plots have few colours, so the change is
    hardly visible), or the original bytes when that is not smaller.

    Parameters
    ----------
    data
        PNG bytes (as written beside the page).
    colours
        Palette size, 2–256.

    Returns
    -------
    bytes
        PNG bytes.
    """
    import io

    from PIL import Image

    with Image.open(io.BytesIO(data)) as im:
        rgba = im.convert("RGBA")
    flat = Image.alpha_composite(Image.new("RGBA", rgba.size, "white"), rgba).convert("RGB")
    pal = flat.quantize(colors=colours, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    buf = io.BytesIO()
    pal.save(buf, format="PNG", optimize=True)
    return buf.getvalue() if buf.tell() < len(data) else data


def img(figures: Mapping[str, bytes], name: str, alt: str) -> list[str]:
    """An ``<img>`` of ``figures[name]`` inlined as a palette PNG (:func:`page_png`) data URL.

    Parameters
    ----------
    figures
        Figure images (PNG bytes) by name.
    name
        The figure's name.
    alt
        Its alternative text.

    Returns
    -------
    list of str
        One HTML line, or none.
    """
    if name not in figures:
        return []
    data = base64.b64encode(page_png(figures[name])).decode("ascii")
    return [f'<img alt="{escape(alt)}" src="data:image/png;base64,{data}">']


def page(title: str, body: Sequence[str]) -> str:
    """The whole page: ``title`` and the ``body`` HTML parts, with :data:`CSS`."""
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>{escape(title)}</title>"
        f"<style>{CSS}</style></head><body>\n" + "\n".join(body) + "\n</body></html>\n"
    )
