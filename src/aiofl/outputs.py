"""Output directories replaced as a whole, and atomic file writes.

Every command that writes results uses :func:`atomic_output_dir`: files are written into a
hidden staging directory next to the target, ``.NAME.staging-PID-XXXX``, and when the
command succeeds the directory is swapped in as a whole::

    out  -> .NAME.trash-PID-XXXX      (rename)
    .NAME.staging-PID-XXXX -> out     (rename)
    rm -r .NAME.trash-PID-XXXX

Both renames are atomic on one file system, so a reader sees the complete old directory,
no directory at all (between the two renames), or the complete new one, never a mix of old
and new files.  A run that fails (bad input, a crash, an exception) leaves ``out`` as it
was.  A run killed mid-way (``kill -9``) leaves its staging or trash folder behind; the
next run into the same ``out`` removes every such folder whose owning process (the PID in
its name) is no longer alive (:func:`remove_stale`).

An existing ``out`` is replaced only if it is empty or was written by aiofl (it holds the
marker file :data:`MARKER`), so ``--out .`` or ``--out ~/papers`` never deletes a user's
files: :func:`check_replaceable` refuses such a directory before any work is done.

**One rule for existing outputs** (every ``aiofl`` command that writes): an existing
non-empty ``--out`` (or an existing output file, ``aiofl analyze --figure``) is refused
unless ``--force`` is given; with ``--force`` a folder aiofl wrote is replaced as a whole,
a file atomically.  The commands apply it through ``check_replaceable(out, force=...)`` /
:func:`check_file_replaceable` before any work.  The one command that adds to a folder
instead of replacing it, ``aiofl export --params-only`` (another parameter instance beside
an exported controller), uses :func:`add_files`: the folder's other files are kept, and
only a file of the same name needs ``--force``.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = [
    "MARKER",
    "OutputDirError",
    "add_files",
    "atomic_output_dir",
    "atomic_write_bytes",
    "atomic_write_text",
    "check_addable",
    "check_file_replaceable",
    "check_replaceable",
    "ensure_output_dir",
    "is_aiofl_dir",
    "remove_stale",
]

#: file in every output directory aiofl writes; only such a directory is replaced
MARKER = ".aiofl-output"
_MARKER_TEXT = "Written by aiofl; aiofl replaces this directory as a whole on its next run.\n"


class OutputDirError(FileExistsError):
    """``out`` cannot be used: it is a file, or a non-empty directory aiofl did not write."""


def _is_empty_dir(path: Path) -> bool:
    return path.is_dir() and next(path.iterdir(), None) is None


def is_aiofl_dir(path: str | Path) -> bool:
    """Whether ``path`` is a directory aiofl wrote (holds :data:`MARKER`)."""
    path = Path(path)
    return path.is_dir() and (path / MARKER).is_file()


def check_replaceable(out: str | Path, *, force: bool = True) -> None:
    """Refuse an ``out`` that :func:`atomic_output_dir` must not replace.

    Parameters
    ----------
    out
        The output directory.
    force
        Whether an existing non-empty directory written by aiofl may be replaced.  With
        ``force=False`` (``aiofl simulate`` without ``--force``) any non-empty ``out`` is
        refused.

    Raises
    ------
    OutputDirError
        ``out`` exists and is not a directory; or it is a non-empty directory and either
        ``force`` is false or it lacks :data:`MARKER` (aiofl did not write it).
    """
    out = Path(out)
    if out.is_symlink() or (out.exists() and not out.is_dir()):
        raise OutputDirError(f"--out {str(out)!r} exists and is not a directory")
    _check_creatable(out)
    if out.exists() and Path.cwd().resolve().is_relative_to(out.resolve()):
        raise OutputDirError(
            f"--out {str(out)!r} is the working folder or contains it; choose a new folder"
        )
    if not out.exists() or _is_empty_dir(out):
        return
    if not force:
        raise OutputDirError(
            f"--out {str(out)!r} exists and is not empty; pass --force to replace it "
            "(its files are removed), or choose another --out"
        )
    if not is_aiofl_dir(out):
        raise OutputDirError(
            f"--out {str(out)!r} is a non-empty directory that aiofl did not write (no "
            f"{MARKER} file); aiofl replaces its output directory as a whole, so choose an "
            "empty or new --out"
        )


def _check_creatable(out: Path) -> None:
    """Refuse an ``out`` whose folder cannot be created or written: the nearest existing
    ancestor must be a writable directory (``--out report.pdf/sub`` is refused before any
    work, not after it)."""
    parent = _absolute(out).parent
    while not parent.exists() and parent != parent.parent:
        if parent.is_symlink():  # a dangling link: mkdir would fail
            break
        parent = parent.parent
    if not parent.is_dir():
        raise OutputDirError(
            f"--out {str(out)!r} cannot be created: {str(parent)!r} is not a directory; "
            "choose an --out in a folder"
        )
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputDirError(
            f"--out {str(out)!r} cannot be created: the folder {str(parent)!r} is not "
            "writable; choose another --out"
        )


def ensure_output_dir(out: str | Path) -> Path:
    """Create ``out`` (with :data:`MARKER`) if it does not exist; for files written into
    ``out`` while a command runs (a tuning checkpoint).  Refuses like
    :func:`check_replaceable`."""
    out = Path(out)
    check_replaceable(out)
    out.mkdir(parents=True, exist_ok=True)
    if not (out / MARKER).exists():
        atomic_write_text(out / MARKER, _MARKER_TEXT)
    return out


def check_file_replaceable(path: str | Path, *, force: bool, option: str = "--out") -> None:
    """Refuse an output *file* ``path`` that must not be written (the rule of the module
    docstring): a directory, a folder that does not exist or is not writable, or an
    existing file without ``force``.  ``option`` names the path in the message.

    Parameters
    ----------
    path
        The file.
    force
        Whether an existing file may be replaced.
    option
        The option named in the message (default ``"--out"``).

    Raises
    ------
    OutputDirError
        Naming ``option``, ``path`` and ``--force``.
    """
    path = Path(path)
    where = f"{option} {str(path)!r}"
    if path.is_dir():
        raise OutputDirError(f"{where} is a directory; give a file name")
    parent = _absolute(path).parent
    if not parent.is_dir():
        raise OutputDirError(f"{where}: folder {str(path.parent)!r} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputDirError(f"{where}: the folder {str(parent)!r} is not writable")
    if (path.exists() or path.is_symlink()) and not force:
        raise OutputDirError(
            f"{where} exists; pass --force to replace it, or choose another file name"
        )


def check_addable(out: str | Path, names: Iterable[str], *, force: bool) -> None:
    """Refuse an ``out`` that :func:`add_files` cannot add the files ``names`` to: a file, a
    non-empty folder aiofl did not write, or (without ``force``) one that already holds a
    file of one of these names.

    Parameters
    ----------
    out
        The folder.
    names
        The files' names.
    force
        Whether files of those names may be replaced.
    """
    out = Path(out)
    check_replaceable(out, force=True)
    present = sorted(name for name in names if (out / name).exists())
    if present and not force:
        raise OutputDirError(
            f"--out {str(out)!r} already holds {', '.join(present)}; pass --force to replace "
            "them (the folder's other files are kept), or choose other names"
        )


def add_files(out: str | Path, files: dict[str, str | bytes], *, force: bool) -> None:
    """Write ``files`` (name -> text or bytes) into the folder ``out``, keeping its other
    files (``aiofl export --params-only``).

    ``out`` is created (an aiofl output folder, with :data:`MARKER`) if it does not exist;
    an existing ``out`` must be empty or written by aiofl (:func:`check_replaceable`).  A
    file of the same name already there is replaced only with ``force``; every name is
    checked before anything is written, and each file is written atomically.

    Parameters
    ----------
    out
        The folder.
    files
        ``{name: text or bytes}``.
    force
        Replace files of the same name.

    Raises
    ------
    OutputDirError
        ``out`` cannot be used, or a file exists and ``force`` is false (naming the files
        and ``--force``).
    """
    out = Path(out)
    check_addable(out, files, force=force)
    ensure_output_dir(out)
    for name, data in files.items():
        if isinstance(data, bytes):
            atomic_write_bytes(out / name, data)
        else:
            atomic_write_text(out / name, data)


_LEFTOVER = re.compile(r"^\.(?P<name>.+)\.(?:staging|trash)-(?P<pid>\d+)-[^/]*$")


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


def _process_start(pid: int) -> float | None:
    """When process ``pid`` started (seconds since the epoch), from ``/proc``; None where
    that is not known (not Linux, no access)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        boot = next(
            float(line.split()[1])
            for line in Path("/proc/stat").read_text().splitlines()
            if line.startswith("btime ")
        )
        ticks = float(stat.rsplit(")", 1)[1].split()[19])  # field 22: starttime
        return boot + ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, StopIteration):
        return None


