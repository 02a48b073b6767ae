"""The plant's function table: a plant's functions called through addresses, so that one
compiled time loop serves every plant.

A *plant-independent* instance (:mod:`aiofl.engine.instances`, every width-1 instance but
the diagnostic one) does not compile the plant's f, g, h, b_d, normal form and α, β into
its code.  It calls them through the addresses in the batch's ``plant_table``
(:class:`aiofl.engine.batch.Batch`), one per :data:`TABLE` entry.  Each address is the
native function of a small compiled *entry* (:func:`plant_table`), in numba's calling
convention::

    int32 entry(int32 *result, void **exception,
                const double *x, intp n_x, const double *p, intp n_p, double *out)

that calls the plant's function(s) on the arrays ``x[:n_x]`` and ``p[:n_p]``, writes their
values into ``out`` and returns status 0, or a nonzero status if one raised (the kernel then
raises :class:`PlantCallFailed`).  f and g share an entry: the loop evaluates them
together, at the same state, so one call gives both.

The entries are compiled per plant (a fraction of a second, cached on disk by the compile
factory like any kernel); the time loop is compiled once per number of states and cached
for every plant.  A template calls the plant as ``_PFG(fns, x, p)`` (f and g),
``_PH(fns, x, p)``, ...: in a plant-independent instance these are :func:`_tpl_call_pair`,
:func:`_tpl_call_value` and :func:`_tpl_call_values` (the call through ``fns[k]``,
:func:`call_bindings`), in a plant-specific one (the lane instances, the diagnostic
instance) :func:`_tpl_direct` and :func:`_tpl_direct_pair`, which call the plant's
functions themselves (inlined: no cost; :func:`direct_bindings`).

The numbers are the same either way: the entries compile the plant functions with the
instance's math (the branch-free vector math of the lane instances, libm for the scalar
check and the normal form) and strict IEEE arithmetic, so a call through the table rounds
as the inlined code does (the tests compare the width-1 and width-32 instances bit for bit).

This module's source is part of the cache fingerprint of every kernel that binds it.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.engine import compile as compile_
from aiofl.plants.base import Plant

__all__ = [
    "BOUND_NAMES",
    "N_TABLE",
    "TABLE",
    "PlantCallFailed",
    "call_bindings",
    "direct_binding",
    "direct_bindings",
    "entry_sizes",
    "plant_table",
    "table_entries",
    "table_recipe",
]

TABLE = ("f_g", "h", "bd", "normal_form", "alpha_beta_of_xi")
"""The entries of a plant table, in order: f and g together, h, b_d, the normal form and
α, β (``alpha_beta_of_xi``)."""

N_TABLE = len(TABLE)
"""Addresses in a plant table."""

BOUND_NAMES = ("_PFG", "_PH", "_PBD", "_PNF", "_PAB")
"""The global names the templates call the table's entries by, in table order."""

_FUNCTIONS = ((0, 1), (2,), (3,), (4,), (5,))
"""Each entry's plant functions, as indices into ``Plant.compiled`` (f, g, h, b_d, normal
form, α β)."""


def entry_sizes(n_states: int) -> tuple[tuple[int, ...], ...]:
    """The values each entry writes, per plant function: n and n for f and g, 1 for h, n for
    b_d, ρ_max + 2 for the normal form ``(ξ_1..ξ_ρ, α, β)``, 2 for ``alpha_beta_of_xi``."""
    n = n_states
    return ((n, n), (1,), (n,), (L.RHO_MAX + 2,), (2,))


class PlantCallFailed(Exception):
    """Raised inside a plant-independent kernel when a plant function of table entry
    ``args[0]`` raised; the host replays the member in the diagnostic instance to name the
    function and the state (:func:`aiofl.engine.instances.run_groups`)."""


# --------------------------------------------------------------- the entries (per plant)
_FN = _FN2 = None  # placeholders: the plant function(s) an entry calls
_SIZE = 1  # placeholder: the values each returns (entry_sizes)
_CARRAY = None  # numba.carray


