"""The plant's function table: a plant's functions called through addresses, so that one
compiled time loop serves every plant.

A *plant-independent* instance (:mod:`aiofl.engine.instances`, every width-1 instance) does
not compile the plant's f, g, h, b_d, normal form and α, β into its code.  It calls them
through the addresses in the batch's ``plant_table`` (:class:`aiofl.engine.batch.Batch`),
in the order of :data:`~aiofl.engine.compile.PLANT_FUNCTIONS`.  Each address is the C entry
point of a small compiled function (:func:`plant_table`)::

    int32 entry(const double *x, intp n_x, const double *p, intp n_p, double *out)

that calls the plant function on the arrays ``x[:n_x]`` and ``p[:n_p]``, writes its values
into ``out`` (at most :func:`entry_sizes` of them) and returns 0, or 1 if the function raised.
The entries are compiled per plant (a fraction of a second, cached on disk by the compile
factory like any kernel); the time loop is compiled once per number of states and cached
for every plant.  A template calls a plant function as ``_PF(fns, x, p)``: in a
plant-independent instance ``_PF`` is :func:`_tpl_call_values` (the call through
``fns[0]``), in a plant-specific one (the lane instances, the diagnostic instance)
:func:`_tpl_direct`, which calls the plant's function itself (inlined: no cost).

The numbers are the same either way: the entries compile the plant functions with the
instance's math (the branch-free vector math of the lane instances, libm for the scalar
check) and strict IEEE arithmetic, so a call through the table rounds as the inlined code
does (the tests compare the width-1 and width-32 instances bit for bit).

This module's source is part of the cache fingerprint of every kernel that binds it.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.engine import compile as compile_
from aiofl.engine.compile import PLANT_FUNCTIONS
from aiofl.plants.base import Plant

__all__ = [
    "N_TABLE",
    "PlantCallFailed",
    "call_bindings",
    "direct_binding",
    "direct_bindings",
    "entry_sizes",
    "plant_table",
    "table_entries",
    "table_recipe",
]

N_TABLE = len(PLANT_FUNCTIONS)
"""Addresses in a plant table: f, g, h, b_d, normal form, α and β."""


def entry_sizes(n_states: int) -> tuple[int, ...]:
    """The number of values each plant function's entry writes (``out``'s length): n for
    f, g and b_d, 1 for h, ρ_max + 2 for the normal form ``(ξ_1..ξ_ρ, α, β)``, 2 for
    ``alpha_beta_of_xi``."""
    return (n_states, n_states, 1, n_states, L.RHO_MAX + 2, 2)


class PlantCallFailed(Exception):
    """Raised inside a plant-independent kernel when the plant function at ``args[0]``
    (an index into PLANT_FUNCTIONS) raised; the caller replays the member in the
    diagnostic instance to name the function and the state
    (:func:`aiofl.engine.instances.run_groups`)."""


# --------------------------------------------------------------- the entries (per plant)
_FN = None  # placeholder: the plant function an entry calls
_SIZE = 1  # placeholder: the values it returns (entry_sizes)
_CARRAY = None  # numba.carray


def _tpl_entry_values(x, n_x, p, n_p, out):  # pragma: no cover - compiled
    """Call the plant function on ``x[:n_x]``, ``p[:n_p]``; its values into ``out``."""
    try:
        r = _FN(_CARRAY(x, (n_x,)), _CARRAY(p, (n_p,)))
        for i in range(min(len(r), _SIZE)):
            out[i] = r[i]
    except Exception:
        return 1
    return 0


def _tpl_entry_value(x, n_x, p, n_p, out):  # pragma: no cover - compiled
    """Call the plant's h on ``x[:n_x]``, ``p[:n_p]``; its value into ``out[0]``."""
    try:
        out[0] = _FN(_CARRAY(x, (n_x,)), _CARRAY(p, (n_p,)))
    except Exception:
        return 1
    return 0


def entry_signature() -> Any:
    """The numba signature of an entry: ``int32(double*, intp, double*, intp, double*)``."""
    from numba import types

    ptr = types.CPointer(types.float64)
    return types.int32(ptr, types.intp, ptr, types.intp, ptr)


