"""Engine instances: every compiled kernel the engine runs, and running a batch on them.

An *instance* is the time loop of :mod:`aiofl.engine.kernel.loop` compiled for one plant, or for
every plant of a number of states (:func:`plant_independent`), with compile-time choices
(:func:`recipe`, built by :mod:`aiofl.engine.build.compile`):

- the lane width ``W``: 32 (groups of members, one per SIMD lane) or 1 (a lone member);
- the timing: continuous (the controller's blocks in the stage right-hand side,
  :mod:`aiofl.engine.kernel.continuous`) or sampled (the discrete controller at the samples,
  :mod:`aiofl.engine.kernel.sampled`);
- the variant: ``"lanes"`` (the default engine: branch-free vector math, strict IEEE
  arithmetic, so a member's numbers are bitwise the same at any width), ``"scalar"``
  (``engine="scalar"``: width 1 with libm and the components' fast-math flags, a
  differently-rounded check of the same code), or ``"guarded"`` (the diagnostic instance
  whose plant functions report which of them raised, at which state).

In the lane variant the plant's f, g, h, b_d and the controller's component functions are
compiled *inlined* into the lane blocks (numba IR inlining) with ``exp``/``log``/``sin``/
``cos`` rebound to :mod:`aiofl.components.vecmath`
(:func:`aiofl.engine.build.bindings.vector_math_globals`), so the loops over lanes vectorize.
Every width-1 instance but the diagnostic one is compiled without the plant and calls its
functions through the batch's plant table (:mod:`aiofl.engine.build.plant_table`; :func:`run`
writes the plant's table into the batch), so one compiled loop serves every plant of its
size.  :func:`instance_for` builds an instance on first use (one per plant, or per size,
and choice per process; across processes the disk cache of :mod:`aiofl.engine.build.compile`
skips the compile); only the instances a batch needs are built.

:func:`plan_groups` splits a batch into groups with uniform component kinds (ESO, TD, SEF and
law kinds, ρ, the feedback length, the ESO start and the reference kind), in batch order
(sampled members: by sample time first; lanes of one group may sample at different
periods, :mod:`aiofl.engine.kernel.sampled`), padding the last group of each kind with -1;
:func:`run_groups` runs them on ``numba.get_num_threads()`` threads: the compiled loop
releases the GIL and each thread claims the next unclaimed group, so a group that diverges
early frees its core at once.  Members are independent, so a member's numbers do not depend
on the batch it is in, the thread count or the scheduling (bitwise).

**User plants that fail.**  A plant whose functions are defined outside aiofl is
type-checked (:meth:`aiofl.plants.base.Plant.typecheck`) before its instance (or its
table's entries) is compiled when it is not loaded from the disk cache, and again whenever
compiling fails, so a
function numba cannot compile, or one that returns complex numbers, is a
:class:`~aiofl.plants.base.PlantError` naming the plant and the function, not a numba
traceback.  At run time a division by zero or a math domain error in a plant function gives
inf/NaN (numba's ``numpy`` error model), which the loop reports as the member diverging at
that time.  A plant function that *raises* stops the run (in a plant-independent
instance as :class:`~aiofl.engine.kernel.plant_calls.PlantCallFailed`): :func:`run_groups` then
replays the group's members one by one in the guarded instance, calls the function that
raised once more from Python at the state (and parameters) it reports, and raises a
PlantError ``plant function f failed at state x = [...]: ValueError: ...``.
"""

from __future__ import annotations

import contextlib
import itertools
import sys
import threading
import types
from collections.abc import Iterator
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.cache import cache_enabled
from aiofl.engine.build import bindings, plant_table
from aiofl.engine.build import compile as compile_
from aiofl.engine.build.bindings import PLANT_FUNCTIONS, PlantFailure
from aiofl.engine.kernel import continuous, lane_blocks, loop, member, plant_calls, sampled, views
from aiofl.engine.kernel.sampled import N_CS
from aiofl.plants.base import Plant, PlantError

__all__ = [
    "VARIANTS",
    "instance_built",
    "instance_for",
    "instance_kind",
    "plan_groups",
    "plant_independent",
    "recipe",
    "run",
    "run_groups",
    "set_plant_table",
]

