"""Random Unicode through every user string into every sink (issue 34).

Hypothesis draws a plant's name, description, unit, state name and parameter name from
control characters, bidirectional controls, compatibility characters (``ﬁ``, ``²``, full
width), characters around the surrogates and the noncharacters, lone surrogates, line
separators, and the special characters of each format (``<&"'>``, ``[/]``, ``,``, ``*/``,
``$``).  Each goes in where a user gives it (a plant file, a Python ``Plant``, a config's
``name`` and ``description``) and is either refused with a message naming the field, exactly
when it holds a character the rule refuses (decided here from Unicode's own properties,
not from :mod:`aiofl.text`), or accepted and then found, unchanged, in the terminal text
(also printed through rich with markup on), the JSON of ``aiofl analyze --json``, the
units line of trajectory.csv (read back by :mod:`csv` and :func:`numpy.loadtxt`), an HTML
table cell of the report's escaping (read back by :mod:`html.parser`) and the FMU's
``modelDescription.xml`` (read back by :mod:`xml.etree`).  The raw text, unchecked, goes
through each sink's own escape as well, and every output still parses.  Two tests build
once what is slow: a C export compiled with ``-Werror -pedantic`` and an FMU that FMPy loads
and validates, both from text that holds every class of character drawn here.
"""

from __future__ import annotations

import csv
import io
import json
import shutil
import subprocess
import unicodedata
import xml.etree.ElementTree as ET
from html.parser import HTMLParser
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from aiofl.cli.app import _column_labels, _csv_text
from aiofl.export.fmu import _model_description
from aiofl.plants.base import unit_label
from aiofl.reporting.page import escape as _e
from aiofl.text import one_line, terminal_text, xml_text

SPECIAL = [
    *map(chr, range(0x20)),
    "\x7f",
    "\x85",
    "\x9b",  # DEL, C1: NEL, CSI
    *"\u061c\u200e\u200f\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069",  # bidi
    "\u2028",
    "\u2029",
    *"\ufb01\u00b2\uff21\u2460\u210c\u1e9b\u0323\u01c4\u3000",  # compatibility
    *"\ud7ff\ue000\ufffd\ufffe\uffff\ufdd0\ufdef\ud800\udbff\udc00\udfff",  # around surrogates
    "\U00010000",
    "\U0001fffe",
    "\U0010ffff",
    *"<>&\"'[]/\\,*?#$%{};=",
    *"Ωé制🤖θ",
    "\u200d",
    "\u00ad",  # other format characters: kept
]
HOSTILE = st.text(alphabet=st.sampled_from(SPECIAL) | st.characters(), max_size=12)
HOSTILE_NAME = st.builds(
    lambda head, tail: head + tail,
    st.sampled_from(["x", "ﬁ", "Ｘ", "θ", "ℌ", "x₂", "_", "1", "if", "sin", ""]),
    st.text(alphabet=st.sampled_from([*SPECIAL, "a", "1", "_"]), max_size=4),
)
_BIDI = {"LRE", "RLE", "LRO", "RLO", "PDF", "LRI", "RLI", "FSI", "PDI"}


def _refused(text: str) -> bool:
    """Whether the rule refuses a character of ``text`` (:func:`_refused_char`)."""
    return any(_refused_char(c) for c in text)


def _refused_char(ch: str) -> bool:
    """Whether the rule refuses ``ch``, from Unicode's properties (not aiofl's code)."""
    cp = ord(ch)
    return (
        unicodedata.category(ch) in ("Cc", "Cs", "Zl", "Zp")
        or unicodedata.bidirectional(ch) in _BIDI
        or ch in "\u200e\u200f\u061c"
        or 0xFDD0 <= cp <= 0xFDEF
        or cp & 0xFFFE == 0xFFFE
    )


#: text with none of the refused characters (mostly): what the sinks must hold unchanged
CLEAN = st.text(
    alphabet=st.sampled_from([c for c in SPECIAL if not _refused_char(c)])
    | st.characters(blacklist_categories=("Cc", "Cs", "Zl", "Zp")),
    max_size=12,
)


def _clean_name(heads: list[str]) -> st.SearchStrategy[str]:
    tail = st.text(alphabet=st.sampled_from(["a", "1", "_", "ﬁ", "θ", "Ｘ", "ǅ"]), max_size=4)
    return st.builds(lambda head, rest: head + rest, st.sampled_from(heads), tail)


