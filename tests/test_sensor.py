"""The sensor model ([sensor], aiofl.sensor), per-draw noise and noise-aware tuning."""

from __future__ import annotations

import copy
import math
import tomllib
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from aiofl.config import ConfigError, load_config, parse_config, preset_text
from aiofl.engine.simulation import simulate, simulate_batch
from aiofl.scenario import Scenario, realisation_seed
from aiofl.sensor import SENSOR_PRESETS, Sensor
from aiofl.uncertainty import UncertaintyModel, sample_draws


def _data(preset: str = "retuned-s1-leso", **tables: Any) -> dict[str, Any]:
    data = tomllib.loads(preset_text(preset))
    data.pop("tune", None)
    for key, value in tables.items():
        if key == "discrete":
            data["controller"]["discrete"] = value
        else:
            data[key] = value
    return data


def _short(data: dict[str, Any], t_final: float = 0.5) -> dict[str, Any]:
    data = copy.deepcopy(data)
    data["scenario"]["t_final"] = t_final
    return data


# ------------------------------------------------------------------ presets and keys
@pytest.mark.parametrize(("preset", "bits"), [("encoder-12bit", 12), ("encoder-16bit", 16)])
def test_encoder_presets_give_the_documented_quantum_and_ts(preset: str, bits: int) -> None:
    s = Sensor.from_preset(preset)
    assert s.ts == 1e-3
    assert s.quantum == 2 * math.pi / 2**bits
    cfg = parse_config(_data(sensor={"preset": preset}), preset)
    assert cfg.sampling is not None and cfg.sampling.ts == 1e-3
    assert cfg.sampling.y_quantum == 2 * math.pi / 2**bits
    assert cfg.sensor.preset == preset and f"2π/{2**bits}" in cfg.sensor.describe()


def test_ideal_preset_sets_nothing_and_explicit_keys_override_a_preset() -> None:
    assert SENSOR_PRESETS["ideal"] == {}
    cfg = parse_config(_data(sensor={"preset": "ideal"}), "ideal")
    base = load_config("retuned-s1-leso")
    assert cfg.sampling is None and cfg.scenario == base.scenario
    s = Sensor.from_preset("encoder-12bit", ts=5e-4, noise_variance=1e-8)
    assert (s.ts, s.quantum, s.noise_variance) == (5e-4, 2 * math.pi / 4096, 1e-8)
    cfg = parse_config(
        _data(sensor={"preset": "encoder-16bit", "ts": 2e-3, "noise_variance": 1e-8}), "x"
    )
    assert cfg.sampling.ts == 2e-3
    assert cfg.scenario.noise_variance == 1e-8 and cfg.scenario.noise_hold == 2e-3


@pytest.mark.parametrize(
    ("table", "words"),
    [
        ({"preset": "encoder-13bit"}, ["sensor.preset", "ideal, encoder-12bit"]),
        ({"quantum": -1.0}, ["sensor.quantum", "greater than or equal to 0"]),
        ({"ts": 0.0}, ["sensor.ts", "greater than 0"]),
        ({"ts": 2.0}, ["sensor.ts", "less than or equal to 1"]),
        ({"noise_variance": -1e-4}, ["sensor.noise_variance"]),
        ({"noise_hold": 0.0}, ["sensor.noise_hold"]),
        ({"ts": True}, ["sensor.ts", "a number"]),
        ({"pixels": 3}, ["sensor.pixels", "unknown key"]),
        ({"quantum": 1e-3}, ["sensor.quantum", "needs a sample time"]),
    ],
)
def test_bad_sensor_tables_are_refused_naming_the_field(table: dict, words: list[str]) -> None:
    with pytest.raises(ConfigError) as exc:
        parse_config(_data(sensor=table), "bad")
    for w in words:
        assert w in str(exc.value)


def test_python_constructor_is_as_strict_as_the_table() -> None:
    bad: list[dict[str, Any]] = [
        {"ts": True},
        {"ts": "1e-3"},
        {"quantum": -1.0},
        {"noise_seed": 1.5},
        {"noise_variance": math.nan},
        {"ts": 0.0},
        {"noise_hold": -1.0},
    ]
    for kwargs in bad:
        with pytest.raises(ValueError, match="sensor\\."):
            Sensor(**kwargs)
    with pytest.raises(ValueError, match="encoder-12bit"):
        Sensor.from_preset("encoder-8bit")


