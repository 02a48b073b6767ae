"""Issue 33's defects met on the way, each pinned by a test that failed before its fix.

The user's own plant is :file:`tests/maglev_plant.toml` (open loop unstable, ρ = 3 = n,
operated around x1 = 1 cm) where a plant of that kind matters; the others use the shipped
pendulum (its kernels are in every test cache).
"""

from __future__ import annotations

import copy
import json
import math
import tomllib
import typing
import warnings
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from aiofl import Controller, Design, Plant, Reference, Scenario
from aiofl.analysis.corners import _nominal_beta
from aiofl.analysis.linearize import linearize_closed_loop
from aiofl.analysis.numeric_warnings import numeric_warnings, warnings_note
from aiofl.analysis.sampled_loop import sampled_margins
from aiofl.cli.app import app
from aiofl.cli.export_command import FORMATS, _loop_checks, export_command
from aiofl.config import load_config, parse_config, resolve_plant
from aiofl.plants import get_plant
from aiofl.plants.base import PlantError
from aiofl.sensor import Sensor
from aiofl.tuning.search import prepare
from aiofl.tuning.space import ParameterBounds, SearchSpace, to_toml
from test_tuning import FAST

HERE = Path(__file__).parent
MAGLEV = HERE / "maglev_plant.toml"
PENDULUM = get_plant("pendulum")
CTRL = Controller.from_structure(
    "LADRC",
    rho=2,
    values={"eso.omega0": 40.0, "sef.omega_c": 5.0, "td.omega": 10.0, "law.b0": 4.0},
)
runner = CliRunner()
SCEN = Scenario(reference=Reference(amplitude=0.5, omega=1.0), t_final=1.0)


def _design(**kw: Any) -> Design:
    return Design(PENDULUM, CTRL, SCEN, **{"dt": 1e-3, **kw})


# ------------------------------------------------------------ 1. Design(sensor=Sensor(...))
def test_a_design_takes_a_sensor_object() -> None:
    """It was always refused: "noise_variance is set twice" (the scenario's noise keys)."""
    sensor = Sensor(ts=1e-3, quantum=1e-4, noise_variance=1e-8, noise_seed=3)
    cfg = _design(sensor=sensor).config
    assert cfg.sampling is not None and cfg.sampling.ts == 1e-3
    assert cfg.sampling.y_quantum == 1e-4
    assert cfg.scenario.noise_variance == 1e-8 and cfg.scenario.noise_seed == 3
    assert cfg.scenario.noise_hold == 1e-3  # the sensor's sample time
    assert _design(sensor=Sensor()).config.sampling is None  # the ideal sensor


def test_a_sensor_object_and_a_scenario_with_other_noise_are_refused() -> None:
    noisy = Scenario(
        reference=Reference(amplitude=0.5, omega=1.0), t_final=1.0, noise_variance=1e-6
    )
    with pytest.raises(ValueError, match=r"noise_variance is set twice.*1e-06"):
        Design(PENDULUM, CTRL, noisy, dt=1e-3, sensor=Sensor(noise_variance=1e-8))
    # the same noise in both places is no contradiction
    d = Design(PENDULUM, CTRL, noisy, dt=1e-3, sensor=Sensor(noise_variance=1e-6))
    assert d.config.scenario.noise_variance == 1e-6


# -------------------------------------------------- 3. a custom sensor's label and unit
def _with_sensor(preset: str, table: dict[str, Any]) -> Any:
    data = copy.deepcopy(load_config(preset).raw)
    data["sensor"] = table
    return parse_config(data, f"{preset} with a sensor")


