"""Defaults and inputs that mislead (issue 22): required controller parameters, documented
defaults printed by ``--check``, ``[controller.discrete]`` sizes, ``--out`` checked before any
work, stale staging folders, named options, and an export of a diverging design (refused)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pytest
from typer.testing import CliRunner

from aiofl.cli.app import app
from aiofl.config import ConfigError, list_presets, parse_config

runner = CliRunner()

LADRC = """
plant = "slfjm"
[scenario]
t_final = 1.0
[scenario.reference]
kind = "sine"
amplitude = 0.5
omega = 2.0
[controller]
structure = "LADRC"
[controller.eso]
omega0 = 50.0
[controller.td]
omega = 10.0
[controller.sef]
omega_c = 10.0
[controller.law]
b0 = 26833.0
[simulation]
dt = 1e-4
"""


def _parse(text: str):
    return parse_config(tomllib.loads(text), "test.toml")


def _drop(text: str, line: str) -> str:
    assert line in text, line
    return text.replace(line + "\n", "")


# ------------------------------------------------------------ required parameters
def test_a_complete_ladrc_config_is_valid() -> None:
    cfg = _parse(LADRC)
    assert cfg.controller.value("law.b0") == 26833.0
    assert not any("reference" in d for d in cfg.defaults)


def test_ladrc_without_its_parameters_is_refused_naming_each() -> None:
    """Regression: omega0, b0, omega_c, td.omega silently became 10, 1, 1, 10."""
    bare = LADRC.split("[controller.eso]")[0] + "[simulation]\ndt = 1e-4\n"
    with pytest.raises(ConfigError) as err:
        _parse(bare)
    for key in ("eso.omega0", "td.omega", "sef.omega_c", "law.b0"):
        assert f"controller.{key}" in str(err.value)
    assert "missing" in str(err.value) and "LADRC" in str(err.value)
    with pytest.raises(ConfigError, match=r"controller\.law\.b0: missing"):
        _parse(_drop(LADRC, "b0 = 26833.0"))


def test_the_kinds_decide_what_is_required() -> None:
    # an exact TD needs no td.omega; Kalman gains need q, not omega0
    exact = _drop(_drop(LADRC, "[controller.td]"), "omega = 10.0")
    exact = exact.replace('structure = "LADRC"', 'structure = "LADRC"\ntd_kind = "exact"')
    assert _parse(exact).controller.td == "exact"
    kalman = exact.replace("omega0 = 50.0", 'gains = "kalman"\nq = 1e12\nr = 1e-7')
    assert _parse(kalman).controller.eso_gains == "kalman"
    inleso = LADRC.replace('structure = "LADRC"', 'structure = "INLESO"')
    with pytest.raises(ConfigError) as err:
        _parse(inleso)
    for key in ("eso.k_alpha", "eso.g_beta", "td.a", "td.rho", "sef.kb", "sef.mu"):
        assert f"controller.{key}" in str(err.value)


@pytest.mark.parametrize("name", list_presets())
def test_every_preset_gives_the_parameters_its_controller_uses(name: str) -> None:
    from aiofl.config import load_config

    load_config(name)


def test_check_prints_the_documented_defaults(tmp_path: Path) -> None:
    """Regression: an unset reference silently became the paper's (π/4)·sin 2t."""
    text = LADRC.replace('[scenario.reference]\nkind = "sine"\namplitude = 0.5\nomega = 2.0\n', "")
    path = tmp_path / "run.toml"
    path.write_text(text, encoding="utf-8")
    res = runner.invoke(app, ["simulate", str(path), "--check"])
    assert res.exit_code == 0, res.output
    assert "default: scenario.reference = the paper's (π/4)·sin 2t" in res.stdout
    assert 'default: controller.eso.alpha = "binomial"' in res.stdout
    assert "default: controller.law.u_max = inf" in res.stdout


# --------------------------------------------------------------- [controller.discrete]
@pytest.mark.parametrize(
    ("table", "needles"),
    [
        ("ts = 1.0", ["controller.discrete.ts = 1 s", "scenario.t_final = 1 s", "at least 10"]),
        ("ts = 0.2", ["controller.discrete.ts = 0.2 s", "5 sample(s)"]),
        ("ts = 1e-3\ndelay = true", ["controller.discrete.delay", "integer"]),
        ("ts = 1e-3\nh0 = 1e300", ["controller.discrete.h0 = 1e+300", "100·ts", "0.1 s"]),
        ("ts = 1e-3\nh0 = 1e-9", ["controller.discrete.h0 = 1e-09", "0.001·ts"]),
    ],
)
def test_discrete_table_refuses_what_would_mislead(table: str, needles: list[str]) -> None:
    """Regression: ts > t_final ran one sample (ISU 0), delay = true was 1, h0 = 1e300
    froze the TD (u ≡ 0), all without a word."""
    with pytest.raises(ConfigError) as err:
        _parse(LADRC + "[controller.discrete]\n" + table + "\n")
    for needle in needles:
        assert needle in str(err.value), str(err.value)


