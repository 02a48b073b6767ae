"""Corrections to numba, made by re-compiling one of its functions from its own source.

numba compiles every kernel of :mod:`aiofl.engine` and every component of
:mod:`aiofl.components`.  :func:`patch_source` replaces a numba method by its own source
with a line or two changed (if the source is not the one a patch was written for, another
numba version, nothing is changed and the patch reports False).  Two patches use it:

- :func:`key_helpers_by_fastmath` (here): the helpers numba compiles while lowering are
  cached per set of fast-math flags, so a function's code does not depend on what the
  process compiled before it; applied when :mod:`aiofl.components.fastmath` is imported,
  i.e. before any component or kernel is compiled;
- :func:`aiofl.engine.build.compile.share_scope_when_inlining`: numba's IR inliner copies a
  callee with one memo (compile time only; applied by the engine's compile factory).
"""

from __future__ import annotations

import types
from collections.abc import Mapping
from typing import Any

__all__ = ["fastmath_key", "key_helpers_by_fastmath", "patch_source"]

_HELPERS_KEYED: list[bool] = []
_HELPER_KEY_OLD = "cache_key = (impl.__code__, sig, type(self.error_model))\n"
_HELPER_KEY_NEW = (
    "cache_key = (impl.__code__, sig, type(self.error_model), fastmath_key(self))  # aiofl\n"
)


def fastmath_key(context: Any) -> Any:
    """A target context's fast-math flags as a hashable value (a set of LLVM flags, or a
    bool; numba's ``FastMathOptions`` holds the set in ``flags``)."""
    fm = getattr(context, "fastmath", False)
    flags = getattr(fm, "flags", fm)
    return frozenset(flags) if isinstance(flags, (set, frozenset)) else bool(flags)


def key_helpers_by_fastmath() -> bool:
    """Make numba compile its lowering helpers once per set of fast-math flags.

    While lowering, numba compiles small helper functions (``x ** 3`` by repeated
    multiplication, and the like; ``BaseContext.compile_subroutine``) and keeps them in one
    cache per target, keyed by the helper's code, signature and error model, but **not** by
    the fast-math flags of the function being compiled: the first function to need a
    helper fixes its flags for every later one.  So a kernel's code depended on what the
    process had compiled before it: with ``x ** 2`` in the plant's α, β, the discrete
    controller's update (fast-math) got strict multiplications after a strict plant
    function, fast-math ones otherwise, its numbers differed in the last bit, and the
    sampled loop's finite-difference linearisation of the model-assisted designs moved by
    1e-9 relative (their spectral radii in ``sampling.json``); a strict lane instance
    compiled after a fast-math one could link fast-math multiplications.  This adds the
    flags to the key (numba's ``compile_subroutine`` re-compiled from its source with that
    one line changed; if the source is not the one this was written for, nothing is
    changed).  Applied once per process; returns whether it is in place.
    """
    if not _HELPERS_KEYED:
        from numba.core import base

        extra = {"fastmath_key": fastmath_key}
        ok = patch_source(
            base.BaseContext, "compile_subroutine", base, _HELPER_KEY_OLD, _HELPER_KEY_NEW, extra
        )
        _HELPERS_KEYED.append(ok)
    return _HELPERS_KEYED[0]


def patch_source(
    owner: type,
    name: str,
    module: types.ModuleType,
    old: str,
    new: str,
    extra: Mapping[str, Any] | None = None,
) -> bool:
    """Replace method ``name`` of numba's class ``owner`` by its own source (from
    ``module``) with the text ``old`` (present exactly once) replaced by ``new``, compiled
    in the module's globals plus ``extra``; False (nothing changed) when the source is not
    available or not the expected one.

    Parameters
    ----------
    owner
        The numba class.
    name
        The method.
    module
        The module it is defined in (its globals).
    old, new
        The text replaced, and its replacement.
    extra
        More globals (None: none).

    Returns
    -------
    bool
        Whether the method was replaced.
    """
    import inspect
    import textwrap

    try:
        src = textwrap.dedent(inspect.getsource(getattr(owner, name)))
        if src.count(old) != 1:
            return False
        space = {**vars(module), **(extra or {})}
        exec(compile(src.replace(old, new), module.__file__ or name, "exec"), space)
        setattr(owner, name, space[name])
    except (OSError, TypeError, SyntaxError):  # pragma: no cover - source unavailable
        return False
    return True