#: five texts (name, description, unit, state name, parameter name), clean or hostile
TEXTS = st.one_of(
    st.tuples(
        CLEAN, CLEAN, CLEAN, _clean_name(["x", "ﬁ", "Ｘ", "θ"]), _clean_name(["k", "ℌ", "Ω", "ﬀ"])
    ),
    st.tuples(HOSTILE, HOSTILE, HOSTILE, HOSTILE_NAME, HOSTILE_NAME),
)


class _Cells(HTMLParser):
    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.cells: list[str] = []
        self._in = False

    def handle_starttag(self, tag, attrs):
        if tag == "td":
            self.cells.append("")
            self._in = True

    def handle_endtag(self, tag):
        self._in = tag != "td" and self._in

    def handle_data(self, data):
        if self._in:
            self.cells[-1] += data


def _xml(title: str, description: str, unit: str) -> ET.Element:
    data = _model_description(
        model_identifier="aiofl",
        title=title,
        description=description,
        guid="{0}",
        inputs=[("y", unit_label("measured output y", unit))],
        params=[],
        sources=["aiofl.c"],
        ts=1e-3,
        stop_time=1.0,
        start=0,
    )
    return ET.fromstring(data)


def _csv_rows(unit: str, state_label: str) -> tuple[list[list[str]], np.ndarray]:
    plant = SimpleNamespace(
        output_unit=unit, input_unit="V", disturbance_unit="", state_label=lambda i: state_label
    )
    columns = ["t", "r", "y", "u", "x1"]
    labels = _column_labels(SimpleNamespace(plant=plant), columns)
    t = np.linspace(0.0, 1.0, 4)
    text = _csv_text(SimpleNamespace(t=t, signals={c: t for c in columns}), columns, labels)
    rows = list(csv.reader(io.StringIO(text, newline="")))
    data = np.loadtxt(io.StringIO(text), delimiter=",", skiprows=1)
    assert len(rows) == 2 + len(t) and all(len(r) == len(columns) for r in rows)
    assert data.shape == (len(t), len(columns))
    return rows, data


def _raw_sinks(text: str) -> None:
    """Text no entry check saw, through each sink's own escape: every output parses."""
    shown = terminal_text(text)
    assert not any(unicodedata.category(c) in ("Cc", "Cs", "Zl", "Zp") for c in shown)
    assert "\n" not in one_line(text) and "\r" not in one_line(text)
    root = _xml(text, text, text)
    assert root.get("modelName") == xml_text(text)
    _csv_rows(text, unit_label("x1", text))


