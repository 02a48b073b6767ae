"""How long ``report.html`` is with nothing opened: a text-layout estimate (no browser).

Run ``python benchmarks/report_layout.py DIR/report.html [...]``.  No browser is needed (none
is installed on the machines this was written on), so the height is *estimated* from the
page's structure at a 1400 px wide window:

* content width 1148 px (the page's ``max-width`` of 1180 px less its padding); body text
  7.4 px per character, lines 23 px apart; headings scaled by their font size;
* a table shares the width among its columns in proportion to each column's longest cell
  (like a browser's automatic layout), each row as tall as its tallest wrapped cell;
* an image is scaled to the content width;
* a closed ``<details>`` counts as its one ``<summary>`` line.

On the page before issue 22 this gives 20,276 px where a browser measured ~21,800 px, so
the figures are good to about 10 %.  Also printed: the page's bytes and the elements open
outside ``<details>`` (the text-based proxy of the issue).
"""

from __future__ import annotations

import argparse
import base64
import io
import math
import re
from html.parser import HTMLParser

from PIL import Image

WIDTH = 1148.0  # px of content at a 1400 px window
CHAR = 7.4  # px per character of body text
LINE = 23.0  # px per line of body text
BLOCKS = ("p", "li", "h1", "h2", "h3")
SCALE = {"h1": 1.6, "h2": 1.5, "h3": 1.17}
MARGIN = {"h1": 30.0, "h2": 50.0, "h3": 30.0, "p": 16.0, "li": 5.0}
COUNTED = ("p", "li", "tr", "img", "h2", "h3", "table")


def table_height(rows: list[list[str]]) -> float:
    """Estimated height [px] of a table of cell texts."""
    if not rows:
        return 0.0
    ncol = max(len(r) for r in rows)
    natural = [0.0] * ncol
    for row in rows:
        for i, cell in enumerate(row):
            natural[i] = max(natural[i], len(cell) * CHAR * 0.92 + 20)
    total = sum(natural)
    widths = natural if total <= WIDTH else [WIDTH * n / total for n in natural]
    height = 0.0
    for row in rows:
        lines = max(
            max(1, math.ceil(len(cell) * CHAR * 0.92 / max(widths[i] - 20, 30)))
            for i, cell in enumerate(row)
        )
        height += lines * 21 + 9
    return height


class Layout(HTMLParser):
    """Walks the page, adding up the estimated height of what is open."""

    def __init__(self) -> None:
        super().__init__()
        self.height = 0.0
        self.counts: dict[str, int] = {}
        self._closed = 0  # depth inside closed <details> (outside their <summary>)
        self._details: list[bool | None] = []
        self._summary = 0
        self._text: list[str] = []
        self._table: list[list[str]] | None = None
        self._row: list[str] | None = None
        self._cell: list[str] | None = None

    def _open(self) -> bool:
        return self._closed == 0 or self._summary > 0

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        """Track tables, details and images; start collecting a block's text."""
        if self._open() and tag in COUNTED:
            self.counts[tag] = self.counts.get(tag, 0) + 1
        if tag == "details":
            if self._closed and not self._summary:
                self._closed += 1
                self._details.append(None)
                return
            is_open = any(k == "open" for k, _ in attrs)
            self._details.append(is_open)
            self._closed += 0 if is_open else 1
        elif tag == "summary":
            self._summary += 1
            self._text = []
        elif tag in BLOCKS and self._cell is None:
            self._text = []
        elif tag == "table":
            self._table = []
        elif tag == "tr" and self._table is not None:
            self._row = []
        elif tag in ("td", "th") and self._row is not None:
            self._cell = []
        elif tag == "img" and self._open():
            src = dict(attrs).get("src") or ""
            if src.startswith("data:image/png;base64,"):
                with Image.open(io.BytesIO(base64.b64decode(src.split(",", 1)[1]))) as im:
                    w, h = im.size
                self.height += h * min(1.0, WIDTH / w) + 16

    def handle_endtag(self, tag: str) -> None:
        """Add a finished block's, summary line's or table's height."""
        if tag == "details":
            is_open = self._details.pop()
            if is_open is None or not is_open:
                self._closed -= 1
        elif tag == "summary":
            self._summary -= 1
            if self._cell is None:
                text = "".join(self._text)
                self.height += max(1, math.ceil(len(text) * CHAR / WIDTH)) * LINE + 8
                self._text = []
        elif tag in BLOCKS and self._cell is None:
            if self._open() and not self._summary:
                text = "".join(self._text)
                scale = SCALE.get(tag, 1.0)
                lines = max(1, math.ceil(len(text) * CHAR * scale / WIDTH))
                self.height += lines * LINE * scale + MARGIN[tag]
            self._text = []
        elif tag in ("td", "th") and self._cell is not None and self._row is not None:
            self._row.append("".join(self._cell))
            self._cell = None
        elif tag == "tr" and self._row is not None and self._table is not None:
            self._table.append(self._row)
            self._row = None
        elif tag == "table" and self._table is not None:
            if self._open():
                self.height += table_height(self._table) + 16
            self._table = None

    def handle_data(self, data: str) -> None:
        """Collect the text that is open."""
        if not self._open():
            return
        (self._cell if self._cell is not None else self._text).append(data)


def main() -> None:
    """Print bytes, estimated height and open elements of each page given."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("pages", nargs="+")
    args = parser.parse_args()
    for path in args.pages:
        with open(path, encoding="utf-8") as f:
            page = f.read()
        layout = Layout()
        layout.feed(page)
        text = re.sub(r'src="data:[^"]*"', "", page)
        print(
            f"{path}: {len(page.encode()):,} bytes ({len(text.encode()):,} without images); "
            f"estimated height {layout.height:,.0f} px with nothing opened; "
            f"open elements {dict(sorted(layout.counts.items()))}"
        )


if __name__ == "__main__":
    main()
