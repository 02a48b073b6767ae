"""A plant's compiled kernel: building it from the templates, caching it, running its members.

:func:`kernel_for` builds the one-member kernel of a plant (:func:`scalar_recipe`, compiled
by the factory of :mod:`aiofl.engine.compile`): the templates of :mod:`aiofl.engine.kernel`
compiled in a namespace (a copy of that module's globals) that binds the plant's compiled
f, g, h, b_d and normal form, its sizes and private copies of the controller's component
functions (:func:`private_components`); this module also provides those bindings to the
lane kernels (:mod:`aiofl.engine.lanes_build`).  Every kernel whose plant functions come
from a source file (built-in plants, plant files, user plants defined in a module or
script) is cached on disk under a fingerprint of all the code it is compiled from, so later
processes load it instead of compiling; ``AIOFL_NO_CACHE=1`` disables the cache
(:mod:`aiofl.cache`).

:func:`run_members` runs a batch on ``numba.get_num_threads()`` threads: the compiled member
function releases the GIL and each thread claims the next unclaimed member, so a member that
diverges early frees its core at once.  Members are independent, so a member's numbers do
not depend on the batch it is in, the thread count or the scheduling (bitwise).

**User plants that fail.**  A plant whose functions are defined outside aiofl is
type-checked (:meth:`aiofl.plants.base.Plant.typecheck`) before its kernel is compiled
when the kernel is not loaded from the disk cache, and again whenever compiling the kernel
fails, so a function numba cannot compile, or one that returns complex numbers, is a
:class:`~aiofl.plants.base.PlantError` naming the plant and the function, not a numba
traceback; a failure not caused by a plant function stays a traceback.  At run time a
division by zero or a math domain error in a plant function gives inf/NaN (numba's
``numpy`` error model), which the kernel reports as the member diverging at that time.  A
plant function that *raises* stops the run: :func:`run_members` then replays that member
once in a diagnostic kernel whose plant functions are wrapped to report which of them
raised and at which state (:class:`PlantFailure`), and raises a PlantError
``plant function f failed at state x = [...]: ValueError: ...``.
"""

from __future__ import annotations

import itertools
import sys
import threading
import types
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from aiofl import layout as L
from aiofl.cache import cache_enabled
from aiofl.engine import compile as compile_
from aiofl.engine import kernel, views
from aiofl.engine.compile import PLANT_FUNCTIONS
from aiofl.plants.base import Plant, PlantError

if TYPE_CHECKING:  # pragma: no cover
    import numpy as np
    from numpy.typing import NDArray

__all__ = ["Kernel", "PlantFailure", "kernel_for", "run_members"]


class PlantFailure(Exception):
    """Raised inside a diagnostic kernel by a plant function that raised:
    ``(index into PLANT_FUNCTIONS, x_1, ..., x_n)``."""


@dataclass(frozen=True)
class Kernel:
    """The compiled functions of one plant."""

    member: Any  # integrates one member of a batch (releases the GIL)
    evaluate: Any  # one F(t, z) evaluation (compiled lazily by closed_loop_rhs)
    n_cols: int
    cached: bool


_KERNELS: dict[int, tuple[Plant, Kernel]] = {}
_KERNELS_LOCK = threading.Lock()
_PRIVATE_LOCK = threading.Lock()
_PLANT_OF_MEMBER: dict[int, Plant] = {}  # id(kernel.member) -> its plant, for diagnosis
_GROUP_FUNCTIONS: set[int] = set()  # ids of lane-kernel group functions among those


def register_group_function(group: Any, plant: Plant) -> None:
    """Record that ``group`` (a lane kernel's group function, :mod:`aiofl.engine.lanes`)
    runs ``plant``: a failure in it is explained member by member like a scalar member's
    (:func:`run_members`); its first argument after the group index is the groups table."""
    _PLANT_OF_MEMBER[id(group)] = plant
    _GROUP_FUNCTIONS.add(id(group))


def _user_functions(plant: Plant) -> bool:
    """Whether any plant function is defined outside aiofl (aiofl's own are tested)."""
    for fname in PLANT_FUNCTIONS:
        fn = getattr(plant, fname)
        mod = getattr(getattr(fn, "py_func", fn), "__module__", None) or ""
        if fn is not None and not mod.startswith("aiofl."):
            return True
    return False


def engine_sources() -> tuple[str, ...]:
    """The files every kernel's code comes from besides the plant's: the layout, the
    scalar templates, this module, the compile factory, the array views, the plant
    interface (its functions' compile flags) and the component modules."""
    base = sys.modules[Plant.__module__]
    here = sys.modules[__name__]
    mods = (L, kernel, here, compile_, views, base, *_component_modules())
    return tuple(m.__file__ for m in mods)


