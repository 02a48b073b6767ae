"""Inputs that ran silently or failed with a traceback, now refused with exit 2 naming the
field (issue 34 items 5 and 6): a transport delay on a continuous controller, delays not
shorter than the horizon, an absurd measurement quantum, ``sensor.ts = 5e-324``, and a
``[tune]`` table that ``aiofl tune`` refuses but ``simulate`` / ``analyze`` accepted."""

from __future__ import annotations

import copy
import tomllib
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from aiofl.cli.app import app
from aiofl.config import preset_text
from aiofl.tuning.space import to_toml


def _config(tmp_path: Path, preset: str, edit: Any) -> Path:
    """``preset`` as a file in ``tmp_path``, its dict changed by ``edit(data)``."""
    data = tomllib.loads(preset_text(preset))
    edit(data)
    path = tmp_path / "case.toml"
    path.write_text(to_toml(data), encoding="utf-8")
    return path


def _refused(*args: str) -> str:
    """The stderr of an aiofl command that must exit 2 without a traceback."""
    res = CliRunner().invoke(app, list(args))
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    assert res.stderr.startswith("aiofl: error: ")
    return res.stderr


def test_a_delay_on_a_continuous_controller_is_refused_naming_the_field(tmp_path: Path) -> None:
    """Item 5: frontier-s1-ladrc plus input_delay = 0.001 exited 1 with a traceback.  A
    continuous controller now holds a delay of whole steps (issue 36); one between grid
    points is refused naming the field, exit 2, nothing written."""
    edit = lambda d: d["scenario"].update(input_delay=1.5e-4)  # noqa: E731
    cfg = _config(tmp_path, "frontier-s1-ladrc", edit)
    err = _refused("simulate", str(cfg), "--out", str(tmp_path / "o"))
    assert "scenario.input_delay = 0.00015 s is not an integer multiple of the step" in err
    assert not (tmp_path / "o").exists()


def test_delays_not_shorter_than_the_horizon_are_refused(tmp_path: Path) -> None:
    """Item 6: assisted-s1-ladrc with t_final = 0.5 and both delays 1.0 ran."""

    def edit(d: dict[str, Any]) -> None:
        d["scenario"].update(t_final=0.5, input_delay=1.0, output_delay=1.0)
        d["tune"]["t_final"] = 0.5

    err = _refused("simulate", str(_config(tmp_path, "assisted-s1-ladrc", edit)), "--check")
    assert "scenario.input_delay = 1 s is not shorter than the horizon t_final = 0.5 s" in err
    assert "allowed: 0 <= input_delay < t_final" in err


@pytest.mark.parametrize(
    ("quantum", "where"),
    [(1e300, "sensor"), (0.9, "sensor"), (1e300, "discrete")],
    ids=["1e300", "above-the-range", "controller.discrete.y_quantum"],
)
def test_a_quantum_larger_than_the_output_range_is_refused_with_the_range(
    tmp_path: Path, quantum: float, where: str
) -> None:
    """Item 6: [sensor] quantum = 1e300 ran (ITAE 222, every reading 0); the output's range
    here is the reference's amplitude π/4 rad."""

    def edit(d: dict[str, Any]) -> None:
        if where == "sensor":
            d["sensor"]["quantum"] = quantum
        else:  # the older place: a sampled controller without [sensor]
            del d["sensor"]
            d["controller"]["discrete"] = {"ts": 1e-3, "y_quantum": quantum}

    err = _refused("simulate", str(_config(tmp_path, "assisted-s1-ladrc", edit)), "--check")
    key = "sensor.quantum" if where == "sensor" else "controller.discrete.y_quantum"
    assert f"{key} = {quantum:g} is larger than the output's range" in err
    assert "<= 0.7854 rad" in err and "allowed: 0 (none) or 1e-12 <= quantum <= 0.7854" in err


def test_an_encoder_quantum_within_the_range_still_runs(tmp_path: Path) -> None:
    cfg = _config(tmp_path, "assisted-s1-ladrc", lambda d: d["sensor"].update(quantum=0.01))
    assert CliRunner().invoke(app, ["simulate", str(cfg), "--check"]).exit_code == 0