VARIANTS = ("lanes", "scalar", "guarded")
"""The ways an instance's code is compiled (see the module notes)."""

_INSTANCES: dict[tuple[int, bool, int, bool, str], tuple[Plant | None, compile_.Instance]] = {}
_LOCK = threading.Lock()


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
"""The component functions whose lane blocks stay calls in the width-1 lane instance.

With one lane there is no loop to vectorize and a call per formula costs a lone member much
of its time, so the width-1 instance inlines its blocks into the step, all but those calling
one of these: the IOFL law (large), the reference's sine and cosine and the tracking
differentiators (once per step or cheap: inlining them lengthens the first compile for no
measurable gain).  Strict IEEE arithmetic rounds alike inlined or not: the numbers stay
those of the width-32 instance.  The measurements behind the choice are in
``docs/architecture.md`` ("Members in SIMD lanes")."""
_LIGHT = {"inline": "always"}


def _sources(sampled_data: bool) -> tuple[str, ...]:
    """Source files of an instance: every kernel's, the loop, the lane blocks, the
    controller's module, this module, the plant calls and their bindings (how it calls the
    plant) and the vector math (and, sampled, the discrete controller and its coefficient
    rows)."""
    from aiofl.components import vecmath, vecmath_tables
    from aiofl.engine import discrete_rows

    here = sys.modules[__name__]
    mods = [loop, lane_blocks, continuous, here, plant_table, plant_calls, vecmath, vecmath_tables]
    if sampled_data:
        mods += [sampled, discrete_rows]
    return (*bindings.engine_sources(), *(m.__file__ for m in mods))


def _imported(obj: Any) -> bool:
    """Whether a module global is an aiofl module or a compiled function (neither is called
    by a template unless bound by its placeholder name)."""
    from numba.core.dispatcher import Dispatcher

    if isinstance(obj, types.ModuleType):
        return obj.__name__.startswith("aiofl.") and obj is not L
    return isinstance(obj, Dispatcher)


def plant_independent(width: int, variant: str) -> bool:
    """Whether the instance of ``width`` and ``variant`` calls the plant's functions through
    the batch's plant table (:mod:`aiofl.engine.build.plant_table`), compiled once per number of
    plant states and shared by every plant of that size: every width-1 instance but the
    diagnostic one.  A new or edited plant then costs its table's entries (under a
    second), not a time loop (12-16 s), and a plant of a size the cache has seen runs
    without a compile.  A lone member pays for the calls (0.8-0.95 of its speed with the
    plant inlined, ``docs/benchmarks.md``).  The width-32 lane instances inline the plant's
    functions into their lane loops, which vectorize only so; the diagnostic instance wraps
    them and is never shared."""
    return width == 1 and variant != "guarded"


def instance_kind(width: int, sampled_data: bool, variant: str, n_states: int | None) -> str:
    """The kind an instance's kernels are cached under: variant, timing and width, e.g.
    ``"ls32"``, and for a plant-independent instance its number of states, ``"lc1n4"``
    (``n_states`` None: a plant-specific instance, whose cache key names the plant)."""
    kind = f"{variant[0]}{'s' if sampled_data else 'c'}{width}"
    return kind if n_states is None else f"{kind}n{n_states}"


