"""Caches that heal: a damaged kernel or plant-module entry is detected (size, digest, load
failure), removed and built again with one warning naming it; a cache folder others may
write is not used (issue 34, item 2).

Every test works in its own scratch cache (``tmp_path``).  The kernel tests share one
compiled scratch cache (the discrete controller's kernels, compiled once in a subprocess by
a module-scoped fixture) and damage a copy of it per case; each case then compiles the
damaged kernel again in a fresh process.
"""

from __future__ import annotations

import json
import os
import pickle
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from aiofl import cache
from aiofl.engine.build import compile

# ----------------------------------------------------------------- kernel cache files
_PROBE = """\
import json, sys
import aiofl
from aiofl.engine.build import controller_update
ctrl = aiofl.DiscreteController.from_config("frontier-s1-ladrc", ts=1e-3)
ctrl.reset(0.0)
us = [ctrl.step(1.0, 0.01 * k) for k in range(5)]
fns = vars(controller_update.compiled_update(None))
print(json.dumps({
    "us": us,
    "hits": {k: sum(f.stats.cache_hits.values()) for k, f in fns.items()},
    "misses": {k: sum(f.stats.cache_misses.values()) for k, f in fns.items()},
}))
"""


def _probe(cache_dir: Path) -> tuple[dict, str]:
    """Run the discrete controller in a fresh process on ``cache_dir``: its numbers, the
    cache hits and misses of its kernels, and its stderr."""
    env = {**os.environ, "AIOFL_CACHE_DIR": str(cache_dir)}
    env.pop("AIOFL_NO_CACHE", None)
    proc = subprocess.run(
        [sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1]), proc.stderr


@pytest.fixture(scope="module")
def compiled_cache(tmp_path_factory) -> tuple[Path, dict]:
    """A scratch cache holding the discrete controller's kernels, and the probe's result."""
    cache_dir = tmp_path_factory.mktemp("kernels") / "cache"
    result, err = _probe(cache_dir)
    assert "CacheWarning" not in err
    assert sum(result["misses"].values()) > 0
    return cache_dir, result


def _step_files(cache_dir: Path) -> tuple[Path, Path]:
    """The index and data file of the step kernel (the entry a controller calls)."""
    folder = cache_dir / "kernels"
    (index,) = folder.glob("sampled._tpl_ctrl_step_standalone_*.nbi")
    (data,) = folder.glob("sampled._tpl_ctrl_step_standalone_*.1.nbc")
    return index, data