@pytest.mark.parametrize(
    ("tables", "words"),
    [
        (
            {"sensor": {"preset": "encoder-12bit"}, "discrete": {"ts": 2e-3}},
            ["sensor.ts", "controller.discrete.ts"],
        ),
        (
            {"sensor": {"preset": "encoder-12bit"}, "discrete": {"ts": 1e-3, "y_quantum": 1e-3}},
            ["sensor.quantum", "controller.discrete.y_quantum"],
        ),
        (
            {"sensor": {"noise_variance": 1e-6}, "scenario": {"noise_variance": 1e-6}},
            ["sensor.noise_variance", "scenario.noise_variance"],
        ),
    ],
)
def test_a_quantity_set_in_two_places_is_refused(tables: dict, words: list[str]) -> None:
    data = _data(sensor=tables["sensor"])
    if "discrete" in tables:
        data["controller"]["discrete"] = tables["discrete"]
    if "scenario" in tables:
        data["scenario"].update(tables["scenario"])
    with pytest.raises(ConfigError) as exc:
        parse_config(data, "twice")
    for w in words:
        assert w in str(exc.value)


def test_a_discrete_table_that_agrees_with_the_sensor_is_accepted() -> None:
    cfg = parse_config(
        _data(sensor={"preset": "encoder-12bit"}, discrete={"ts": 1e-3, "delay": 1}), "ok"
    )
    assert cfg.sampling.delay == 1 and cfg.sampling.y_quantum == 2 * math.pi / 4096


def test_old_keys_still_work_and_equal_the_sensor() -> None:
    q = 2 * math.pi / 4096
    old = parse_config(_short(_data(discrete={"ts": 1e-3, "y_quantum": q})), "old")
    new = parse_config(_short(_data(sensor={"preset": "encoder-12bit"})), "new")
    assert old.sampling == new.sampling and old.scenario == new.scenario
    assert old.simulate(store=False).metrics == new.simulate(store=False).metrics


def test_with_sensor_and_with_sample_time_keep_the_quantum() -> None:
    cfg = load_config("retuned-s1-leso").with_sensor("encoder-12bit")
    assert cfg.sensor.preset == "encoder-12bit" and cfg.sampling.ts == 1e-3
    two = cfg.with_sample_time(2e-3)
    assert two.sampling.ts == 2e-3 and two.sampling.y_quantum == 2 * math.pi / 4096
    with pytest.raises(ConfigError, match="encoder-12bit"):
        cfg.with_sensor("encoder-7bit")


# ------------------------------------------------------------------ quantisation
def test_a_huge_quantum_moves_y_meas_in_whole_quanta() -> None:
    q = 0.1
    data = _short(_data(sensor={"ts": 1e-3, "quantum": q}), t_final=2.0)
    res = parse_config(data, "coarse").simulate(store=True)
    y = res.signals["y_meas"]
    y = y[np.isfinite(y)]
    k = y / q
    np.testing.assert_allclose(k, np.round(k), atol=1e-9)  # on the grid of the quantum
    steps = np.diff(np.round(k))
    assert set(np.unique(np.abs(steps))) <= {0.0, 1.0, 2.0}
    assert np.count_nonzero(steps) > 0  # the sine crosses several quanta


# ------------------------------------------------------------------ noise per draw
def test_every_draw_has_its_own_reproducible_noise_seed() -> None:
    base = Scenario(noise_variance=1e-6, noise_seed=5)
    spec = UncertaintyModel(parameters={"J_l": {"uniform": 0.2}}, seed=3)  # type: ignore[dict-item]
    d = sample_draws(spec, draws=6)
    seeds = [s.noise_seed for s in d.scenarios(base)]
    assert len(set(seeds)) == 6 and 5 not in seeds
    assert seeds == [s.noise_seed for s in sample_draws(spec, draws=6).scenarios(base)]
    assert seeds[:3] == [s.noise_seed for s in sample_draws(spec, draws=3).scenarios(base)]
    other = [s.noise_seed for s in sample_draws(spec, draws=6, seed=4).scenarios(base)]
    assert set(other).isdisjoint(seeds)
    # a noise-free scenario is not touched (no noise to realise)
    assert all(s.noise_seed == 0 for s in d.scenarios(Scenario()))
    assert realisation_seed(7, 0) == 7 and realisation_seed(7, 1) != realisation_seed(7, 2)