def _owner_alive(pid: int, folder: Path) -> bool:
    """Whether process ``pid`` is alive and can be the one that made ``folder``: a process
    that started after the folder was last changed has reused the PID of a dead owner."""
    if not _pid_alive(pid):
        return False
    if pid == os.getpid():
        return True
    start = _process_start(pid)
    if start is None:
        return True
    try:
        changed = folder.stat().st_mtime
    except OSError:
        return False
    return start <= changed + 2.0  # 2 s: clock-tick rounding of the start time


def remove_stale(out: str | Path) -> list[Path]:
    """Remove the staging and trash folders of ``out`` left by runs that were killed.

    A folder ``.NAME.staging-PID-*`` or ``.NAME.trash-PID-*`` next to ``out`` is removed
    when process PID is no longer alive (or the PID now belongs to a process started after
    the folder was last changed: a reused PID); folders of live processes (another run
    writing the same ``out`` right now) are left alone.  A run killed between its two renames
    leaves no ``out`` and the old directory in its trash folder: that old directory is put
    back as ``out`` first (the newest one if there are several), so nothing that was
    complete is lost.  Returns the removed paths.
    """
    out = _absolute(out)
    parent = out.parent
    removed: list[Path] = []
    if not parent.is_dir():
        return removed
    stale = []
    for item in parent.iterdir():
        m = _LEFTOVER.match(item.name)
        if m is None or m["name"] != out.name or not item.is_dir() or item.is_symlink():
            continue
        if not _owner_alive(int(m["pid"]), item):
            stale.append(item)
    if not out.exists():
        olds = [p / "old" for p in stale if ".trash-" in p.name and (p / "old").is_dir()]
        if olds:
            os.replace(max(olds, key=lambda p: p.stat().st_mtime_ns), out)
    for item in stale:
        shutil.rmtree(item, ignore_errors=True)
        removed.append(item)
    return removed