def _component_modules() -> tuple[Any, ...]:
    """The modules whose compiled functions the kernels call (their sources are part of the
    kernels' cache fingerprint; ``discrete``'s are called by the sampled loops)."""
    from aiofl.components import differentiators, discrete, fastmath, feedback, law, observers

    return fastmath, feedback, observers, differentiators, law, discrete


def component_functions(variant: str = "scalar") -> dict[str, Any]:
    """The controller's component functions, by the global name the templates use: the
    process's private, uncached copies (see :func:`private_components`)."""
    private = private_components(variant)
    fb, law, ob, td = (private[m] for m in ("feedback", "law", "observers", "differentiators"))
    return {
        "_HAN_TD": td.han_td_rhs,
        "_ITD": td.improved_td_rhs_scaled,
        "_ITD_CONSTANTS": td.improved_td_constants,
        "_PREFILTER": td.linear_prefilter_update,
        "_PREFILTER_COEF": td.linear_prefilter_coefficient,
        "_FAL": fb.fal_scaled,
        "_FAL_SLOPE": fb.fal_inner_slope,
        "_FAL_POWER_NEEDED": fb.fal_power_needed,
        "_FAL_LINEAR": fb.fal_linear,
        "_INLSEF_TERM": fb.inlsef_term,
        "_INLSEF_LIMIT": fb.inlsef_limit,
        "_LINEAR_SEF": fb.linear_sef,
        "_LINEAR_SEF_GAIN": fb.linear_sef_gain,
        "_ESO_GAIN": ob.eso_gain,
        "_ESO_UPDATE": ob.eso_update,
        "_INLESO": ob.inleso_injection,
        "_AIOFL_LAW": law.aiofl_law,
        "_IOFL_LAW": law.iofl_law,
        "_SATURATE": law.saturate_range,
    }


_PRIVATE: dict[str, dict[str, types.ModuleType]] = {}


def private_components(variant: str = "scalar") -> dict[str, types.ModuleType]:
    """Uncached copies of the component modules' compiled functions, built once per process.

    The component functions are compiled with ``cache=True``, and numba keys each one's
    on-disk cache on *its own* source file only: ``feedback.linear_sef_gain`` cached before
    an edit of :func:`aiofl.components.fastmath.binomial_power` (or of ``FASTMATH``) is
    loaded unchanged after it, with the old callee's code linked in.  A kernel compiled
    against it would be stored under the *new* fingerprint (which covers fastmath.py) and
    differ from a fresh compile of the same source.  So the kernel never links the cached
    component functions: each is re-compiled from its Python function, without ``cache``
    and with its other options (fast-math flags, error model, inlining), in a copy of its
    module's globals whose compiled functions are these copies too.  Returns one stand-in
    module per component module (by short name), holding its copied functions.

    ``variant = "lanes"`` builds the copies the lane kernel (:mod:`aiofl.engine.lanes`)
    links: every function inlined where called and ``np.exp``/``np.log``/``np.sin``/
    ``np.cos`` rebound to the branch-free :mod:`aiofl.components.vecmath` functions
    (:func:`vector_math_globals`), so a loop over lanes that calls them vectorizes, and the
    lane kernel's fast-math flags (:data:`aiofl.engine.lanes.LANE_FASTMATH`).
    """
    with _PRIVATE_LOCK:
        if variant in _PRIVATE:
            return _PRIVATE[variant]
        from numba.core.dispatcher import Dispatcher

        from aiofl.engine.lanes import LANE_FASTMATH

        lanes = variant == "lanes"
        mods = _component_modules()
        copies: dict[int, Any] = {}  # id(original dispatcher) -> uncached copy
        spaces: list[dict[str, Any]] = []
        for mod in mods:
            space = vector_math_globals(vars(mod)) if lanes else dict(vars(mod))
            spaces.append(space)
            for obj in vars(mod).values():
                if isinstance(obj, Dispatcher) and obj.py_func.__module__ == mod.__name__:
                    extra = {"inline": "always", "fastmath": LANE_FASTMATH} if lanes else {}
                    copies[id(obj)] = compile_.rejit(obj, space, **extra)
        for space in spaces:  # calls between components go to the copies too
            for name, obj in list(space.items()):
                if id(obj) in copies:
                    space[name] = copies[id(obj)]
        out: dict[str, types.ModuleType] = {}
        for mod, space in zip(mods, spaces, strict=True):
            stand_in = types.ModuleType(mod.__name__)
            stand_in.__dict__.update(space)
            out[mod.__name__.rsplit(".", 1)[1]] = stand_in
        _PRIVATE[variant] = out
        return out


