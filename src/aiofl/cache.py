"""aiofl's on-disk cache: where compiled kernels and generated plant modules live.

Two kinds of entry share one directory, :func:`cache_root`:

- ``kernels/``: numba's cache files of the compiled closed-loop kernels, one per plant,
  kernel instance and fingerprint of the code it was compiled from
  (:mod:`aiofl.engine.build.compile`);
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

**Damage heals.**  Every entry carries a digest of its content (a plant module its last
line, a kernel file a header, :mod:`aiofl.engine.build.compile`); an entry that is damaged
(truncated, emptied, flipped bits, another entry's file under its name, text that is not
UTF-8) or fails to load is removed and built again, with one :class:`CacheWarning` naming
the file (:func:`warn_damaged`).  No command keeps failing until the cache is deleted.

**Trust.**  A cached plant module is executed and a cached kernel is unpickled: whoever can
write the cache can run code in aiofl's process.  The digests detect damage, not
authorship (anyone able to edit an entry can recompute its digest), so the cache must be
writable by its owner alone.  aiofl creates its folders private (mode 0o700) and, on POSIX,
uses a folder only if it belongs to the current user and is not writable by group or
others (:func:`untrusted`); otherwise the cache is off for the process, with one
:class:`CacheWarning` saying why and how to fix it (``chmod go-w FOLDER``).  An entry file
that is writable by others, or belongs to another user, is discarded like a damaged one.
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
import time
import warnings
from pathlib import Path

__all__ = [
    "CACHE_DIR_ENV",
    "NO_CACHE_ENV",
    "STALE_AFTER_DAYS",
    "CacheWarning",
    "cache_enabled",
    "cache_root",
    "discard",
    "plain_cache_warnings",
    "prune_older_than",
    "subdir",
    "touch",
    "untrusted",
    "warn_damaged",
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


class CacheWarning(UserWarning):
    """A cache entry was damaged and is rebuilt, or the cache folder is not private and is
    not used (see the module notes)."""


_WARNED_FOLDERS: set[str] = set()
"""The folders this process has warned about (:func:`subdir` is called often)."""


def untrusted(path: Path | str, st: os.stat_result | None = None) -> str | None:
    """Why ``path`` (a cache folder or entry) must not be trusted, or None: on POSIX, it
    belongs to another user than the current one, or group or others may write it (the
    owner alone may, see the module notes).  ``st``: its ``os.stat`` result, if known.
    Elsewhere (no POSIX owners and modes) always None."""
    if os.name != "posix":
        return None
    if st is None:
        st = os.stat(path)
    uid = os.geteuid()
    if st.st_uid != uid:
        return f"it belongs to user id {st.st_uid}, not to this user (id {uid})"
    if st.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        return f"group or others may write it (mode {stat.S_IMODE(st.st_mode):#o})"
    return None


def _private_folder(path: Path) -> str | None:
    """Create ``path`` if missing (mode 0o700) and check it: why it cannot hold the cache
    (:func:`untrusted`), or None."""
    with contextlib.suppress(FileExistsError):
        path.mkdir(mode=0o700)
    return untrusted(path)


def subdir(name: str) -> Path | None:
    """The cache's folder ``name`` (created private), or None if the cache is disabled, the
    folder cannot be created and written, or it or the cache root is not private
    (:func:`untrusted`; one :class:`CacheWarning` per folder and process)."""
    root = cache_root()
    if root is None:
        return None
    path = root / name
    try:
        root.parent.mkdir(parents=True, exist_ok=True)
        for folder in (root, path):
            reason = _private_folder(folder)
            if reason is not None:
                if str(folder) not in _WARNED_FOLDERS:
                    _WARNED_FOLDERS.add(str(folder))
                    warnings.warn(
                        f"the cache folder {folder} is not used: {reason}. Cached plant "
                        "modules are executed and cached kernels unpickled, so the folder "
                        f"must be writable by its owner alone (chmod go-w {folder}), or "
                        f"set {CACHE_DIR_ENV} to a private folder",
                        CacheWarning,
                        stacklevel=2,
                    )
                return None
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError:
        return None
    return path


def warn_damaged(path: Path | str, reason: str) -> None:
    """The one warning of a damaged cache entry ``path``, removed to be built again."""
    warnings.warn(
        f"the cache entry {path} was damaged ({reason}); it was removed and is built again",
        CacheWarning,
        stacklevel=2,
    )


def plain_cache_warnings() -> None:
    """Print :class:`CacheWarning` as ``aiofl: warning: ...`` (one line, no source line),
    as the command line prints its other warnings; other warnings keep Python's format."""
    formatter = warnings.formatwarning
    if getattr(formatter, "_aiofl_plain", False):
        return

    def plain(message: Warning | str, category: type[Warning], *args: object, **kw: object) -> str:
        if issubclass(category, CacheWarning):
            return f"aiofl: warning: {message}\n"
        return formatter(message, category, *args, **kw)  # type: ignore[arg-type]

    plain._aiofl_plain = True  # type: ignore[attr-defined]
    warnings.formatwarning = plain  # type: ignore[assignment]


def discard(path: Path | str, reason: str) -> None:
    """Remove the damaged or untrusted cache entry ``path`` (if still there) and warn once
    (:func:`warn_damaged`)."""
    with contextlib.suppress(OSError):
        os.remove(path)
    warn_damaged(path, reason)


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
