"""aiofl.numba_patches: numba's lowering helpers compiled per set of fast-math flags."""

from __future__ import annotations

import types

import numpy as np
from numba import njit

import aiofl.components.fastmath  # noqa: F401 - importing a component applies the patch
from aiofl import numba_patches


def _powers(x):
    return x**7 + x**5


def _copy(fn, name):
    return types.FunctionType(fn.__code__, dict(fn.__globals__), name)


def test_a_strict_function_never_links_a_helper_compiled_under_fast_math():
    """``x ** 7`` lowers through a helper numba caches per target (repeated
    multiplication).  Compiled first for a fast-math function, the helper used to be
    linked into a strict one too (its multiplications ``fmul fast``), so a function's code
    depended on what the process had compiled before it; now the strict function gets a
    strict helper."""
    assert numba_patches.key_helpers_by_fastmath()  # the pinned numba's source matched
    fast = njit(fastmath=True)(_copy(_powers, "fast_powers"))
    strict = njit(_copy(_powers, "strict_powers"))
    x = np.float32(1.1)
    fast(x)  # the fast-math helpers first
    strict(x)
    ir = next(iter(strict.inspect_llvm().values()))
    assert "fmul float" in ir
    assert "fmul fast" not in ir and "reassoc" not in ir
    fast_ir = next(iter(fast.inspect_llvm().values()))
    assert "fmul fast" in fast_ir or "reassoc" in fast_ir


def test_fastmath_keys():
    class Ctx:
        fastmath = types.SimpleNamespace(flags={"nsz", "arcp"})

    assert numba_patches.fastmath_key(Ctx()) == frozenset({"nsz", "arcp"})
    assert numba_patches.fastmath_key(object()) is False
    assert numba_patches.patch_source(int, "bit_length", types, "x", "y") is False
