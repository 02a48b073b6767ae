"""Plant files built once: the generated module of a symbolic plant, cached on disk.

Building a plant from a plant file (:meth:`aiofl.plants.symbolic.SymbolicPlant.from_toml`)
parses it, derives ρ and the normal form with sympy and generates the Python source of its
functions (:mod:`aiofl.plants.codegen`).  :func:`plant_from_file` does this once: it writes
the generated functions and what the :class:`~aiofl.plants.base.Plant` needs besides them
(name, parameters, ρ, names and units) as **one module file** in ``<cache root>/plants``
(:mod:`aiofl.cache`), named by a hash of the plant file's text and of the code that
generates it, and imports the plant from that module.  Later processes import the module
and skip sympy altogether; and because the plant's functions now live in a real source
file, the engine's compiled kernel of the plant is cached on disk too
(:mod:`aiofl.engine.build.compile`), so a command on a plant file compiles nothing the second
time.

A module is written under a temporary name and renamed into place, so concurrent processes
filling the same entry never import half a file; a module that is damaged (not UTF-8, not
matching the digest it carries, not loading) is removed with one warning naming it and
rebuilt (:func:`aiofl.plants.plant_modules.load_module`).  When a plant file is edited,
the entries made from its older texts are removed, and entries unused for
:data:`aiofl.cache.STALE_AFTER_DAYS` days go as well.  With the cache disabled
(``AIOFL_NO_CACHE=1``) the plant is built in memory, as before.

The module files themselves (their text, loading, atomic writing) are
:mod:`aiofl.plants.plant_modules`, shared with symbolic plants built in Python.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
from pathlib import Path
from typing import Any

from aiofl.cache import prune_older_than, subdir, touch
from aiofl.plants.base import Plant
from aiofl.plants.plant_modules import generator_digest, load_module, module_source, store_module

__all__ = ["declared_states", "plant_from_file", "plant_module_path"]


def _key(path: Path, text: bytes) -> str:
    """The cache key of a plant file: its text, its stem (the default plant name) and the
    code generator's digest."""
    h = hashlib.sha256(text)
    h.update(f"|{path.stem}|{generator_digest()}".encode())
    return h.hexdigest()[:24]


def plant_module_path(path: str | Path) -> Path | None:
    """Where the cached module of plant file ``path`` is (or would be), or None when the
    cache is off."""
    folder = subdir("plants")
    if folder is None:
        return None
    p = Path(path)
    return folder / f"plant_{_key(p, p.read_bytes())}.py"


def declared_states(path: str | Path) -> int | None:
    """The number of states plant file ``path`` lists (``states = [...]``), read without
    building the plant; None when the file does not say so plainly, or is larger than
    :data:`~aiofl.limits.MAX_PLANT_FILE_BYTES` (it is then checked when built)."""
    import tomllib

    from aiofl.limits import MAX_PLANT_FILE_BYTES

    try:
        p = Path(path)
        if p.stat().st_size > MAX_PLANT_FILE_BYTES:
            return None
        states = tomllib.loads(p.read_text(encoding="utf-8")).get("states")
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return None
    return len(states) if isinstance(states, list) and states else None


def plant_from_file(path: str | Path) -> Plant:
    """The :class:`Plant` of a symbolic-plant TOML file, built once and cached on disk.

    Raises
    ------
    aiofl.plants.expressions.SymbolicPlantError
        The file is not a valid plant (raised only when it is built, i.e. not cached).
    """
    p = Path(path)
    text = p.read_bytes()
    folder = subdir("plants")
    if folder is None:
        return _build(p).to_plant(cache=False)
    key = _key(p, text)
    module_path = folder / f"plant_{key}.py"
    plant = load_module(module_path)
    if plant is not None:
        touch(module_path)
        return plant
    symbolic = _build(p)
    built = symbolic.to_plant(cache=False)
    source = module_source(symbolic.module_functions(), built, key, str(p.resolve()))
    plant = store_module(module_path, source)
    _prune(folder, str(p.resolve()), module_path)
    return plant if plant is not None else built


def _build(path: Path) -> Any:
    from aiofl.plants.symbolic import SymbolicPlant

    return SymbolicPlant.from_toml(path)


def _prune(folder: Path, origin: str, keep: Path) -> None:
    """Remove the entries made from older texts of the plant file ``origin``, and every
    entry unused for a long time."""
    needle = f"ORIGIN = {origin!r}\n"
    with contextlib.suppress(OSError):
        for entry in os.scandir(folder):
            if not entry.name.startswith("plant_") or entry.path == str(keep):
                continue
            head = ""
            with (
                contextlib.suppress(OSError),
                open(entry.path, encoding="utf-8", errors="replace") as fh,
            ):
                head = fh.read(4096)
            if needle in head:
                with contextlib.suppress(OSError):
                    os.remove(entry.path)
    prune_older_than(folder)
