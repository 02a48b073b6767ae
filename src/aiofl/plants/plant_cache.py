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
(:mod:`aiofl.engine.compile`), so a command on a plant file compiles nothing the second
time.

A module is written under a temporary name and renamed into place, so concurrent processes
filling the same entry never import half a file; a module whose text does not match the
digest it carries is rebuilt.  When a plant file is edited, the entries made from its older
texts are removed, and entries unused for :data:`aiofl.cache.STALE_AFTER_DAYS` days go as
well.  With the cache disabled (``AIOFL_NO_CACHE=1``) the plant is built in memory, as
before.

A symbolic plant built in Python (:meth:`aiofl.plants.symbolic.SymbolicPlant.to_plant`, from
a dict, strings or a TOML file) goes through :func:`plant_from_symbolic`: sympy runs (the
model is in hand, not a file to hash), but its generated module is written into the same
folder, named by a hash of the module's text, so its functions have a source file and the
kernel compiled for them is cached on disk like a plant file's.  Those entries are pruned
by age only (no file is their origin).
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import os
import sys
from pathlib import Path
from typing import Any

from aiofl.cache import prune_older_than, subdir, touch, write_atomic
from aiofl.plants.base import Plant

__all__ = ["plant_from_file", "plant_from_symbolic", "plant_module_path"]

_FORMAT = 1
"""Version of the cached module's layout (part of every key)."""
_FIELDS = (
    "name",
    "n_states",
    "params",
    "relative_degree",
    "state_names",
    "description",
    "output_unit",
    "input_unit",
    "state_units",
    "disturbance_unit",
)
"""The Plant fields a cached module records besides its functions."""


def _generator_digest() -> str:
    """A digest of the modules whose code turns a plant file into a Plant (read as files:
    importing them would import sympy, which a cached plant does not need)."""
    here = Path(__file__).parent
    h = hashlib.sha256(f"{_FORMAT}".encode())
    for name in (
        "base",
        "codegen",
        "coordinates",
        "expressions",
        "normal_form",
        "symbolic",
        "plant_cache",
    ):
        h.update(hashlib.sha256((here / f"{name}.py").read_bytes()).digest())
    return h.hexdigest()


def _key(path: Path, text: bytes) -> str:
    """The cache key of a plant file: its text, its stem (the default plant name) and the
    code generator's digest."""
    h = hashlib.sha256(text)
    h.update(f"|{path.stem}|{_generator_digest()}".encode())
    return h.hexdigest()[:24]


def plant_module_path(path: str | Path) -> Path | None:
    """Where the cached module of plant file ``path`` is (or would be), or None when the
    cache is off."""
    folder = subdir("plants")
    if folder is None:
        return None
    p = Path(path)
    return folder / f"plant_{_key(p, p.read_bytes())}.py"


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
    plant = _load(module_path, key)
    if plant is not None:
        touch(module_path)
        return plant
    symbolic = _build(p)
    built = symbolic.to_plant(cache=False)
    source = _module_source(symbolic, built, key, str(p.resolve()))
    write_atomic(module_path, source.encode())
    _prune(folder, str(p.resolve()), module_path)
    plant = _load(module_path, key)
    return plant if plant is not None else built


def plant_from_symbolic(symbolic: Any, built: Plant) -> Plant:
    """``built`` (the in-memory :class:`Plant` of the symbolic plant ``symbolic``) with its
    functions imported from a cached module instead (see the module notes), so that its
    kernel can be cached on disk; ``built`` itself when the cache is off or unwritable."""
    folder = subdir("plants")
    if folder is None:
        return built
    origin = f"<SymbolicPlant {built.name!r} built in Python>"
    draft = _module_source(symbolic, built, "", origin)
    key = hashlib.sha256(f"{_FORMAT}|{draft}".encode()).hexdigest()[:24]
    module_path = folder / f"plant_{key}.py"
    plant = _load(module_path, key)
    if plant is None:
        try:
            write_atomic(module_path, _module_source(symbolic, built, key, origin).encode())
        except OSError:
            return built
        prune_older_than(folder)
        plant = _load(module_path, key)
    else:
        touch(module_path)
    return plant if plant is not None else built


def _build(path: Path) -> Any:
    from aiofl.plants.symbolic import SymbolicPlant

    return SymbolicPlant.from_toml(path)


def _digest_line(body: str) -> str:
    return f"# aiofl-digest: {hashlib.sha256(body.encode()).hexdigest()}\n"


def _module_source(symbolic: Any, plant: Plant, key: str, origin: str) -> str:
    """The cached module: the generated functions and ``PLANT``, the other fields (the
    module's text is a function of ``key``, ``origin`` and the plant alone)."""
    from aiofl.plants.codegen import GENERATED_FUNCTIONS  # sympy: only on a miss

    srcs = symbolic.function_sources(prefix="_fn_")
    fields = {name: getattr(plant, name) for name in _FIELDS}
    fields["params"] = dict(plant.params)
    body = "".join(
        [
            f'"""aiofl plant module, of a symbolic plant (key {key}); generated, do not edit."""\n',
            "import math\n\n",
            f"ORIGIN = {origin!r}\n",
            f"PLANT = {fields!r}\n",
            *(f"\n\n{srcs[k]}" for k in GENERATED_FUNCTIONS if k in srcs),
        ]
    )
    return body + _digest_line(body)


def _load(module_path: Path, key: str) -> Plant | None:
    """The plant of a cached module, or None if it is missing or not intact."""
    try:
        source = module_path.read_text(encoding="utf-8")
    except OSError:
        return None
    body, _, last = source.rpartition("# aiofl-digest: ")
    if not body or _digest_line(body) != f"# aiofl-digest: {last}":
        return None  # damaged or partial: rebuilt by the caller
    name = f"aiofl_plant_{key}"
    module = sys.modules.get(name)
    if module is None:
        spec = importlib.util.spec_from_file_location(name, module_path)
        if spec is None or spec.loader is None:
            return None
        module = importlib.util.module_from_spec(spec)
        try:
            spec.loader.exec_module(module)
        except Exception:  # an entry of another format: rebuilt by the caller
            return None
        # registered, so numba can name the functions' module in a cached kernel (it
        # imports it by name when the kernel is loaded)
        sys.modules[name] = module
    fields = dict(module.PLANT)
    return Plant(
        f=module._fn_f,
        g=module._fn_g,
        h=module._fn_h,
        bd=getattr(module, "_fn_bd", None),
        normal_form=module._fn_normal_form,
        alpha_beta_of_xi=getattr(module, "_fn_alpha_beta_of_xi", None),
        state_of_xi=getattr(module, "_fn_state_of_xi", None),
        **fields,
    )


def _prune(folder: Path, origin: str, keep: Path) -> None:
    """Remove the entries made from older texts of the plant file ``origin``, and every
    entry unused for a long time."""
    needle = f"ORIGIN = {origin!r}\n"
    with contextlib.suppress(OSError):
        for entry in os.scandir(folder):
            if not entry.name.startswith("plant_") or entry.path == str(keep):
                continue
            head = ""
            with contextlib.suppress(OSError), open(entry.path, encoding="utf-8") as fh:
                head = fh.read(4096)
            if needle in head:
                with contextlib.suppress(OSError):
                    os.remove(entry.path)
    prune_older_than(folder)