def recipe(
    plant: Plant, width: int, *, sampled_data: bool = False, variant: str = "lanes"
) -> compile_.Recipe:
    """The recipe of the instance of ``plant`` for groups of ``width``, continuous or
    ``sampled_data``, compiled as ``variant`` (see the module notes).

    Parameters
    ----------
    plant, width, sampled_data, variant
        The plant, lane width, timing and ``"lanes"``/``"scalar"``/``"guarded"``.

    Returns
    -------
    Recipe
    """
    from aiofl.components import vecmath
    from aiofl.components.fastmath import FASTMATH

    if variant not in VARIANTS:
        raise ValueError(f"variant = {variant!r}; allowed: {', '.join(VARIANTS)}")
    lanes = variant != "scalar"  # the guarded instance is a lane instance
    private = "lanes" if lanes else "scalar"
    fastmath = loop.LANE_FASTMATH if lanes else FASTMATH
    opts = {"fastmath": fastmath, "error_model": "numpy"}
    tpl = compile_.Template
    # the per-member setup and the laws (aiofl.engine.kernel.member), compiled against this
    # variant's private components (nothing shared with another variant's instances); its
    # placeholders bound below
    ns_member = compile_.template_globals(member)
    bindings.bind_private(ns_member, private)
    n, n_p = plant.n_states, len(plant.params)
    independent = plant_independent(width, variant)
    ns_member.update(_N=n, **bindings.component_functions(private))
    # names unique to the plant's code, or to the number of states (see plant_tag)
    tag = f"{variant}_n{n}" if independent else f"{variant}_{compile_.plant_tag(plant)}"
    member_setup = compile_.instantiate(member._tpl_setup, ns_member, tag, **opts)

    if independent:  # the plant's functions called through the batch's plant table
        plant_fns = plant_table.call_bindings(n, tag)
    else:
        fns = plant.compiled
        if variant == "guarded":
            own = tuple(bindings.guarded(fn, k, n, n_p) for k, fn in enumerate(fns))
        else:
            own = tuple(
                bindings.plant_function(fn, "scalar" if k == 4 else variant)  # nf: called
                for k, fn in enumerate(fns)
            )
        plant_fns = plant_table.direct_bindings(own, tag)
    # the templates' modules' globals (layout constants) without their placeholders (bound
    # below; the factory checks that every one a template reads is) and the modules and
    # compiled functions they import: an instance calls only what is bound below
    merged = compile_.template_globals(lane_blocks, continuous, sampled, loop)
    ns = {k: v for k, v in merged.items() if not _imported(v)}
    sin, cos = (vecmath.vsin, vecmath.vcos) if lanes else (np.sin, np.cos)
    nza = n + L.N_METRIC
    ns.update(
        _W=width,
        _SAMPLED=sampled_data,
        _N=n,
        _NZ=nza if sampled_data else nza + 2 * L.RHO_MAX + 1,
        _CONTROLLER_SIZE=max(N_CS, sampled.N_DISC) if sampled_data else 1,
        **plant_fns,
        _MEMBER_SETUP=member_setup,
        _IOFL_COMMAND=ns_member["_iofl_command"],
        _UNMANAGED=views.unmanaged_intrinsic(),
        _COLUMN=views.lane_column_intrinsic(),
        _LEADING_ROWS=views.leading_rows_intrinsic(),
        _SIN=sin,
        _COS=cos,
        **bindings.component_functions(private),
    )
    block_opts = {**opts, **(_noalias_option() if lanes else {})}
    inline_all = width == 1 and variant == "lanes"
    templates = []
    for name, fn in vars(lane_blocks).items():  # each block its own function
        if name.startswith("_blk_"):
            light = inline_all and not set(fn.__code__.co_names) & _HEAVY
            templates.append(tpl(name.upper(), fn, {**block_opts, **(_LIGHT if light else {})}))
    inline = {"inline": "always", **opts}
    templates.append(tpl("_KEEP_ALIVE", loop._tpl_keep_alive))
    for name in (
        "assign_lanes",
        "load_lanes",
        "start_members",
        "stop_lane",
        "finish_lanes",
        "watch",
    ):
        templates.append(tpl(f"_{name.upper()}", getattr(loop, f"_tpl_{name}"), opts))
    templates += [
        tpl("_STEP_INPUTS", loop._tpl_step_inputs, inline),
        tpl("_REFERENCE", loop._tpl_reference, inline),
        tpl("_STORE_ROW", loop._tpl_store_row, opts),
        tpl("_DELAY_SETUP", loop._tpl_delay_setup, opts),
        tpl("_DELAY_STAGE_IN", continuous._tpl_delay_stage_in, opts),
        tpl("_DELAY_STAGE_OUT", continuous._tpl_delay_stage_out, opts),
    ]
    if sampled_data:
        # the controller's update, compiled as the blocks are, in the members' namespace
        ns_ctrl = dict(ns_member)
        ns_ctrl["_PAB"] = plant_fns["_PAB"]
        bindings.bind_discrete(ns_ctrl, bindings.private_components(private)["discrete"])
        ns_ctrl["_DELAY_REFERENCE"] = compile_.instantiate(
            sampled._tpl_delay_reference, ns_ctrl, tag, **opts
        )
        ns["_CTRL_INIT"] = compile_.instantiate(sampled._tpl_ctrl_init, ns_ctrl, tag, **opts)
        ns["_CTRL_STEP"] = compile_.instantiate(sampled._tpl_ctrl_step, ns_ctrl, tag, **opts)
        templates += [
            tpl("_SETUP", sampled._tpl_setup, opts),
            tpl("_SAMPLE", sampled._tpl_sample, opts),
            tpl("_DELAY_OUTPUT", sampled._tpl_delay_output, opts),
            tpl("_DELAY_INPUT", sampled._tpl_delay_input, opts),
            tpl("_RHS", sampled._tpl_plant_deriv, inline),
            tpl("_CONTROLLER_BAD", sampled._tpl_controller_bad, inline),
            tpl("_STORE_CONTROLLER", sampled._tpl_store_controller, inline),
        ]
    else:
        # the loop's sampled-only calls, in branches on _SAMPLED that numba prunes
        ns.update(_SAMPLE=None, _CONTROLLER_BAD=None, _DELAY_OUTPUT=None, _DELAY_INPUT=None)
        templates += [
            tpl("_SETUP", continuous._tpl_setup, opts),
            tpl("_RHS", continuous._tpl_deriv, inline),
            tpl("_STORE_CONTROLLER", continuous._tpl_store_controller, inline),
            tpl("_EVAL", continuous._tpl_evaluate, opts),
        ]
    return compile_.Recipe(
        kind=instance_kind(width, sampled_data, variant, n if independent else None),
        plant=None if independent else plant,
        bindings=ns,
        templates=tuple(templates),
        entry=tpl("loop", loop._tpl_loop, {"nogil": True, **opts}),
        sources=_sources(sampled_data),
        # the stage right-hand side at one state (engine.simulation.closed_loop_rhs): a
        # kernel of its own, cached like the loop (it was compiled in every process)
        also_cached=() if sampled_data else ("_EVAL",),
    )


