"""A design on a rig (aiofl.analysis.rig_check), the known delay taken from the rig
(``[controller.eso] delay = "rig"``), ``--rig`` on the commands, and the preset sets."""

from __future__ import annotations

import copy
import math
import tomllib
from typing import Any

import pytest
from typer.testing import CliRunner

from aiofl.analysis.rig_check import (
    RigCheck,
    no_control_itae,
    rig_check,
    rig_checks,
    rig_config,
)
from aiofl.cli.app import app
from aiofl.config import (
    PRESET_SETS,
    ConfigError,
    list_presets,
    load_config,
    parse_config,
    preset_sets,
    preset_text,
)
from aiofl.config.objects import controller_table

runner = CliRunner()


def _data(preset: str = "assisted-s1-ladrc", t_final: float = 0.3, **tables: Any) -> dict:
    data = tomllib.loads(preset_text(preset))
    data.pop("tune", None)
    data["scenario"]["t_final"] = t_final
    data.update(copy.deepcopy(tables))
    return data


def _check(nominal: dict[str, Any], counts: dict[str, int], own_isu: float = 10.0) -> RigCheck:
    return RigCheck(
        name="d",
        rig="servo-1khz",
        nominal={"u_peak": 1.0, "screaming": False, **nominal},
        own={"itae": 0.1, "isu": own_isu, "status": "ok", "stopped_at": None},
        draws=sum(counts.values()),
        status_counts=counts,
        not_lost=counts.get("ok", 0) / max(1, sum(counts.values())),
        itae_q50=None,
        itae_q95=None,
        isu_q95=None,
        told=False,
        no_control_itae=100.0,
    )


OK = {"itae": 1.0, "isu": 12.0, "status": "ok", "stopped_at": None}


@pytest.mark.parametrize(
    ("nominal", "counts", "verdict"),
    [
        (OK, {"ok": 8}, "holds"),
        ({**OK, "status": "lost", "stopped_at": 0.25}, {}, "lost at t = 0.25 s"),
        ({**OK, "status": "diverged", "stopped_at": 1.5}, {}, "diverged at t = 1.5 s"),
        (OK, {"ok": 6, "lost": 2}, "lost in 2 of 8 draws"),
        ({**OK, "screaming": True}, {"ok": 8}, "screams"),
        ({**OK, "isu": 25.0}, {"ok": 8}, "command ×2.5"),
        ({**OK, "itae": 60.0}, {"ok": 8}, "does not track (ITAE 60 % of no control's)"),
        ({**OK, "screaming": True}, {"ok": 7, "diverged": 1}, "screams; lost in 1 of 8 draws"),
    ],
)
def test_the_verdict_says_what_the_plant_did(nominal: dict, counts: dict, verdict: str) -> None:
    chk = _check(nominal, counts)
    assert chk.verdict == verdict
    assert chk.holds is (verdict == "holds")
    assert chk.to_dict()["verdict"] == verdict


def test_no_control_itae_is_the_integral_of_t_abs_r() -> None:
    """r = A sin(ωt) over k whole half-periods: ∫_0^{kπ/ω} t |A sin ωt| dt = A k² π / ω²."""
    data = _data(t_final=20.0)
    data["scenario"]["reference"]["omega"] = math.pi / 2.0  # half-period 2 s: k = 10, A = π/4
    cfg = parse_config(data, "whole half-periods")
    assert no_control_itae(cfg) == pytest.approx(100.0, rel=1e-6)  # (π/4)·10²·π/(π/2)²


def test_rig_config_puts_a_design_on_the_rig_and_draws_its_lag_and_friction() -> None:
    cfg = parse_config(_data(), "s1")
    on = rig_config(cfg, "servo-1khz", draws=5, seed=3)
    assert on.plant.name == "slfjm+rig" and on.rig is not None and on.rig.coulomb == 0.01
    assert on.scenario.output_delay == 1e-3 and on.sensor.preset == "encoder-12bit"
    assert on.controller.value("eso.delay") == 0.0  # as shipped: not told
    params = on.uncertainty.parameters
    assert set(params) == {"J_l", "K_s", "R_m", "J_h", "rig_lag", "rig_coulomb"}
    assert (on.uncertainty.draws, on.uncertainty.seed) == (5, 3)
    told = rig_config(cfg, "servo-1khz", told=True, box={"K_s": 0.05})
    assert told.controller.value("eso.delay") == 1e-3
    assert set(told.uncertainty.parameters) == {"K_s", "rig_lag", "rig_coulomb"}
    # a rig-augmented config goes on the rig again (its plant's velocity state still known)
    again = rig_config(on, "servo-1khz")
    assert again.plant.params["rig_coulomb"] == 0.01
    tank = rig_config(load_config("tank-ladrc"), "servo-1khz")
    assert tank.rig is not None and tank.rig.coulomb == 0.0  # no velocity state known


