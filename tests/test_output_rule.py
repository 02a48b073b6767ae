"""One rule for existing outputs across every command that writes (issues 33 and 34 item 8):
an existing non-empty OUT is refused without --force (exit 2, a message naming OUT and
--force, OUT untouched); ``export --params-only`` adds its files to an export folder and
keeps the controller; ``analyze --figure`` refuses an existing file the same way."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from aiofl.cli.app import app
from aiofl.outputs import (
    MARKER,
    OutputDirError,
    add_files,
    check_file_replaceable,
    ensure_output_dir,
)

ROOT = Path(__file__).resolve().parents[1]


def _invoke(*args: str) -> Any:
    return CliRunner().invoke(app, list(args))


def _earlier_output(tmp_path: Path) -> Path:
    """A folder an earlier aiofl run wrote (marker and one file)."""
    out = ensure_output_dir(tmp_path / "out")
    (out / "old.txt").write_text("earlier run")
    return out


def _files(d: Path) -> dict[str, str]:
    return {p.name: p.read_text() for p in sorted(d.iterdir()) if p.name != MARKER}


COMMANDS = {
    "simulate": ["simulate", "paper-s1-leso", "--t-final", "0.05"],
    "export": ["export", "frontier-s1-ladrc", "--ts", "1e-3"],
    "export-fmu": ["export", "frontier-s1-ladrc", "--ts", "1e-3", "--format", "fmu"],
    "tune": ["tune", "frontier-s1-ladrc", "--generations", "1"],
    "robustness": ["robustness", "frontier-s1-ladrc", "--draws", "2"],
    "reproduce": ["reproduce", "--draws", "0"],
    "analyze-sampling": ["analyze", "paper-s1-leso", "--sampling"],
    "report": ["report", "paper-s1-leso"],
}


@pytest.mark.parametrize("command", list(COMMANDS), ids=list(COMMANDS))
def test_every_command_refuses_an_existing_non_empty_out_without_force(
    tmp_path: Path, command: str
) -> None:
    out = _earlier_output(tmp_path)
    res = _invoke(*COMMANDS[command], "--out", str(out))
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    assert str(out) in res.stderr and "--force" in res.stderr
    assert _files(out) == {"old.txt": "earlier run"}  # refused before any work


@pytest.mark.parametrize("command", ["simulate", "tune"], ids=["simulate", "tune"])
def test_force_lets_the_check_pass(tmp_path: Path, command: str) -> None:
    """--check validates OUT by the same rule: with --force the existing folder passes."""
    out = _earlier_output(tmp_path)
    res = _invoke(*COMMANDS[command], "--out", str(out), "--check", "--force")
    assert res.exit_code == 0, res.output
    assert _files(out) == {"old.txt": "earlier run"}


def test_tune_resume_continues_into_the_folder_holding_its_checkpoint(tmp_path: Path) -> None:
    """--resume needs no --force: OUT holds the checkpoint it continues (here a damaged
    one, so the refusal is about the checkpoint, not about OUT)."""
    out = _earlier_output(tmp_path)
    (out / "checkpoint.npz").write_bytes(b"")
    res = _invoke(*COMMANDS["tune"], "--out", str(out), "--resume", "--check")
    assert res.exit_code == 2
    assert "checkpoint" in res.stderr and "--force" not in res.stderr


def test_params_only_adds_to_an_export_folder_and_keeps_the_controller(tmp_path: Path) -> None:
    """Issue 34 item 8: ``export P --out fw`` then ``export P --params-only --params-name
    alt --out fw`` left only aiofl_alt.c/.h."""
    fw = tmp_path / "fw"
    base = ["export", "frontier-s1-ladrc", "--ts", "1e-3", "--out", str(fw)]
    assert _invoke(*base).exit_code == 0
    controller = _files(fw)
    assert "aiofl_controller.c" in controller
    res = _invoke(*base, "--params-only", "--params-name", "alt")
    assert res.exit_code == 0, res.output
    after = _files(fw)
    assert {k: after[k] for k in controller} == controller  # the controller kept as it was
    assert set(after) - set(controller) == {"aiofl_alt.c", "aiofl_alt.h"}
    assert "holds no aiofl_controller.h" not in res.output
    # the same instance again: refused without --force (naming the files), replaced with it
    res = _invoke(*base, "--params-only", "--params-name", "alt")
    assert res.exit_code == 2 and "aiofl_alt.c" in res.stderr and "--force" in res.stderr
    res = _invoke(*base, "--params-only", "--params-name", "alt", "--force")
    assert res.exit_code == 0, res.output
    assert set(_files(fw)) == set(after)


def test_params_only_into_a_folder_aiofl_did_not_write_is_refused(tmp_path: Path) -> None:
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine")
    with pytest.raises(OutputDirError, match="did not write"):
        add_files(mine, {"a.c": "x"}, force=True)
    assert _files(mine) == {"notes.txt": "mine"}


def test_params_name_without_params_only_is_refused(tmp_path: Path) -> None:
    out = tmp_path / "o"
    res = _invoke(*COMMANDS["export"], "--params-name", "alt", "--out", str(out))
    assert res.exit_code == 2
    assert "--params-name" in res.stderr and "--params-only" in res.stderr
    assert not out.exists()


def test_analyze_figure_refuses_an_existing_file_without_force(tmp_path: Path) -> None:
    fig = tmp_path / "loop.png"
    fig.write_bytes(b"mine")
    args = ["analyze", "paper-s1-leso", "--closed-loop", "--no-orbit", "--figure", str(fig)]
    res = _invoke(*args)
    assert res.exit_code == 2 and str(fig) in res.stderr and "--force" in res.stderr
    assert fig.read_bytes() == b"mine"
    with pytest.raises(OutputDirError, match="is a directory"):
        check_file_replaceable(tmp_path, force=True, option="--figure")
    check_file_replaceable(fig, force=True, option="--figure")  # --force: replaced


def test_make_run_replaces_its_results_folder() -> None:
    """`make run` runs reproduce into the same OUT every time: it passes --force."""
    text = (ROOT / "Makefile").read_text()
    run = [ln for ln in text.splitlines() if "aiofl reproduce" in ln and ln.startswith("\t")]
    assert run and all("--force" in ln for ln in run)


def test_an_infeasible_nsga2_run_leaves_no_checkpoint(tmp_path: Path) -> None:
    """Issue 34 item 6: a finished NSGA-II run with no feasible design exited 2 and left
    OUT/checkpoint.npz behind (nothing to resume: the same run finds the same nothing)."""
    import tomllib

    from aiofl.config import preset_text
    from aiofl.tuning.space import to_toml

    data = tomllib.loads(preset_text("frontier-s1-ladrc"))
    data["tune"].update(
        constraints=["isu:nominal <= -1"], population=4, generations=1, t_final=0.05
    )
    del data["tune"]["robust"]
    data["tune"]["objectives"] = ["itae:nominal", "isu:nominal"]
    cfg = tmp_path / "infeasible.toml"
    cfg.write_text(to_toml(data), encoding="utf-8")
    out = tmp_path / "out"
    res = _invoke("tune", str(cfg), "--out", str(out), "--quiet")
    assert res.exit_code == 2 and "no design of the 4 evaluated" in res.stderr
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["infeasible.toml"]  # no staging
