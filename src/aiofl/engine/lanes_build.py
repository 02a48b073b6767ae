"""A plant's lane kernel: compiling the templates of :mod:`aiofl.engine.lanes`, grouping a
batch by component kinds and running the groups.

:func:`lane_kernel_for` compiles the lane templates for one plant (the continuous time loop
of :mod:`aiofl.engine.lanes`, or the sampled-data one of :mod:`aiofl.engine.lanes_sampled`)
by the compile factory (:func:`lane_recipe`, :mod:`aiofl.engine.compile`: a namespace that
binds the plant; the on-disk cache under a fingerprint of every source involved) with the
bindings of :mod:`aiofl.engine.build`, with two differences that make
the lane loops vectorize: the plant's f, g, h and b_d and the controller's component
functions are compiled *inlined* (numba IR inlining) and with ``exp``/``log``/``sin``/``cos``
rebound to :mod:`aiofl.components.vecmath` (:func:`aiofl.engine.build.vector_math_globals`).

:func:`group_members` splits a batch into groups of :data:`aiofl.engine.lanes.WIDTH`
members with uniform component kinds (ESO, TD, SEF and law kinds, ρ, the feedback length,
the ESO start, the reference kind and, for sampled members, the steps per sample), in batch
order, padding the last group of each kind with -1; :func:`run_groups` runs them on
``numba.get_num_threads()`` threads through :func:`aiofl.engine.build.run_members`.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.cache import cache_enabled
from aiofl.engine import build, kernel, lane_blocks, lanes, lanes_sampled, sampled, views
from aiofl.engine import compile as compile_
from aiofl.plants.base import Plant

__all__ = ["group_members", "lane_kernel_for", "plan_groups", "run_groups"]

_LANE_KERNELS: dict[tuple[int, int, bool], tuple[Plant, Any]] = {}
_LOCK = threading.Lock()


def _lane_plant_function(fn: Any, *, inline: bool = True) -> Any:
    """``fn`` (a plant function) compiled for the lane kernel: a private copy, with vector
    math and inlined where called (``inline``), else as the scalar kernel compiles it."""
    py = getattr(fn, "py_func", fn)
    if inline:
        space = build.vector_math_globals(py.__globals__)
        return compile_.rejit(py, space, inline="always", error_model="numpy")
    return compile_.rejit(py, error_model="numpy")


def _noalias_option() -> dict[str, Any]:
    """``{"_noalias": True}``: compile a function with LLVM's ``noalias`` on its pointer
    arguments, or ``{}`` where this numba cannot.

    Without it LLVM must assume that two array arguments of a lane block may overlap, and
    does not vectorize a loop of 8 lanes that stores into one and loads from the other (the
    run-time overlap check costs more than the loop).  numba sets this flag only for its
    parallel gufuncs (``Flags.noalias``); the CPU target's option table maps decorator
    keywords to flags, and this adds the mapping ``_noalias -> noalias`` to it (nothing
    else changes: a function compiled without the keyword is compiled as before).  Every
    block is called with arrays that do not overlap (distinct rows of the group's
    workspace), which is what ``noalias`` promises.  If a future numba lacks the flag or
    the table, the blocks compile without it: the same numbers, unvectorized.
    """
    try:
        from numba.core.compiler import Flags
        from numba.core.cpu import CPUTargetOptions
        from numba.core.options import TargetOptions
    except ImportError:  # pragma: no cover - numba internals moved
        return {}
    if not hasattr(Flags, "noalias"):  # pragma: no cover
        return {}
    if not isinstance(getattr(CPUTargetOptions, "_noalias", None), TargetOptions.Mapping):
        CPUTargetOptions._noalias = TargetOptions.Mapping("noalias")
    return {"_noalias": True}


_HEAVY = frozenset({"_IOFL_COMMAND", "_SIN", "_COS", "_HAN_TD", "_ITD"})
"""The component functions whose lane blocks stay calls in the width-1 instance.

With one lane there is no loop to vectorize and a call per formula cost ~40 % of a lone
member's time, so the width-1 instance inlines its blocks into the step, all but those
calling one of these: the IOFL law (large), the reference's sine and cosine and the
tracking differentiators (once per step or cheap: inlining them too took the first compile
of paper-s1-inleso from 20 to 26 s and gave no measurable gain).  Inlining fal, the linear
SEF, the law and the saturation took a lone LESO member from 65 to 40 ms (20-s S1; the
scalar engine: 37-41 ms); inlining the INLESO structure's components (INLESO, the INLSEF
terms and limit, each holding several exp/log) took a lone INLESO member from 0.75 to
0.96 of the scalar engine's speed, for a first compile of 15 -> 20 s.  Strict IEEE
arithmetic rounds alike inlined or not: the numbers stay those of the width-32
instance."""
_LIGHT = {"inline": "always"}


def _lane_sources() -> tuple[str, ...]:
    """Source files of the lane kernels: every kernel's, the lane templates and blocks, the
    sampled controller's, this module and the vector math."""
    import sys

    from aiofl.components import vecmath, vecmath_tables
    from aiofl.engine import discrete

    here = sys.modules[__name__]
    mods = (lanes, lane_blocks, lanes_sampled, sampled, discrete, here, vecmath, vecmath_tables)
    return (*build.engine_sources(), *(m.__file__ for m in mods))


