"""The ``aiofl`` command line: presets, show, simulate and bad-input handling."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from aiofl.cli.app import app
from aiofl.config import list_presets, load_config, parse_config, preset_text

runner = CliRunner()
PAPER_PRESETS = [f"paper-s{s}-{k}" for s in (1, 2, 3) for k in ("leso", "inleso")]


def _leftovers(parent: Path, name: str) -> list[Path]:
    """The output directory and any staging directory left next to it."""
    return [p for p in parent.iterdir() if p.name == name or p.name.startswith(f".{name}.")]


# --------------------------------------------------------------------------- basics
def test_importing_the_cli_does_not_import_heavy_modules() -> None:
    code = (
        "import sys, aiofl.cli.app; "
        "print([m for m in ('numba', 'matplotlib', 'scipy', 'pymoo', 'dask', 'sympy') "
        "if m in sys.modules])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_help_lists_the_commands() -> None:
    res = runner.invoke(app, ["--help"])
    assert res.exit_code == 0
    for cmd in ("presets", "show", "simulate", "reproduce"):
        assert cmd in res.stdout


def _click_group() -> Any:
    import typer.main

    return typer.main.get_command(app)


COMMANDS = (
    *("presets", "show", "simulate", "reproduce", "tune", "analyze", "export", "robustness"),
    *("trim", "design", "report", "excite", "identify"),
)


@pytest.mark.parametrize("flag", ["--version", "-V"])
def test_version_prints_the_installed_version(flag: str) -> None:
    from importlib.metadata import version

    res = runner.invoke(app, [flag])
    assert res.exit_code == 0
    assert res.stdout.strip() == f"aiofl {version('aiofl')}"


def test_python_dash_m_aiofl_is_the_same_command_line() -> None:
    from importlib.metadata import version

    out = subprocess.run(
        [sys.executable, "-m", "aiofl", "--version"], capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == f"aiofl {version('aiofl')}"
    bad = subprocess.run(
        [sys.executable, "-m", "aiofl", "show", "no-such-preset"], text=True, capture_output=True
    )
    assert bad.returncode == 2 and "no-such-preset" in bad.stderr


def test_the_commands_are_the_documented_ones() -> None:
    assert tuple(_click_group().commands) == COMMANDS


@pytest.mark.parametrize("command", [[], *([c] for c in COMMANDS)])
def test_dash_h_is_help_on_every_command(command: list[str]) -> None:
    long = runner.invoke(app, [*command, "--help"], env={"COLUMNS": "120"})
    short = runner.invoke(app, [*command, "-h"], env={"COLUMNS": "120"})
    assert long.exit_code == short.exit_code == 0
    assert short.stdout == long.stdout
    assert "Usage: aiofl" in short.stdout


@pytest.mark.parametrize("command", [[], *([c] for c in COMMANDS)])
def test_flags_are_shown_without_a_type(command: list[str]) -> None:
    res = runner.invoke(app, [*command, "--help"], env={"COLUMNS": "160"})
    assert "<bool>" not in res.stdout
    group = _click_group()
    cmd = group.commands[command[0]] if command else group
    flags = [o for p in cmd.params if getattr(p, "is_flag", False) for o in p.opts]
    for flag in flags:  # every flag is still listed
        assert flag in res.stdout


@pytest.mark.parametrize("name", COMMANDS)
def test_every_command_has_examples_that_parse(name: str) -> None:
    """Each example is shown in the help and parses with the command's own parser (its
    options exist, their values have the right types, the arguments are all there)."""
    import shlex

    from aiofl.cli.app import EXAMPLES

    res = runner.invoke(app, [name, "--help"], env={"COLUMNS": "200"})
    assert "Examples:" in res.stdout
    cmd = _click_group().commands[name]
    assert EXAMPLES[name]
    for example in EXAMPLES[name]:
        assert example in res.stdout
        words = shlex.split(example.split(">")[0])
        assert words[:2] == ["aiofl", name]
        with cmd.make_context(name, words[2:]) as ctx:  # raises a UsageError if wrong
            given = {k for k, v in ctx.params.items() if v not in (None, False)}
        flags = [w for w in words[2:] if w.startswith("--")]
        assert len(given) >= len(flags), example


def test_method_lists_its_choices_and_refuses_others(tmp_path: Path) -> None:
    res = runner.invoke(app, ["simulate", "--help"], env={"COLUMNS": "160"})
    assert "rk4|euler" in res.stdout
    assert "[s]" in res.stdout  # units in brackets survive the rich markup
    bad = runner.invoke(
        app, ["simulate", "paper-s1-leso", "--method", "rk45", "-o", str(tmp_path / "o")]
    )
    assert bad.exit_code == 2
    assert "'rk4'" in bad.stderr and "'euler'" in bad.stderr
    assert _leftovers(tmp_path, "o") == []


def test_presets_lists_every_shipped_preset() -> None:
    res = runner.invoke(app, ["presets"], env={"COLUMNS": "200"})
    assert res.exit_code == 0
    for name in list_presets():
        assert name in res.stdout
    assert set(PAPER_PRESETS) <= set(list_presets())


@pytest.mark.parametrize("name", list_presets())
def test_show_prints_the_toml_verbatim_and_it_round_trips(name: str) -> None:
    res = runner.invoke(app, ["show", name])
    assert res.exit_code == 0
    assert res.stdout.rstrip("\n") == preset_text(name).rstrip("\n")
    shown = parse_config(tomllib.loads(res.stdout), "shown")
    loaded = load_config(name)
    assert shown.raw == loaded.raw
    assert dict(shown.controller.values) == dict(loaded.controller.values)
    assert shown.scenario == loaded.scenario
    assert (shown.dt, shown.method, shown.weights) == (loaded.dt, loaded.method, loaded.weights)


def test_show_unknown_preset_exits_2_and_names_it() -> None:
    res = runner.invoke(app, ["show", "no-such-preset"])
    assert res.exit_code == 2
    assert "no-such-preset" in res.stderr
    assert "Traceback" not in res.stderr + res.stdout


# ----------------------------------------------------------------------- bad inputs
BAD_CONFIGS = {
    "malformed": ('name = "x"\n[scenario\n', "malformed TOML"),
    "unknown_key": ('name = "x"\ncolour = "red"\n', "colour"),
    "negative_omega0": ("[controller.eso]\nomega0 = -1\n", "controller.eso.omega0"),
    "x0_length": ("[scenario]\nx0 = [0.1, 0.2]\n", "scenario.x0"),
    "bad_dt": ("[simulation]\ndt = 0.5\n", "simulation.dt"),
}


@pytest.mark.parametrize("case", sorted(BAD_CONFIGS))
def test_bad_config_exits_2_names_the_field_and_writes_nothing(tmp_path: Path, case: str) -> None:
    text, field = BAD_CONFIGS[case]
    cfg = tmp_path / "bad.toml"
    cfg.write_text(text)
    res = runner.invoke(app, ["simulate", str(cfg), "--out", str(tmp_path / "out")])
    assert res.exit_code == 2
    assert field in res.stderr
    assert "Traceback" not in res.stderr + res.stdout
    assert _leftovers(tmp_path, "out") == []


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (["no-such-preset"], "no-such-preset"),
        (["missing.toml"], "missing.toml"),
        (["paper-s1-leso", "--dt", "-1"], "--dt"),
        (["paper-s1-leso", "--method", "rk45"], "--method"),
    ],
)
def test_bad_arguments_exit_2_and_write_nothing(
    tmp_path: Path, args: list[str], field: str
) -> None:
    res = runner.invoke(app, ["simulate", *args, "--out", str(tmp_path / "out")])
    assert res.exit_code == 2
    assert field in res.stderr
    assert _leftovers(tmp_path, "out") == []


@pytest.mark.parametrize("command", [["simulate", "paper-s1-leso"], ["reproduce"]])
def test_out_that_is_a_file_exits_2(tmp_path: Path, command: list[str]) -> None:
    out = tmp_path / "taken"
    out.write_text("not a directory")
    res = runner.invoke(app, [*command, "--out", str(out)])
    assert res.exit_code == 2
    assert "not a directory" in res.stderr
    assert out.read_text() == "not a directory"
    assert [p.name for p in tmp_path.iterdir()] == ["taken"]


def test_bad_input_in_a_fresh_process_has_no_traceback(tmp_path: Path) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text("[controller.eso]\nomega0 = -1\n")
    cmd = [sys.executable, "-c", "from aiofl.cli.app import main; main()", "simulate", str(cfg)]
    out = subprocess.run(
        [*cmd, "--out", str(tmp_path / "o")],
        capture_output=True,
        text=True,
    )
    assert out.returncode == 2
    assert "Traceback" not in out.stderr
    assert "controller.eso.omega0" in out.stderr


# ------------------------------------------------------------------------- simulate
@pytest.mark.slow
def test_simulate_writes_the_engines_metrics(tmp_path: Path) -> None:
    out = tmp_path / "run"
    res = runner.invoke(app, ["simulate", "paper-s1-inleso", "--out", str(out)])
    assert res.exit_code == 0, res.stderr
    rec = json.loads((out / "metrics.json").read_text())
    direct = load_config("paper-s1-inleso").simulate(store=False)
    assert direct.metrics is not None
    for key in ("itae", "isu", "iau", "iae", "ise"):
        assert rec[key] == direct.metrics[key]
    assert rec["opi"] == pytest.approx(
        0.6 * direct.metrics["itae"] / 10
        + 0.2 * direct.metrics["isu"] / 2
        + 0.6 * direct.metrics["iau"] / 2.7,
        rel=1e-12,
    )
    assert rec["scenario"] == 1
    assert rec["scenario_name"] == "nominal"
    assert (rec["structure"], rec["source"], rec["failed"], rec["stopped_at"]) == (
        "INLESO",
        "config",
        False,
        None,
    )
    # trajectory: the used observer states (rho + 1 = 5) and TD states (the ITD has 2)
    header = (out / "trajectory.csv").read_text().splitlines()[0].split(",")
    assert header[:6] == ["t", "r", "y", "y_meas", "u", "d"]
    assert [c for c in header if c.startswith("xi_hat")] == [f"xi_hat{i}" for i in range(1, 6)]
    assert [c for c in header if c[0] == "r" and c[1:].isdigit()] == ["r1", "r2"]
    data = np.loadtxt(out / "trajectory.csv", delimiter=",", skiprows=1)
    assert data[-1, 0] == pytest.approx(20.0)
    assert np.allclose(data[:, 1], np.pi / 4 * np.sin(2 * data[:, 0]))
    assert (out / "figure.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_simulate_reports_divergence_with_time_and_null_metrics(tmp_path: Path) -> None:
    out = tmp_path / "run"
    res = runner.invoke(app, ["simulate", "paper-s1-leso", "--out", str(out)])
    assert res.exit_code == 0, res.stderr
    text = (out / "metrics.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    rec = json.loads(text)
    # lost when |y - r| passes ten times max |r| (its numbers would diverge at 12.42 s)
    assert rec["failed"] is True and rec["status"] == "lost"
    assert rec["stopped_at"] == pytest.approx(11.98, abs=0.01)
    assert "verdict: lost at t = 11.98 s: |y - r|" in res.stdout
    for key in ("itae", "isu", "iau", "opi", "iae", "ise"):
        assert rec[key] is None
    data = np.loadtxt(out / "trajectory.csv", delimiter=",", skiprows=1)
    assert data[-1, 0] <= rec["stopped_at"]
    assert np.isfinite(data).all()
    assert (out / "figure.png").exists()


@pytest.mark.slow
def test_simulate_dt_override_is_used(tmp_path: Path) -> None:
    out = tmp_path / "run"
    cfg = tmp_path / "short.toml"
    text = preset_text("paper-s1-inleso").replace("t_final = 20.0", "t_final = 1.0")
    cfg.write_text(text)
    res = runner.invoke(app, ["simulate", str(cfg), "--out", str(out), "--dt", "2e-4"])
    assert res.exit_code == 0, res.stderr
    t = np.loadtxt(out / "trajectory.csv", delimiter=",", skiprows=1, usecols=0)
    assert np.allclose(np.diff(t), 10 * 2e-4)  # decimation 10 of the preset
    rec = json.loads((out / "metrics.json").read_text())
    assert rec["scenario"] is None  # a custom file whose name encodes no paper scenario


# ------------------------------------------------------------------------ best.toml
PEND_PLANT = """
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

