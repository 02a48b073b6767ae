"""Verdicts that say what the plant did (ok, lost, diverged), step metrics, noise in u, the
operating point and ISU/IAU about the holding input, on a plant the paper never saw: a
levitated ball (open-loop unstable, rho = 3 = n, beta < 0 at the operating point)."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import control
import numpy as np
import pytest
from typer.testing import CliRunner

from aiofl import load_config, simulate
from aiofl.cli.app import app
from aiofl.engine.response import screaming
from aiofl.plants.base import PlantError
from aiofl.plants.operating_point import trim
from aiofl.reporting.verdict import command_text, step_text, verdict_text
from aiofl.scenario import ENVELOPE_FACTOR, Reference, Scenario

DATA = Path(__file__).parent / "data"
M, K, R, L, G = 0.05, 1e-4, 1.0, 0.01, 9.81  # tests/data/maglev.toml


@pytest.fixture(scope="module")
def cfg():
    return load_config(str(DATA / "maglev-ladrc.toml"))


@pytest.fixture(scope="module")
def nominal(cfg):
    return simulate(cfg.plant, cfg.controller, cfg.scenario, dt=cfg.dt, store=True, decimation=1)


def test_trim_matches_the_maglev_equilibrium_in_closed_form(cfg):
    z = 0.01
    op = trim(cfg.plant, z, x_guess=[z, 0.0, 0.5])
    i_e = z * math.sqrt(M * G / K)
    assert op.x == pytest.approx([z, 0.0, i_e], rel=1e-10, abs=1e-12)
    assert op.u == pytest.approx(R * i_e, rel=1e-10)
    # beta = L_g L_f^2 h = -2 k i / (m z^2 L)
    assert op.beta == pytest.approx(-2 * K * i_e / (M * z**2 * L), rel=1e-8)
    # poles: +-sqrt(2 g / z) (the unstable pair of the ball) and -R/L (the coil)
    want = sorted([math.sqrt(2 * G / z), -math.sqrt(2 * G / z), -R / L], reverse=True)
    assert op.poles.real == pytest.approx(want, rel=1e-5)
    assert op.unstable and op.fastest_unstable == pytest.approx(math.sqrt(2 * G / z), rel=1e-5)


def test_trim_refuses_an_output_no_equilibrium_holds():
    from aiofl.plants.operating_point import TrimError
    from aiofl.plants.registry import get_plant

    with pytest.raises(TrimError, match="y = nan"):
        trim(get_plant("tank"), float("nan"))


def test_nominal_design_is_ok_with_step_metrics_of_python_control(nominal, cfg):
    assert nominal.status == "ok" and nominal.stopped_at is None
    ref = cfg.scenario.reference
    on = nominal.t >= ref.t_step - 1e-12
    t, y = nominal.t[on] - ref.t_step, nominal["y"][on] - ref.offset
    info = control.step_info(y, t, yfinal=ref.amplitude, SettlingTimeThreshold=0.02)
    r = nominal.response
    dt = cfg.dt
    assert r["overshoot"] == pytest.approx(info["Overshoot"], rel=1e-9, abs=1e-9)
    assert r["rise_time"] == pytest.approx(info["RiseTime"], abs=1.5 * dt)
    assert r["settling_time"] == pytest.approx(info["SettlingTime"], abs=1.5 * dt)
    assert r["overshoot"] > 0.1  # the design does overshoot: the comparison is not vacuous
    # the steady window (the last 20 %): the mean error and u's spread there
    tail = nominal.t >= 0.8 * cfg.scenario.t_final
    e = (nominal["y"] - nominal["r"])[tail][:-1]
    u = nominal["u"][tail][:-1]
    assert r["steady_error"] == pytest.approx(abs(e.mean()), rel=1e-6, abs=1e-15)
    assert r["u_std"] == pytest.approx(u.std(), rel=1e-6, abs=1e-12)
    assert r["u_peak"] == pytest.approx(np.abs(nominal["u"]).max(), rel=1e-12)
    assert r["saturated_time"] == 0.0
    jumps = np.diff(u)
    jumps = jumps[jumps != 0.0]
    assert r["u_noise"] == pytest.approx(np.sqrt(np.mean(jumps**2) / 2), rel=1e-6)
    assert r["u_noise"] < 1e-3 * r["u_rms"] and not screaming(r)  # a smooth command
    assert "overshoot" in step_text(nominal, "m")
    assert "peak |u|" in command_text(nominal, cfg.scenario.t_final, "V")


def test_a_dropped_ball_is_lost_at_its_bound_not_diverged(cfg):
    # the observer told a gain 20 times too large: the ball leaves the magnet's reach
    ctrl = cfg.controller.with_values(**{"law.b0": 20.0 * cfg.controller.values["law.b0"]})
    res = simulate(cfg.plant, ctrl, cfg.scenario, dt=cfg.dt, store=True, decimation=10)
    assert res.status == "lost" and res.lost and not res.diverged and res.metrics is None
    assert 0.0 < res.stopped_at < cfg.scenario.t_final
    z = res["x1"]
    assert z[-1] < 0.001 or z[-1] > 0.03  # it stopped at the declared range of z
    assert np.all(np.abs(z) < 1.0)  # ... long before any number blew up
    text = verdict_text(replace(cfg, controller=ctrl), res)
    assert text.startswith("lost at t = ") and "range" in text


def test_without_declared_bounds_the_default_envelope_decides(cfg):
    plant = replace(cfg.plant, state_bounds={}, output_range=None)
    ctrl = cfg.controller.with_values(**{"law.b0": 20.0 * cfg.controller.values["law.b0"]})
    res = simulate(plant, ctrl, cfg.scenario, dt=cfg.dt, store=True, decimation=10)
    env = ENVELOPE_FACTOR * 0.011  # ten times max(|r|, |y(0)|)
    assert res.status == "lost"
    assert abs(res["y"][-1] - res["r"][-1]) > env
    assert np.all(np.abs(res["y"][:-1] - res["r"][:-1]) <= env)
    # no envelope at all: the same run is not lost (the ball falls through a model that
    # knows no floor until the numbers give out)
    free = replace(cfg.scenario, envelope=math.inf)
    res = simulate(plant, ctrl, free, dt=cfg.dt)
    assert res.status != "lost"


def test_isu_and_iau_about_the_holding_input(cfg, nominal):
    u_e = trim(cfg.plant, 0.01, x_guess=list(cfg.scenario.x0)).u
    about = simulate(
        cfg.plant,
        cfg.controller,
        replace(cfg.scenario, u_ref=u_e),
        dt=cfg.dt,
        store=True,
        decimation=1,
    )
    assert about.status == "ok"
    assert np.all(nominal["u"] >= 0.0)  # so that IAU = int u dt
    t_f = cfg.scenario.t_final
    m0, m1 = nominal.metrics, about.metrics
    # int (u - c)^2 = int u^2 - 2 c int u + c^2 T, the integrals of the same run
    assert m1["isu"] == pytest.approx(m0["isu"] - 2 * u_e * m0["iau"] + u_e**2 * t_f, rel=1e-6)
    assert m1["isu"] < 0.1 * m0["isu"]  # holding the ball is most of ISU about 0
    assert m1["itae"] == m0["itae"]  # the tracking is the same run


def test_u_ref_trim_in_a_config(tmp_path):
    text = (DATA / "maglev-ladrc.toml").read_text()
    text = text.replace("[scenario]\n", '[scenario]\nu_ref = "trim"\n')
    (tmp_path / "maglev.toml").write_text((DATA / "maglev.toml").read_text())
    (tmp_path / "run.toml").write_text(text)
    cfg = load_config(str(tmp_path / "run.toml"))
    assert cfg.scenario.u_ref == pytest.approx(R * 0.01 * math.sqrt(M * G / K), rel=1e-9)


def test_envelope_defaults_follow_the_scenario():
    sine = Scenario(reference=Reference(kind="sine", amplitude=0.5, offset=1.0), t_final=1.0)
    assert sine.default_envelope() == pytest.approx(ENVELOPE_FACTOR * 1.5)
    step = Scenario(reference=Reference(kind="step", amplitude=-0.2, offset=0.1), t_final=1.0)
    assert step.default_envelope() == pytest.approx(ENVELOPE_FACTOR * 0.1)
    assert step.default_envelope(y0=0.5) == pytest.approx(ENVELOPE_FACTOR * 0.5)
    zero = Scenario(reference=Reference(kind="step", amplitude=0.0, offset=0.0), t_final=1.0)
    assert zero.default_envelope() == math.inf
    assert Scenario(envelope=0.3).resolved_envelope() == 0.3
    with pytest.raises(ValueError, match=r"scenario\.envelope"):
        Scenario(envelope=-1.0)
    with pytest.raises(ValueError, match=r"scenario\.steady_from"):
        Scenario(t_final=1.0, steady_from=2.0)


def test_bounds_are_checked_where_declared(cfg, tmp_path):
    with pytest.raises(PlantError, match="state_bounds names 'w'"):
        replace(cfg.plant, state_bounds={"w": (0.0, 1.0)})
    with pytest.raises(PlantError, match="output_range"):
        replace(cfg.plant, output_range=(1.0, 0.0))
    bad = (DATA / "maglev.toml").read_text().replace("z = [0.001, 0.03]", "q = [0.0, 1.0]")
    (tmp_path / "bad.toml").write_text(bad)
    from aiofl.plants.expressions import SymbolicPlantError
    from aiofl.plants.symbolic import SymbolicPlant

    with pytest.raises(SymbolicPlantError, match=r"bounds\.q"):
        SymbolicPlant.from_toml(tmp_path / "bad.toml")
    assert cfg.plant.bounds_array()[0].tolist() == [0.001, 0.03]
    assert cfg.plant.bounds_array()[3].tolist() == [0.0, 0.03]  # the output's row
    assert cfg.plant.bounds_array()[1].tolist() == [-math.inf, math.inf]


def test_trim_command(tmp_path):
    runner = CliRunner()
    res = runner.invoke(
        app, ["trim", str(DATA / "maglev-ladrc.toml"), "--json", str(tmp_path / "op.json")]
    )
    assert res.exit_code == 0, res.output
    assert "UNSTABLE" in res.output and "holding input" in res.output
    assert (tmp_path / "op.json").is_file()
    res = runner.invoke(app, ["trim", str(DATA / "maglev.toml")])
    assert res.exit_code == 2 and "--y" in res.output
    res = runner.invoke(app, ["trim", str(DATA / "maglev.toml"), "--y", "0.01", "--x0", "1,2"])
    assert res.exit_code == 2 and "3 states" in res.output


def test_a_quantised_command_that_screams_is_ok_and_flagged_not_diverged():
    """frontier-s1-ladrc on a 12-bit encoder: the output stays bounded while u swings by
    ~1e5 V; it was reported "diverged at 1.75 s" when the observer's states decided."""
    cfg = load_config("frontier-s1-ladrc").with_sensor("encoder-12bit")
    res = cfg.simulate(store=False)
    assert res.status == "ok"
    assert res.response["e_peak"] < 0.1  # |y - r| stays small: the plant is held
    assert res.response["u_peak"] > 1e4
    assert screaming(res.response)
    assert "SCREAMING" in command_text(res, cfg.scenario.t_final, "V")