def test_a_subnormal_sensor_ts_is_refused_naming_sensor_ts(tmp_path: Path) -> None:
    """Item 6: sensor.ts = 5e-324 was refused naming noise_hold (the sensor's ts fills it)."""
    cfg = _config(tmp_path, "assisted-s1-ladrc", lambda d: d["sensor"].update(ts=5e-324))
    err = _refused("simulate", str(cfg), "--check")
    assert "sensor.ts = 5e-324 s is shorter than the step simulation.dt = 0.0001 s" in err
    assert "noise_hold" not in err


# ----------------------------------------------------------------- [tune] everywhere
def _tune(**changes: Any) -> Any:
    def edit(d: dict[str, Any]) -> None:
        for key, value in changes.items():
            if value is None:
                d["tune"].pop(key, None)
            else:
                d["tune"][key] = value

    return edit


def _param(name: str, bounds: dict[str, Any]) -> Any:
    def edit(d: dict[str, Any]) -> None:
        d["tune"]["parameters"] = {**copy.deepcopy(d["tune"]["parameters"]), name: bounds}

    return edit


#: invalid [tune] tables on frontier-s1-ladrc (NSGA-II over eso.omega0, sef.omega_c, law.b0,
#: robust over 4 draws): one per check of the tune schema and of tuning.prepared.prepare
TUNE_CASES: dict[str, Any] = {
    "algorithm": _tune(algorithm="bogus"),
    "choose": _tune(choose="bogus"),
    "population-1": _tune(population=1),
    "population-bool": _tune(population=True),
    "generations-0": _tune(generations=0),
    "seed-negative": _tune(seed=-1),
    "t_final-0": _tune(t_final=0.0),
    "t_final-huge": _tune(t_final=1e9),
    "t_final-not-steps": _tune(t_final=0.00015),
    "divergence_penalty": _tune(divergence_penalty=0.0),
    "dt-0": _tune(dt=0.0),
    "method": _tune(method="heun"),
    "chunks-0": _tune(chunks=0),
    "noise_realisations-0": _tune(noise_realisations=0),
    "noise_realisations-no-noise": _tune(noise_realisations=2),
    "unknown-key": _tune(bogus_key=1),
    "one-objective": _tune(objectives=["itae:nominal"]),
    "unknown-objective": _tune(objectives=["itae:nominal", "bogus"]),
    "repeated-objective": _tune(objectives=["itae:nominal", "itae:nominal"]),
    "stable_fraction-objective": _tune(objectives=["stable_fraction", "itae"]),
    "malformed-constraint": _tune(constraints=["isu <"]),
    "objectives-without-nsga2": _tune(algorithm="ga"),
    "aggregate-without-robust": _tune(robust=None, constraints=["isu:worst <= 20"]),
    "population-times-generations": _tune(population=2048, generations=100_000),
    "robust-draws-0": _tune(robust={"draws": 0}),
    "robust-aggregate": _tune(robust={"draws": 4, "aggregate": "median"}),
    "robust-alpha": _tune(robust={"draws": 4, "alpha": 1.5}),
    "no-parameters": _tune(parameters={}),
    "unknown-parameter": _param("eso.bogus", {"lo": 1.0, "hi": 2.0}),
    "reversed-bounds": _param("eso.omega0", {"lo": 100.0, "hi": 10.0}),
    "log-with-lo-0": _param("eso.omega0", {"lo": 0.0, "hi": 10.0, "log": True}),
    "unused-parameter": _param("td.R", {"lo": 1.0, "hi": 10.0}),
    "bound-outside-the-config-range": _param("eso.omega0", {"lo": -5.0, "hi": 10.0}),
}


@pytest.mark.parametrize("case", list(TUNE_CASES), ids=list(TUNE_CASES))
def test_simulate_and_analyze_refuse_a_tune_table_as_tune_does(tmp_path: Path, case: str) -> None:
    """Item 6: `aiofl simulate --check` passed `choose = "bogus"` and 27 more [tune] values
    that `aiofl tune` refuses; now one validation, one message."""
    cfg = str(_config(tmp_path, "frontier-s1-ladrc", TUNE_CASES[case]))
    expected = _refused("tune", cfg, "--check")
    assert "tune" in expected
    assert _refused("simulate", cfg, "--check") == expected
    assert _refused("analyze", cfg, "--closed-loop", "--no-orbit") == expected


def test_a_valid_tune_table_passes_every_command(tmp_path: Path) -> None:
    cfg = str(_config(tmp_path, "frontier-s1-ladrc", lambda d: None))
    for args in (["tune", cfg, "--check"], ["simulate", cfg, "--check"]):
        assert CliRunner().invoke(app, args).exit_code == 0