def instance_for(
    plant: Plant, width: int = loop.WIDTH, *, sampled_data: bool = False, variant: str = "lanes"
) -> compile_.Instance:
    """The compiled instance of ``plant`` (see :func:`recipe`), built on first use in this
    process; a plant-independent one (:func:`plant_independent`) is shared by every plant of
    its number of states.  The guarded variant is never cached on disk (loaded from numba's
    cache, its plant wrappers no longer caught the plant's exception: the ValueError of a
    raising plant escaped instead of the PlantFailure naming the function and the state).

    Parameters
    ----------
    plant, width, sampled_data, variant
        As for :func:`recipe`.

    Returns
    -------
    Instance
    """
    independent = plant_independent(width, variant)
    key, owner = _instance_key(plant, width, sampled_data, variant)
    with _LOCK:
        if key not in _INSTANCES or _INSTANCES[key][0] is not owner:
            rec = recipe(plant, width, sampled_data=sampled_data, variant=variant)
            inst = compile_.build(rec, cache=cache_enabled() and variant != "guarded")
            if not independent and not inst.cached and bindings.user_functions(plant):
                plant.typecheck()  # numba compiles them now rather than inside the kernel
            _INSTANCES[key] = (owner, inst)
        return _INSTANCES[key][1]


def instance_built(
    plant: Plant, width: int = loop.WIDTH, *, sampled_data: bool = False, variant: str = "lanes"
) -> bool:
    """Whether :func:`instance_for` has built this instance in this process (its kernel is
    compiled, or loaded from the disk cache, by its first run)."""
    key, owner = _instance_key(plant, width, sampled_data, variant)
    with _LOCK:
        return key in _INSTANCES and _INSTANCES[key][0] is owner


