"""aiofl's on-disk cache: where compiled kernels and generated plant modules live.

Two kinds of entry share one directory, :func:`cache_root`:

- ``kernels/``: numba's cache files of the compiled closed-loop kernels, one per plant,
  kernel instance and fingerprint of the code it was compiled from
  (:mod:`aiofl.engine.compile`);
- ``plants/``: the generated Python module of a symbolic plant (a plant file) with its
  analysis, keyed by a hash of the plant's text (:mod:`aiofl.plants.plant_cache`), so that
  numba can cache the kernel of a plant file like that of any plant with a source file.

The root is ``$AIOFL_CACHE_DIR`` if set, else the platform's user cache directory
(``platformdirs.user_cache_dir("aiofl")``, e.g. ``~/.cache/aiofl`` on Linux);
``AIOFL_NO_CACHE=1`` disables the cache (everything is built in each process).  A cache
that cannot be created or written is treated as disabled.

Entries are written whole or not at all (:func:`write_atomic`: a temporary name in the
same directory, then a rename), so concurrent processes filling the same entry never see
a partial one; :func:`prune_older_than` removes entries nobody used for a while (use
refreshes an entry's modification time, :func:`touch`).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import time
from pathlib import Path

__all__ = [
    "CACHE_DIR_ENV",
    "NO_CACHE_ENV",
    "STALE_AFTER_DAYS",
    "cache_enabled",
    "cache_root",
    "prune_older_than",
    "subdir",
    "touch",
    "write_atomic",
]

CACHE_DIR_ENV = "AIOFL_CACHE_DIR"
"""Environment variable naming the cache directory."""
NO_CACHE_ENV = "AIOFL_NO_CACHE"
"""Environment variable that disables the cache when set to ``1``, ``true`` or ``yes``."""
STALE_AFTER_DAYS = 30.0
"""An entry not used for this many days is removed the next time its kind is written."""


def cache_enabled() -> bool:
    """Whether the on-disk cache is on (``AIOFL_NO_CACHE`` is not ``1``/``true``/``yes``)."""
    return os.environ.get(NO_CACHE_ENV, "").strip().lower() not in ("1", "true", "yes")


def cache_root() -> Path | None:
    """The cache directory (see the module notes), or None if the cache is disabled."""
    if not cache_enabled():
        return None
    env = os.environ.get(CACHE_DIR_ENV, "").strip()
    if env:
        return Path(env).expanduser()
    import platformdirs

    return Path(platformdirs.user_cache_dir("aiofl", appauthor=False))


def subdir(name: str) -> Path | None:
    """The cache's folder ``name`` (created), or None if the cache is disabled or the folder
    cannot be created and written."""
    root = cache_root()
    if root is None:
        return None
    path = root / name
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError:
        return None
    return path


def write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` as a whole: into a temporary file of the same folder, then
    renamed over ``path`` (atomic on POSIX and Windows), so a reader sees the old entry,
    none, or the new one."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.remove(tmp)
        raise


def touch(path: Path) -> None:
    """Mark ``path`` as used now (its modification time), for :func:`prune_older_than`."""
    with contextlib.suppress(OSError):
        os.utime(path)


def prune_older_than(folder: Path, days: float = STALE_AFTER_DAYS) -> int:
    """Remove the files of ``folder`` not modified (used) for ``days``; returns how many.

    Leftover temporary files of a killed writer (``.*.tmp``) older than an hour go too.
    Files another process removes meanwhile are skipped."""
    now = time.time()
    removed = 0
    with contextlib.suppress(OSError):
        for entry in os.scandir(folder):
            with contextlib.suppress(OSError):
                age = now - entry.stat().st_mtime
                tmp = entry.name.startswith(".") and entry.name.endswith(".tmp")
                if entry.is_file() and (age > days * 86400.0 or (tmp and age > 3600.0)):
                    os.remove(entry.path)
                    removed += 1
    return removed
