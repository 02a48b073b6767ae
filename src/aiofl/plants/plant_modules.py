"""Generated plant modules on disk: the store shared by plant files and symbolic plants.

A symbolic plant's functions are generated Python source (:mod:`aiofl.plants.codegen`).
Executed in memory they have no source file; written as a **module file** into
``<cache root>/plants`` (:mod:`aiofl.cache`) and imported from there, they are plain
functions of a real module, and the engine's kernel compiled for them is cached on disk
(:mod:`aiofl.engine.build.compile`).  This module writes, reads and prunes those files:

- :func:`module_source`: the text of a module, the generated functions and ``PLANT`` (the
  :class:`~aiofl.plants.base.Plant`'s other fields), with a digest of its text on its last
  line (a damaged or partial file is detected, removed with a warning and rebuilt by the
  caller) and, on its first line, the name it is imported as: ``aiofl_plant_`` and a
  digest of the functions alone.
  A kernel loaded from numba's disk cache imports its plant functions' module by that name,
  so a plant whose parameter values changed (another file, the same functions, the same
  kernel: :mod:`aiofl.engine.build.code_fingerprint`) keeps it;
- :func:`load_module`: the plant of a module file (executed afresh, so its ``PLANT`` is the
  file's; registered in ``sys.modules`` under its name), or None;
- :func:`store_module`: write a module under a temporary name and rename it into place, so
  concurrent processes never import half a file;
- :func:`generator_digest`: a digest of the code that turns a symbolic model into a module
  (part of every key, so a new aiofl version rebuilds its entries);
- :func:`cached_plant` and :func:`plant_from_sources`: the entry of a symbolic plant built in
  Python (:meth:`aiofl.plants.symbolic.SymbolicPlant.to_plant`), keyed by its definition
  (:meth:`~aiofl.plants.symbolic.SymbolicPlant.definition_key`), so a later process takes
  the plant from the module without the symbolic analysis; pruned by age only (no file is
  its origin).  Plant files have their own keys and pruning (:mod:`aiofl.plants.plant_cache`).
"""

from __future__ import annotations

import hashlib
import importlib.util
import math
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from aiofl.cache import discard, prune_older_than, subdir, touch, untrusted, write_atomic
from aiofl.plants.base import Plant

__all__ = [
    "FORMAT",
    "cached_plant",
    "generator_digest",
    "load_module",
    "module_source",
    "plant_from_sources",
    "store_module",
]

FORMAT = 2
"""Version of a module's layout (part of every key)."""
_MODULE_LINE = "# aiofl-module: "
"""How a module's first line starts: the name it is imported as follows."""
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
    "state_bounds",
    "output_range",
)
"""The Plant fields a module records besides its functions."""


def _open_side(pair: tuple[float, float]) -> tuple[float | None, float | None]:
    """A range as a module writes it: an infinite side as None (``inf`` is no literal)."""
    lo, hi = pair
    return (lo if math.isfinite(lo) else None, hi if math.isfinite(hi) else None)


def generator_digest() -> str:
    """A digest of the modules whose code turns a symbolic model into a plant module (read
    as files: importing them would import sympy, which a cached plant does not need)."""
    here = Path(__file__).parent
    h = hashlib.sha256(f"{FORMAT}".encode())
    for name in (
        "base",
        "codegen",
        "coordinates",
        "expressions",
        "normal_form",
        "symbolic",
        "plant_cache",
        "plant_modules",
    ):
        h.update(hashlib.sha256((here / f"{name}.py").read_bytes()).digest())
    return h.hexdigest()


def module_source(functions: Sequence[str], plant: Plant, key: str, origin: str) -> str:
    """The module of the generated ``functions`` (sources of ``_fn_f``, ``_fn_g``, ...) and
    ``plant``'s other fields; ``key`` names the entry, ``origin`` what it was made from.

    Parameters
    ----------
    functions
        The generated functions' sources.
    plant
        The plant whose other fields the module holds.
    key
        The cache entry's key.
    origin
        What the plant was made from.

    Returns
    -------
    str
        The module's source.
    """
    code = hashlib.sha256(f"{FORMAT}|{'|'.join(functions)}".encode()).hexdigest()[:24]
    fields = {name: getattr(plant, name) for name in _FIELDS}
    fields["params"] = dict(plant.params)
    fields["state_bounds"] = {k: _open_side(v) for k, v in plant.state_bounds.items()}
    if plant.output_range is not None:
        fields["output_range"] = _open_side(plant.output_range)
    body = "".join(
        [
            f"{_MODULE_LINE}aiofl_plant_{code}\n",
            f'"""aiofl plant module of a symbolic plant (key {key}); generated, do not edit."""\n',
            "import math\n\n",
            f"ORIGIN = {origin!r}\n",
            f"PLANT = {fields!r}\n",
            *(f"\n\n{src}" for src in functions),
        ]
    )
    return body + _digest_line(body)