def _instance_key(
    plant: Plant, width: int, sampled_data: bool, variant: str
) -> tuple[tuple[int, bool, int, bool, str], Plant | None]:
    """An instance's key in this process's table, and the plant it belongs to (None for a
    plant-independent one, shared by every plant of its number of states)."""
    independent = plant_independent(width, variant)
    key = (plant.n_states if independent else id(plant), independent, width, sampled_data, variant)
    return key, None if independent else plant


def set_plant_table(plant: Plant, batch: Any, variant: str = "lanes") -> None:
    """Write the addresses of ``plant``'s functions, compiled for the instances of
    ``variant``, into ``batch.plant_table`` (:func:`aiofl.engine.build.plant_table.plant_table`)."""
    batch.plant_table[:] = plant_table.plant_table(plant, variant, cache=cache_enabled())


def run(
    plant: Plant,
    width: int,
    groups: NDArray[np.int64],
    batch: Any,
    out: Any,
    *,
    sampled_data: bool = False,
    variant: str = "lanes",
    compile_only: bool = False,
) -> None:
    """Run ``groups`` of ``batch`` (a batch of ``plant``) on the instance of ``width``,
    ``sampled_data`` and ``variant`` (:func:`instance_for`), writing ``out``: the plant's
    table into the batch first when the instance is plant-independent (its entries compiled
    or loaded now).  ``compile_only``: compile (or load) and return.

    Parameters
    ----------
    plant, width, sampled_data, variant
        As for :func:`recipe`.
    groups, batch, out
        The groups (member indices, one row each), the packed batch and its outputs.
    compile_only
        Compile (or load) only.
    """
    inst = instance_for(plant, width, sampled_data=sampled_data, variant=variant)
    if plant_independent(width, variant):
        set_plant_table(plant, batch, variant)
    run_groups(
        inst.entry,
        groups,
        batch,
        out,
        plant=plant,
        sampled_data=sampled_data,
        compile_only=compile_only,
    )


def _by_kind(
    ints: NDArray[np.int64],
    ref_kind: NDArray[np.float64],
    members: NDArray[np.int64],
    steps: NDArray[np.float64] | None = None,
) -> list[list[int]]:
    """``members`` split by component kinds (the integer row and the reference kind), the
    kinds in order of first appearance; each list in batch order, or for sampled members
    (``steps``, each member's engine steps per sample) by steps per sample, then batch
    order, so lanes sampling together share a group where they can."""
    by_kind: dict[tuple[int, ...], list[int]] = {}
    for i in members.tolist():
        by_kind.setdefault((*(int(v) for v in ints[i]), int(ref_kind[i])), []).append(i)
    kinds = list(by_kind.values())
    if steps is not None:
        kinds = [sorted(group, key=lambda i: int(steps[i])) for group in kinds]  # stable
    return kinds


def group_members(
    ints: NDArray[np.int64],
    ref_kind: NDArray[np.float64],
    members: NDArray[np.int64],
    width: int = loop.WIDTH,
    steps: NDArray[np.float64] | None = None,
) -> NDArray[np.int64]:
    """Groups of :data:`~aiofl.engine.kernel.loop.WIDTH` members with uniform kinds.

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
        Sampled members: each member's engine steps per sample (a group may mix sample
        times; members of one are put next to each other).

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
    of :data:`~aiofl.engine.kernel.loop.WIDTH` run in such groups (the last one padded), the
    others in groups of one lane.  Either way a member's numbers are the same (bitwise).
    ``steps``: as for :func:`group_members` (sampled members).

    Parameters
    ----------
    ints, ref_kind
        The members' integer rows and reference kinds.
    members, steps
        The members to plan; their sample steps (None: continuous).

    Returns
    -------
    dict of int to ndarray
    """
    w = loop.WIDTH
    kinds = _by_kind(ints, ref_kind, members, steps)
    wide = [i for group in kinds if 2 * len(group) >= w for i in group]
    narrow = [i for group in kinds if 2 * len(group) < w for i in group]
    plan = {}
    if wide:
        plan[w] = group_members(ints, ref_kind, np.array(wide, dtype=np.int64), w, steps)
    if narrow:
        plan[1] = np.array(narrow, dtype=np.int64).reshape(-1, 1)
    return plan