@settings(
    max_examples=60,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(texts=TEXTS)
def test_random_text_is_refused_naming_the_field_or_held_by_every_sink(
    texts: tuple[str, str, str, str, str],
) -> None:
    from rich.console import Console

    from aiofl.analysis.plant_structure import analysis_to_dict, format_analysis_text
    from aiofl.config.schema import ConfigModel
    from aiofl.plants.base import Plant, PlantError
    from aiofl.plants.expressions import SymbolicPlantError
    from aiofl.plants.symbolic import SymbolicPlant

    name, description, unit, state, param = texts
    for text in texts:
        _raw_sinks(text)

    # a config's name and description (pydantic schema)
    try:
        ConfigModel.model_validate({"name": name, "description": description})
        assert not _refused(name) and not _refused(description)
    except ValueError as exc:
        assert _refused(name) or _refused(description)
        assert ("name = " in str(exc) or "description = " in str(exc)) and "U+" in str(exc)

    # a Python plant
    def fn(x, p):
        return (0.0,)

    try:
        Plant(name, 1, fn, fn, fn, params={param: 1.0}, state_names=(state,), output_unit=unit)
        assert not any(map(_refused, (name, unit, state, param)))
    except PlantError as exc:
        msg = str(exc)
        assert any(k in msg for k in ("name", "params", "state_names", "output_unit")), msg

    # a plant file
    spec = {
        "name": name,
        "description": description,
        "states": [state],
        "params": {param: 2.0},
        "f": [f"-{param}*{state}"],
        "g": ["1"],
        "h": state,
        "output_unit": unit,
        "input_unit": unit,
    }
    try:
        plant = SymbolicPlant.from_dict(spec)
    except SymbolicPlantError as exc:
        event("plant file refused")
        msg = str(exc)
        fields = ("name", "description", "output_unit", "input_unit", "states", "params")
        assert any(f"{k} " in msg or f"{k}[" in msg for k in fields), msg
        assert ("U+" in msg or "characters" in msg or "valid name" in msg or "reserved" in msg
                or "same name" in msg), msg  # fmt: skip
        return
    assert not any(map(_refused, (name, description, unit, state, param)))
    event("plant file accepted")

    # the terminal: the text as given, no control character; rich with markup on as well
    printed = terminal_text(format_analysis_text(plant.analyze()), lines=True)
    assert f"Plant {name}" in printed and description in printed
    assert not any(unicodedata.category(c) == "Cc" for c in printed.replace("\n", ""))
    buf = io.StringIO()
    Console(file=buf, width=400, markup=True, highlight=False).print(
        terminal_text(name, markup=True)
    )
    assert buf.getvalue().rstrip("\n").rstrip() == name.rstrip()
    # JSON
    doc = analysis_to_dict(plant.analyze())
    assert json.loads(json.dumps(doc)) == doc and doc["plant"] == name
    # CSV: one header row, one units row, the data; the unit held (a comma reads ;)
    rows, _ = _csv_rows(plant.output_unit, unit_label("x1", unit))
    assert rows[1][2].removeprefix("# ") == unit_label("y", unit).replace(",", ";")
    # HTML: the report's escape, read back
    cells = _Cells()
    cells.feed(f"<table><tr><td>{_e(name)}</td><td>{_e(description)}</td></tr></table>")
    cells.close()
    assert cells.cells == [name, description]
    # the FMU's XML
    root = _xml(name, description, unit)
    assert root.get("modelName") == name and root.get("description") == description
    desc_y = root.find("ModelVariables/ScalarVariable").get("description")
    assert desc_y == unit_label("measured output y", unit)


# ------------------------------------------------------------------ built once
ALLOWED = "ﬁ² ＡΩ制🤖 <&\"'> [/] [red] */ ??/ #x $\\frac$ , ; \u200d\u00ad \ufffd \U0010fffd"
RAW = ALLOWED + "".join(c for c in SPECIAL if _refused(c))


def _controller():
    from aiofl.controller import Controller

    vals = {"law.b0": 4.0, "law.u_max": 10.0, "eso.omega0": 60.0, "td.R": 50.0}
    for i, (k, a) in enumerate(((56.0, 0.8), (15.0, 0.9)), start=1):
        vals |= {f"sef.k{i}": k / 4.0, f"sef.alpha{i}": a, f"sef.delta{i}": 0.05}
    kinds = {"eso": "linear", "td": "han", "sef": "nonlinear", "law": "aiofl"}
    return Controller(**kinds, rho=2, n_feedback=2, values=vals, structure=ALLOWED)


def test_allowed_text_is_allowed_and_raw_text_is_refused() -> None:
    from aiofl.text import check_text

    assert not _refused(ALLOWED) and check_text("name", ALLOWED) == ALLOWED
    for ch in RAW[len(ALLOWED) :]:
        with pytest.raises(ValueError, match=r"name = .*U\+"):
            check_text("name", f"a{ch}b")


@pytest.mark.skipif(shutil.which("gcc") is None, reason="no gcc on the PATH")
def test_the_c_export_of_any_text_compiles(tmp_path: Path) -> None:
    from aiofl.engine.discrete_rows import Sampling
    from aiofl.export import export_c

    files = export_c(_controller(), Sampling(1e-3), title=ALLOWED, notes=[RAW, f"Config: {RAW}"])
    for fname, text in files.items():
        assert text.isascii(), fname
        (tmp_path / fname).write_text(text, encoding="utf-8")
    srcs = [f for f in files if f.endswith(".c")]
    flags = ["-std=c99", "-trigraphs", "-Wall", "-Wextra", "-Werror", "-pedantic"]
    res = subprocess.run(
        ["gcc", *flags, "-fsyntax-only", *srcs], cwd=tmp_path, capture_output=True, text=True
    )
    assert res.returncode == 0, res.stderr


def test_fmpy_loads_the_fmu_of_any_text(tmp_path: Path) -> None:
    fmpy = pytest.importorskip("fmpy")
    from aiofl.engine.discrete_rows import Sampling
    from aiofl.export.fmu import export_fmu, find_compiler

    try:
        find_compiler()
    except ValueError:
        pytest.skip("no C compiler on the PATH")
    name, data = export_fmu(_controller(), Sampling(1e-3), title=ALLOWED, description=RAW)
    path = tmp_path / name
    path.write_bytes(data)
    md = fmpy.read_model_description(str(path), validate=True)  # before: XMLSyntaxError
    assert md.modelName == ALLOWED and md.description == xml_text(RAW)
    assert "\\u0001" in md.description and "\\ufffe" in md.description
