"""numba's disk cache of a compiled kernel, in aiofl's kernel folder, with files that heal.

:class:`KernelCache` is the numba cache :func:`aiofl.engine.build.compile.build` gives a kernel's
entry: its files live in ``<cache root>/kernels`` (:mod:`aiofl.cache`) and the kernel's
fingerprint is numba's freshness stamp.  Every file (numba's index ``.nbi`` and data
``.nbc``) is **sealed** (:class:`CheckedCacheFile`): a header with the format
(:data:`FORMAT`, part of every kernel's fingerprint), the payload's size and a SHA-256
digest of the file's own name and the payload.  A file that is empty, truncated, has
flipped bits, holds another entry's payload (files swapped or copied), belongs to another
user or is writable by others (:func:`aiofl.cache.untrusted`), or fails to unpickle or load
at all, is **discarded**: the entry's files are removed, the kernel is compiled as if it
had never been cached and stored again, and one :class:`aiofl.cache.CacheWarning` names the
file.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import os
import pickle
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from numba.core.caching import (
    CompileResultCacheImpl,
    FunctionCache,
    IndexDataCacheFile,
    _CacheLocator,
)

from aiofl.cache import untrusted, warn_damaged

__all__ = ["FORMAT", "CheckedCacheFile", "DamagedEntry", "KernelCache"]

FORMAT = 1
"""Version of the sealed file layout (part of every kernel's fingerprint)."""


class _KernelLocator(_CacheLocator):
    """numba's cache locator for a kernel: aiofl's kernel folder, and the fingerprint as the
    freshness stamp (numba's own locators stamp the template's source file, which does not
    change when a plant or a component does)."""

    def __init__(self, folder: str, stamp: str) -> None:
        self._folder = folder
        self._stamp = stamp

    def get_cache_path(self) -> str:
        return self._folder

    def get_source_stamp(self) -> str:
        return self._stamp

    def get_disambiguator(self) -> str:
        return "k"

    @classmethod
    def from_function(cls, py_func: Any, py_file: str) -> Any:
        where = getattr(py_func, "_aiofl_cache", None)
        return None if where is None else cls(*where)


class _KernelCacheImpl(CompileResultCacheImpl):
    _locator_classes = [_KernelLocator]  # noqa: RUF012 - numba's class attribute


class DamagedEntry(Exception):
    """A kernel cache file that is not intact (see :class:`CheckedCacheFile`); its message
    says how, ``path`` names the file (None: not known yet)."""

    def __init__(self, reason: str, path: str | None = None) -> None:
        super().__init__(reason)
        self.path = path


_HEADER = f"aiofl-kernel-cache {FORMAT}\n".encode()
"""How every kernel cache file starts (then the payload's size, 8 bytes, and the digest)."""
_SIZE = struct.Struct("<Q")


def _seal(name: str, payload: bytes) -> bytes:
    """``payload`` with its header: the format line, its size and the SHA-256 digest of the
    file ``name`` and the payload (a payload under another entry's name does not match)."""
    digest = hashlib.sha256(name.encode() + b"\0" + payload).digest()
    return _HEADER + _SIZE.pack(len(payload)) + digest + payload


def _unseal(name: str, data: bytes) -> bytes:
    """The payload of the file ``name`` whose bytes are ``data``; raises
    :class:`DamagedEntry` unless header, size and digest match."""
    if not data:
        raise DamagedEntry("the file is empty")
    start = len(_HEADER) + _SIZE.size + 32
    if len(data) < start or not data.startswith(_HEADER):
        raise DamagedEntry("the file does not start with aiofl's kernel cache header")
    (size,) = _SIZE.unpack_from(data, len(_HEADER))
    payload = data[start:]
    if len(payload) != size:
        raise DamagedEntry(f"the file holds {len(payload)} bytes of {size}")
    digest = hashlib.sha256(name.encode() + b"\0" + payload).digest()
    if data[start - 32 : start] != digest:
        raise DamagedEntry("its digest does not match its content or name")
    return payload


class CheckedCacheFile(IndexDataCacheFile):
    """numba's index and data files of one kernel, each sealed with a header (format, size,
    digest of the file's name and content, :func:`_seal`), written private (mode 0o600),
    data before index, so an index never names data not yet written.  Reading a file that
    is not intact or not trusted (:func:`aiofl.cache.untrusted`) raises
    :class:`DamagedEntry`; a missing file is no entry (as in numba)."""

    def _read(self, path: str) -> bytes:
        with open(path, "rb") as fh:
            reason = untrusted(path, os.fstat(fh.fileno()))
            if reason is not None:
                raise DamagedEntry(f"not trusted: {reason}", path)
            data = fh.read()
        try:
            return _unseal(os.path.basename(path), data)
        except DamagedEntry as exc:
            raise DamagedEntry(str(exc), path) from None

    def _load_index(self) -> dict[Any, str]:
        try:
            payload = self._read(self._index_path)
        except FileNotFoundError:
            return {}
        try:
            stream = io.BytesIO(payload)
            version = pickle.load(stream)
            if version != self._version:
                return {}
            stamp, overloads = pickle.loads(stream.read())
        except Exception as exc:
            reason = f"the index does not unpickle: {type(exc).__name__}"
            raise DamagedEntry(reason, self._index_path) from exc
        if stamp != self._source_stamp or not isinstance(overloads, dict):
            return {}
        return overloads

    def _save_index(self, overloads: dict[Any, str]) -> None:
        payload = pickle.dumps(self._version, protocol=-1) + self._dump(
            (self._source_stamp, overloads)
        )
        with self._open_for_write(self._index_path) as fh:
            fh.write(_seal(self._index_name, payload))

    def _load_data(self, name: str) -> Any:
        path = self._data_path(name)
        payload = self._read(path)
        try:
            return pickle.loads(payload)
        except Exception as exc:
            reason = f"the data does not unpickle: {type(exc).__name__}"
            raise DamagedEntry(reason, path) from exc

    def _save_data(self, name: str, data: Any) -> None:
        with self._open_for_write(self._data_path(name)) as fh:
            fh.write(_seal(name, self._dump(data)))

    def load(self, key: Any) -> Any:
        data_name = self._load_index().get(key)
        if data_name is None:
            return None
        try:
            return self._load_data(data_name)
        except FileNotFoundError:  # removed while the index names it: compiled again
            return None

    def save(self, key: Any, data: Any) -> None:
        try:
            overloads = self._load_index()
        except DamagedEntry:
            overloads = {}
        data_name = overloads.get(key)
        if data_name is None:
            existing = set(overloads.values())
            data_name = next(
                n
                for n in (self._data_name(i) for i in range(1, len(existing) + 2))
                if n not in existing
            )
        self._save_data(data_name, data)
        if overloads.get(key) != data_name:
            self._save_index({**overloads, key: data_name})

    @contextlib.contextmanager
    def _open_for_write(self, filepath: str) -> Iterator[Any]:
        """A private temporary file beside ``filepath``, renamed over it when written."""
        tmp = f"{filepath}.tmp.{os.getpid()}.{id(self):x}"
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            with os.fdopen(fd, "wb") as fh:
                yield fh
            os.replace(tmp, filepath)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise

    def discard(self) -> None:
        """Remove the entry's index and data files (not its compile lock, which a process
        may hold)."""
        base = self._index_name[: -len(".nbi")]
        with contextlib.suppress(OSError):
            for entry in os.scandir(self._cache_path):
                name = entry.name
                if name == self._index_name or (
                    name.startswith(base + ".") and name.endswith(".nbc")
                ):
                    with contextlib.suppress(OSError):
                        os.remove(entry.path)


class KernelCache(FunctionCache):
    """numba's disk cache of a kernel entry, in aiofl's kernel folder (:func:`build`), with
    files that are checked when read (:class:`CheckedCacheFile`).

    An entry that does not load (:class:`DamagedEntry`, or any error unpickling or
    rebuilding it) is discarded with one :class:`aiofl.cache.CacheWarning` naming its index
    file, and numba compiles the kernel as if it were not cached, then stores it again."""

    _impl_class = _KernelCacheImpl

    def __init__(self, py_func: Any) -> None:
        super().__init__(py_func)
        self._cache_file = CheckedCacheFile(
            cache_path=self._cache_path,
            filename_base=self._impl.filename_base,
            source_stamp=self._impl.locator.get_source_stamp(),
        )

    @classmethod
    def for_function(cls, py_func: Any, folder: Path, stamp: str) -> KernelCache:
        """The cache of ``py_func`` in ``folder``, fresh while the fingerprint is ``stamp``.

        Parameters
        ----------
        py_func
            The Python function of the kernel.
        folder
            The cache's folder.
        stamp
            The code fingerprint the cache is valid for.

        Returns
        -------
        KernelCache
        """
        py_func._aiofl_cache = (str(folder), stamp)
        return cls(py_func)

    def load_overload(self, sig: Any, target_context: Any) -> Any:
        try:
            return super().load_overload(sig, target_context)
        except Exception as exc:  # any failure to load is a damaged entry: compiled again
            path = getattr(exc, "path", None) or self._cache_file._index_path
            reason = str(exc) if isinstance(exc, DamagedEntry) else f"{type(exc).__name__}: {exc}"
            self._cache_file.discard()
            warn_damaged(path, reason)
            return None
