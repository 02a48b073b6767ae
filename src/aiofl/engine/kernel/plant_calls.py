"""How a kernel calls the plant's functions: directly (inlined), or through a table of
addresses so that one compiled time loop serves every plant.

A *plant-independent* instance (:mod:`aiofl.engine.build.instances`, every width-1 instance
but the diagnostic one) does not compile the plant's f, g, h, b_d, normal form and α, β into
its code.  It calls them through the addresses in the batch's ``plant_table``
(:class:`aiofl.engine.batch.Batch`), one per :data:`TABLE` entry.  Each address is the
native function of a small compiled *entry* (:func:`_tpl_entry_values` ..., built per plant
by :mod:`aiofl.engine.build.plant_table`), in numba's calling convention::

    int32 entry(int32 *result, void **exception,
                const double *x, intp n_x, const double *p, intp n_p, double *out)

that calls the plant's function(s) on the arrays ``x[:n_x]`` and ``p[:n_p]``, writes their
values into ``out`` and returns status 0, or a nonzero status if one raised (the kernel then
raises :class:`PlantCallFailed`).  f and g share an entry: the loop evaluates them
together, at the same state, so one call gives both.

A template calls the plant as ``_PFG(fns, x, p)`` (f and g), ``_PH(fns, x, p)``, ...
(:data:`BOUND_NAMES`): in a plant-independent instance these are :func:`_tpl_call_pair`,
:func:`_tpl_call_value` and :func:`_tpl_call_values` (the call through ``fns[k]`` by
:func:`call_intrinsic`), in a plant-specific one (the lane instances, the diagnostic
instance) :func:`_tpl_direct` and :func:`_tpl_direct_pair`, which call the plant's
functions themselves (inlined: no cost).

This module's source is part of the cache fingerprint of every kernel that binds it.
"""

from __future__ import annotations

from typing import Any

from aiofl import layout as L

__all__ = [
    "BOUND_NAMES",
    "N_TABLE",
    "TABLE",
    "TABLE_FUNCTIONS",
    "PlantCallFailed",
    "call_intrinsic",
    "entry_sizes",
]

TABLE = ("f_g", "h", "bd", "normal_form", "alpha_beta_of_xi")
"""The entries of a plant table, in order: f and g together, h, b_d, the normal form and
α, β (``alpha_beta_of_xi``)."""

N_TABLE = len(TABLE)
"""Addresses in a plant table."""

BOUND_NAMES = ("_PFG", "_PH", "_PBD", "_PNF", "_PAB")
"""The global names the templates call the table's entries by, in table order."""

TABLE_FUNCTIONS = ((0, 1), (2,), (3,), (4,), (5,))
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
    function and the state (:func:`aiofl.engine.build.instances.run_groups`)."""


# --------------------------------------------------------------- the entries (per plant)
# Placeholders of the entry templates: stand-ins so this module imports.  Each entry gets
# them from aiofl/engine/build/plant_table.py:table_recipe (the template's own bindings and
# the recipe's):
_FN = _FN2 = None  # the plant function it calls (f and g of the f-g pair): private copies
_SIZE = 1  # the values each function returns (entry_sizes)
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


# ------------------------------------------------ the calls (in the kernel's templates)
# Placeholders of the call templates: stand-ins so this module imports.  A call through the
# table (_tpl_call_*) gets them from aiofl/engine/build/plant_table.py:call_bindings, a
# direct call (_tpl_direct*) from aiofl/engine/build/plant_table.py:direct_binding:
_INDEX = 0  # the entry's index in the table (TABLE)
_CALL = None  # call_intrinsic(entry_sizes(n)[_INDEX]): the call through an address
_PLANT_FN = _PLANT_FN2 = None  # the compiled plant function(s) called directly (f, g: a pair)
PLACEHOLDERS = tuple(
    """
    _FN _FN2 _SIZE _CARRAY _INDEX _CALL _PLANT_FN _PLANT_FN2
    """.split()  # noqa: SIM905 - the names as a reader scans them
)
"""The names of the placeholder blocks: what the compile factory checks a recipe binds
when a template of this module reads one (:func:`aiofl.engine.build.compile.build`)."""


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


def call_intrinsic(sizes: tuple[int, ...]) -> Any:
    """A numba intrinsic ``call(address, x, p) -> (status, values_1, ...)``: the entry at
    ``address`` (numba's calling convention,
    :func:`aiofl.engine.build.plant_table.plant_table`) called on the 1-D float arrays ``x``
    and ``p``; its values, read back from a buffer on the stack, returned as one
    tuple per plant function (of ``sizes[i]`` floats each); status 0, or nonzero if a plant
    function raised.  No call, and zeros, where ``x`` or ``p`` is strided (status 2: every
    column of a width-1 instance is contiguous) or the address is 0 (status 3: a batch whose
    table was never set, :func:`aiofl.engine.build.instances.set_plant_table`).
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
