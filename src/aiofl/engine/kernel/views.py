"""Array views for the compiled kernels, as numba intrinsics: no reference counting, and
addresses LLVM can follow.

Each function returns a fresh intrinsic (the engine binds it into a kernel's namespace under
a placeholder name such as ``_UNMANAGED``).  The views have a NULL memory-info pointer: the
kernel keeps the owning arrays alive itself (``_KEEP_ALIVE``).  This module's source is part
of every kernel's cache fingerprint.
"""

from __future__ import annotations

from typing import Any

__all__ = ["lane_column_intrinsic", "leading_rows_intrinsic", "unmanaged_intrinsic"]


def unmanaged_intrinsic() -> Any:
    """A numba intrinsic returning a view of an array without a memory-info pointer.

    numba reference-counts arrays with atomic increments whenever an array is passed to a
    compiled function or bound to a new name; in a loop that calls the plant's f, g and h
    four times per step this dominated the run time, and on a *shared* input array the
    atomics made parallel members contend for one cache line.  A view whose meminfo is
    NULL is never counted (numba's incref/decref return at once on NULL and LLVM removes
    them).  The caller must keep the owning array alive while the view is used (the
    kernel passes the owners to ``_KEEP_ALIVE`` after its loop).
    """
    from numba.core import cgutils
    from numba.core import types as nbtypes
    from numba.extending import intrinsic

    @intrinsic
    def unmanaged(typingctx: Any, arr: Any) -> Any:
        if not isinstance(arr, nbtypes.Array):
            return None

        def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
            src = context.make_array(sig.args[0])(context, builder, value=args[0])
            dst = context.make_array(sig.return_type)(context, builder)
            for name in ("nitems", "itemsize", "data", "shape", "strides"):
                setattr(dst, name, getattr(src, name))
            dst.meminfo = cgutils.get_null_value(dst.meminfo.type)
            dst.parent = cgutils.get_null_value(dst.parent.type)
            return dst._getvalue()

        return arr(arr), codegen

    return unmanaged


def _row_major_view_intrinsic(layout: str, view: Any) -> Any:
    """A numba intrinsic ``f(a, k)`` returning an unmanaged 1-D view of the 2-D C-contiguous
    array ``a``: ``view(builder, data, shape0, shape1, itemsize, k)`` gives the view's data
    pointer, length and stride (bytes); ``layout`` is its numba layout."""
    from numba.core import cgutils
    from numba.core import types as nbtypes
    from numba.extending import intrinsic

    @intrinsic
    def row_major_view(typingctx: Any, arr: Any, k: Any) -> Any:
        if not (
            isinstance(arr, nbtypes.Array)
            and arr.ndim == 2
            and arr.layout == "C"
            and isinstance(k, nbtypes.Integer)
        ):
            return None

        def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
            src = context.make_array(sig.args[0])(context, builder, value=args[0])
            dst = context.make_array(sig.return_type)(context, builder)
            kk = context.cast(builder, args[1], sig.args[1], nbtypes.intp)
            shape0, shape1 = cgutils.unpack_tuple(builder, src.shape, 2)
            data, size, stride = view(builder, src.data, shape0, shape1, src.itemsize, kk)
            intp = context.get_value_type(nbtypes.intp)
            context.populate_array(
                dst,
                data=data,
                shape=cgutils.pack_array(builder, [size], ty=intp),
                strides=cgutils.pack_array(builder, [stride], ty=intp),
                itemsize=src.itemsize,
                meminfo=cgutils.get_null_value(dst.meminfo.type),
                parent=cgutils.get_null_value(dst.parent.type),
            )
            return dst._getvalue()

        return arr.copy(ndim=1, layout=layout)(arr, k), codegen

    return row_major_view


def lane_column_intrinsic() -> Any:
    """A numba intrinsic ``column(a, l)``: the unmanaged 1-D view ``a[:, l]`` of a 2-D
    C-contiguous array, its data pointer ``&a[0, l]`` computed by a plain GEP.

    numba's own ``a[:, l]`` computes the view's start in branches (negative and empty
    slices) and by integer arithmetic on the pointer; inside a loop over ``l`` LLVM then
    cannot see that lane l + 1's ``x[i]`` lies next to lane l's, and its loop vectorizer
    loads every plant state and parameter with a gather (on AMD Zen 4, ~20 cycles per 8
    doubles).  With the GEP the loads are plain vector loads.  No bounds check (``l`` is
    a lane index, ``0 <= l < a.shape[1]``) and no reference count (see
    :func:`unmanaged_intrinsic`).
    """

    def column(builder: Any, data: Any, n_rows: Any, n_cols: Any, item: Any, lane: Any) -> Any:
        return builder.gep(data, [lane], inbounds=True), n_rows, builder.mul(n_cols, item)

    return _row_major_view_intrinsic("A", column)


def leading_rows_intrinsic() -> Any:
    """A numba intrinsic ``leading_rows(a, n)``: the unmanaged 1-D view of the first ``n``
    rows of a 2-D C-contiguous array, flat (row i, column l at ``i * a.shape[1] + l``).

    The same view as ``a[:n].reshape(n * a.shape[1])`` without numba's run-time reshape
    (a library call per use, ~2 % of a lane kernel's time).  No bounds check
    (``0 <= n <= a.shape[0]``) and no reference count (see :func:`unmanaged_intrinsic`).
    """

    def rows(builder: Any, data: Any, n_rows: Any, n_cols: Any, item: Any, n: Any) -> Any:
        return data, builder.mul(n, n_cols), item

    return _row_major_view_intrinsic("C", rows)