COMMENTED_RUN = """# My pendulum run: keep this comment
name = "pend-tune"
plant = "plants/pend.toml"   # relative to this file

[scenario]
t_final = 2.0   # seconds
[scenario.reference]
kind = "step"
amplitude = 0.5

[controller]
structure = "LADRC"
rho = 2
[controller.eso]
omega0 = 60.0   # observer bandwidth
alpha = [3.0, 3.0, 1.0]   # binomial for rho = 2
[controller.td]
omega = 8.0
[controller.sef]
omega_c = 8.0
[controller.law]
b0 = 4.0   # 1/(m l^2)

[simulation]
dt = 1e-3

[tune]
t_final = 1.0
population = 4
generations = 2
seed = 3
[tune.parameters]
"eso.omega0" = { lo = 20.0, hi = 200.0, log = true }   # tuned
"eso.alpha2" = { lo = 1.0, hi = 5.0 }
"""


@pytest.mark.slow  # compiles a kernel for the plant file and runs a tiny GA
def test_best_toml_keeps_comments_and_a_relative_plant(tmp_path: Path, monkeypatch) -> None:
    (tmp_path / "cfg" / "plants").mkdir(parents=True)
    (tmp_path / "cfg" / "plants" / "pend.toml").write_text(PEND_PLANT)
    (tmp_path / "cfg" / "run.toml").write_text(COMMENTED_RUN)
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    monkeypatch.chdir(tmp_path / "a")
    res = runner.invoke(app, ["tune", "../cfg/run.toml", "--out", "../out", "--quiet"])
    assert res.exit_code == 0, res.stderr
    best_text = (tmp_path / "out" / "best.toml").read_text()
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    best = tomllib.loads(best_text)
    # only the tuned values and the plant path changed; every other line is kept verbatim
    assert best["plant"] == "../cfg/plants/pend.toml"
    assert best["controller"]["eso"]["omega0"] == summary["best_values"]["eso.omega0"]
    assert best["controller"]["eso"]["alpha"] == [3.0, summary["best_values"]["eso.alpha2"], 1.0]
    changed = ("plant =", "omega0 =", "alpha =")
    for line in COMMENTED_RUN.splitlines():
        if not line.startswith(changed):
            assert line in best_text.splitlines(), line
    assert "# observer bandwidth" in best_text and "# binomial for rho = 2" in best_text
    assert best_text.startswith("# Tuned by `aiofl tune`")
    # it runs from another working folder and gives the tuned config's numbers
    monkeypatch.chdir(tmp_path / "b")
    sim = runner.invoke(app, ["simulate", "../out/best.toml", "--out", "sim"])
    assert sim.exit_code == 0, sim.stderr
    rec = json.loads((tmp_path / "b" / "sim" / "metrics.json").read_text())
    full = summary["full_horizon"]
    assert (rec["itae"], rec["isu"], rec["iau"]) == (full["itae"], full["isu"], full["iau"])
