"""aiofl.outputs: output directories replaced as a whole, stale staging removed, atomic files."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import pytest

from aiofl import outputs
from aiofl.outputs import (
    MARKER,
    OutputDirError,
    atomic_output_dir,
    atomic_write_text,
    check_replaceable,
    ensure_output_dir,
    remove_stale,
)


def _leftovers(parent: Path) -> list[str]:
    return sorted(p.name for p in parent.iterdir() if ".staging-" in p.name or ".trash-" in p.name)


def _files(d: Path) -> dict[str, str]:
    return {p.name: p.read_text() for p in sorted(d.iterdir()) if p.name != MARKER}


def _dead_pid() -> int:
    """The pid of a process that has exited (reaped, so it no longer exists)."""
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def _write(out: Path, files: dict[str, str]) -> None:
    with atomic_output_dir(out) as stage:
        for name, text in files.items():
            atomic_write_text(stage / name, text)


def test_success_replaces_the_whole_directory(tmp_path: Path) -> None:
    out = tmp_path / "out"
    _write(out, {"a.txt": "old", "only-old.txt": "old"})
    assert (out / MARKER).is_file()
    _write(out, {"a.txt": "new", "b.txt": "b"})
    # files of the old run that the new one did not write are gone: no mix of runs
    assert _files(out) == {"a.txt": "new", "b.txt": "b"}
    assert _leftovers(tmp_path) == []


def test_keep_carries_a_file_of_the_old_directory_over(tmp_path: Path) -> None:
    out = ensure_output_dir(tmp_path / "out")
    (out / "checkpoint.npz").write_text("ckpt")
    (out / "stale.csv").write_text("old")
    with atomic_output_dir(out, keep=("checkpoint.npz", "absent.txt")) as stage:
        atomic_write_text(stage / "best.toml", "x")
    assert _files(out) == {"best.toml": "x", "checkpoint.npz": "ckpt"}


def test_error_in_body_leaves_nothing_and_keeps_the_old_directory(tmp_path: Path) -> None:
    fresh = tmp_path / "fresh"
    with pytest.raises(RuntimeError), atomic_output_dir(fresh) as stage:
        atomic_write_text(stage / "a.txt", "partial")
        raise RuntimeError("boom")
    assert not fresh.exists()
    out = tmp_path / "out"
    _write(out, {"a.txt": "old"})
    with pytest.raises(RuntimeError), atomic_output_dir(out) as stage:
        atomic_write_text(stage / "a.txt", "partial")
        raise RuntimeError("boom")
    assert _files(out) == {"a.txt": "old"}
    assert _leftovers(tmp_path) == []


def test_out_that_is_a_file_or_a_foreign_directory_is_refused(tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.write_text("a file, not a directory")
    with pytest.raises(OutputDirError, match="not a directory"), atomic_output_dir(out):
        pass
    assert out.read_text() == "a file, not a directory"
    mine = tmp_path / "papers"  # a user's folder: never replaced, even with force
    mine.mkdir()
    (mine / "thesis.tex").write_text("years of work")
    with pytest.raises(OutputDirError, match=r"aiofl did not write.*\.aiofl-output"):
        check_replaceable(mine, force=True)
    with pytest.raises(OutputDirError), atomic_output_dir(mine):
        pass
    assert _files(mine) == {"thesis.tex": "years of work"}
    assert _leftovers(tmp_path) == []


def test_non_empty_directory_needs_force(tmp_path: Path) -> None:
    out = tmp_path / "out"
    _write(out, {"a.txt": "old"})
    with pytest.raises(OutputDirError, match="--force"):
        check_replaceable(out, force=False)
    check_replaceable(out, force=True)
    empty = tmp_path / "empty"
    empty.mkdir()
    check_replaceable(empty, force=False)  # an empty folder is always fine
    check_replaceable(tmp_path / "new", force=False)


def test_the_working_folder_is_never_replaced(tmp_path: Path, monkeypatch) -> None:
    work = tmp_path / "work"
    (work / "sub").mkdir(parents=True)
    monkeypatch.chdir(work / "sub")
    for out in (Path("."), Path(".."), work):
        with pytest.raises(OutputDirError, match="working folder"):
            check_replaceable(out)


def test_a_reader_never_sees_a_mix_of_old_and_new(tmp_path: Path, monkeypatch) -> None:
    """At every rename the swap performs, ``out`` is the complete old set, absent, or the
    complete new set (a per-file move would expose a mix after its first file)."""
    out = tmp_path / "out"
    old = {f"f{i}.txt": "old" for i in range(5)}
    new = {f"f{i}.txt": "new" for i in range(1, 7)}
    _write(out, old)
    seen: list[dict[str, str] | None] = []
    real_replace = os.replace

    def spy(src: object, dst: object) -> None:
        seen.append(_files(out) if out.exists() else None)
        real_replace(src, dst)
        seen.append(_files(out) if out.exists() else None)

    monkeypatch.setattr(outputs.os, "replace", spy)
    _write(out, new)
    monkeypatch.setattr(outputs.os, "replace", real_replace)
    assert seen and all(s in (old, new, None) for s in seen), seen
    assert seen[-1] == new


def test_stale_folders_of_dead_processes_are_removed_live_ones_kept(tmp_path: Path) -> None:
    out = tmp_path / "out"
    dead, live = _dead_pid(), os.getppid()
    stale = [tmp_path / f".out.staging-{dead}-abc", tmp_path / f".out.trash-{dead}-xyz"]
    running = tmp_path / f".out.staging-{live}-def"
    other = tmp_path / f".results.staging-{dead}-abc"  # another output's folder
    for d in (*stale, running, other):
        d.mkdir()
        (d / "partial.txt").write_text("x")
    _write(out, {"a.txt": "new"})
    assert not any(d.exists() for d in stale)
    assert running.exists() and other.exists()
    assert _files(out) == {"a.txt": "new"}


def test_a_run_killed_between_the_renames_gets_its_old_directory_back(tmp_path: Path) -> None:
    out = tmp_path / "out"
    dead = _dead_pid()
    trash = tmp_path / f".out.trash-{dead}-abc"
    (trash / "old").mkdir(parents=True)
    (trash / "old" / "a.txt").write_text("old")
    (tmp_path / f".out.staging-{dead}-def").mkdir()
    removed = remove_stale(out)
    assert len(removed) == 2 and _leftovers(tmp_path) == []
    assert _files(out) == {"a.txt": "old"}


def test_kill_9_inside_the_body_leaves_staging_that_the_next_run_removes(
    tmp_path: Path,
) -> None:
    out = tmp_path / "out"
    script = textwrap.dedent(
        f"""
        import sys, time
        from aiofl.outputs import atomic_output_dir, atomic_write_text
        with atomic_output_dir({str(out)!r}) as stage:
            atomic_write_text(stage / "a.txt", "half")
            print("ready", flush=True)
            time.sleep(60)
        """
    )
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(30)
    assert len(_leftovers(tmp_path)) == 1 and not out.exists()
    _write(out, {"a.txt": "complete"})
    assert _leftovers(tmp_path) == []
    assert _files(out) == {"a.txt": "complete"}


def test_atomic_write_replaces_and_leaves_no_temporary(tmp_path: Path) -> None:
    path = tmp_path / "x.txt"
    atomic_write_text(path, "one")
    atomic_write_text(path, "two")
    assert path.read_text() == "two"
    assert [p.name for p in tmp_path.iterdir()] == ["x.txt"]
    assert path.stat().st_mode & 0o777 == 0o666 & ~outputs._umask()


# -------------------------------------------------------- aiofl simulate and --force
def _simulate(out: Path, *extra: str) -> Any:
    from typer.testing import CliRunner

    from aiofl.cli.app import app

    args = ["simulate", "paper-s1-leso", "--out", str(out), "--t-final", "0.05", *extra]
    return CliRunner().invoke(app, args)


def test_simulate_refuses_a_non_empty_out_unless_force(tmp_path: Path) -> None:
    out = ensure_output_dir(tmp_path / "out")
    (out / "metrics.json").write_text("{}")
    res = _simulate(out, "--check")
    assert res.exit_code == 2 and "--force" in res.stderr and "Traceback" not in res.output
    assert _files(out) == {"metrics.json": "{}"}
    assert _simulate(out, "--check", "--force").exit_code == 0  # validated, nothing run
    assert _files(out) == {"metrics.json": "{}"}
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    res = _simulate(foreign, "--force")
    assert res.exit_code == 2 and "did not write" in res.stderr
    assert _files(foreign) == {"notes.txt": "mine"}
    assert _leftovers(tmp_path) == []


@pytest.mark.slow
def test_simulate_with_force_replaces_the_whole_directory(tmp_path: Path) -> None:
    out = ensure_output_dir(tmp_path / "out")
    (out / "old-figure.png").write_text("from an older run")
    res = _simulate(out, "--force")
    assert res.exit_code == 0, res.output
    names = {p.name for p in out.iterdir()}
    assert names == {MARKER, "metrics.json", "trajectory.csv", "figure.png"}
    assert _leftovers(tmp_path) == []