def test_robustness_draws_run_their_own_noise_and_compose_with_the_sensor() -> None:
    from aiofl.analysis.robustness_draws import run_robustness

    unc = {"draws": 4, "seed": 1, "noise_variance": [1e-6, 1e-6]}  # one variance: only noise
    data = _short(
        _data(sensor={"preset": "encoder-16bit", "noise_variance": 1e-4}, uncertainty=unc)
    )
    cfg = parse_config(data, "noisy")
    assert cfg.sampling.y_quantum == 2 * math.pi / 65536
    res = run_robustness(cfg)
    scen = res.draws.scenarios(cfg.scenario)
    assert all(s.noise_variance == 1e-6 for s in scen)  # the drawn variance replaces the sensor's
    assert len({s.noise_seed for s in scen}) == 4
    assert len(set(res.itae)) == 4  # four different noise sequences, four ITAEs
    again = run_robustness(cfg)
    np.testing.assert_array_equal(again.itae, res.itae)
    for k in (0, 3):  # draw k is the config run with the draw's scenario
        one = simulate(cfg.plant, cfg.controller, scen[k], dt=cfg.dt, sampling=cfg.sampling)
        assert one.metrics["itae"] == res.itae[k]


# ------------------------------------------------------------------ tuning
FAST: dict[str, Any] = {
    "name": "fast-noisy-ladrc",
    "plant": "slfjm",
    "scenario": {"name": "noisy", "t_final": 20.0},
    "sensor": {"noise_variance": 1e-6},
    "controller": {
        "structure": "LADRC",
        "rho": 4,
        "n_feedback": 4,
        "eso": {"omega0": 300.0, "alpha": "binomial"},
        "td": {"omega": 50.0},
        "sef": {"omega_c": 10.0},
        "law": {"b0": 26800.0},
    },
    "simulation": {"dt": 1e-3},
    "tune": {
        "objective": {"itae": 1.0, "isu": 0.1},
        "t_final": 0.6,
        "population": 4,
        "generations": 1,
        "seed": 7,
        "parameters": {
            "eso.omega0": {"lo": 50.0, "hi": 600.0, "log": True},
            "sef.omega_c": {"lo": 2.0, "hi": 30.0, "log": True},
        },
    },
}


def test_noise_realisations_score_the_mean_over_common_noise_sequences() -> None:
    from aiofl.controller import controller_batch
    from aiofl.tuning.objective import objective_coefficients
    from aiofl.tuning.search import tune

    cfg = parse_config({**FAST, "tune": {**FAST["tune"], "noise_realisations": 3}}, "fast")
    res = tune(cfg, progress=False)
    sc = replace(cfg.scenario, t_final=0.6)
    seeds = [realisation_seed(sc.noise_seed, r) for r in range(3)]
    assert len(set(seeds)) == 3 and seeds[0] == sc.noise_seed
    c = objective_coefficients(res.settings, cfg)
    for b in range(res.values.shape[0]):
        ctrl = controller_batch(
            cfg.controller, {n: np.repeat(res.values[b, j], 3) for j, n in enumerate(res.names)}
        )
        runs = simulate_batch(
            cfg.plant, ctrl, [replace(sc, noise_seed=s) for s in seeds], dt=cfg.dt
        )
        assert not runs.failed.any()
        per = runs.metrics @ c
        assert len(set(per)) == 3  # three different noise sequences
        np.testing.assert_allclose(res.objective[b], per.mean(), rtol=1e-12)
    one = tune(parse_config(FAST, "fast"), progress=False)  # R = 1: today's scoring
    assert not np.array_equal(one.objective, res.objective)


def test_noise_realisations_are_refused_without_noise_or_over_budget() -> None:
    from aiofl.tuning.search import prepare

    quiet = {k: v for k, v in FAST.items() if k != "sensor"}
    with pytest.raises(ConfigError, match="no noise"):
        prepare(parse_config({**quiet, "tune": {**FAST["tune"], "noise_realisations": 2}}, "q"))
    with pytest.raises(ConfigError, match="noise_realisations"):
        prepare(
            parse_config(
                {**FAST, "tune": {**FAST["tune"], "population": 5000, "noise_realisations": 64}},
                "big",
            )
        )


# ------------------------------------------------------------------ CLI
def test_cli_simulate_names_the_sensor_and_refuses_a_bad_one(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from aiofl.cli import app

    runner = CliRunner()
    out = tmp_path / "run"
    args = ["simulate", "retuned-s1-leso", "--sensor", "encoder-16bit", "--t-final", "0.5"]
    r = runner.invoke(app, [*args, "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "sensor: encoder-16bit (sampled at 1 ms, quantum 2π/65536" in r.output
    import json

    rec = json.loads((out / "metrics.json").read_text())
    assert rec["sample_time"] == 1e-3 and rec["sensor"].startswith("encoder-16bit")
    bad = tmp_path / "bad"
    r = runner.invoke(app, ["simulate", "retuned-s1-leso", "--sensor", "laser", "-o", str(bad)])
    assert r.exit_code == 2 and "encoder-12bit" in r.output
    assert not bad.exists()
