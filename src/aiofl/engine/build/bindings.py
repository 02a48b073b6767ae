"""What the engine's templates are compiled with: the plant's and the controller's functions.

Every kernel instance (:mod:`aiofl.engine.build.instances`) binds, under the global names its
templates use, private copies of the controller's component functions
(:func:`component_functions`, :func:`private_components`) and of the plant's f, g, h, b_d
and normal form.  Private, because numba keys a ``cache=True`` function's disk cache on its
own file only: a cached component loaded after an edit of a module it calls would link that
module's old code into a kernel stored under the new fingerprint.  Two variants:
``"lanes"`` (every function inlined where called, ``exp``/``log``/``sin``/``cos`` rebound to
the branch-free :mod:`aiofl.components.vecmath` by :func:`vector_math_globals`, strict IEEE
arithmetic) for the SIMD lane instances, and ``"scalar"`` (the components' own fast-math
flags and libm) for the differently-rounded check instance.

:func:`engine_sources` lists the files every kernel's code comes from (their text is part of
every kernel's cache fingerprint, :mod:`aiofl.engine.build.compile`).  :func:`guarded` wraps a
plant function for the diagnostic instance that names the plant function that raised and
the state it raised at (:class:`PlantFailure`, see :func:`aiofl.engine.build.instances.run_groups`).
"""

from __future__ import annotations

import sys
import threading
import types
from typing import Any

from aiofl import layout as L
from aiofl.engine import batch
from aiofl.engine.build import compile as compile_
from aiofl.engine.build.compile import PLANT_FUNCTIONS
from aiofl.engine.kernel import member, views
from aiofl.plants.base import Plant

__all__ = [
    "PlantFailure",
    "bind_discrete",
    "bind_private",
    "component_functions",
    "engine_sources",
    "guarded",
    "plant_function",
    "private_components",
    "user_functions",
    "vector_math_globals",
]


class PlantFailure(Exception):
    """Raised inside a diagnostic kernel by a plant function that raised:
    ``(index into PLANT_FUNCTIONS, x_1, ..., x_n, p_1, ..., p_np)``."""


_PRIVATE_LOCK = threading.Lock()


def user_functions(plant: Plant) -> bool:
    """Whether any plant function is defined outside aiofl (aiofl's own are tested)."""
    for fname in PLANT_FUNCTIONS:
        fn = getattr(plant, fname)
        mod = getattr(getattr(fn, "py_func", fn), "__module__", None) or ""
        if fn is not None and not mod.startswith("aiofl."):
            return True
    return False


def engine_sources() -> tuple[str, ...]:
    """The files every kernel's code comes from besides the plant's: the layout, the
    per-member setup and law, this module, the compile factory, the array views, the batch
    record, the plant interface (its functions' compile flags), the corrections to numba
    (how its helpers are compiled) and the component modules."""
    from aiofl import numba_patches

    base = sys.modules[Plant.__module__]
    here = sys.modules[__name__]
    mods = (L, member, here, compile_, views, batch, base, numba_patches, *_component_modules())
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
        "_MODEL_ASSISTED_LAW": law.model_assisted_law,
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

    ``variant = "lanes"`` builds the copies the lane instances (:mod:`aiofl.engine.kernel.loop`)
    links: every function inlined where called and ``np.exp``/``np.log``/``np.sin``/
    ``np.cos`` rebound to the branch-free :mod:`aiofl.components.vecmath` functions
    (:func:`vector_math_globals`), so a loop over lanes that calls them vectorizes, and the
    lane instances' fast-math flags (:data:`aiofl.engine.kernel.loop.LANE_FASTMATH`).
    """
    with _PRIVATE_LOCK:
        if variant in _PRIVATE:
            return _PRIVATE[variant]
        from numba.core.dispatcher import Dispatcher

        from aiofl.engine.kernel.loop import LANE_FASTMATH

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


def plant_function(fn: Any, variant: str) -> Any:
    """A plant function as an instance of ``variant`` binds it: a private copy, with vector
    math and inlined where called (``"lanes"``: the lane instances and the plant table's
    entries), else as written (``"scalar"``: libm, called)."""
    py = getattr(fn, "py_func", fn)
    if variant == "lanes":
        space = vector_math_globals(py.__globals__)
        return compile_.rejit(py, space, inline="always", error_model="numpy")
    return compile_.rejit(py, error_model="numpy")


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


def bind_private(ns: dict[str, Any], variant: str = "scalar") -> None:
    """Point the component modules ``ns`` names (``_fb``, ``_law``) at the private copies of
    :func:`private_components`, and re-compile :mod:`aiofl.engine.kernel.member`'s compiled
    functions (``_aiofl_command``, ``_iofl_command``, inlined where called) with ``ns`` as
    globals, so nothing a kernel compiled from ``ns`` calls comes from numba's per-function
    disk cache.
    ``variant`` as for :func:`private_components`."""
    from numba.core.dispatcher import Dispatcher

    private = private_components(variant)
    for name, obj in list(ns.items()):
        if isinstance(obj, types.ModuleType) and obj.__name__.startswith("aiofl.components."):
            ns[name] = private[obj.__name__.rsplit(".", 1)[1]]
        elif isinstance(obj, Dispatcher) and obj.py_func.__module__ == member.__name__:
            ns[name] = compile_.rejit(obj, ns)


def bind_discrete(ns: dict[str, Any], cd: Any = None) -> None:
    """Add what the discrete controller's templates (:mod:`aiofl.engine.kernel.sampled`) read to
    ``ns``: the layout constants of the discrete coefficient row
    (:mod:`aiofl.engine.discrete_rows`) and of the controller state (``C_*``, ``N_CS``), and the
    discrete component functions of ``cd`` (default :mod:`aiofl.components.discrete`; the
    kernels pass the private copies, :func:`private_components`)."""
    from aiofl.engine import discrete_rows
    from aiofl.engine.kernel import sampled

    if cd is None:
        from aiofl.components import discrete as cd

    ns.update({k: v for k, v in vars(discrete_rows).items() if k.isupper() and isinstance(v, int)})
    ns.update({k: v for k, v in vars(sampled).items() if k.startswith("C_") or k == "N_CS"})
    ns.update(
        _FHAN_TD=cd.fhan_td_step,
        _OBS_INNOVATION=cd.observer_innovation,
        _OBS_CORRECT=cd.observer_correct,
        _OBS_PREDICT=cd.observer_predict,
        _LIN_UPDATE=cd.linear_discrete_update,
    )


def guarded(fn: Any, index: int, n: int, n_p: int) -> Any:
    """``fn`` wrapped so that an exception it raises becomes
    ``PlantFailure(index, x_1, ..., x_n, p_1, ..., p_np)`` (numba cannot bind the exception
    itself; the host calls ``fn`` again at that state to learn it).

    Parameters
    ----------
    fn
        The compiled plant function ``fn(x, p)``.
    index
        Which plant function it is (reported in the exception).
    n, n_p
        The numbers of states and parameters.

    Returns
    -------
    numba dispatcher
    """
    from numba import njit

    state = "".join(f", x[{i}]" for i in range(n)) + "".join(f", p[{j}]" for j in range(n_p))
    src = (
        "def guarded(x, p):\n"
        "    try:\n"
        "        return fn(x, p)\n"
        "    except Exception:\n"
        "        pass\n"
        f"    raise PlantFailure({index}{state})\n"
    )
    ns: dict[str, Any] = {"fn": fn, "PlantFailure": PlantFailure}
    exec(compile(src, "<aiofl.engine.build.bindings guard>", "exec"), ns)  # fixed source, no input
    return njit(error_model="numpy")(ns["guarded"])