def test_a_sensor_without_a_preset_is_custom_and_its_step_is_in_the_output_unit() -> None:
    """It was labelled "ideal", its step in metres written as 2π/N (an angle encoder's)."""
    quantum = 2 * math.pi / 4096  # a step in metres that happens to be 2π/4096
    cfg = _with_sensor("tank-ladrc", {"ts": 1e-3, "quantum": quantum})
    text = cfg.sensor.describe()
    assert text.startswith("custom (sampled at 1 ms") and "ideal" not in text
    assert f"quantum {quantum:.4g} m" in text and "2π" not in text
    # an encoder on an angle keeps its wording; the ideal sensor is still "ideal"
    enc = _with_sensor("retuned-s1-leso", {"preset": "encoder-12bit"})
    described = enc.sensor.describe()
    assert described.startswith("encoder-12bit (") and "2π/4096 = 0.001534 rad" in described
    ideal = _with_sensor("tank-ladrc", {"noise_seed": 4})
    assert ideal.sensor.describe().startswith("ideal (continuous")
    assert Sensor(ts=1e-3).describe().startswith("custom (")


# ------------------------------------------- 2. the tuning horizon follows the scenario's
def _tune_config(tmp_path: Path, **tune: Any) -> Path:
    data = copy.deepcopy(FAST)
    data["scenario"]["t_final"] = 1.0
    data["tune"] = {k: v for k, v in {**data["tune"], **tune}.items() if v is not None}
    path = tmp_path / "notf.toml"
    path.write_text(to_toml(data))
    return path


def test_the_tuning_horizon_is_the_scenarios_by_default_and_check_says_so(
    tmp_path: Path,
) -> None:
    """It was 6 s whatever the scenario's horizon, silently ("simulations of 6 s")."""
    res = runner.invoke(app, ["tune", str(_tune_config(tmp_path, t_final=None)), "--check"])
    assert res.exit_code == 0, res.output
    assert "simulations of 1 s (the scenario's horizon)" in res.output
    assert prepare(str(_tune_config(tmp_path, t_final=None))).settings.t_final == 1.0
    res = runner.invoke(app, ["tune", str(_tune_config(tmp_path, t_final=0.6)), "--check"])
    assert res.exit_code == 0 and "simulations of 0.6 s (tune.t_final)" in res.output


def test_a_tuning_horizon_longer_than_the_scenario_is_refused(tmp_path: Path) -> None:
    res = runner.invoke(app, ["tune", str(_tune_config(tmp_path, t_final=6.0)), "--check"])
    assert res.exit_code == 2, res.output
    assert "tune.t_final = 6 s is longer than the scenario's horizon" in res.stderr
    assert "scenario.t_final = 1 s" in res.stderr