def table_recipe(plant: Plant, variant: str) -> compile_.Recipe:
    """The recipe of ``plant``'s entries for the instances of ``variant`` (``"lanes"``: the
    vector math; ``"scalar"``: libm), cached on disk under the plant's code: one template
    per plant function (``_ENTRY_0`` ... in table order, the first the recipe's entry)."""
    import numba

    from aiofl.components import vecmath, vecmath_tables
    from aiofl.engine import bindings

    sizes = entry_sizes(plant.n_states)
    templates = []
    for k, (name, fn) in enumerate(zip(PLANT_FUNCTIONS, plant.compiled, strict=True)):
        body = _tpl_entry_value if name == "h" else _tpl_entry_values
        # as the plant-specific instances bind it (the normal form: libm, called)
        flavour = "scalar" if name == "normal_form" else variant
        # called, not inlined: numba's try does not catch a raise inlined into it
        own = {"_FN": bindings.plant_function(fn, flavour, inline=False), "_SIZE": sizes[k]}
        # each entry a function of its own name (its cache files and symbol are named by it)
        renamed = compile_.copy_function(body, {}, name=f"_tpl_entry_{name}")
        templates.append(compile_.Template(f"_ENTRY_{k}", renamed, {"error_model": "numpy"}, own))
    first, *others = templates
    return compile_.Recipe(
        kind=f"table_{variant}",
        plant=plant,
        # __name__: numba names the module of a cached function's globals by it
        bindings={"__name__": __name__, "_CARRAY": numba.carray},
        templates=tuple(others),
        entry=first,
        sources=(*bindings.engine_sources(), __file__, vecmath.__file__, vecmath_tables.__file__),
        also_cached=tuple(t.name for t in others),
    )


_TABLES: dict[tuple[int, str], tuple[Plant, NDArray[np.int64], tuple[Any, ...]]] = {}
_LOCK = threading.Lock()


def plant_table(plant: Plant, variant: str, *, cache: bool = True) -> NDArray[np.int64]:
    """The addresses of ``plant``'s entries for ``variant`` (see the module notes),
    compiled (or loaded from the disk cache) on first use in this process; the compiled
    entries live as long as the process."""
    return _table(plant, variant, cache)[0]


def table_entries(plant: Plant, variant: str, *, cache: bool = True) -> tuple[Any, ...]:
    """The compiled entries of ``plant``'s table for ``variant`` (numba dispatchers, in
    table order; their ``stats`` tell whether they came from the disk cache)."""
    return _table(plant, variant, cache)[1]


def _table(plant: Plant, variant: str, cache: bool) -> tuple[NDArray[np.int64], tuple[Any, ...]]:
    from aiofl.engine import bindings

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
    """The C entry point of ``dispatcher`` compiled for ``sig`` (numba's cfunc wrapper of
    a jitted function, as its first-class function types use it)."""
    from numba.core.errors import NumbaError

    from aiofl.engine import bindings

    try:
        with compile_.compile_lock(dispatcher):  # processes at once: one compiles
            dispatcher.compile(sig.args)
    except NumbaError:
        if bindings.user_functions(plant):
            plant.typecheck()
        raise
    cres = dispatcher.overloads[sig.args]
    return int(cres.library.get_pointer_to_function(cres.fndesc.llvm_cfunc_wrapper_name))


# ------------------------------------------------ the calls (in the kernel's templates)
_INDEX = 0  # placeholder: the function's index in the table
_CALL = None  # placeholder: call_intrinsic(size)
_PLANT_FN = None  # placeholder: the plant function a plant-specific instance calls


def _tpl_call_values(fns, x, p):  # pragma: no cover - compiled
    """The plant function at ``fns[_INDEX]`` at (x, p): a tuple of its values."""
    status, r = _CALL(fns[_INDEX], x, p)
    if status != 0:
        raise PlantCallFailed(_INDEX)
    return r


def _tpl_call_value(fns, x, p):  # pragma: no cover - compiled
    """The plant's h at (x, p) through ``fns[_INDEX]``: one float."""
    status, r = _CALL(fns[_INDEX], x, p)
    if status != 0:
        raise PlantCallFailed(_INDEX)
    return r[0]


def _tpl_direct(fns, x, p):  # pragma: no cover - compiled
    """The plant function itself at (x, p) (a plant-specific instance; ``fns`` unread)."""
    return _PLANT_FN(x, p)


BOUND_NAMES = ("_PF", "_PG", "_PH", "_PBD", "_PNF", "_PAB")
"""The global names the templates call the plant's functions by, in table order."""