def _tpl_entry_values(x, n_x, p, n_p, out):  # pragma: no cover - compiled
    """Call the plant function on ``x[:n_x]``, ``p[:n_p]``; its values into ``out``."""
    r = _FN(_CARRAY(x, (n_x,)), _CARRAY(p, (n_p,)))
    for i in range(min(len(r), _SIZE)):
        out[i] = r[i]
    return 0


def _tpl_entry_value(x, n_x, p, n_p, out):  # pragma: no cover - compiled
    """Call the plant's h on ``x[:n_x]``, ``p[:n_p]``; its value into ``out[0]``."""
    out[0] = _FN(_CARRAY(x, (n_x,)), _CARRAY(p, (n_p,)))
    return 0


def _tpl_entry_pair(x, n_x, p, n_p, out):  # pragma: no cover - compiled
    """Call the plant's f and g on ``x[:n_x]``, ``p[:n_p]``; f's values into
    ``out[:_SIZE]``, g's after them."""
    xa = _CARRAY(x, (n_x,))
    pa = _CARRAY(p, (n_p,))
    a = _FN(xa, pa)
    b = _FN2(xa, pa)
    for i in range(min(len(a), _SIZE)):
        out[i] = a[i]
    for i in range(min(len(b), _SIZE)):
        out[_SIZE + i] = b[i]
    return 0


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
    from aiofl.engine import bindings

    sizes = entry_sizes(plant.n_states)
    compiled = plant.compiled
    templates = []
    for k, name in enumerate(TABLE):
        # as the plant-specific instances bind them (the normal form: libm, called)
        flavour = "scalar" if name == "normal_form" else variant
        fns = [bindings.plant_function(compiled[i], flavour) for i in _FUNCTIONS[k]]
        body = {"f_g": _tpl_entry_pair, "h": _tpl_entry_value}.get(name, _tpl_entry_values)
        own = {"_FN": fns[0], "_FN2": fns[-1], "_SIZE": sizes[k][0]}
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
    """The address of ``dispatcher``'s native function compiled for ``sig``: numba's own
    calling convention, ``int32 fn(int32 *result, void **exception, args...)``, which
    returns 0, or a nonzero status if the function raised (numba's cfunc wrapper would
    print the exception and hide it)."""
    from numba.core.errors import NumbaError

    from aiofl.engine import bindings

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


# ------------------------------------------------ the calls (in the kernel's templates)
_INDEX = 0  # placeholder: the entry's index in the table
_CALL = None  # placeholder: call_intrinsic(sizes)
_PLANT_FN = _PLANT_FN2 = None  # placeholders: the functions a plant-specific instance calls


def _tpl_call_values(fns, x, p):  # pragma: no cover - compiled
    """The plant function of entry ``fns[_INDEX]`` at (x, p): a tuple of its values."""
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


def _tpl_call_pair(fns, x, p):  # pragma: no cover - compiled
    """The plant's f and g at (x, p) through ``fns[_INDEX]``: two tuples."""
    status, a, b = _CALL(fns[_INDEX], x, p)
    if status != 0:
        raise PlantCallFailed(_INDEX)
    return a, b


def _tpl_direct(fns, x, p):  # pragma: no cover - compiled
    """The plant function itself at (x, p) (a plant-specific instance; ``fns`` unread)."""
    return _PLANT_FN(x, p)


def _tpl_direct_pair(fns, x, p):  # pragma: no cover - compiled
    """The plant's f and g themselves at (x, p) (``fns`` unread)."""
    return _PLANT_FN(x, p), _PLANT_FN2(x, p)


