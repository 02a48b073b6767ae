"""User text (issue 34, items 1, 3 and 4): one rule where it enters, one escape per sink.

Before the fix a config's ``name = "ctl\\u0001name"`` gave an FMU whose
``modelDescription.xml`` no XML parser loads; a plant file's ``"fi"`` and ``"ﬁ"`` (U+FB01)
were two parameters of which the expression ``-ﬁ*theta`` silently used ``fi`` (Python's
parser reads identifiers in NFKC); a newline in ``output_unit`` split trajectory.csv's units
line into stray rows; a NUL in a name was accepted and failed later without naming the
field; a description's ESC sequences reached the terminal raw; a config named ``[/]`` made
``aiofl simulate`` fail on rich markup.  Now every such string is checked where it enters
(:mod:`aiofl.text`: refused with the field named, exit 2 on the command line) and every
sink escapes for its format all the same.
"""

from __future__ import annotations

import csv
import io
import json
import xml.etree.ElementTree as ET
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from typer.testing import CliRunner

from aiofl.cli.app import app

TANK = """\
name = {name}
description = {description}
plant = {plant}

[scenario]
t_final = 0.05

[simulation]
dt = 1e-4

[controller]
structure = "LADRC"
td_kind = "exact"
rho = 1

[controller.eso]
omega0 = 20.0

[controller.sef]
omega_c = 4.0

[controller.law]
b0 = 0.05
"""

PLANT = """\
name = {name}
description = {description}
states = ["theta", "omega"]
f = ["omega", "-fi*theta - c*omega"]
g = ["0", "1"]
h = "theta"
output_unit = {unit}
input_unit = "N·m"

[params]
"fi" = 1.0
c = 0.5
"""


def _config(tmp_path: Path, name: str = "tank", description: str = "", plant: str = "tank") -> Path:
    """A tank LADRC config with these texts (JSON's escapes are TOML's)."""
    path = tmp_path / "c.toml"
    text = TANK.format(
        name=json.dumps(name), description=json.dumps(description), plant=json.dumps(plant)
    )
    path.write_text(text, encoding="utf-8")
    return path


def _plant_file(
    tmp_path: Path, name: str = "osc", description: str = "", unit: str = "rad"
) -> Path:
    path = tmp_path / "plant.toml"
    text = PLANT.format(
        name=json.dumps(name), description=json.dumps(description), unit=json.dumps(unit)
    )
    path.write_text(text, encoding="utf-8")
    return path


def _invoke(*args: str):
    return CliRunner().invoke(app, list(args))


# ------------------------------------------------------------- item 1: the FMU's XML
def test_a_control_character_in_the_name_is_refused_before_the_export(tmp_path: Path) -> None:
    """Before: exit 0 and a modelDescription.xml that is not well formed."""
    for field, name, description in (
        ("name", "ctl\u0001name", ""),
        ("description", "ok", "desc\u0000x"),
        ("description", "ok", "noncharacter \ufffe"),
        ("name", "ok\uffff", ""),
    ):
        cfg = _config(tmp_path, name=name, description=description)
        out = tmp_path / "o1"
        res = _invoke("export", str(cfg), "--ts", "1e-3", "--format", "fmu", "--out", str(out))
        assert res.exit_code == 2, res.output
        assert f"{field} = " in res.output and "U+" in res.output, res.output
        assert not out.exists()


def test_the_fmu_xml_holds_any_text_well_formed() -> None:
    """The sink's own escape: text no entry check saw (the Python export API) still gives
    a well-formed modelDescription.xml; text XML can hold is kept as given."""
    from aiofl.export.fmu import _model_description

    hostile = "ctl\u0001name \x00 \x1b[2J \ufffe \uffff \ud800 <&\"'> ]]> ﬁ ² \u202e"
    xml = _model_description(
        model_identifier="aiofl",
        title=hostile,
        description=hostile,
        guid="{0}",
        inputs=[("y", f"measured output [{hostile}]")],
        params=[],
        sources=["aiofl.c"],
        ts=1e-3,
        stop_time=1.0,
        start=0,
    )
    root = ET.fromstring(xml)  # before: ParseError, not well-formed (invalid token)
    title = root.get("modelName")
    assert "\\u0001" in title and "\\u0000" in title and "\\ufffe" in title
    assert "<&\"'> ]]> ﬁ ² \u202e" in title  # what XML can hold, unchanged


# ------------------------------------------------------------- item 3: one name, one meaning
def _osc(params: dict[str, float], f2: str):
    from aiofl.plants.symbolic import SymbolicPlant

    spec = {"states": ["theta", "omega"], "f": ["omega", f2], "g": ["0", "1"], "h": "theta"}
    return SymbolicPlant.from_dict({**spec, "params": params})


