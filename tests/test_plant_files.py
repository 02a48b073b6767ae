"""A run config may name a symbolic-plant TOML file instead of a registered plant."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from aiofl.config import ConfigError, load_config

PLANT = """
name = "pendulum_file"
states = ["theta", "theta_dot"]
f = ["theta_dot", "-g/l*sin(theta) - c/(m*l**2)*theta_dot"]
g = ["0", "1/(m*l**2)"]
h = "theta"
[params]
m = 1.0
l = 0.5
c = 0.1
g = 9.81
"""

RUN = """
plant = "{plant}"
[scenario]
t_final = 3.0
[scenario.reference]
kind = "step"
amplitude = 0.5
[controller]
structure = "LADRC"
n_feedback = 2
[controller.eso]
omega0 = 60.0
[controller.td]
omega = 8.0
[controller.sef]
omega_c = 8.0
[controller.law]
b0 = 4.0
[simulation]
dt = 1e-3
"""


@pytest.mark.slow
def test_config_with_a_relative_plant_file_compiles_and_tracks(tmp_path: Path) -> None:
    (tmp_path / "pend.toml").write_text(PLANT)
    cfg_path = tmp_path / "run.toml"
    cfg_path.write_text(RUN.format(plant="pend.toml"))
    cfg = load_config(cfg_path)
    assert cfg.plant.name == "pendulum_file"
    assert cfg.controller.rho == 2  # the default order is the symbolic relative degree
    # loading twice reuses the compiled plant (one kernel per process)
    assert load_config(cfg_path).plant is cfg.plant
    res = cfg.simulate()
    assert not res.failed
    late = res.t > 2.0
    assert np.max(np.abs(res["y"][late] - 0.5)) < 5e-3


def test_missing_or_bad_plant_file_is_a_config_error(tmp_path: Path) -> None:
    cfg_path = tmp_path / "run.toml"
    cfg_path.write_text(RUN.format(plant="nowhere.toml"))
    with pytest.raises(ConfigError, match=r"plant: file .*nowhere\.toml.* does not exist"):
        load_config(cfg_path)
    (tmp_path / "bad.toml").write_text(PLANT.replace('h = "theta"', 'h = "theta + zeta"'))
    cfg_path.write_text(RUN.format(plant="bad.toml"))
    with pytest.raises(ConfigError, match="plant:"):
        load_config(cfg_path)