def test_sampling_refuses_a_bool_delay_and_a_huge_h0_in_python() -> None:
    from aiofl.controller import controller_batch
    from aiofl.engine.discrete_rows import Sampling, sampling_rows

    with pytest.raises(ValueError, match="delay = True; allowed: the integer 0 or 1"):
        Sampling(1e-3, delay=True)  # type: ignore[arg-type]
    ctrl = _parse(LADRC).controller
    with pytest.raises(ValueError, match="h0"):
        sampling_rows(controller_batch(ctrl), [Sampling(1e-3, h0=1.0)], 1e-4)
    with pytest.raises(ValueError, match=r"scenario\.t_final"):
        Sampling(1e-3).check_horizon(5e-3)
    Sampling(1e-3).check_horizon(1e-2)


def test_a_ts_override_passes_the_horizon_check() -> None:
    cfg = _parse(LADRC)
    with pytest.raises(ConfigError, match="at least 10"):
        cfg.with_sample_time(0.5)
    assert cfg.with_sample_time(1e-3).sampling.ts == 1e-3


# ------------------------------------------------------------------------ --out
WRITERS = [
    ["simulate", "paper-s1-leso"],
    ["robustness", "assisted-s1-ladrc"],
    ["export", "frontier-s1-ladrc", "--ts", "1e-3"],
    ["analyze", "frontier-s1-ladrc", "--sampling"],
    ["tune", "assisted-s1-ladrc", "--generations", "1", "--population", "4", "--quiet"],
    ["reproduce", "--draws", "0"],
]


@pytest.mark.parametrize("args", WRITERS, ids=[a[0] for a in WRITERS])
def test_out_under_a_file_is_refused_before_any_work(tmp_path: Path, args: list[str]) -> None:
    """Regression: ``--out afile/sub`` failed with 'File exists' only after the work."""
    (tmp_path / "afile").write_text("mine\n")
    out = tmp_path / "afile" / "sub"
    t0 = time.perf_counter()
    res = runner.invoke(app, [*args, "--out", str(out)])
    assert res.exit_code == 2, res.output
    assert "--out" in res.stderr and "cannot be created" in res.stderr, res.stderr
    assert "is not a directory" in res.stderr
    assert time.perf_counter() - t0 < 20  # refused up front, nothing simulated
    assert (tmp_path / "afile").read_text() == "mine\n"


def test_check_out_refuses_an_unwritable_folder(tmp_path: Path, monkeypatch) -> None:
    from aiofl.outputs import OutputDirError, check_replaceable

    monkeypatch.setattr(os, "access", lambda *a, **k: False)
    with pytest.raises(OutputDirError, match="not writable"):
        check_replaceable(tmp_path / "new" / "out")


# ------------------------------------------------------------------- stale staging
def test_stale_staging_of_a_reused_pid_is_removed(tmp_path: Path) -> None:
    """A ``kill -9``-ed run's staging folder whose PID now belongs to another (younger)
    process is stale: removed, while a live owner's folder is kept."""
    from aiofl.outputs import remove_stale

    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        time.sleep(0.2)
        old = tmp_path / f".D.staging-{proc.pid}-abc"
        old.mkdir()
        (old / "robustness.json").write_text('{"partial')
        past = time.time() - 3600  # made an hour before the process started
        os.utime(old, (past, past))
        live = tmp_path / f".D.staging-{os.getpid()}-def"
        live.mkdir()
        removed = remove_stale(tmp_path / "D")
        assert removed == [old] and not old.exists() and live.is_dir()
    finally:
        proc.kill()
        proc.wait()


def test_a_failing_run_still_removes_stale_staging(tmp_path: Path) -> None:
    dead = 2**22 + 12345  # above pid_max on Linux: never alive
    stale = tmp_path / f".D.staging-{dead}-abc"
    stale.mkdir()
    bad = tmp_path / "bad.toml"
    bad.write_text(LADRC.replace("b0 = 26833.0", ""), encoding="utf-8")
    res = runner.invoke(app, ["robustness", str(bad), "--out", str(tmp_path / "D")])
    assert res.exit_code == 2 and "controller.law.b0" in res.stderr
    assert not stale.exists() and not (tmp_path / "D").exists()


# ------------------------------------------------------------------------ options
def test_r_op_without_an_operating_point_names_the_option() -> None:
    res = runner.invoke(app, ["analyze", "frontier-s1-ladrc", "--closed-loop", "--r-op", "1e300"])
    assert res.exit_code == 2
    assert res.stderr.startswith("aiofl: error: --r-op = 1e+300"), res.stderr


def test_export_of_a_diverging_design_is_refused(tmp_path: Path) -> None:
    """Regression: the paper's S1 LESO (diverging at 12-14 s) was exported without a word;
    then with a warning; now refused (exit 2, nothing written).  frontier-s1-ladrc at
    0.2 ms (within 10 % of its continuous ITAE) is exported without a warning."""
    out = tmp_path / "c"
    res = runner.invoke(app, ["export", "paper-s1-leso", "--ts", "1e-3", "--out", str(out)])
    assert res.exit_code == 2, res.output
    assert "aiofl: error: paper-s1-leso is lost at" in res.stderr and not out.exists()
    ok = runner.invoke(app, ["export", "frontier-s1-ladrc", "--ts", "2e-4", "--out", str(out)])
    assert ok.exit_code == 0 and "warning" not in ok.stderr, ok.stderr
    assert (out / "aiofl_controller.c").is_file()