def vector_math_globals(space: dict[str, Any]) -> dict[str, Any]:
    """A copy of a function's globals ``space`` in which ``exp``, ``log``, ``sin`` and
    ``cos`` (bound by name, or reached as attributes of the ``math`` or ``numpy`` module)
    are the branch-free functions of :mod:`aiofl.components.vecmath`."""
    import math

    import numpy as np

    from aiofl.components import vecmath

    swap = {"exp": vecmath.vexp, "log": vecmath.vlog, "sin": vecmath.vsin, "cos": vecmath.vcos}
    by_id = {id(getattr(mod, name)): fn for name, fn in swap.items() for mod in (math, np)}
    out = dict(space)
    for name, obj in space.items():
        if id(obj) in by_id:
            out[name] = by_id[id(obj)]
        elif obj is math or obj is np:
            stand_in = types.ModuleType(obj.__name__)
            stand_in.__dict__.update(vars(obj))
            stand_in.__dict__.update(swap)
            out[name] = stand_in
    return out


def scalar_recipe(plant: Plant, *, guarded: bool = False) -> compile_.Recipe:
    """The recipe of the one-member kernel of ``plant`` (:mod:`aiofl.engine.kernel`): the
    time loop (entry, ``"member"``), the right-hand side inlined into its stage loop, the
    per-member setup, the reference and a one-evaluation function (``_EVAL``, for
    :func:`aiofl.engine.simulation.closed_loop_rhs`).  ``guarded`` builds the diagnostic
    kernel of :func:`run_members` (plant functions wrapped by :func:`_guarded`)."""
    from aiofl.components.fastmath import FASTMATH

    ns = plant_namespace(plant, guarded=guarded)
    # the time loop is compiled with the components' fast-math flags and error model
    opts = {"fastmath": FASTMATH, "error_model": "numpy"}
    tpl = compile_.Template
    return compile_.Recipe(
        kind="guarded" if guarded else "scalar",
        plant=plant,
        bindings=ns,
        templates=(
            tpl("_KEEP_ALIVE", kernel._tpl_keep_alive),
            tpl("_SETUP", kernel._tpl_setup, opts),
            tpl("_REFERENCE", kernel._tpl_reference, opts),
            # one call site in the stage loop: inlined, so the compiler sees the whole step
            tpl("_DERIV", kernel._tpl_deriv, {"inline": "always", **opts}),
            tpl("_EVAL", kernel._tpl_eval, opts),
        ),
        entry=tpl("member", kernel._tpl_member, {"nogil": True, **opts}),
        sources=engine_sources(),
    )


def _build_kernel(plant: Plant, *, cache: bool | None = None, guarded: bool = False) -> Kernel:
    """Compile the closed-loop functions for one plant (see the module notes)."""
    use_cache = cache_enabled() if cache is None else cache
    recipe = scalar_recipe(plant, guarded=guarded)
    inst = compile_.build(recipe, cache=use_cache and not guarded)
    if not inst.cached and _user_functions(plant):
        plant.typecheck()  # numba compiles them now rather than inside the kernel
    n_cols = kernel.N_SIG + plant.n_states + (L.RHO_MAX + 1) + L.RHO_MAX
    _PLANT_OF_MEMBER[id(inst.entry)] = plant
    return Kernel(
        member=inst.entry, evaluate=inst.namespace["_EVAL"], n_cols=n_cols, cached=inst.cached
    )


def plant_namespace(plant: Plant, *, guarded: bool = False) -> dict[str, Any]:
    """The globals the scalar kernel templates are compiled with for ``plant``: a copy of
    :mod:`aiofl.engine.kernel`'s globals (layout constants, ``L``, ``np``) with the plant's
    compiled functions (wrapped by :func:`_guarded` when ``guarded``), its sizes, the
    controller's component functions and the array views bound."""
    f, g, h, bd, nf = plant.compiled
    n = plant.n_states
    if guarded:
        f, g, h, bd, nf = (_guarded(fn, k, n) for k, fn in enumerate((f, g, h, bd, nf)))
    ns = dict(vars(kernel))
    bind_private(ns)
    ns.update(
        _N=n,
        _N_P=len(plant.params),
        _NZ=n + L.N_METRIC + 2 * L.RHO_MAX + 1,
        _PF=f,
        _PG=g,
        _PH=h,
        _PBD=bd,
        _PNF=nf,
        _UNMANAGED=views.unmanaged_intrinsic(),
        **component_functions(),
    )
    return ns