def test_eso_delay_rig_takes_the_rigs_measurement_delay_and_round_trips() -> None:
    rig = {"preset": "servo-1khz", "friction_state": "theta_dot"}
    data = _data(rig=rig)
    data["controller"]["eso"]["delay"] = "rig"
    cfg = parse_config(data, "told")
    assert cfg.controller.value("eso.delay") == cfg.rig.measurement_delay == 1e-3
    table = controller_table(cfg.controller)
    assert table["eso"]["delay"] == 1e-3
    data.pop("rig")
    with pytest.raises(ConfigError, match=r'controller\.eso\.delay = "rig" needs a \[rig\]'):
        parse_config(data, "no rig")
    data["controller"]["eso"]["delay"] = 2.0
    with pytest.raises(ConfigError, match=r"controller\.eso\.delay"):
        parse_config(data, "too long")


def test_batched_rig_checks_equal_one_design_at_a_time() -> None:
    """Designs of one plant share an engine call in rig_checks; each equals its own call."""
    cfgs = [parse_config(_data(p), p) for p in ("assisted-s1-ladrc", "frontier-s1-leso")]
    box = {"J_l": 0.2, "K_s": 0.2}
    both = rig_checks(cfgs, draws=3, box=box)
    for cfg, chk in zip(cfgs, both, strict=True):
        alone = rig_check(cfg, draws=3, box=box)
        assert chk.to_dict() == alone.to_dict()
    assert both[0].status_counts["ok"] + both[0].status_counts["lost"] in (0, 3)


def test_rig_option_on_the_commands() -> None:
    res = runner.invoke(app, ["simulate", "assisted-s1-ladrc", "--rig", "servo-1khz", "--check"])
    assert res.exit_code == 0, res.output
    assert "plant slfjm+rig" in res.stdout and "encoder-12bit" in res.stdout
    bad = runner.invoke(app, ["robustness", "assisted-s1-ladrc", "--rig", "servo", "-o", "x"])
    assert bad.exit_code == 2
    assert "rig.preset = 'servo'; allowed: ideal, servo-1khz" in bad.output


def test_preset_sets_are_disjoint_and_listed_apart() -> None:
    sets = preset_sets()
    assert [k for k, _, _ in PRESET_SETS] == list(sets)
    names = [n for v in sets.values() for n in v]
    assert len(names) == len(set(names)) == len(list_presets())
    assert {n for n in sets["paper"]} >= {"paper-s1-leso", "iofl-s3"}
    assert {"rig-s1-ladrc", "rig-s2-ladrc", "rig-s3-ladrc"} <= set(sets["designs"])
    for name in names:  # every preset loads by its name, whatever its set
        assert tomllib.loads(preset_text(name))["name"] == name
    res = runner.invoke(app, ["presets"], env={"COLUMNS": "200"})
    assert res.exit_code == 0
    text = res.stdout
    titles = [t for k, _, t in PRESET_SETS if sets[k]]
    positions = [text.index(t) for t in titles]
    assert positions == sorted(positions)
    for key, _, title in PRESET_SETS:  # each name printed under its own set's title
        for name in sets[key]:
            at = text.index(f" {name} ")
            assert max(p for p in positions if p < at) == text.index(title)
    with pytest.raises(ConfigError, match="unknown preset"):
        preset_text("paper/paper-s1-leso")


def test_a_design_that_cannot_go_on_the_rig_is_skipped_and_said_or_raises() -> None:
    cfg = parse_config(_data(), "s1")
    skipped: dict[str, str] = {}
    assert rig_checks([cfg], "servo", draws=0, skipped=skipped) == []
    assert skipped == {cfg.name: "rig.preset = 'servo'; allowed: ideal, servo-1khz"}
    with pytest.raises(ValueError, match=r"rig\.preset = 'servo'"):
        rig_checks([cfg], "servo", draws=0)
