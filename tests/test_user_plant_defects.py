"""Issue 33's defects met on the way, each pinned by a test that failed before its fix.

The user's own plant is :file:`tests/maglev_plant.toml` (open loop unstable, ρ = 3 = n,
operated around x1 = 1 cm) where a plant of that kind matters; the others use the shipped
pendulum (its kernels are in every test cache).
"""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Any

import pytest

from aiofl import Controller, Design, Reference, Scenario
from aiofl.config import load_config, parse_config
from aiofl.plants import get_plant
from aiofl.sensor import Sensor

HERE = Path(__file__).parent
MAGLEV = HERE / "maglev_plant.toml"
PENDULUM = get_plant("pendulum")
CTRL = Controller.from_structure(
    "LADRC",
    rho=2,
    values={"eso.omega0": 40.0, "sef.omega_c": 5.0, "td.omega": 10.0, "law.b0": 4.0},
)
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