def _flip_one_bit(path: Path) -> None:
    raw = bytearray(path.read_bytes())
    raw[len(raw) // 2] ^= 0x01  # in the compiled code, which unpickles fine
    path.write_bytes(bytes(raw))


def _swap(a: Path, b: Path) -> None:
    first = a.read_bytes()
    a.write_bytes(b.read_bytes())
    b.write_bytes(first)


def _damage(case: str, cache_dir: Path) -> list[Path]:
    """Damage the copy ``cache_dir`` as the issue's cases did; the damaged files."""
    index, data = _step_files(cache_dir)
    if case == "empty index":
        index.write_bytes(b"")
        return [index]
    if case == "index not a pickle":
        index.write_bytes(b"\xff\xfegarbage")
        return [index]
    if case == "truncated data":
        data.write_bytes(data.read_bytes()[:1000])
        return [data]
    if case == "one flipped bit in the data":
        _flip_one_bit(data)
        return [data]
    if case == "data files swapped":
        (other,) = (cache_dir / "kernels").glob("sampled._tpl_ctrl_init_standalone_*.1.nbc")
        _swap(data, other)
        return [data, other]
    raise AssertionError(case)


@pytest.mark.slow
@pytest.mark.parametrize(
    "case",
    [
        "empty index",
        "truncated data",
        "one flipped bit in the data",
        "data files swapped",
    ],
)
def test_a_damaged_kernel_is_compiled_again_with_one_warning(compiled_cache, tmp_path, case):
    """Before: an empty index aborted every command ("Aborted."), a truncated or garbled
    file raised UnpicklingError / UnicodeDecodeError / KeyError on every run, and a flipped
    bit in the compiled code was loaded unnoticed.  Now the damaged entry is removed, the
    kernel compiled again (the same numbers), one warning names each damaged file, and the
    next process loads the rebuilt entry without a word."""
    pristine, first = compiled_cache
    cache_dir = tmp_path / "cache"
    shutil.copytree(pristine, cache_dir)
    damaged = _damage(case, cache_dir)
    healed, err = _probe(cache_dir)
    assert healed["us"] == first["us"]
    lines = [line for line in err.splitlines() if "CacheWarning" in line]
    assert len(lines) == len(damaged), err
    for path in damaged:
        assert sum(str(path) in line for line in lines) == 1, err
    assert healed["misses"]["step"] == 1  # compiled again
    again, err = _probe(cache_dir)
    assert "CacheWarning" not in err and again["us"] == first["us"]
    assert sum(again["misses"].values()) == 0  # every kernel loaded from the cache


def _sealed_file(tmp_path: Path) -> compile.CheckedCacheFile:
    return compile.CheckedCacheFile(str(tmp_path), "mod.fn_kind_fp-k.py311", "stamp")


def test_kernel_cache_files_are_sealed_and_checked(tmp_path):
    """The checked index/data files (no compile): a round trip; every damage raises
    DamagedEntry naming the file; a stale stamp is no entry; a missing file is no entry."""
    store = _sealed_file(tmp_path)
    key, payload = ("sig", "magic"), {"code": b"\x00" * 64, "n": 3}
    store.save(key, payload)
    assert store.load(key) == payload
    index = tmp_path / "mod.fn_kind_fp-k.py311.nbi"
    data = tmp_path / "mod.fn_kind_fp-k.py311.1.nbc"
    assert index.is_file() and data.is_file()
    assert oct(data.stat().st_mode & 0o777) == oct(0o600)
    good = data.read_bytes()
    for damaged, what in [
        (b"", "empty"),
        (good[:-1], "holds"),
        (good[:-1] + bytes([good[-1] ^ 1]), "digest"),
        (pickle.dumps(payload), "header"),
    ]:
        data.write_bytes(damaged)
        with pytest.raises(compile.DamagedEntry, match=what) as info:
            store.load(key)
        assert info.value.path == str(data)
    # another entry's data under this name: the digest binds the file name
    other = compile.CheckedCacheFile(str(tmp_path), "mod.other_kind_fp-k.py311", "stamp")
    other.save(key, payload)
    data.write_bytes((tmp_path / "mod.other_kind_fp-k.py311.1.nbc").read_bytes())
    with pytest.raises(compile.DamagedEntry, match="digest"):
        store.load(key)
    data.write_bytes(good)
    assert store.load(key) == payload
    if os.name == "posix":  # writable by others: not trusted
        data.chmod(0o606)
        with pytest.raises(compile.DamagedEntry, match="others may write"):
            store.load(key)
        data.chmod(0o600)
    # a stale stamp (another fingerprint) is no entry, not damage
    assert compile.CheckedCacheFile(str(tmp_path), store._index_name[:-4], "new").load(key) is None
    store.discard()
    assert not index.exists() and not data.exists() and store.load(key) is None


# --------------------------------------------------------------------- plant modules
PLANT_TOML = """\
name = "duffing"
states = ["x", "v"]
f = ["v", "(-k*x - 0.5*k*x**3 - c*v)/m"]
g = ["0", "1/m"]
h = "x"
[params]
k = 4.0
c = 0.3
m = 1.0
"""


def _not_a_plant(text: str) -> bytes:
    """A module with a valid digest whose PLANT is not a plant's fields."""
    from aiofl.plants.plant_modules import _digest_line

    body = text.rpartition("# aiofl-digest: ")[0].replace("PLANT = {", "PLANT = {'bogus': 1, ")
    return (body + _digest_line(body)).encode()


@pytest.mark.parametrize(
    "damage",
    ["not UTF-8", "empty", "truncated", "digest of other text", "valid digest, not a plant"],
)
def test_a_damaged_plant_module_is_rebuilt_with_one_warning(tmp_path, monkeypatch, damage):
    """Before: a cached module that is not UTF-8 (``\\377\\376garbage``) failed every run
    with "'utf-8' codec can't decode byte 0xff"; partial modules were rebuilt silently.
    Now each is removed and rebuilt, with one warning naming it."""
    from aiofl.plants import plant_cache

    monkeypatch.setenv("AIOFL_CACHE_DIR", str(tmp_path / "cache"))
    path = tmp_path / "duffing.toml"
    path.write_text(PLANT_TOML)
    plant = plant_cache.plant_from_file(path)
    module = plant_cache.plant_module_path(path)
    text = module.read_text()
    module.write_bytes(
        {
            "not UTF-8": b"\xff\xfegarbage",
            "empty": b"",
            "truncated": text[: len(text) // 2].encode(),
            "digest of other text": text.replace("k", "K", 1).encode(),
            "valid digest, not a plant": _not_a_plant(text),
        }[damage]
    )
    with pytest.warns(cache.CacheWarning) as record:
        again = plant_cache.plant_from_file(path)
    assert len(record) == 1 and str(module) in str(record[0].message)
    assert "damaged" in str(record[0].message)
    assert module.read_text() == text
    x, p = [0.3, -0.2], [4.0, 0.3, 1.0]
    assert again.f(x, p) == plant.f(x, p)
    with warnings.catch_warnings():
        warnings.simplefilter("error", cache.CacheWarning)
        plant_cache.plant_from_file(path)  # intact now: no warning


def test_pruning_skips_a_module_that_is_not_utf8(tmp_path, monkeypatch):
    """Pruning the entries of a plant file reads every entry's head: an entry that is not
    UTF-8 (another plant's, damaged) made it raise UnicodeDecodeError."""
    from aiofl.plants import plant_cache

    monkeypatch.setenv("AIOFL_CACHE_DIR", str(tmp_path / "cache"))
    path = tmp_path / "duffing.toml"
    path.write_text(PLANT_TOML)
    plant_cache.plant_from_file(path)
    stray = tmp_path / "cache" / "plants" / "plant_0123456789abcdef01234567.py"
    stray.write_bytes(b"\xff\xfegarbage")
    path.write_text(PLANT_TOML.replace("k = 4.0", "k = 5.0"))
    assert dict(plant_cache.plant_from_file(path).params)["k"] == 5.0
    assert stray.exists()  # not this plant file's entry: left to age out


# ---------------------------------------------------------------------------- trust
@pytest.mark.skipif(os.name != "posix", reason="POSIX owners and modes")
def test_a_cache_folder_others_may_write_is_not_used(tmp_path, monkeypatch):
    """A cached module is executed: a cache root or folder writable by group or others is
    refused (the cache is off) with one warning naming it and the fix; the folders aiofl
    creates are private."""
    root = tmp_path / "cache"
    monkeypatch.setenv("AIOFL_CACHE_DIR", str(root))
    assert cache.subdir("plants") == root / "plants"
    assert (root.stat().st_mode & 0o777, (root / "plants").stat().st_mode & 0o777) == (
        0o700,
        0o700,
    )
    for folder, mode in [(root, 0o770), (root / "plants", 0o702)]:
        folder.chmod(mode)
        with pytest.warns(cache.CacheWarning) as record:
            assert cache.subdir("plants") is None
            assert cache.subdir("plants") is None  # warned once
        assert len(record) == 1
        message = str(record[0].message)
        assert str(folder) in message and f"chmod go-w {folder}" in message
        folder.chmod(0o700)
    assert cache.subdir("plants") == root / "plants"


@pytest.mark.skipif(os.name != "posix", reason="POSIX owners and modes")
def test_a_plant_module_others_may_write_is_rebuilt(tmp_path, monkeypatch):
    from aiofl.plants import plant_cache

    monkeypatch.setenv("AIOFL_CACHE_DIR", str(tmp_path / "cache"))
    path = tmp_path / "duffing.toml"
    path.write_text(PLANT_TOML)
    plant_cache.plant_from_file(path)
    module = plant_cache.plant_module_path(path)
    assert module.stat().st_mode & 0o077 == 0  # written private
    module.chmod(0o666)
    with pytest.warns(cache.CacheWarning, match="not trusted"):
        plant_cache.plant_from_file(path)
    assert module.stat().st_mode & 0o077 == 0


def test_the_command_line_prints_a_cache_warning_on_one_line(monkeypatch):
    monkeypatch.setattr(warnings, "formatwarning", warnings.formatwarning)  # restored after
    cache.plain_cache_warnings()
    cache.plain_cache_warnings()  # installed once
    text = warnings.formatwarning("the cache entry X was damaged", cache.CacheWarning, "f.py", 1)
    assert text == "aiofl: warning: the cache entry X was damaged\n"
    other = warnings.formatwarning("w", UserWarning, "f.py", 1)
    assert other.startswith("f.py:1: UserWarning: w")
