"""The driven simulation's kernel (:mod:`aiofl.engine.kernel.driven_plant`) compiled for
one plant through the compile factory: compiled on first use and cached on disk under a
fingerprint of its template and the plant's functions, like every engine kernel
(:func:`driven_kernel`; run by :func:`aiofl.engine.driven.simulate_driven`).
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np

from aiofl.engine.build import bindings
from aiofl.engine.build import compile as compile_
from aiofl.engine.kernel import driven_plant
from aiofl.plants.base import Plant

__all__ = ["driven_kernel"]

_KERNELS: dict[int, tuple[Plant, Any]] = {}
_LOCK = threading.Lock()


def driven_kernel(plant: Plant, *, cache: bool = True) -> Any:
    """The compiled driven-simulation kernel of ``plant`` (built once per process, loaded
    from the disk cache when this file and the plant's functions are unchanged)."""
    import numba

    with _LOCK:
        hit = _KERNELS.get(id(plant))
        if hit is not None and hit[0] is plant:
            return hit[1]
        compiled = plant.compiled
        space = {
            "__name__": driven_plant.__name__,
            "np": np,
            "_F": bindings.plant_function(compiled[0], "scalar"),
            "_G": bindings.plant_function(compiled[1], "scalar"),
            "_H": bindings.plant_function(compiled[2], "scalar"),
            "_N": plant.n_states,
            "_PRANGE": numba.prange,
        }
        options = {"parallel": True, "error_model": "numpy", "nogil": True}
        entry = compile_.Template("_DRIVEN", driven_plant._tpl_driven, options)
        recipe = compile_.Recipe(
            kind="driven",
            plant=plant,
            bindings=space,
            templates=(),
            entry=entry,
            sources=(driven_plant.__file__, __file__, *bindings.engine_sources()),
        )
        inst = compile_.build(recipe, cache=cache)
        if not inst.cached and bindings.user_functions(plant):
            plant.typecheck()  # a function numba cannot compile: a PlantError naming it
        _KERNELS[id(plant)] = (plant, inst.entry)
        return inst.entry