def _absolute(path: str | Path) -> Path:
    """``path`` made absolute and normalised (``.`` and ``..`` removed), symlinks kept."""
    return Path(os.path.abspath(path))


def _carry_over(out: Path, stage: Path, keep: Iterable[str]) -> None:
    """Hard-link (or copy) the files named in ``keep`` from the old ``out`` into ``stage``."""
    for name in keep:
        src, dst = out / name, stage / name
        if not src.is_file() or dst.exists():
            continue
        try:
            os.link(src, dst)
        except OSError:
            shutil.copy2(src, dst)


@contextmanager
def atomic_output_dir(out: str | Path, *, keep: Iterable[str] = ()) -> Iterator[Path]:
    """Yield a staging directory; on success it replaces ``out`` as a whole.

    Parameters
    ----------
    out
        The output directory.  It may not exist; if it exists it must be empty or written
        by aiofl (:func:`check_replaceable`), and every file in it is replaced.
    keep
        Names of files in the old ``out`` to carry into the new one (e.g. a tuning
        checkpoint written while the command ran), unless the body wrote a file of the
        same name.

    Notes
    -----
    On an exception in the body the staging directory is removed and ``out`` is untouched
    (not even created).  Stale staging/trash folders of killed runs are removed first
    (:func:`remove_stale`).  The swap is two renames (see the module docstring): a reader
    never sees a mix of old and new files.
    """
    out = _absolute(out)
    check_replaceable(out)
    parent = out.parent
    parent.mkdir(parents=True, exist_ok=True)
    remove_stale(out)
    pid = os.getpid()
    stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.staging-{pid}-", dir=parent))
    trash: Path | None = None
    try:
        atomic_write_text(stage / MARKER, _MARKER_TEXT)
        yield stage
        check_replaceable(out)  # it may have changed while the body ran
        if out.is_dir():
            _carry_over(out, stage, keep)
            trash = Path(tempfile.mkdtemp(prefix=f".{out.name}.trash-{pid}-", dir=parent))
            os.replace(out, trash / "old")  # trash/old: the directory as it was
        os.chmod(stage, 0o777 & ~_umask())  # mkdtemp makes 0700; give the usual mode
        try:
            os.replace(stage, out)
        except BaseException:
            if trash is not None and not out.exists():
                os.replace(trash / "old", out)  # put the old directory back
            raise
    finally:
        shutil.rmtree(stage, ignore_errors=True)
        if trash is not None:
            shutil.rmtree(trash, ignore_errors=True)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` via a temporary file and :func:`os.replace`."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the file the usual mode
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8) atomically, see :func:`atomic_write_bytes`."""
    atomic_write_bytes(path, text.encode("utf-8"))