def test_two_names_equal_after_nfkc_are_refused_naming_both() -> None:
    """Before: accepted, and ``-ﬁ*theta`` used fi = 1, not ﬁ = 1000."""
    from aiofl.plants.expressions import SymbolicPlantError

    with pytest.raises(SymbolicPlantError, match="'fi' and 'ﬁ' are the same name once normal"):
        _osc({"fi": 1.0, "ﬁ": 1000.0}, "-ﬁ*theta")
    from aiofl.plants.symbolic import SymbolicPlant

    spec = {"params": {"k": 1.0}, "f": ["-k*X", "0"], "g": ["1", "0"], "h": "X"}
    with pytest.raises(SymbolicPlantError, match="'X' and 'Ｘ' are the same name once"):
        SymbolicPlant.from_dict({**spec, "states": ["X", "Ｘ"]})  # U+FF38, full width
    # x₂ reads x2 once normalised, but Python does not read it as a name as written
    with pytest.raises(SymbolicPlantError, match="states name = 'x₂' is not a valid name"):
        SymbolicPlant.from_dict({**spec, "states": ["X", "x₂"]})


def test_a_name_reads_the_same_declared_and_in_an_expression() -> None:
    """Before: declaring ``ﬁ`` and writing ``ﬁ`` in f gave "unknown name 'fi'; allowed
    names: ... ﬁ"."""
    import sympy as sp

    plant = _osc({"ﬁ": 1000.0}, "-ﬁ*theta")
    assert [str(s) for s in plant.param_symbols] == ["fi"]
    theta, fi = sp.Symbol("theta", real=True), sp.Symbol("fi", real=True)
    assert plant.f[1] == -fi * theta
    assert _osc({"ﬁ": 1000.0}, "-fi*theta").f == plant.f  # either spelling, one name


def test_sympy_symbols_from_python_are_renamed_to_their_normal_names() -> None:
    import sympy as sp

    from aiofl.plants.expressions import SymbolicPlantError
    from aiofl.plants.symbolic import SymbolicPlant

    x, lig = sp.Symbol("x", real=True), sp.Symbol("ﬁ", real=True)
    plant = SymbolicPlant("p", (x,), ((lig, 2.0),), f=[-lig * x], g=[1], h=x)
    (fi,) = plant.param_symbols
    assert str(fi) == "fi" and plant.f[0] == -fi * x and lig not in plant.f.free_symbols
    with pytest.raises(SymbolicPlantError, match="'fi' and 'ﬁ'"):
        fi_plain = sp.Symbol("fi", real=True)
        SymbolicPlant("p", (x,), ((fi_plain, 1.0), (lig, 2.0)), f=[-lig * x], g=[1], h=x)


def test_python_plants_and_parameter_keys_use_the_normal_names() -> None:
    """A Python plant's names, scenario overrides and [uncertainty] parameters are read in
    NFKC too: ``plant_overrides = {"ﬁ" = 2}`` sets parameter fi."""
    from aiofl.plants.base import Plant, PlantError
    from aiofl.scenario import Scenario
    from aiofl.uncertainty import UncertaintyModel

    def f(x, p):
        return (-p[0] * x[0],)

    def g(x, p):
        return (1.0,)

    def h(x, p):
        return x[0]

    plant = Plant("p", 1, f, g, h, params={"ﬁ": 1.0}, state_names=("ｘ",))
    assert plant.param_names == ("fi",) and plant.state_names == ("x",)
    assert plant.param_vector({"ﬁ": 3.0})[0] == 3.0 == plant.param_vector({"fi": 3.0})[0]
    with pytest.raises(PlantError, match="'fi' and 'ﬁ'"):
        Plant("p", 1, f, g, h, params={"fi": 1.0, "ﬁ": 2.0})
    assert dict(Scenario(plant_overrides={"ﬁ": 2.0}).plant_overrides) == {"fi": 2.0}
    with pytest.raises(ValueError, match=r"scenario\.plant_scale: 'fi' and 'ﬁ'"):
        Scenario(plant_scale={"fi": 1.1, "ﬁ": 1.2})
    model = UncertaintyModel.model_validate({"parameters": {"ﬁ": {"uniform": 0.1}}})
    assert list(model.parameters) == ["fi"]


# ------------------------------------------------------------- item 4: files and terminals
def test_a_newline_in_a_unit_is_refused_naming_the_unit(tmp_path: Path) -> None:
    """Before: ``simulate --check`` accepted it and the run wrote stray CSV rows."""
    plant = _plant_file(tmp_path, unit="rad\nEVIL,1,2")
    cfg = _config(tmp_path, plant=str(plant))
    res = _invoke("simulate", str(cfg), "--check")
    assert res.exit_code == 2, res.output
    assert "output_unit = 'rad\\nEVIL,1,2': U+000A (a control character)" in res.output


