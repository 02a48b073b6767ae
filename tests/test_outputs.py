"""aiofl.outputs: all-or-nothing output directories and atomic file writes."""

from __future__ import annotations

from pathlib import Path

import pytest

from aiofl.outputs import atomic_output_dir, atomic_write_text


def _staging_dirs(parent: Path) -> list[Path]:
    return [p for p in parent.iterdir() if ".staging-" in p.name]


def test_success_moves_files_in_and_keeps_other_files(tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("old")
    (out / "a.txt").write_text("old")
    with atomic_output_dir(out) as stage:
        atomic_write_text(stage / "a.txt", "new")
        atomic_write_text(stage / "b.txt", "b")
    assert (out / "a.txt").read_text() == "new"
    assert (out / "b.txt").read_text() == "b"
    assert (out / "keep.txt").read_text() == "old"
    assert _staging_dirs(tmp_path) == []


def test_error_in_body_leaves_nothing(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with pytest.raises(RuntimeError), atomic_output_dir(out) as stage:
        atomic_write_text(stage / "a.txt", "partial")
        raise RuntimeError("boom")
    assert not out.exists()
    assert _staging_dirs(tmp_path) == []


def test_out_is_a_file_raises_and_removes_the_staging_dir(tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.write_text("a file, not a directory")
    with pytest.raises(FileExistsError), atomic_output_dir(out) as stage:
        atomic_write_text(stage / "a.txt", "x")
    assert out.read_text() == "a file, not a directory"
    assert _staging_dirs(tmp_path) == []
