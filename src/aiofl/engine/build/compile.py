"""The compile factory: one way to turn the engine's templates into a compiled, cached kernel.

Every kernel instance of the engine (the lane kernels, continuous or sampled, at each lane
width; the one-member kernels; the diagnostic kernel) is described by a :class:`Recipe`:

- ``bindings``, the globals its templates are compiled with (the plant's compiled
  functions, the sizes, the controller's component functions, layout constants, array-view
  intrinsics);
- ``templates``, plain Python functions compiled into that namespace under the global name
  the others call them by, each with its numba options (:class:`Template`);
- ``entry``, the template a caller runs (the time loop), cached on disk; ``also_cached``
  names further templates a caller runs directly (the discrete controller's setup, start
  and step), cached the same way;
- ``sources``, the files its compiled code comes from, and the ``plant`` it runs.

:func:`build` compiles a recipe.  The entry is cached under a **fingerprint** of everything
the compiled code depends on (:func:`fingerprint`: Python, numba and llvmlite versions, the
recipe's kind, every template's options, the path in the package and the text of every
source file, and the plant's functions by their code and the values they read,
:mod:`aiofl.engine.build.code_fingerprint`),
in ``<cache root>/kernels`` (:mod:`aiofl.cache`): numba's index and data files of a kernel
carry the plant's key and the fingerprint in their name, and the fingerprint is also
numba's freshness stamp of the entry, so a kernel is loaded only if it was compiled from
exactly this code.  When a plant's kernel is stored under a new fingerprint, the entries of
its older fingerprints are deleted (:func:`prune_kernels`).  A plant function that cannot
be fingerprinted (it reads a global, or closes over a value, of a type the fingerprint
cannot describe) makes the kernel uncacheable: it is compiled in every process.  A source
file edited on disk after this process loaded it would make the fingerprint describe code
numba is not compiling, so such a kernel is not cached either (:func:`sources_changed`).

Every cache file of a kernel is sealed (size and SHA-256 header) and a damaged entry is
removed and compiled again with one warning (:mod:`aiofl.engine.build.kernel_cache`).

:func:`rejit` is the one helper that re-compiles a compiled function's Python code with
other globals or options (private, uncached copies of the component functions; the plant
functions compiled for the lanes).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import sys
import types
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from aiofl.cache import subdir
from aiofl.engine.build import kernel_cache
from aiofl.engine.build.code_fingerprint import file_digest, function_fingerprint, source_digest
from aiofl.engine.build.kernel_cache import CheckedCacheFile, DamagedEntry, KernelCache
from aiofl.numba_patches import key_helpers_by_fastmath, patch_source
from aiofl.plants.base import Plant

__all__ = [
    "NO_PLANT_KEY",
    "CheckedCacheFile",
    "DamagedEntry",
    "Instance",
    "KernelCache",
    "Recipe",
    "Template",
    "build",
    "compile_lock",
    "fingerprint",
    "function_fingerprint",
    "has_kernel",
    "plant_key",
    "prune_kernels",
    "rejit",
    "share_scope_when_inlining",
    "source_digest",
    "sources_changed",
    "template_globals",
    "unbound_placeholders",
]

NO_PLANT_KEY = "noplant"
"""The plant key in the cache names of a recipe without a plant (a plant-independent
instance, the discrete controller's update)."""

PLANT_FUNCTIONS = ("f", "g", "h", "bd", "normal_form", "alpha_beta_of_xi")
"""The plant's functions a kernel may call, in the order of ``Plant.compiled``."""


@dataclass(frozen=True)
class Template:
    """A template: plain Python that reads its collaborators as globals.

    Attributes
    ----------
    name
        The global name the other templates call it by (``"_DERIV"``); for the entry, the
        name of the compiled function a caller gets.
    function
        The Python function whose code is compiled.
    options
        numba ``njit`` options (``inline``, ``fastmath``, ``error_model``, ``nogil``...).
    bindings
        Globals of this template alone, over the recipe's (a template compiled several
        times with different collaborators, such as one entry per plant function); it
        sees the recipe's templates compiled before it.
    """

    name: str
    function: Callable[..., Any]
    options: Mapping[str, Any] = field(default_factory=dict)
    bindings: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Recipe:
    """Everything that makes one compiled kernel instance (see the module notes).

    Attributes
    ----------
    kind
        The instance's name, file-name safe (``"w32"``: continuous lanes of 32; ``"s1"``:
        sampled, one lane; ``"scalar"``...).  Part of the fingerprint and the cache name.
    plant
        The plant the kernel runs (None: a kernel without a plant).
    bindings
        Globals of every template.
    templates
        Compiled into the namespace before the entry, under their names.
    entry
        The function the caller runs, cached on disk.
    sources
        The files whose text the compiled code comes from (besides the plant's functions).
    also_cached
        Names of templates that callers run directly too (besides the entry): cached on
        disk under the same fingerprint, each in its own files.
    """

    kind: str
    plant: Plant | None
    bindings: Mapping[str, Any]
    templates: tuple[Template, ...]
    entry: Template
    sources: tuple[str, ...]
    also_cached: tuple[str, ...] = ()


@dataclass(frozen=True)
class Instance:
    """A built recipe: the compiled ``entry``, the namespace it was compiled in, and
    whether it is cached on disk (under ``fingerprint``)."""

    entry: Any
    namespace: dict[str, Any]
    cached: bool
    fingerprint: str | None


# ------------------------------------------------------------------------ fingerprints
def sources_changed(paths: tuple[str, ...] | list[str]) -> bool:
    """Whether a file of ``paths`` changed on disk since this process first digested it
    (another process editing the tree): a kernel compiled now must not be cached under a
    fingerprint of either text."""
    for path in paths:
        first = source_digest(path)
        try:
            if file_digest(path) != first:
                return True
        except OSError:
            return True
    return False


def plant_key(plant: Plant) -> str:
    """A short digest of a plant's identity (name, size, function names): stable across
    edits of its code, so the cache entries of one plant can be found and pruned."""
    ident = "|".join(
        [plant.name, str(plant.n_states)]
        + [getattr(getattr(plant, k), "__qualname__", "-") for k in ("f", "g", "h", "bd")]
    )
    return hashlib.sha256(ident.encode()).hexdigest()[:8]


def plant_tag(plant: Plant) -> str:
    """A name suffix unique to a plant's code (its key and a digest of its functions'
    fingerprints, or of its identity when they cannot be fingerprinted).

    Functions compiled from a template with a plant's functions bound (the per-member setup,
    the discrete update with the model's α, β) carry it in their names: numba names a
    compiled function's symbol after its qualified name, and two kernels in one process
    whose callees share a symbol name can be linked to the same one (a kernel loaded from
    the disk cache then called another plant's discrete update)."""
    parts = _plant_parts(plant) or [f"id{id(plant)}"]
    digest = hashlib.sha256("|".join(parts).encode()).hexdigest()[:12]
    return f"{plant_key(plant)}_{digest}"


def _plant_parts(plant: Plant | None) -> list[str] | None:
    if plant is None:
        return ["no plant"]
    parts = [f"n={plant.n_states}", f"n_p={len(plant.params)}"]
    for fname in PLANT_FUNCTIONS:
        fn = getattr(plant, fname)
        if fn is None:
            parts.append(f"{fname}=None")
            continue
        fp = function_fingerprint(fn)
        if fp is None:
            return None
        parts.append(f"{fname}={fp}")
    return parts


def _canonical_repr(value: Any) -> str:
    """``repr`` that is the same in every process: a set's (or a mapping's) items sorted,
    since the iteration order of a set of strings changes with Python's hash seed (the
    fast-math flags are a set; their plain ``repr`` gave the scalar kernels a new
    fingerprint in every process, so they were never loaded from the cache)."""
    if isinstance(value, set | frozenset):
        return "{" + ", ".join(sorted(_canonical_repr(v) for v in value)) + "}"
    if isinstance(value, Mapping):
        items = sorted((repr(k), _canonical_repr(v)) for k, v in value.items())
        return "{" + ", ".join(f"{k}: {v}" for k, v in items) + "}"
    if isinstance(value, list | tuple):
        return type(value).__name__ + "(" + ", ".join(_canonical_repr(v) for v in value) + ")"
    return repr(value)


_PACKAGE_ROOT = Path(__file__).resolve().parents[2]
"""The aiofl package's folder (``src/aiofl``)."""


def _source_name(path: str) -> str:
    """A source file as the fingerprint names it: its path inside the aiofl package
    (``engine/kernel/loop.py``: a template moved to another folder makes new kernels, as
    numba's cached code names its module by it), else its file name; the same in every
    checkout, so checkouts of one code share the cache."""
    try:
        return Path(path).resolve().relative_to(_PACKAGE_ROOT).as_posix()
    except ValueError:
        return os.path.basename(path)


def fingerprint(recipe: Recipe) -> str | None:
    """A digest of everything ``recipe``'s compiled code depends on (see the module
    notes), or None if a plant function cannot be fingerprinted."""
    import llvmlite
    import numba

    plant_parts = _plant_parts(recipe.plant)
    if plant_parts is None:
        return None
    parts = [sys.version, numba.__version__, llvmlite.__version__, recipe.kind]
    parts.append(f"sealed cache files {kernel_cache.FORMAT}")
    for tpl in (*recipe.templates, recipe.entry):
        opts = sorted((k, _canonical_repr(v)) for k, v in tpl.options.items())
        parts.append(f"{tpl.name}:{tpl.function.__name__}:{opts}")
    parts += [f"{_source_name(p)}={source_digest(p)}" for p in recipe.sources]
    parts += plant_parts
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()[:20]


# ---------------------------------------------------------------------------- compiling
def copy_function(
    fn: Callable[..., Any],
    space: dict[str, Any],
    qualname: str | None = None,
    name: str | None = None,
) -> types.FunctionType:
    """A copy of the Python function ``fn`` whose globals are ``space`` (named ``name``,
    default ``fn``'s).

    Parameters
    ----------
    fn
        The function.
    space
        The copy's globals.
    qualname, name
        The copy's qualified name and name (None: ``fn``'s).

    Returns
    -------
    types.FunctionType
    """
    name = name or fn.__name__
    py = types.FunctionType(fn.__code__, space, name, fn.__defaults__, fn.__closure__)
    py.__qualname__ = qualname or fn.__qualname__
    py.__doc__ = fn.__doc__
    if "__name__" not in space:  # still the template of its module (its PLACEHOLDERS)
        py.__module__ = fn.__module__
    return py


def _names_read(code: types.CodeType) -> set[str]:
    """The global (and attribute) names ``code`` and the code objects nested in it read."""
    names: set[str] = set()
    stack = [code]
    while stack:
        c = stack.pop()
        names.update(c.co_names)
        stack += [k for k in c.co_consts if isinstance(k, types.CodeType)]
    return names


def template_globals(*modules: types.ModuleType) -> dict[str, Any]:
    """The globals of template modules (later ones over earlier ones) without their
    placeholders' stand-ins: what a recipe starts from and binds the placeholders into.

    Parameters
    ----------
    *modules
        The template modules (:mod:`aiofl.engine.kernel`).

    Returns
    -------
    dict
    """
    out: dict[str, Any] = {}
    for mod in modules:
        out.update(vars(mod))
    for mod in modules:
        for name in getattr(mod, "PLACEHOLDERS", ()):
            out.pop(name, None)
    return out


def unbound_placeholders(tpl: Callable[..., Any], space: Mapping[str, Any]) -> list[str]:
    """The placeholders of ``tpl``'s module (its ``PLACEHOLDERS``, see
    :mod:`aiofl.engine.kernel`) that the template reads and ``space`` does not bind.

    Parameters
    ----------
    tpl
        The template (a Python function).
    space
        The globals it is to be compiled with.

    Returns
    -------
    list of str
    """
    declared = getattr(sys.modules.get(tpl.__module__ or ""), "PLACEHOLDERS", ())
    read = _names_read(tpl.__code__)
    return sorted(n for n in declared if n in read and n not in space)


def _refuse_unbound(tpl: Callable[..., Any], space: Mapping[str, Any], what: str) -> None:
    """Raise ValueError if ``tpl`` reads a placeholder ``space`` does not bind."""
    missing = unbound_placeholders(tpl, space)
    if missing:
        raise ValueError(
            f"{what}: template {tpl.__name__} of {tpl.__module__} reads the placeholder(s) "
            f"{', '.join(missing)}, which its recipe does not bind (that module's placeholder "
            "block says what fills them)"
        )


def instantiate(
    tpl: Callable[..., Any],
    ns: dict[str, Any],
    suffix: str,
    *,
    check_placeholders: bool = True,
    **options: Any,
) -> Any:
    """Template ``tpl`` as a numba function (compiled lazily) with the globals ``ns``; its
    qualified name carries ``suffix`` (the instance's kind, plant key and fingerprint).
    A placeholder of its module that it reads and ``ns`` does not bind is a ValueError
    naming it (:func:`unbound_placeholders`).

    Parameters
    ----------
    tpl
        The template (a Python function).
    ns
        Its globals.
    suffix
        Appended to its qualified name.
    check_placeholders
        Refuse a template that reads a placeholder ``ns`` does not bind (False: the
        caller checks, :func:`build`).
    **options
        numba's ``njit`` options.

    Returns
    -------
    numba dispatcher
    """
    from numba import njit

    if check_placeholders:
        _refuse_unbound(tpl, ns, f"{tpl.__name__}_{suffix}")
    return njit(**options)(copy_function(tpl, ns, f"{tpl.__name__}_{suffix}"))


def rejit(fn: Any, space: dict[str, Any] | None = None, **override: Any) -> Any:
    """A private, uncached copy of the compiled (or plain) function ``fn``: its Python code
    with the globals ``space`` (default its own) and its numba options updated by
    ``override``.  numba keys a function's disk cache on its own file only, so a kernel
    never links a cached function (whose callees might be stale); see
    :func:`aiofl.engine.build.bindings.private_components`.

    Parameters
    ----------
    fn
        The function (compiled or plain).
    space
        The globals (None: its own).
    **override
        numba options to change.

    Returns
    -------
    numba dispatcher
    """
    from numba import njit

    py = getattr(fn, "py_func", fn)
    opts = {k: v for k, v in getattr(fn, "targetoptions", {}).items() if k != "nopython"}
    opts.update(override)
    locals_ = dict(getattr(fn, "locals", {}))
    return njit(locals=locals_, **opts)(copy_function(py, space or py.__globals__))


def build(recipe: Recipe, *, cache: bool = True) -> Instance:
    """Compile ``recipe`` (lazily: numba compiles on the first call, or loads the cached
    entry) and cache its entry on disk when possible (see the module notes)."""
    share_scope_when_inlining()
    fp = fingerprint(recipe) if cache else None
    folder = subdir("kernels") if fp is not None else None
    if folder is not None and sources_changed(recipe.sources):
        folder = None
    prefix = kernel_prefix(recipe.kind, recipe.plant)
    suffix = f"{prefix}{fp}" if folder is not None else f"{recipe.kind}_{id(recipe):x}"
    unknown = set(recipe.also_cached) - {tpl.name for tpl in recipe.templates}
    if unknown:
        raise ValueError(f"also_cached names no template of the recipe: {sorted(unknown)}")
    ns = dict(recipe.bindings)
    spaces = []
    for tpl in (*recipe.templates, recipe.entry):  # each sees those compiled before it
        space = {**ns, **tpl.bindings} if tpl.bindings else ns
        spaces.append(space)
        ns[tpl.name] = instantiate(
            tpl.function, space, suffix, check_placeholders=False, **tpl.options
        )
    # every placeholder a template reads bound, by the recipe or by a template (numba reads
    # a global when it compiles, so a template may call one built after it)
    for tpl, space in zip((*recipe.templates, recipe.entry), spaces, strict=True):
        _refuse_unbound(tpl.function, space, f"recipe {recipe.kind!r}")
    entry = ns[recipe.entry.name]
    if folder is not None:
        cached = [recipe.entry, *(t for t in recipe.templates if t.name in recipe.also_cached)]
        for tpl in cached:
            fn = ns[tpl.name]
            fn._cache = KernelCache.for_function(fn.py_func, folder, fp)
            prune_kernels(folder, tpl.function, prefix, fp)
    return Instance(entry=entry, namespace=ns, cached=folder is not None, fingerprint=fp)


# ------------------------------------------------------------ numba's IR inlining, faster
_INLINING_PATCHED: list[bool] = []
_INLINE_COPY_OLD = """\
        for block_label, block in the_ir.blocks.items():
            new_block = copy.deepcopy(the_ir.blocks[block_label])
"""
_INLINE_COPY_NEW = """\
        memo = {}  # one memo for the whole IR (aiofl.engine.build.compile)
        for block_label, block in the_ir.blocks.items():
            new_block = copy.deepcopy(the_ir.blocks[block_label], memo)
"""


def share_scope_when_inlining() -> bool:
    """Make numba's IR inlining copy a callee's blocks with one ``deepcopy`` memo.

    ``inline="always"`` (how the lane instances put the plant's and the components'
    functions into each lane block) copies the callee's IR at every call site, block by
    block, each with a fresh memo: every block's copy then deep-copies the whole shared
    variable scope again (``ir.Var.__deepcopy__`` copies its scope), so the copy grows
    like blocks × variables; it was half of a lane instance's compile time.  With one memo
    for all blocks of a copy, the scope is copied once and shared by the copied blocks, as
    it is by the original ones: a cold compile of a lane instance takes about a third less
    time, with the same numbers bit for bit (``docs/benchmarks.md``).

    The change is applied once per process, to numba's ``InlineWorker.inline_ir`` by
    re-compiling its source with the two lines above replaced; if the source is not the
    one this was written for (another numba version), nothing is changed.  Returns whether
    the faster copy is in place.  Applied by :func:`build`, which thereby also makes sure
    of :func:`aiofl.numba_patches.key_helpers_by_fastmath` (in place already once any
    component module is imported).
    """
    if not _INLINING_PATCHED:
        from numba.core import inline_closurecall as ic

        ok = patch_source(ic.InlineWorker, "inline_ir", ic, _INLINE_COPY_OLD, _INLINE_COPY_NEW)
        _INLINING_PATCHED.append(ok)
    key_helpers_by_fastmath()
    return _INLINING_PATCHED[0]


@contextlib.contextmanager
def compile_lock(entry: Any) -> Iterator[None]:
    """Hold an exclusive lock on ``entry``'s cache entry while it is compiled, so that
    processes needing the same kernel at once compile it once: the others wait, then load
    it from the disk cache (numba looks there first).  No lock for an uncached entry, or
    where ``fcntl`` (POSIX) is missing."""
    cache = getattr(entry, "_cache", None)
    impl = getattr(cache, "_impl", None)
    folder = getattr(cache, "_cache_path", None)
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        fcntl = None  # type: ignore[assignment]
    if impl is None or not folder or fcntl is None:
        yield
        return
    path = os.path.join(folder, f"{impl.filename_base}.lock")
    try:
        fh = open(path, "a+b")  # noqa: SIM115 - held across the yield
    except OSError:
        yield
        return
    try:
        fcntl.flock(fh, fcntl.LOCK_EX)
        yield
    finally:
        fh.close()  # releases the lock


def _cache_file_start(template: Callable[..., Any], prefix: str) -> str:
    """How the names of the cache files of ``template``'s instances named ``prefix`` start
    (numba's ``<module stem>.<function name>``, the function being ``template`` renamed
    with the instance's suffix, :func:`build`)."""
    stem = os.path.splitext(os.path.basename(template.__code__.co_filename))[0]
    return f"{stem}.{template.__name__}_{prefix}"


def kernel_prefix(kind: str, plant: Plant | None) -> str:
    """How the names of a recipe's cached kernels start, before the fingerprint: its kind
    and the plant's key (:data:`NO_PLANT_KEY` for a plant-independent instance)."""
    return f"{kind}_{plant_key(plant) if plant is not None else NO_PLANT_KEY}_"


def kernel_at_hand(recipe: Recipe) -> bool:
    """Whether ``recipe``'s entry costs this process no compile beyond a load: stored in the
    kernel folder under the fingerprint of today's code, or being compiled into it now by
    another process (:func:`being_compiled`; waiting for its lock, this one loads it)."""
    folder = subdir("kernels")
    fp = fingerprint(recipe)
    if folder is None or fp is None or sources_changed(recipe.sources):
        return False
    name = kernel_prefix(recipe.kind, recipe.plant) + fp
    entry = recipe.entry.function
    return has_kernel(folder, entry, name) or being_compiled(folder, entry, name)


def has_kernel(folder: Path, template: Callable[..., Any], prefix: str) -> bool:
    """Whether ``folder`` holds an index file of an instance of ``template`` named
    ``prefix`` (kind and plant key, :func:`build`), of any fingerprint: a look at file
    names that compiles and loads nothing (a file of an older fingerprint counts too).

    Parameters
    ----------
    folder
        The kernel cache's folder.
    template
        The instance's template.
    prefix
        Its name (kind and plant key).

    Returns
    -------
    bool
    """
    start = _cache_file_start(template, prefix)
    with contextlib.suppress(OSError):
        return any(e.name.startswith(start) and e.name.endswith(".nbi") for e in os.scandir(folder))
    return False


def being_compiled(folder: Path, template: Callable[..., Any], prefix: str) -> bool:
    """Whether another process holds the compile lock (:func:`compile_lock`) of an instance
    of ``template`` named ``prefix`` in ``folder``: it is compiling that kernel now, and a
    caller that waits for the lock loads it.

    Parameters
    ----------
    folder, template, prefix
        As for :func:`has_kernel`.

    Returns
    -------
    bool
    """
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        return False
    start = _cache_file_start(template, prefix)
    with contextlib.suppress(OSError):
        for entry in os.scandir(folder):
            if not (entry.name.startswith(start) and entry.name.endswith(".lock")):
                continue
            with open(entry.path, "a+b") as fh:
                try:
                    fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except BlockingIOError:
                    return True
                fcntl.flock(fh, fcntl.LOCK_UN)
    return False


def prune_kernels(folder: Path, template: Callable[..., Any], prefix: str, keep: str) -> None:
    """Delete the cache files of ``template``'s instances named ``prefix`` + a fingerprint
    other than ``keep`` (the same plant and kind compiled from older code).

    Parameters
    ----------
    folder, template, prefix
        As for :func:`has_kernel`.
    keep
        The fingerprint whose files are kept.
    """
    start = _cache_file_start(template, prefix)
    with contextlib.suppress(OSError):
        for entry in os.scandir(folder):
            if entry.name.startswith(start) and not entry.name.startswith(start + keep):
                with contextlib.suppress(OSError):  # another process may have removed it
                    os.remove(entry.path)