def test_a_nul_in_a_name_is_refused_where_it_enters(tmp_path: Path) -> None:
    """Before: ``--check`` and ``analyze`` accepted it; the run failed with "embedded null
    character", naming no field."""
    res = _invoke("simulate", str(_config(tmp_path, name="pe\u0000nd")), "--check")
    assert res.exit_code == 2 and "name = 'pe\\x00nd': U+0000" in res.output, res.output
    plant = _plant_file(tmp_path, name="pe\u0000nd")
    res = _invoke("analyze", str(plant))
    assert res.exit_code == 2 and "name = 'pe\\x00nd': U+0000" in res.output, res.output


def test_escape_sequences_in_a_description_never_reach_the_terminal(tmp_path: Path) -> None:
    """Before: ``aiofl analyze`` printed the clear-screen and window-title sequences raw."""
    evil = "evil\u001b[2J\u001b]0;TITLE\u0007 end"
    res = _invoke("analyze", str(_plant_file(tmp_path, description=evil)))
    assert res.exit_code == 2 and "description = " in res.output and "U+001B" in res.output
    assert "\x1b" not in res.output
    from aiofl.text import terminal_text

    shown = terminal_text(f"Plant p: {evil}\nnext line", lines=True)
    assert "\x1b" not in shown and "\x07" not in shown and shown.count("\n") == 1
    assert "\\x1b[2J" in shown


def test_the_units_line_of_trajectory_csv_stays_one_line() -> None:
    """The CSV sink's own escape, for a unit no entry check saw."""
    from aiofl.cli.app import _column_labels, _csv_text

    unit = "rad\nEVIL,1,2\r\u2028x"
    plant = SimpleNamespace(
        output_unit=unit,
        input_unit="V",
        disturbance_unit="",
        state_label=lambda i: f"x{i + 1} [{unit}]",
    )
    columns = ["t", "r", "y", "x1"]
    labels = _column_labels(SimpleNamespace(plant=plant), columns)
    t = np.linspace(0.0, 1.0, 5)
    result = SimpleNamespace(t=t, signals={c: t * k for k, c in enumerate(columns)})
    text = _csv_text(result, columns, labels)
    rows = list(csv.reader(io.StringIO(text)))
    assert len(rows) == 2 + len(t) and all(len(r) == len(columns) for r in rows)
    data = np.loadtxt(io.StringIO(text), delimiter=",", skiprows=1)  # before: ValueError
    assert data.shape == (len(t), len(columns))
    assert rows[1][2] == "y [rad\\nEVIL;1;2\\r\\u2028x]"


def test_a_name_with_rich_markup_is_printed_as_written(tmp_path: Path) -> None:
    """Before: ``aiofl simulate`` on a config named ``[/]`` failed with rich's MarkupError
    (its status line read the name as markup)."""
    out = tmp_path / "out"
    res = _invoke("simulate", str(_config(tmp_path, name="[/] [red]x")), "--out", str(out))
    assert res.exit_code == 0, res.output
    assert json.loads((out / "metrics.json").read_text())["name"] == "[/] [red]x"


def test_the_python_api_refuses_the_same_text_naming_the_field() -> None:
    from aiofl.controller import Controller
    from aiofl.plants.base import Plant, PlantError
    from aiofl.scenario import Scenario

    def f(x, p):
        return (0.0,)

    with pytest.raises(PlantError, match=r"plant.name = 'a\\x1b\[2J': U\+001B"):
        Plant("a\x1b[2J", 1, f, f, lambda x, p: x[0], params={})
    with pytest.raises(PlantError, match=r"output_unit = 'm\\n': U\+000A"):
        Plant("a", 1, f, f, lambda x, p: x[0], params={}, output_unit="m\n")
    with pytest.raises(ValueError, match=r"scenario.name = 'a\\u2028b': U\+2028"):
        Scenario(name="a\u2028b")
    with pytest.raises(ValueError, match=r"controller.structure = .*U\+202E"):
        Controller(structure="LESO\u202e")
    with pytest.raises(ValueError, match="has 201 characters"):
        Scenario(name="a" * 201)
    from aiofl.design import Design
    from aiofl.plants.registry import get_plant

    vals = {"law.b0": 0.05, "eso.omega0": 20.0, "sef.omega_c": 4.0}
    ctrl = Controller.from_structure("LADRC", rho=1, values=vals)
    with pytest.raises(ValueError, match=r"description = 'a\\x1bb': U\+001B"):
        Design(get_plant("tank"), ctrl, Scenario(t_final=0.1), description="a\x1bb")


def test_an_error_quoting_user_text_never_drives_the_terminal(tmp_path: Path) -> None:
    """Before: an unknown TOML key holding ESC sequences was printed raw in the error."""
    cfg = _config(tmp_path)
    cfg.write_text('"\\u001b[2Jkey\\u0007" = 1\n' + cfg.read_text(encoding="utf-8"), "utf-8")
    res = _invoke("simulate", str(cfg), "--check")
    assert res.exit_code == 2 and "unknown key" in res.output, res.output
    assert "\x1b" not in res.output and "\x07" not in res.output
    assert "\\x1b[2Jkey\\x07" in res.output
