"""Shared fixtures: one ``aiofl reproduce`` run per test session (it compiles a kernel)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pytest


@dataclass(frozen=True)
class ReproduceRun:
    """The output directory of one ``aiofl reproduce`` run and its CLI result."""

    out: Path
    exit_code: int
    stdout: str
    stderr: str


@pytest.fixture(scope="session")
def reproduced(tmp_path_factory: pytest.TempPathFactory) -> ReproduceRun:
    """Run ``aiofl reproduce --out DIR`` once (in-process, through the typer app)."""
    from typer.testing import CliRunner

    from aiofl.cli.app import app

    out = tmp_path_factory.mktemp("reproduce") / "results"
    res = CliRunner().invoke(app, ["reproduce", "--out", str(out)])
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        raise res.exception
    return ReproduceRun(out, res.exit_code, res.stdout, res.stderr)