def run_groups(
    loop_fn: Any,
    groups: NDArray[np.int64],
    batch: Any,
    out: Any,
    *,
    plant: Plant | None = None,
    sampled_data: bool = False,
    compile_only: bool = False,
) -> None:
    """Run ``loop_fn(g, groups, batch, out)`` for every group, on all threads (``plant``,
    ``sampled_data``: what the loop runs, to name a failing plant function; see
    :func:`_explain_failure`).

    The loop is compiled (or loaded from the disk cache) here, in the calling thread,
    before any worker starts: with LLVM's SLP vectorizer on (:func:`_slp_on`).  Each
    thread claims the next unclaimed group (dynamic scheduling, so groups that diverge
    early do not leave a core idle); the numbers do not depend on the thread count.

    Parameters
    ----------
    loop_fn, groups, batch, out
        The compiled loop and what it runs: groups, packed batch, outputs.
    plant, sampled_data
        What the loop runs, to name a failing plant function.
    compile_only
        Compile (or load) and return.
    """
    import numba
    from numba.core.errors import NumbaError

    sig = tuple(numba.typeof(a) for a in (0, groups, batch, out))
    if sig not in loop_fn.signatures:
        try:
            with compile_.compile_lock(loop_fn), _slp_on():
                loop_fn.compile(sig)
        except NumbaError:  # a user plant function numba cannot compile: say which
            if plant is not None and bindings.user_functions(plant):
                plant.typecheck()
            raise
    if compile_only:
        return
    n_groups = len(groups)
    n_threads = max(1, min(numba.get_num_threads(), n_groups))
    claim = itertools.count()  # next() on a count is atomic under the GIL
    errors: list[tuple[int, BaseException]] = []

    def work() -> None:
        g = -1
        try:
            while not errors:
                g = next(claim)
                if g >= n_groups:
                    return
                loop_fn(g, groups, batch, out)
        except BaseException as exc:  # re-raised below
            errors.append((g, exc))

    threads = [threading.Thread(target=work, daemon=True) for _ in range(n_threads - 1)]
    for th in threads:
        th.start()
    work()
    for th in threads:
        th.join()
    if errors:
        g, exc = errors[0]
        if isinstance(exc, Exception) and plant is not None:
            _explain_failure(plant, sampled_data, groups[g], exc, batch, out)
        raise exc


def _explain_failure(
    plant: Plant, sampled_data: bool, group: Any, exc: Exception, batch: Any, out: Any
) -> None:
    """Raise a PlantError if a user plant's function caused ``exc`` (see the module notes):
    the group's members are replayed one by one in the guarded instance, which reports the
    function and the state (and parameters) it raised at; the function is then called there
    once more from Python for its exception (a plant-independent instance knows only that
    one raised, :class:`~aiofl.engine.kernel.plant_calls.PlantCallFailed`).  Returns otherwise,
    so the caller re-raises ``exc`` with its traceback."""
    if not bindings.user_functions(plant):
        return
    guarded = instance_for(plant, 1, sampled_data=sampled_data, variant="guarded").entry
    for m in (int(v) for v in group if v >= 0):
        one = np.array([[m]], dtype=np.int64)
        run_groups(guarded, one, batch, out, compile_only=True)
        try:  # replay the member with every plant function reporting where it raised
            guarded(0, one, batch, out)
        except PlantFailure as failure:
            index, *values = failure.args
            state = [float(v) for v in values[: plant.n_states]]
            cause = _plant_exception(plant, index, values) or exc
            raise PlantError(
                f"plant {plant.name!r}: plant function {PLANT_FUNCTIONS[index]} failed at "
                f"state x = {state}: {type(cause).__name__}: {cause}"
            ) from None
        except Exception:  # not a plant function: the caller re-raises the original
            return


def _plant_exception(plant: Plant, index: int, values: list[float]) -> Exception | None:
    """The exception plant function ``index`` raises at the state and parameters ``values``
    (a diagnostic replay's report), or None if it does not raise there."""
    n = plant.n_states
    x = np.array(values[:n], dtype=np.float64)
    p = np.array(values[n:], dtype=np.float64)
    try:
        plant.compiled[index](x, p)
    except Exception as err:
        return err
    return None


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