def _digest_line(body: str) -> str:
    return f"# aiofl-digest: {hashlib.sha256(body.encode()).hexdigest()}\n"


def load_module(module_path: Path) -> Plant | None:
    """The plant of a module file, or None if it is missing or not intact.  The module is
    executed afresh (its ``PLANT`` is this file's) and registered under the name on its
    first line, replacing a module of the same functions loaded before.

    A file that is not intact (not UTF-8, not matching its digest, not of this layout, not
    loading as a plant) or not trusted (:func:`aiofl.cache.untrusted`) is removed with one
    :class:`aiofl.cache.CacheWarning` naming it (:func:`aiofl.cache.discard`); the caller
    builds the entry again."""
    try:
        with open(module_path, "rb") as fh:
            reason = untrusted(module_path, os.fstat(fh.fileno()))
            raw = fh.read()
    except FileNotFoundError:
        return None
    except OSError as exc:
        discard(module_path, f"it cannot be read: {exc.strerror or exc}")
        return None
    if reason is not None:
        discard(module_path, f"not trusted: {reason}")
        return None
    try:
        plant = _plant_of(module_path, raw)
    except _Damaged as exc:
        discard(module_path, str(exc))
        return None
    except Exception as exc:  # it does not load as a plant: rebuilt by the caller
        discard(module_path, f"it does not load: {type(exc).__name__}: {exc}")
        return None
    return plant


class _Damaged(Exception):
    """A module file that is not intact; the message says how."""


def _plant_of(module_path: Path, raw: bytes) -> Plant:
    """The plant of the module file ``module_path`` whose bytes are ``raw`` (checked, then
    executed); raises :class:`_Damaged`, or whatever executing the module raises."""
    if not raw:
        raise _Damaged("the file is empty")
    try:
        source = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise _Damaged(f"its text is not UTF-8 (byte {exc.start})") from None
    body, _, last = source.rpartition("# aiofl-digest: ")
    if not body or _digest_line(body) != f"# aiofl-digest: {last}":
        raise _Damaged("its digest does not match its text (a partial or edited file)")
    first = body.split("\n", 1)[0]
    name = first[len(_MODULE_LINE) :]
    if not first.startswith(_MODULE_LINE) or not name.isidentifier():
        raise _Damaged("its first line is not an aiofl module line")
    spec = importlib.util.spec_from_file_location(name, module_path)
    if spec is None or spec.loader is None:
        raise _Damaged("it cannot be imported")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    fields = dict(module.PLANT)
    plant = Plant(
        f=module._fn_f,
        g=module._fn_g,
        h=module._fn_h,
        bd=getattr(module, "_fn_bd", None),
        normal_form=module._fn_normal_form,
        alpha_beta_of_xi=getattr(module, "_fn_alpha_beta_of_xi", None),
        state_of_xi=getattr(module, "_fn_state_of_xi", None),
        **fields,
    )
    # registered, so numba can import the functions' module by name when it loads a
    # cached kernel of them
    sys.modules[name] = module
    return plant


def store_module(module_path: Path, source: str) -> Plant | None:
    """Write ``source`` to ``module_path`` as a whole and load it (None if either fails)."""
    try:
        write_atomic(module_path, source.encode())
    except OSError:
        return None
    return load_module(module_path)


def cached_plant(key: str) -> Plant | None:
    """The plant of the entry ``key`` of a symbolic plant built in Python, or None (not
    cached, damaged, or the cache off)."""
    folder = subdir("plants")
    if folder is None:
        return None
    module_path = folder / f"plant_{key}.py"
    plant = load_module(module_path)
    if plant is not None:
        touch(module_path)
    return plant


def plant_from_sources(functions: Sequence[str], built: Plant, key: str) -> Plant:
    """``built`` (a plant whose generated ``functions`` run in memory) with its functions
    imported from the module entry ``key``, written now; ``built`` itself when the cache is
    off or unwritable.

    Parameters
    ----------
    functions
        The generated functions' sources.
    built
        The plant built in memory.
    key
        The cache entry's key.

    Returns
    -------
    Plant
    """
    folder = subdir("plants")
    if folder is None:
        return built
    origin = f"<SymbolicPlant {built.name!r} built in Python>"
    plant = store_module(folder / f"plant_{key}.py", module_source(functions, built, key, origin))
    prune_older_than(folder)
    return plant if plant is not None else built