def call_bindings(n_states: int, tag: str) -> dict[str, Any]:
    """``_PF``, ``_PG``, ... of a plant-independent instance: calls through the table."""
    from numba import njit

    sizes = entry_sizes(n_states)
    out = {}
    for k, name in enumerate(BOUND_NAMES):
        body = _tpl_call_value if PLANT_FUNCTIONS[k] == "h" else _tpl_call_values
        ns = {
            "__name__": __name__,
            "_INDEX": k,
            "_CALL": call_intrinsic(sizes[k]),
            "PlantCallFailed": PlantCallFailed,
        }
        fn = compile_.copy_function(body, ns, f"{body.__name__}_{k}_{tag}")
        out[name] = njit(inline="always", error_model="numpy")(fn)
    return out


def direct_bindings(functions: tuple[Any, ...], tag: str) -> dict[str, Any]:
    """``_PF``, ``_PG``, ... of a plant-specific instance: the compiled plant functions
    ``functions`` (in table order), called directly."""
    return {name: direct_binding(functions[k], f"{k}_{tag}") for k, name in enumerate(BOUND_NAMES)}


def direct_binding(function: Any, tag: str) -> Any:
    """``function(x, p)`` called as ``f(fns, x, p)`` (``fns`` unread), inlined where called;
    ``tag`` makes its name unique to the instance."""
    from numba import njit

    space = {"__name__": __name__, "_PLANT_FN": function}
    fn = compile_.copy_function(_tpl_direct, space, f"_direct_{tag}")
    return njit(inline="always", error_model="numpy")(fn)


def call_intrinsic(size: int) -> Any:
    """A numba intrinsic ``call(address, x, p) -> (status, (v_1, ..., v_size))``: the entry
    at ``address`` called on the 1-D float arrays ``x`` and ``p``, its ``size`` values
    returned as a tuple (from a buffer on the stack).  ``x`` and ``p`` must be contiguous
    (every column of a width-1 instance is); a strided one gives status 2 without a call.
    """
    from llvmlite import ir
    from numba.core import cgutils
    from numba.core import types as nbtypes
    from numba.extending import intrinsic

    @intrinsic
    def call(typingctx: Any, address: Any, x: Any, p: Any) -> Any:
        arrays = (x, p)
        if not isinstance(address, nbtypes.Integer) or not all(
            isinstance(a, nbtypes.Array) and a.ndim == 1 and a.dtype == nbtypes.float64
            for a in arrays
        ):
            return None
        ret = nbtypes.Tuple((nbtypes.int32, nbtypes.UniTuple(nbtypes.float64, size)))

        def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
            i32, i64 = ir.IntType(32), ir.IntType(64)
            dbl_ptr = ir.DoubleType().as_pointer()
            views = [
                context.make_array(ty)(context, builder, value=val)
                for ty, val in zip(sig.args[1:], args[1:], strict=True)
            ]
            item = ir.Constant(i64, 8)
            contiguous = builder.and_(
                *(
                    builder.icmp_unsigned(
                        "==", cgutils.unpack_tuple(builder, v.strides, 1)[0], item
                    )
                    for v in views
                )
            )
            buf = cgutils.alloca_once(builder, ir.DoubleType(), size=size)
            for i in range(size):
                builder.store(
                    ir.Constant(ir.DoubleType(), 0.0), builder.gep(buf, [ir.Constant(i32, i)])
                )
            status = cgutils.alloca_once_value(builder, ir.Constant(i32, 2))
            fnty = ir.FunctionType(i32, [dbl_ptr, i64, dbl_ptr, i64, dbl_ptr])
            with builder.if_then(contiguous, likely=True):
                target = builder.inttoptr(
                    context.cast(builder, args[0], sig.args[0], nbtypes.int64), fnty.as_pointer()
                )
                lengths = [cgutils.unpack_tuple(builder, v.shape, 1)[0] for v in views]
                st = builder.call(
                    target, [views[0].data, lengths[0], views[1].data, lengths[1], buf]
                )
                builder.store(st, status)
            values = [builder.load(builder.gep(buf, [ir.Constant(i32, i)])) for i in range(size)]
            tup = context.make_tuple(builder, sig.return_type.types[1], values)
            return context.make_tuple(builder, sig.return_type, [builder.load(status), tup])

        return ret(address, x, p), codegen

    return call
