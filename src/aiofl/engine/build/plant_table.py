"""The plant's function table built: a plant's table entries compiled and their addresses,
and the bindings a template calls the plant by.

The entries (:mod:`aiofl.engine.kernel.plant_calls`: their templates, the calling
convention and the table's order) are compiled per plant (a fraction of a second, cached on
disk by the compile factory like any kernel: :func:`table_recipe`); :func:`plant_table`
gives their addresses, which :func:`aiofl.engine.build.instances.run` writes into a batch
for the plant-independent instances.  The time loop of those instances is compiled once per
number of states and cached for every plant.  :func:`call_bindings` binds a
plant-independent instance's :data:`~aiofl.engine.kernel.plant_calls.BOUND_NAMES` to calls
through the table, :func:`direct_bindings` a plant-specific instance's to the plant's
functions themselves.

The numbers are the same either way: the entries compile the plant functions with the
instance's math (the branch-free vector math of the lane instances, libm for the scalar
check and the normal form) and strict IEEE arithmetic, so a call through the table rounds
as the inlined code does (the tests compare the width-1 and width-32 instances bit for bit).
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl.engine.build import bindings
from aiofl.engine.build import compile as compile_
from aiofl.engine.kernel import plant_calls
from aiofl.engine.kernel.plant_calls import (
    BOUND_NAMES,
    N_TABLE,
    TABLE,
    TABLE_FUNCTIONS,
    call_intrinsic,
    entry_sizes,
)
from aiofl.plants.base import Plant

__all__ = [
    "call_bindings",
    "direct_binding",
    "direct_bindings",
    "entry_signature",
    "plant_table",
    "table_entries",
    "table_recipe",
]


def entry_signature() -> Any:
    """The numba signature of an entry: ``int32(double*, intp, double*, intp, double*)``."""
    from numba import types

    ptr = types.CPointer(types.float64)
    return types.int32(ptr, types.intp, ptr, types.intp, ptr)


def table_recipe(plant: Plant, variant: str) -> compile_.Recipe:
    """The recipe of ``plant``'s entries for the instances of ``variant`` (``"lanes"``: the
    vector math; ``"scalar"``: libm), cached on disk under the plant's code: one template
    per :data:`TABLE` entry (``_ENTRY_0`` ... in table order, the first the recipe's entry)."""
    import numba

    from aiofl.components import vecmath, vecmath_tables

    sizes = entry_sizes(plant.n_states)
    compiled = plant.compiled
    templates = []
    for k, name in enumerate(TABLE):
        # as the plant-specific instances bind them (the normal form: libm, called)
        flavour = "scalar" if name == "normal_form" else variant
        fns = [bindings.plant_function(compiled[i], flavour) for i in TABLE_FUNCTIONS[k]]
        body = {"f_g": plant_calls._tpl_entry_pair, "h": plant_calls._tpl_entry_value}.get(
            name, plant_calls._tpl_entry_values
        )
        own = {"_FN": fns[0], "_FN2": fns[-1], "_SIZE": sizes[k][0]}
        # each entry a function of its own name (its cache files and symbol are named by it)
        renamed = compile_.copy_function(body, {}, name=f"_tpl_entry_{name}")
        templates.append(compile_.Template(f"_ENTRY_{k}", renamed, {"error_model": "numpy"}, own))
    first, *others = templates
    return compile_.Recipe(
        kind=f"table_{variant}",
        plant=plant,
        # __name__: numba names the module of a cached function's globals by it
        bindings={"__name__": plant_calls.__name__, "_CARRAY": numba.carray},
        templates=tuple(others),
        entry=first,
        sources=(
            *bindings.engine_sources(),
            plant_calls.__file__,
            __file__,
            vecmath.__file__,
            vecmath_tables.__file__,
        ),
        also_cached=tuple(t.name for t in others),
    )


_TABLES: dict[tuple[int, str], tuple[Plant, NDArray[np.int64], tuple[Any, ...]]] = {}
_LOCK = threading.Lock()


def plant_table(plant: Plant, variant: str, *, cache: bool = True) -> NDArray[np.int64]:
    """The addresses of ``plant``'s entries for ``variant`` (see the module notes),
    compiled (or loaded from the disk cache) on first use in this process; the compiled
    entries live as long as the process.

    Parameters
    ----------
    plant, variant
        The plant and the instances' variant.
    cache
        Use the disk cache.

    Returns
    -------
    ndarray
    """
    return _table(plant, variant, cache)[0]


def table_entries(plant: Plant, variant: str, *, cache: bool = True) -> tuple[Any, ...]:
    """The compiled entries of ``plant``'s table for ``variant`` (numba dispatchers, in
    table order; their ``stats`` tell whether they came from the disk cache).

    Parameters
    ----------
    plant, variant, cache
        As for :func:`plant_table`.

    Returns
    -------
    tuple
    """
    return _table(plant, variant, cache)[1]


def _table(plant: Plant, variant: str, cache: bool) -> tuple[NDArray[np.int64], tuple[Any, ...]]:
    key = (id(plant), variant)
    with _LOCK:
        if key in _TABLES and _TABLES[key][0] is plant:
            return _TABLES[key][1], _TABLES[key][2]
        inst = compile_.build(table_recipe(plant, variant), cache=cache)
        if not inst.cached and bindings.user_functions(plant):
            plant.typecheck()  # a function numba cannot compile: a PlantError naming it
        sig = entry_signature()
        entries = tuple(inst.namespace[f"_ENTRY_{k}"] for k in range(N_TABLE))
        addresses = np.array([_entry_address(plant, e, sig) for e in entries], dtype=np.int64)
        addresses.flags.writeable = False
        _TABLES[key] = (plant, addresses, entries)
        return addresses, entries


def _entry_address(plant: Plant, dispatcher: Any, sig: Any) -> int:
    """The address of ``dispatcher``'s native function compiled for ``sig``: numba's own
    calling convention, ``int32 fn(int32 *result, void **exception, args...)``, which
    returns 0, or a nonzero status if the function raised (numba's cfunc wrapper would
    print the exception and hide it)."""
    from numba.core.errors import NumbaError

    try:
        with compile_.compile_lock(dispatcher):  # processes at once: one compiles
            dispatcher.compile(sig)  # the return type too: the caller's result slot is int32
    except NumbaError:
        if bindings.user_functions(plant):
            plant.typecheck()
        raise
    cres = dispatcher.overloads[sig.args]
    if cres.signature != sig:  # pragma: no cover - numba changed how it types the entry
        raise RuntimeError(f"plant table entry compiled as {cres.signature}, expected {sig}")
    return int(cres.library.get_pointer_to_function(cres.fndesc.llvm_func_name))


def call_bindings(n_states: int, tag: str) -> dict[str, Any]:
    """:data:`BOUND_NAMES` of a plant-independent instance: calls through the table."""

    sizes = entry_sizes(n_states)
    bodies = {"f_g": plant_calls._tpl_call_pair, "h": plant_calls._tpl_call_value}
    out = {}
    for k, name in enumerate(BOUND_NAMES):
        body = bodies.get(TABLE[k], plant_calls._tpl_call_values)
        ns = {
            "__name__": plant_calls.__name__,
            "_INDEX": k,
            "_CALL": call_intrinsic(sizes[k]),
            "PlantCallFailed": plant_calls.PlantCallFailed,
        }
        opts = {"inline": "always", "error_model": "numpy"}
        out[name] = compile_.instantiate(body, ns, f"{k}_{tag}", **opts)
    return out


def direct_bindings(functions: tuple[Any, ...], tag: str) -> dict[str, Any]:
    """:data:`BOUND_NAMES` of a plant-specific instance: the compiled plant functions
    ``functions`` (f, g, h, b_d, normal form, α β), called directly."""
    return {
        name: direct_binding(*(functions[i] for i in TABLE_FUNCTIONS[k]), tag=f"{k}_{tag}")
        for k, name in enumerate(BOUND_NAMES)
    }


def direct_binding(function: Any, second: Any = None, *, tag: str) -> Any:
    """``function(x, p)`` (and ``second(x, p)``, as a pair) called as ``f(fns, x, p)``
    (``fns`` unread), inlined where called; ``tag`` makes its name unique.

    Parameters
    ----------
    function, second
        The compiled plant functions (``second`` None: one).
    tag
        Makes the name unique.

    Returns
    -------
    numba dispatcher
    """

    space = {"__name__": plant_calls.__name__, "_PLANT_FN": function, "_PLANT_FN2": second}
    body = plant_calls._tpl_direct if second is None else plant_calls._tpl_direct_pair
    return compile_.instantiate(body, space, tag, inline="always", error_model="numpy")