def test_response_figures_are_tuning_quantities():
    from aiofl import layout as L
    from aiofl.tuning.objective import (
        objective_values,
        parse_constraint,
        parse_quantity,
        quantity_values,
    )

    q = parse_quantity("overshoot:worst")
    c = parse_constraint("settling_time <= 0.3")
    assert q.metric == "overshoot" and c.quantity.metric == "settling_time"
    # two candidates, two draws each (nominal first): the scores of SCORE_NAMES
    m = np.full((2, 2, L.N_SCORE), np.nan)
    m[..., : L.N_METRIC] = 1.0
    over = L.SCORE_NAMES.index("overshoot")
    m[0, :, over] = [5.0, 9.0]
    m[1, :, over] = [2.0, np.nan]  # a step metric that does not apply counts as +inf
    failed = np.zeros((2, 2), dtype=bool)
    got = quantity_values(q, m, failed, "mean", 0.9)
    assert got[0] == 9.0 and got[1] == math.inf
    # the integrals' objective ignores the figures' NaN columns
    coef = np.zeros(L.N_METRIC)
    coef[L.METRIC_NAMES.index("itae")] = 1.0
    j = objective_values(m[:, 0, :], failed[:, 0], np.full(2, np.nan), coef, 1e6, 1.0)
    assert j.tolist() == [1.0, 1.0]
