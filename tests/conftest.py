"""Shared fixtures: one ``aiofl reproduce`` run per test session, shared by every
pytest-xdist worker (the first to need it runs it under a file lock; the others wait and
read its output folder and its pickled :class:`aiofl.reporting.cases.Reproduction`).  Under
``make test``'s ``--dist loadfile`` the files that read it are one unit of work
(:class:`ReproduceScopeScheduling`), so one worker runs it and the other works on.

Every test (and every subprocess a test starts) shares one kernel cache,
``<repository>/.aiofl-cache`` unless ``AIOFL_CACHE_DIR`` is set: a kernel one test
compiled is loaded by the next test that needs it, in this run and the next ones, and the
user's own cache (:func:`aiofl.cache.cache_root`) is left alone.
"""

from __future__ import annotations

import copyreg
import fcntl
import functools
import json
import os
import pickle
import re
import types
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from hypothesis import settings
from xdist.scheduler import LoadFileScheduling

from aiofl.blas_threads import one_blas_thread

os.environ.setdefault("AIOFL_CACHE_DIR", str(Path(__file__).resolve().parents[1] / ".aiofl-cache"))

# property tests draw the same examples in every run (seeded like everything else here):
# a CI run fails only on what the code does, not on the draw.  HYPOTHESIS_PROFILE=explore
# draws fresh examples when hunting for new failures.
settings.register_profile("seeded", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "seeded"))

# the tests' matrices are small and both cores are busy (pytest-xdist): one BLAS thread, as
# the aiofl command has (aiofl.blas_threads)
one_blas_thread()


def _mappingproxy(d: dict[str, Any]) -> types.MappingProxyType[str, Any]:
    return types.MappingProxyType(d)


# the layout's kind tables are read-only mappings; pickle them as such (the Reproduction
# travels between test workers as a pickle)
copyreg.pickle(types.MappingProxyType, lambda m: (_mappingproxy, (dict(m),)))


REPRODUCE_GROUP = "reproduce"
"""The scope (pytest-xdist's unit of work) of the test files that read the session's
reproduce run."""


@functools.cache
def _reads_reproduce(path: Path) -> bool:
    """Whether a test or fixture of the file at ``path`` takes the session's ``reproduced``
    fixture (a parameter of that name)."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError:
        return False
    return re.search(r"def \w+\([^)]*\breproduced\b", text) is not None


def _scope(rootpath: Path, nodeid: str) -> str:
    """A test's scope under ``--dist loadfile``: its file, or :data:`REPRODUCE_GROUP` for
    every file that reads the reproduce run."""
    file = nodeid.split("::", 1)[0]
    return REPRODUCE_GROUP if _reads_reproduce(rootpath / file) else file


class ReproduceScopeScheduling(LoadFileScheduling):
    """``--dist loadfile`` (a test file runs on one worker, so its module fixtures are built
    once) with one change: the files that read the session's reproduce run (the suite's
    longest setup) are one scope, so one worker runs it and the other never waits on its
    lock.  The scopes are queued as loadfile queues them (most tests first): queued first,
    on a cold kernel cache the reproduce compiled alone what the other tests compile too
    (388 s against 143 s).  (``--dist loadgroup`` with ``xdist_group`` marks would say the
    same, but with pytest 9.2 and pytest-xdist 3.8 it silently stops grouping:
    pytest-xdist issue #1386.)
    """

    def _split_scope(self, nodeid: str) -> str:
        return _scope(self.config.rootpath, nodeid)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    """:class:`ReproduceScopeScheduling` for ``--dist loadfile`` (``make test``)."""
    if config.getvalue("dist") != "loadfile":
        return None
    return ReproduceScopeScheduling(config, log)


@dataclass(frozen=True)
class ReproduceRun:
    """The output directory of one ``aiofl reproduce`` run, its CLI result and the
    :class:`~aiofl.reporting.cases.Reproduction` it wrote the files from."""

    out: Path
    exit_code: int
    stdout: str
    stderr: str
    pickled: Path

    def reproduction(self) -> Any:
        """The run's Reproduction (runs with trajectories, verdicts, records, ...)."""
        with self.pickled.open("rb") as fh:
            return pickle.load(fh)  # written by this test session


def _run_reproduce(shared: Path) -> None:
    """``aiofl reproduce --out shared/results --draws 16`` in-process through the typer app,
    keeping the Reproduction the command returns."""
    from typer.testing import CliRunner

    import aiofl.reporting.reproduce as module
    from aiofl.cli.app import app

    kept: list[Any] = []
    original = module.reproduce

    def keep(*args: Any, **kwargs: Any) -> Any:
        kept.append(original(*args, **kwargs))
        return kept[-1]

    module.reproduce = keep
    try:
        # 16 model-error draws per design keep the session affordable (the default is 100)
        res = CliRunner().invoke(
            app, ["reproduce", "--out", str(shared / "results"), "--draws", "16"]
        )
    finally:
        module.reproduce = original
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        raise res.exception
    with (shared / "reproduction.pickle").open("wb") as fh:
        pickle.dump(kept[0] if kept else None, fh, protocol=pickle.HIGHEST_PROTOCOL)
    run = {"exit_code": res.exit_code, "stdout": res.stdout, "stderr": res.stderr}
    (shared / "run.json").write_text(json.dumps(run))


@pytest.fixture(scope="session")
def reproduced(tmp_path_factory: pytest.TempPathFactory) -> ReproduceRun:
    """One ``aiofl reproduce --out DIR --draws 16`` for the whole session: run by the first
    worker that needs it (under a lock in the session's shared temporary folder), read by
    the others."""
    base = tmp_path_factory.getbasetemp()
    root = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base
    shared = root / "reproduce-shared"
    with (root / "reproduce.lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (shared / "run.json").exists():
            shared.mkdir(exist_ok=True)
            _run_reproduce(shared)
    run = json.loads((shared / "run.json").read_text())
    return ReproduceRun(shared / "results", pickled=shared / "reproduction.pickle", **run)