def lane_recipe(plant: Plant, width: int, *, sampled_data: bool = False) -> compile_.Recipe:
    """The recipe of the lane kernel of ``plant`` for groups of ``width`` (see the module
    notes): the continuous time loop, or with ``sampled_data`` the sampled-data one
    (:mod:`aiofl.engine.lanes_sampled`)."""
    from aiofl.components import vecmath

    opts = {"fastmath": lanes.LANE_FASTMATH, "error_model": "numpy"}
    tpl = compile_.Template
    # the per-member setup and the IOFL law are the scalar kernel's templates, compiled
    # here against the lane variant's private components (nothing is shared with the
    # scalar kernel, whose code must not depend on what was compiled first)
    bd, nf = plant.compiled[3:]
    ns_setup = dict(vars(kernel))
    build.bind_private(ns_setup, "lanes")
    ns_setup.update(_N=plant.n_states, **build.component_functions("lanes"))
    setup = compile_.instantiate(kernel._tpl_setup, ns_setup, f"w{width}", **opts)

    ns = {**vars(lane_blocks), **vars(lanes), **vars(lanes_sampled)}
    ns.update(
        _W=width,
        _N=plant.n_states,
        _N_P=len(plant.params),
        _NZ=plant.n_states + L.N_METRIC + 2 * L.RHO_MAX + 1,
        _PF=_lane_plant_function(plant.f),
        _PG=_lane_plant_function(plant.g),
        _PH=_lane_plant_function(plant.h),
        _PBD=_lane_plant_function(bd),
        _PNF=_lane_plant_function(nf, inline=False),
        _SETUP=setup,
        _IOFL_COMMAND=ns_setup["_iofl_command"],
        _UNMANAGED=views.unmanaged_intrinsic(),
        _COLUMN=views.lane_column_intrinsic(),
        _LEADING_ROWS=views.leading_rows_intrinsic(),
        _SIN=vecmath.vsin,
        _COS=vecmath.vcos,
        **build.component_functions("lanes"),
    )
    block_opts = {**opts, **_noalias_option()}
    templates = []
    for name, fn in vars(lane_blocks).items():  # each block its own function
        if name.startswith("_blk_"):
            light = width == 1 and not set(fn.__code__.co_names) & _HEAVY
            templates.append(tpl(name.upper(), fn, {**block_opts, **(_LIGHT if light else {})}))
    templates.append(tpl("_KEEP_ALIVE", lanes._tpl_keep_alive))
    for name in ("assign_lanes", "load_lanes", "start_members", "stop_lane", "finish_lanes"):
        templates.append(tpl(f"_{name.upper()}", getattr(lanes, f"_tpl_{name}"), opts))
    inline = {"inline": "always", **opts}
    templates += [
        tpl("_STEP_INPUTS", lanes._tpl_step_inputs, inline),
        tpl("_GROUP_SETUP", lanes._tpl_group_setup, opts),
        tpl("_REFERENCE", lanes._tpl_reference, inline),
    ]
    if sampled_data:
        # the controller's update: the sampled kernel's, compiled as the lane blocks are
        ns_ctrl = dict(ns_setup)
        sampled._bind(ns_ctrl, build.private_components("lanes")["discrete"])
        ns["_CTRL_INIT"] = compile_.instantiate(sampled._tpl_ctrl_init, ns_ctrl, "lanes", **opts)
        ns["_CTRL_STEP"] = compile_.instantiate(sampled._tpl_ctrl_step, ns_ctrl, "lanes", **opts)
        templates.append(tpl("_PLANT_DERIV", lanes_sampled._tpl_plant_deriv, inline))
        entry = tpl("group", lanes_sampled._tpl_group_sampled, {"nogil": True, **opts})
    else:
        templates.append(tpl("_DERIV", lanes._tpl_deriv, inline))
        entry = tpl("group", lanes._tpl_group, {"nogil": True, **opts})
    return compile_.Recipe(
        kind=f"{'s' if sampled_data else 'w'}{width}",
        plant=plant,
        bindings=ns,
        templates=tuple(templates),
        entry=entry,
        sources=_lane_sources(),
    )


def _build(
    plant: Plant, width: int, *, sampled_data: bool = False, cache: bool | None = None
) -> Any:
    """Compile the lane kernel of ``plant`` (:func:`lane_recipe`) and register its group
    function for the diagnosis of plant failures."""
    use_cache = cache_enabled() if cache is None else cache
    inst = compile_.build(lane_recipe(plant, width, sampled_data=sampled_data), cache=use_cache)
    if not inst.cached and build._user_functions(plant):
        plant.typecheck()  # numba compiles them now rather than inside the kernel
    build.register_group_function(inst.entry, plant)
    return inst.entry


