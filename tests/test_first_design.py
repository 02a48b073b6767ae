"""aiofl design: a first LADRC from the operating point, checked in closed loop."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import pytest
from typer.testing import CliRunner

from aiofl import load_config
from aiofl.analysis.first_design import MAX_OMEGA0_TS, OBSERVER_RATIO, UNSTABLE_FACTOR
from aiofl.cli.app import app

DATA = Path(__file__).parent / "data"


def test_the_maglev_gets_a_stable_design_at_the_first_try(tmp_path):
    out = tmp_path / "first.toml"
    res = CliRunner().invoke(
        app,
        ["design", str(DATA / "maglev.toml"), "--y", "0.01", "--x0", "0.01,0,0.7", "-o", str(out)],
    )
    assert res.exit_code == 0, res.output
    assert "check (a step about the operating point): ok" in res.output
    assert "rounds" not in res.output  # the first proposal held the ball
    data = tomllib.loads(out.read_text())
    p_u = math.sqrt(2 * 9.81 / 0.01)  # the ball's unstable pole at z = 1 cm
    wc = data["controller"]["sef"]["omega_c"]
    assert wc == pytest.approx(UNSTABLE_FACTOR * p_u, rel=1e-5)
    assert data["controller"]["eso"]["omega0"] == pytest.approx(OBSERVER_RATIO * wc)
    assert data["controller"]["law"]["b0"] == pytest.approx(-2801.43, rel=1e-5)
    cfg = load_config(out)  # the written config runs as it is, with the same verdict
    assert cfg.simulate().status == "ok"


def test_a_slow_sample_time_lowers_omega0_and_says_so(tmp_path):
    out = tmp_path / "tank.toml"
    res = CliRunner().invoke(app, ["design", "tank", "--y", "1.0", "--ts", "0.2", "-o", str(out)])
    assert res.exit_code == 0, res.output
    data = tomllib.loads(out.read_text())
    assert data["controller"]["eso"]["omega0"] * 0.2 == pytest.approx(MAX_OMEGA0_TS)
    assert data["controller"]["discrete"]["ts"] == 0.2
    assert "lowered" in res.output and "too slow" in res.output


def test_design_refuses_bad_input(tmp_path):
    runner = CliRunner()
    out = str(tmp_path / "d.toml")
    for args, word in (
        (["tank", "--y", "1", "-o", str(tmp_path / "d.txt")], "--out"),
        (["tank", "--y", "nan", "-o", out], "--y"),
        (["tank", "--y", "1", "--ts", "-1", "-o", out], "--ts"),
        (["tank", "--y", "1", "--rho", "9", "-o", out], "--rho"),
        (["nowhere", "--y", "1", "-o", out], "nowhere"),
    ):
        res = runner.invoke(app, ["design", *args])
        assert res.exit_code == 2, (args, res.output)
        assert word in res.output
        assert not Path(out).exists()
