"""Shared fixtures: one ``aiofl reproduce`` run per test session (it compiles a kernel).

Every test (and every subprocess a test starts) shares one kernel cache,
``<repository>/.aiofl-cache`` unless ``AIOFL_CACHE_DIR`` is set: a kernel one test
compiled is loaded by the next test that needs it, in this run and the next ones, and the
user's own cache (:func:`aiofl.cache.cache_root`) is left alone.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import pytest

os.environ.setdefault("AIOFL_CACHE_DIR", str(Path(__file__).resolve().parents[1] / ".aiofl-cache"))


@dataclass(frozen=True)
class ReproduceRun:
    """The output directory of one ``aiofl reproduce`` run and its CLI result."""

    out: Path
    exit_code: int
    stdout: str
    stderr: str


@pytest.fixture(scope="session")
def reproduced(tmp_path_factory: pytest.TempPathFactory) -> ReproduceRun:
    """Run ``aiofl reproduce --out DIR --draws 16`` once (in-process, through the typer
    app)."""
    from typer.testing import CliRunner

    from aiofl.cli.app import app

    out = tmp_path_factory.mktemp("reproduce") / "results"
    # 16 model-error draws per design keep the session affordable (the default is 100)
    res = CliRunner().invoke(app, ["reproduce", "--out", str(out), "--draws", "16"])
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        raise res.exception
    return ReproduceRun(out, res.exit_code, res.stdout, res.stderr)