# ------------------------------------------- 6. linear bounds decode without an overflow
def test_linear_bounds_decode_without_an_overflow_warning() -> None:
    """Decoding took exp() of every column, linear ones too: "overflow encountered in exp"
    for tuple bounds such as law.b0 in (1e3, 1e5)."""
    space = SearchSpace(
        {
            "law.b0": ParameterBounds(lo=1e3, hi=1e5),
            "eso.omega0": ParameterBounds(lo=10.0, hi=1000.0, log=True),
        }
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        v = space.decode(np.array([[0.5, 0.5], [0.0, 1.0], [0.25, 0.0]]))
    assert np.allclose(v, [[50500.0, 100.0], [1e3, 1000.0], [25750.0, 10.0]])
    assert np.allclose(space.encode(v), [[0.5, 0.5], [0.0, 1.0], [0.25, 0.0]])


# ------------------------------------------- 12. a Python plant's bad parameter is named
@pytest.mark.parametrize("value", ["four", None, True, float("nan"), [4.0]])
def test_a_python_plants_non_numeric_parameter_is_named(value: Any) -> None:
    """It raised "could not convert string to float: 'four'" without naming k."""
    with pytest.raises(PlantError, match=r"plant 'bad_k': params\['k'\] = .*allowed: a finite"):
        Plant(name="bad_k", n_states=1, f=_f1, g=_g1, h=_h1, params={"k": value})
    p = Plant(name="ok_k", n_states=1, f=_f1, g=_g1, h=_h1, params={"k": np.float32(4)})
    assert p.params["k"] == 4.0 and type(p.params["k"]) is float


def _f1(x: Any, p: Any) -> Any:
    return (-p[0] * x[0],)


def _g1(x: Any, p: Any) -> Any:
    return (1.0,)


def _h1(x: Any, p: Any) -> Any:
    return x[0]


# --------------------------------------------------- 10. export --help lists the formats
def test_export_help_lists_the_formats() -> None:
    """It showed ``--format <str>``."""
    res = runner.invoke(app, ["export", "--help"], env={"COLUMNS": "200"})
    assert res.exit_code == 0
    line = next(ln for ln in res.output.splitlines() if "--format" in ln)
    assert "<c|fmu>" in line, line
    hint = typing.get_type_hints(export_command, include_extras=True)["fmt"]
    assert set(typing.get_args(typing.get_args(hint)[0])) == set(FORMATS)


# ----------------------------------------- 7. Design.export as an FMU; 11. its units
def test_a_design_exports_an_fmu(tmp_path: Path) -> None:
    """Design.export had C only; the CLI's --format fmu now has its keyword."""
    paths = _design().export(tmp_path / "fmu", ts=1e-3, prefix="pend", format="fmu")
    assert list(paths) == ["pend.fmu"]
    with zipfile.ZipFile(paths["pend.fmu"]) as z:
        assert any(n.startswith("binaries/") for n in z.namelist())
        xml = ET.fromstring(z.read("modelDescription.xml"))
    # 11. the variables carry the plant's units, each declared in UnitDefinitions
    units = {
        sv.get("name"): sv.find("Real").get("unit")  # type: ignore[union-attr]
        for sv in xml.iter("ScalarVariable")
        if sv.find("Real") is not None
    }
    assert units["y"] == units["r"] == PENDULUM.output_unit == "rad"
    assert units["u"] == PENDULUM.input_unit and units["Ts"] == "s"
    declared = {u.get("name") for u in xml.iter("Unit")}
    assert {u for u in units.values() if u is not None} == declared
    children = [c.tag for c in xml]
    assert children.index("CoSimulation") < children.index("UnitDefinitions")
    assert children.index("UnitDefinitions") < children.index("DefaultExperiment")
    with pytest.raises(ValueError, match=r"format = 'exe'; allowed: c, fmu"):
        _design().export(tmp_path / "no", ts=1e-3, format="exe")
    assert not (tmp_path / "no").exists()


# ------------------------------------- 8. a design saved as TOML; a Python plant's config
def test_a_saved_design_runs_on_the_command_line(tmp_path: Path) -> None:
    """A Design could not be saved as TOML."""
    d = _design(sensor="encoder-16bit")
    path = d.save(tmp_path / "design.toml")
    assert tomllib.loads(path.read_text()) == d.config.raw
    res = runner.invoke(app, ["simulate", str(path), "--check"])
    assert res.exit_code == 0, res.output
    again = load_config(path)
    assert np.array_equal(again.controller.float_row(), CTRL.float_row(), equal_nan=True)
    assert again.sampling == d.config.sampling and again.scenario == d.config.scenario


def test_a_plant_files_design_names_the_file_and_saves_it_relative(tmp_path: Path) -> None:
    plant = resolve_plant(str(MAGLEV))
    ctrl = Controller.from_structure(
        "LADRC",
        rho=3,
        values={"eso.omega0": 400.0, "sef.omega_c": 60.0, "td.omega": 40.0, "law.b0": -2800.0},
    )
    scen = Scenario(
        reference=Reference(kind="step", amplitude=1e-3, offset=0.01),
        t_final=1.0,
        x0=(0.01, 0.0, 0.7004),
    )
    d = Design(plant, ctrl, scen, dt=1e-4)
    assert d.config.raw["plant"] == str(MAGLEV.resolve())
    (tmp_path / "sub").mkdir()
    path = d.save(tmp_path / "sub" / "maglev.toml")
    written = tomllib.loads(path.read_text())["plant"]
    assert not Path(written).is_absolute() and (path.parent / written).resolve() == MAGLEV.resolve()
    assert load_config(path).plant is plant


def test_a_python_plants_config_says_what_to_do(tmp_path: Path) -> None:
    """best.toml tuned on a Python plant failed in the CLI with "unknown plant 'maglev_py'"."""
    data = copy.deepcopy(load_config("tank-ladrc").raw)
    data["plant"] = "maglev_py"
    res_path = tmp_path / "best.toml"
    res_path.write_text(to_toml(data))
    res = runner.invoke(app, ["simulate", str(res_path), "--check"])
    assert res.exit_code == 2
    text = " ".join(res.stderr.split())
    assert "unknown plant 'maglev_py'" in text and "defined in Python" in text
    assert 'plant = "FILE.toml"' in text and "aiofl.register_plant('maglev_py'" in text
    py = Design(
        Plant(name="saved_py", n_states=1, f=_f1, g=_g1, h=_h1, params={"k": 1.0}),
        Controller.from_structure("LADRC", rho=1, values={"law.b0": 1.0}),
        SCEN,
        dt=1e-3,
    )
    with pytest.raises(ValueError, match=r"'saved_py' is defined in Python.*plant file"):
        py.to_toml()
    assert "defined in Python" in py.to_toml(python_plant=True).splitlines()[1]


# ----------------------------------- 9. analyze's β at the operating point = robustness's
MAGLEV_RUN = """
plant = "{plant}"
[scenario]
t_final = 1.0
x0 = [0.01, 0.0, 0.7003570517957252]
[scenario.reference]
kind = "step"
amplitude = 0.001
offset = 0.01
[controller]
structure = "LADRC"
n_feedback = 3
[controller.eso]
omega0 = 400.0
[controller.td]
omega = 40.0
[controller.sef]
omega_c = 60.0
[controller.law]
b0 = -2800.0
u_max = 24.0
[simulation]
dt = 1e-4
"""


def _maglev_run(tmp_path: Path, **changes: str) -> Path:
    path = tmp_path / "maglev_run.toml"
    text = MAGLEV_RUN.format(plant=MAGLEV.as_posix())
    for old, new in changes.items():
        text = text.replace(old, new)
    path.write_text(text)
    return path


def test_analyze_gives_beta_at_the_operating_point_as_robustness_does(tmp_path: Path) -> None:
    """analyze printed beta_nominal: null (β depends on x) where robustness took −2801.43."""
    res = runner.invoke(app, ["analyze", str(MAGLEV), "--json"])
    assert res.exit_code == 0, res.output
    info = json.loads(res.output)
    assert info["beta_nominal"] == pytest.approx(-2801.43, abs=0.01)
    assert info["beta_point"] == [0.01, 0.0, 0.7003570517957252]
    assert "equilibrium" in info["beta_point_label"]
    run = _maglev_run(tmp_path)
    res = runner.invoke(app, ["analyze", str(run), "--json"])
    assert res.exit_code == 0, res.output
    robustness_beta = _nominal_beta(load_config(run))  # what `aiofl robustness` reports
    assert json.loads(res.output)["beta_nominal"] == pytest.approx(robustness_beta, rel=1e-12)
    text = runner.invoke(app, ["analyze", str(run)]).output
    assert "β at x0, the config's initial state = [0.01, 0, 0.700357]: -2801.43" in text


# ------------------------- 5. analyze --closed-loop on the maglev: warnings, a step's orbit
def test_closed_loop_analysis_of_the_maglev_leaks_no_warning_and_handles_the_step(
    tmp_path: Path,
) -> None:
    """It leaked numpy/scipy RuntimeWarnings pointing into the plant cache and reported
    "tracking orbit not analysed (ValueError: array must not contain infs or NaNs)": the
    finite difference's first step crossed x1 = 0, so a good complex step was dropped."""
    run = _maglev_run(tmp_path)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        res = runner.invoke(app, ["analyze", "--closed-loop", str(run), "--json"])
    assert res.exit_code == 0, res.output
    assert not [w for w in seen if issubclass(w.category, RuntimeWarning)], seen[:3]
    info = json.loads(res.stdout)
    orbit = info["orbit"]
    assert orbit["step_final"] == pytest.approx(0.011)
    assert "notes" not in orbit  # every plant function by the exact complex step
    assert "infs or NaNs" not in orbit["verdict"]
    assert "tracking orbit is the equilibrium at its final value r = 0.011 m" in orbit["verdict"]
    assert orbit["verdict"].startswith("equilibrium stable")


def test_numerical_warnings_are_summarised_in_one_note() -> None:
    with numeric_warnings() as caught:
        for _ in range(3):
            warnings.warn_explicit(
                "divide by zero encountered in scalar divide",
                RuntimeWarning,
                "/cache/plants/plant_0123.py",
                10,
            )
        warnings.warn_explicit(
            "invalid value encountered in matmul",
            RuntimeWarning,
            "/venv/site-packages/scipy/differentiate/_d.py",
            5,
        )
    note = warnings_note(caught)
    assert note is not None and note.startswith("4 numerical warning(s) while analysing")
    assert "divide by zero encountered in scalar divide (×3, in the plant's functions)" in note
    assert "invalid value encountered in matmul (×1, in scipy)" in note
    assert warnings_note([]) is None


def test_a_sampled_configs_margins_are_labelled_and_the_sampled_loops_given() -> None:
    """On a sampled config it gave the continuous loop's margins without saying so."""
    res = runner.invoke(app, ["analyze", "--closed-loop", "assisted-s1-ladrc", "--no-orbit"])
    assert res.exit_code == 0, res.output
    first = res.output.splitlines()[0]
    assert "the continuous loop (the design runs sampled at Ts = 0.001 s)" in first
    assert "Sampled loop at Ts = 0.001 s" in res.output
    res = runner.invoke(
        app, ["analyze", "--closed-loop", "assisted-s1-ladrc", "--no-orbit", "--json"]
    )
    info = json.loads(res.stdout)
    assert info["margins_of"] == "the continuous loop (no sampling)"
    sampled = info["sampled_loop"]
    assert sampled["ts"] == 1e-3 and sampled["stable"] and sampled["spectral_radius"] < 1
    assert sampled["phase_margin_deg"] > 0 and sampled["delay_margin_s"] > 0
    # a fast enough sampling gives back the continuous margins
    cfg = load_config("retuned-s1-ladrc")
    fast = sampled_margins(cfg.with_sample_time(1e-4))
    m = linearize_closed_loop(cfg).margins
    assert fast["gain_margin_db"] == pytest.approx(m.gain_margin_db, abs=0.2)
    assert fast["phase_margin_deg"] == pytest.approx(m.phase_margin_deg, abs=0.2)
    assert fast["delay_margin_s"] == pytest.approx(m.delay_margin_s, rel=0.03)


# ------------------ 4. export compares a design made sampled with its own sampled self
def test_export_compares_a_sampled_design_with_its_own_sampled_self() -> None:
    """`aiofl export assisted-s1-ladrc --ts 0.001` warned its sampled ITAE exceeded a
    continuous ideal-sensor version the preset never was."""
    cont = load_config("tank-ladrc")
    made = cont.with_sample_time(0.1)  # a design made sampled (ITAE 3.5 % over continuous)
    assert _loop_checks(made, made, made.sampling, "tank", 0.02) == []
    coarser = made.with_sample_time(0.2)
    (warning,) = _loop_checks(made, coarser, coarser.sampling, "tank", 0.02)
    assert "sampled at Ts = 0.2 s has ITAE" in warning
    assert "of the design at its own Ts = 0.1 s (both without the converters' quanta)" in warning
    (warning,) = _loop_checks(cont, made, made.sampling, "tank", 0.02)
    assert "of the continuous design (the config as it is)" in warning