def call_bindings(n_states: int, tag: str) -> dict[str, Any]:
    """:data:`BOUND_NAMES` of a plant-independent instance: calls through the table."""
    from numba import njit

    sizes = entry_sizes(n_states)
    bodies = {"f_g": _tpl_call_pair, "h": _tpl_call_value}
    out = {}
    for k, name in enumerate(BOUND_NAMES):
        body = bodies.get(TABLE[k], _tpl_call_values)
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
    """:data:`BOUND_NAMES` of a plant-specific instance: the compiled plant functions
    ``functions`` (f, g, h, b_d, normal form, α β), called directly."""
    return {
        name: direct_binding(*(functions[i] for i in _FUNCTIONS[k]), tag=f"{k}_{tag}")
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
    from numba import njit

    space = {"__name__": __name__, "_PLANT_FN": function, "_PLANT_FN2": second}
    body = _tpl_direct if second is None else _tpl_direct_pair
    fn = compile_.copy_function(body, space, f"{body.__name__}_{tag}")
    return njit(inline="always", error_model="numpy")(fn)


def call_intrinsic(sizes: tuple[int, ...]) -> Any:
    """A numba intrinsic ``call(address, x, p) -> (status, values_1, ...)``: the entry at
    ``address`` (numba's calling convention, :func:`_entry_address`) called on the 1-D float
    arrays ``x`` and ``p``; its values, read back from a buffer on the stack, returned as one
    tuple per plant function (of ``sizes[i]`` floats each); status 0, or nonzero if a plant
    function raised.  No call, and zeros, where ``x`` or ``p`` is strided (status 2: every
    column of a width-1 instance is contiguous) or the address is 0 (status 3: a batch whose
    table was never set, :func:`aiofl.engine.instances.set_plant_table`).
    """
    from llvmlite import ir
    from numba.core import cgutils
    from numba.core import types as nbtypes
    from numba.extending import intrinsic

    total = sum(sizes)

    @intrinsic
    def call(typingctx: Any, address: Any, x: Any, p: Any) -> Any:
        arrays = (x, p)
        if not isinstance(address, nbtypes.Integer) or not all(
            isinstance(a, nbtypes.Array) and a.ndim == 1 and a.dtype == nbtypes.float64
            for a in arrays
        ):
            return None
        parts = [nbtypes.UniTuple(nbtypes.float64, n) for n in sizes]
        ret = nbtypes.Tuple((nbtypes.int32, *parts))

        def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
            i32, i64, dbl = ir.IntType(32), ir.IntType(64), ir.DoubleType()
            views = [
                context.make_array(ty)(context, builder, value=val)
                for ty, val in zip(sig.args[1:], args[1:], strict=True)
            ]
            eight = ir.Constant(i64, 8)
            strides = [cgutils.unpack_tuple(builder, v.strides, 1)[0] for v in views]
            contiguous = builder.and_(*(builder.icmp_unsigned("==", s, eight) for s in strides))
            addr = context.cast(builder, args[0], sig.args[0], nbtypes.int64)
            missing = builder.icmp_unsigned("==", addr, ir.Constant(i64, 0))
            buf = cgutils.alloca_once(builder, dbl, size=total)
            slots = [builder.gep(buf, [ir.Constant(i32, i)]) for i in range(total)]
            for slot in slots:  # defined values even where a function returns fewer
                builder.store(ir.Constant(dbl, 0.0), slot)
            status = cgutils.alloca_once_value(
                builder, builder.select(missing, ir.Constant(i32, 3), ir.Constant(i32, 2))
            )
            # numba's calling convention: the result and the exception pointer first
            result = cgutils.alloca_once(builder, i32)
            exc_ptr = ir.IntType(8).as_pointer().as_pointer()
            exc = cgutils.alloca_once(builder, exc_ptr.pointee)
            dbl_ptr = dbl.as_pointer()
            fnty = ir.FunctionType(
                i32, [i32.as_pointer(), exc_ptr, dbl_ptr, i64, dbl_ptr, i64, dbl_ptr]
            )
            callable_ = builder.and_(contiguous, builder.not_(missing))
            with builder.if_then(callable_, likely=True):
                target = builder.inttoptr(addr, fnty.as_pointer())
                lengths = [cgutils.unpack_tuple(builder, v.shape, 1)[0] for v in views]
                call_args = [views[0].data, lengths[0], views[1].data, lengths[1], buf]
                builder.store(builder.call(target, [result, exc, *call_args]), status)
            out = [builder.load(status)]
            start = 0
            for ty, n in zip(parts, sizes, strict=True):
                values = [builder.load(slot) for slot in slots[start : start + n]]
                out.append(context.make_tuple(builder, ty, values))
                start += n
            return context.make_tuple(builder, sig.return_type, out)

        return ret(address, x, p), codegen

    return call