def bind_private(ns: dict[str, Any], variant: str = "scalar") -> None:
    """Point the component modules ``ns`` names (``_fb``, ``_law``) at the private copies of
    :func:`private_components`, and re-compile the kernel module's own compiled functions
    (``_aiofl_command``, ``_iofl_command``, inlined where called) with ``ns`` as globals, so
    nothing a kernel compiled from ``ns`` calls comes from numba's per-function disk cache.
    ``variant`` as for :func:`private_components`."""
    from numba.core.dispatcher import Dispatcher

    private = private_components(variant)
    for name, obj in list(ns.items()):
        if isinstance(obj, types.ModuleType) and obj.__name__.startswith("aiofl.components."):
            ns[name] = private[obj.__name__.rsplit(".", 1)[1]]
        elif isinstance(obj, Dispatcher) and obj.py_func.__module__ == kernel.__name__:
            ns[name] = compile_.rejit(obj, ns)


def _guarded(fn: Any, index: int, n: int) -> Any:
    """``fn`` wrapped so that an exception it raises becomes
    ``PlantFailure(index, x_1, ..., x_n)`` (numba cannot bind the exception itself)."""
    from numba import njit

    state = "".join(f", x[{i}]" for i in range(n))
    src = (
        "def guarded(x, p):\n"
        "    try:\n"
        "        return fn(x, p)\n"
        "    except Exception:\n"
        "        pass\n"
        f"    raise PlantFailure({index}{state})\n"
    )
    ns: dict[str, Any] = {"fn": fn, "PlantFailure": PlantFailure}
    exec(compile(src, "<aiofl.engine.build guard>", "exec"), ns)  # fixed source, no input
    return njit(error_model="numpy")(ns["guarded"])


def kernel_for(plant: Plant) -> Kernel:
    """The compiled kernel of ``plant`` (built on first use, then reused in this process;
    across processes numba's on-disk cache skips the compilation of built-in and
    file-defined plants)."""
    key = id(plant)
    with _KERNELS_LOCK:  # two threads asking for a new plant's kernel build it once
        if key not in _KERNELS or _KERNELS[key][0] is not plant:
            _KERNELS[key] = (plant, _build_kernel(plant))
        return _KERNELS[key][1]


def run_members(
    member: Any, n_members: int, *args: Any, indices: NDArray[np.int64] | None = None
) -> None:
    """Run ``member(i, *args)`` for every member, on ``numba.get_num_threads()`` threads:
    ``i`` in ``range(n_members)``, or in ``indices`` (``n_members`` of them) when given.

    The compiled member function releases the GIL, so Python threads run members truly in
    parallel; each thread takes the next unclaimed member (dynamic scheduling, so members
    that diverge early do not leave a core idle).  Members are independent: the numbers do
    not depend on the thread count or on which thread ran which member.
    """
    import numba

    n_threads = max(1, min(numba.get_num_threads(), n_members))
    claim = itertools.count()  # next() on a count is atomic under the GIL
    errors: list[tuple[int, BaseException]] = []

    def work() -> None:
        i = -1
        try:
            while not errors:
                i = next(claim)
                if i >= n_members:
                    return
                if indices is not None:
                    i = int(indices[i])
                member(i, *args)
        except BaseException as exc:  # re-raised below
            errors.append((i, exc))

    threads = [threading.Thread(target=work, daemon=True) for _ in range(n_threads - 1)]
    for th in threads:
        th.start()
    work()
    for th in threads:
        th.join()
    if errors:
        i, exc = errors[0]
        if isinstance(exc, Exception):
            _explain_failure(member, i, exc, args)
        raise exc


def _explain_failure(member: Any, i: int, exc: Exception, args: tuple[Any, ...]) -> None:
    """Raise a PlantError if a user plant's function caused ``exc`` (see the module notes);
    return otherwise, so the caller re-raises ``exc`` with its traceback."""
    from numba.core.errors import NumbaError

    plant = _PLANT_OF_MEMBER.get(id(member))
    if plant is None or not _user_functions(plant):
        return
    if isinstance(exc, NumbaError):  # compiling the kernel failed: a plant function?
        plant.typecheck()
        return
    members = [i]
    if id(member) in _GROUP_FUNCTIONS:  # a lane group: replay its members one by one
        members = [int(m) for m in args[0][i] if m >= 0]
        args = args[1:]
    guarded = _build_kernel(plant, cache=False, guarded=True).member
    for m in members:
        try:  # replay the member with every plant function reporting where it raised
            guarded(m, *args)
        except PlantFailure as failure:
            index, *state = failure.args
            raise PlantError(
                f"plant {plant.name!r}: plant function {PLANT_FUNCTIONS[index]} failed at "
                f"state x = {[float(v) for v in state]}: {type(exc).__name__}: {exc}"
            ) from None
        except Exception:  # not a plant function: the caller re-raises the original
            return