def lane_kernel_for(plant: Plant, width: int = lanes.WIDTH, *, sampled_data: bool = False) -> Any:
    """The compiled lane kernel (group function) of ``plant`` for groups of ``width``,
    built on first use: the continuous time loop, or with ``sampled_data`` the sampled-data
    one (called with the batch's discrete rows as its last argument)."""
    key = (id(plant), width, sampled_data)
    with _LOCK:
        if key not in _LANE_KERNELS or _LANE_KERNELS[key][0] is not plant:
            _LANE_KERNELS[key] = (plant, _build(plant, width, sampled_data=sampled_data))
        return _LANE_KERNELS[key][1]


def _by_kind(
    ints: NDArray[np.int64],
    ref_kind: NDArray[np.float64],
    members: NDArray[np.int64],
    steps: NDArray[np.float64] | None = None,
) -> list[list[int]]:
    """``members`` split by component kinds (the integer row, the reference kind and, for
    sampled members, the steps per sample ``steps``), each list in batch order, the kinds
    in order of first appearance."""
    by_kind: dict[tuple[int, ...], list[int]] = {}
    for i in members.tolist():
        n_per = int(steps[i]) if steps is not None else 0
        by_kind.setdefault((*(int(v) for v in ints[i]), int(ref_kind[i]), n_per), []).append(i)
    return list(by_kind.values())


def group_members(
    ints: NDArray[np.int64],
    ref_kind: NDArray[np.float64],
    members: NDArray[np.int64],
    width: int = lanes.WIDTH,
    steps: NDArray[np.float64] | None = None,
) -> NDArray[np.int64]:
    """Groups of :data:`~aiofl.engine.lanes.WIDTH` members with uniform kinds.

    Parameters
    ----------
    ints
        The batch's integer rows (:data:`aiofl.layout.INT_NAMES`).
    ref_kind
        Each member's reference kind (scenario column ``S_REF_KIND``).
    members
        The members to group (indices into the batch), in the order to keep.
    width
        Lanes per group.
    steps
        Sampled members: each member's engine steps per sample (uniform within a group).

    Returns
    -------
    ndarray of int64, shape (G, width)
        Member indices per group, -1 for the pads of a group's last lanes.
    """
    w = width
    rows: list[list[int]] = []
    for group in _by_kind(ints, ref_kind, members, steps):
        for start in range(0, len(group), w):
            chunk = group[start : start + w]
            rows.append(chunk + [-1] * (w - len(chunk)))
    return np.array(rows, dtype=np.int64).reshape(len(rows), w)


def plan_groups(
    ints: NDArray[np.int64],
    ref_kind: NDArray[np.float64],
    members: NDArray[np.int64],
    steps: NDArray[np.float64] | None = None,
) -> dict[int, NDArray[np.int64]]:
    """The groups to run, by lane width: members of a kind that fill at least half a group
    of :data:`~aiofl.engine.lanes.WIDTH` run in such groups (the last one padded), the
    others in groups of one lane.  Either way a member's numbers are the same (bitwise).
    ``steps``: as for :func:`group_members` (sampled members)."""
    w = lanes.WIDTH
    kinds = _by_kind(ints, ref_kind, members, steps)
    wide = [i for group in kinds if 2 * len(group) >= w for i in group]
    narrow = [i for group in kinds if 2 * len(group) < w for i in group]
    plan = {}
    if wide:
        plan[w] = group_members(ints, ref_kind, np.array(wide, dtype=np.int64), w, steps)
    if narrow:
        plan[1] = np.array(narrow, dtype=np.int64).reshape(-1, 1)
    return plan


def run_groups(group_fn: Any, groups: NDArray[np.int64], *args: Any) -> None:
    """Run ``group_fn(g, groups, *args)`` for every group, on all threads.

    The group function is compiled (or loaded from the disk cache) here, in the calling
    thread, before any worker starts: with LLVM's SLP vectorizer on (:func:`_slp_on`).
    """
    import numba
    from numba.core.errors import NumbaError

    sig = tuple(numba.typeof(a) for a in (0, groups, *args))
    if sig not in group_fn.signatures:
        try:
            with _slp_on():
                group_fn.compile(sig)
        except NumbaError:  # a user plant function numba cannot compile: say which
            plant = build._PLANT_OF_MEMBER.get(id(group_fn))
            if plant is not None and build._user_functions(plant):
                plant.typecheck()
            raise
    build.run_members(group_fn, len(groups), groups, *args)


@contextlib.contextmanager
def _slp_on() -> Iterator[None]:
    """Compile with LLVM's SLP vectorizer, which numba leaves off by default.

    A loop over 8 lanes is short enough that LLVM unrolls it completely before its loop
    vectorizer runs; the SLP (straight-line) vectorizer then packs the 8 unrolled copies
    into vector instructions.  numba reads ``config.SLP_VECTORIZE`` each time it builds the
    optimisation pipeline of a library: it is switched on while the lane kernel compiles
    (holding numba's compiler lock, so no other compilation sees it) and restored after.
    """
    from numba.core import config
    from numba.core.compiler_lock import global_compiler_lock

    with global_compiler_lock:
        old = config.SLP_VECTORIZE
        config.SLP_VECTORIZE = 1
        try:
            yield
        finally:
            config.SLP_VECTORIZE = old
