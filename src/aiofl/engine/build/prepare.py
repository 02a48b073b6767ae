"""Compiling instances ahead of need, in a second process: both cores busy on a cold cache.

numba compiles on one core, and a command that needs several instances of a plant's time
loop (``aiofl reproduce``: the width-1 continuous one for its single runs, the width-1
sampled one for the sampling limits, the width-32 continuous one for the robustness draws)
compiles them one after the other.  :func:`prepare_in_background` starts a second Python
process that compiles the instances the command will need *later* into the disk cache
while the command compiles (and runs) what it needs now.  The two meet through the cache
and its compile lock (:func:`aiofl.engine.build.compile.compile_lock`): whichever process reaches
an instance second waits for the first and loads it, so nothing is compiled twice and a
wrong guess costs only the second core's time.

The background process compiles with a probe batch of one member whose array types are
those of every real batch (:func:`probe`), so the signature it compiles is the one the
command will look up.  It is stopped when the command's process exits.  With the cache
disabled nothing is started.

``python -m aiofl.engine.build.prepare PLANT SPEC...`` is that process: ``PLANT`` a registered
plant's name or a plant file, each ``SPEC`` an instance as ``c1``, ``c32``, ``s1``, ``s32``
(continuous or sampled, lane width), or ``dc``: the discrete controller's update compiled
without a plant (:mod:`aiofl.engine.build.controller_update`: what
:class:`aiofl.discrete_controller.DiscreteController`, the sampled loop's linearisation and
the exports' checks step).  ``PLANT`` may also be ``--states=N``: the
plant-independent instances (``c1``, ``s1``) of every N-state plant, compiled without
one.

A plant file the cache has never seen (:func:`prepare_loops_ahead`, from
:func:`aiofl.config.run_config.resolve_plant`): the width-1 loops of its number of states
do not depend on it (:mod:`aiofl.engine.build.plant_table`), so when the cache has none of them
a second process compiles them while this one runs sympy on the file and compiles the
plant's table entries: on an empty cache the first command on a plant file waits for the
longer of the two, not for both.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import subprocess
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.cache import cache_enabled, subdir
from aiofl.engine.batch import Batch, Outputs
from aiofl.engine.build import compile as compile_
from aiofl.engine.build.controller_update import compile_ahead
from aiofl.engine.build.instances import (
    instance_for,
    instance_kind,
    plant_independent,
    run,
    run_groups,
)
from aiofl.engine.discrete_rows import N_DISC
from aiofl.engine.kernel import loop
from aiofl.engine.kernel.plant_calls import N_TABLE
from aiofl.limits import MAX_STATES
from aiofl.plants.base import Plant

__all__ = [
    "parse_spec",
    "prepare",
    "prepare_in_background",
    "prepare_loops",
    "prepare_loops_ahead",
    "probe",
    "size_only_plant",
]

SIZE_ONLY = "--states"
"""The ``PLANT`` argument naming a number of states instead of a plant (at most
:data:`aiofl.limits.MAX_STATES`, a plant file's)."""


def parse_spec(text: str) -> tuple[int, bool]:
    """``"c32"`` -> (32, False), ``"s1"`` -> (1, True); raises ValueError otherwise."""
    if len(text) < 2 or text[0] not in "cs" or not text[1:].isdigit():
        raise ValueError(f"instance spec {text!r}; allowed: c1, c32, s1, s32 (or {CONTROLLER})")
    width = int(text[1:])
    if width not in (1, 32):
        raise ValueError(f"instance spec {text!r}: lane width {width}; allowed: 1, 32")
    return width, text[0] == "s"


def probe(plant: Plant) -> tuple[NDArray[np.int64], Batch, Outputs]:
    """A one-member batch (groups, batch, outputs) with the array types of every batch
    :func:`aiofl.engine.simulation.simulate_batch` packs, for compiling an instance."""
    n, n_p = plant.n_states, len(plant.params)
    one = np.zeros(1, dtype=np.int64)
    batch = Batch(
        ints=np.zeros((1, L.N_INT), dtype=np.int64),
        floats=np.zeros((1, L.N_FLOAT)),
        p_before=np.zeros((1, n_p)),
        p_after=np.zeros((1, n_p)),
        p_nom=np.zeros((1, n_p)),
        scen=np.zeros((1, L.N_SCEN)),
        x0=np.zeros((1, n)),
        ref_table=np.zeros((1, 2)),
        ref_row=one,
        noise_table=np.zeros((1, 1)),
        noise_row=one.copy(),
        disc=np.zeros((1, N_DISC)),
        bounds=np.zeros((1, n + 1, 2)),
        plant_table=np.zeros(N_TABLE, dtype=np.int64),
        dt=1e-3,
        n_steps=1,
        method=L.METHOD_RK4,
        decimation=1,
        store=False,
        threshold=1e10,
    )
    out = Outputs(
        metrics=np.zeros((1, L.N_METRIC)),
        status=np.zeros(1, dtype=np.int64),
        t_stop=np.zeros(1),
        stats=np.zeros((1, L.N_STAT)),
        traj=np.empty((1, 0, len(L.trajectory_columns(n)))),
    )
    return np.zeros((1, 1), dtype=np.int64), batch, out


CONTROLLER = "dc"
"""The spec of the discrete controller's update compiled without a plant."""


def prepare(plant: Plant, specs: Sequence[tuple[int, bool]], *, controller: bool = False) -> None:
    """Compile (or load) the discrete controller's update (``controller``, first) and the
    instances ``specs`` (lane width, sampled) of ``plant``.

    Parameters
    ----------
    plant
        The plant.
    specs
        ``(lane width, sampled)`` of each instance.
    controller
        Also the discrete controller's update.
    """
    if controller:
        compile_ahead()
    groups, batch, out = probe(plant)
    for width, sampled_data in specs:
        run(plant, width, groups, batch, out, sampled_data=sampled_data, compile_only=True)


def size_only_plant(n_states: int) -> Plant:
    """A plant of ``n_states`` states and no parameters whose functions are never called:
    what the plant-independent instances of every plant of that size are built from."""

    def unused(x: Any, p: Any) -> float:  # pragma: no cover - never called
        return 0.0

    return Plant(
        name=f"any {n_states}-state plant",
        n_states=n_states,
        f=unused,
        g=unused,
        h=unused,
        params={},
    )


def prepare_loops(n_states: int, specs: Sequence[tuple[int, bool]]) -> None:
    """Compile (or load) the plant-independent instances ``specs`` (lane width 1,
    continuous or sampled) of every ``n_states``-state plant, without a plant.

    Raises
    ------
    ValueError
        A spec names a plant-specific instance (width 32).
    """
    plant = size_only_plant(n_states)
    groups, batch, out = probe(plant)
    for width, sampled_data in specs:
        if not plant_independent(width, "lanes"):
            raise ValueError(f"lane width {width}: not a plant-independent instance; allowed: 1")
        inst = instance_for(plant, width, sampled_data=sampled_data)
        run_groups(inst.entry, groups, batch, out, compile_only=True)


LOOPS_AHEAD = ((1, False), (1, True))
"""The instances :func:`prepare_loops_ahead` compiles: the lone member's loop, continuous
(the common command) first, then sampled."""


def prepare_loops_ahead(n_states: int) -> subprocess.Popen[bytes] | None:
    """Start a process compiling the loops of :data:`LOOPS_AHEAD` for ``n_states``-state
    plants if the disk cache holds neither (by their file names only, any fingerprint:
    after an upgrade the command compiles them itself); None when nothing is started."""
    folder = subdir("kernels")
    if folder is None or not 1 <= n_states <= MAX_STATES:
        return None
    prefix = [
        compile_.kernel_prefix(instance_kind(w, s, "lanes", n_states), None) for w, s in LOOPS_AHEAD
    ]
    if any(compile_.has_kernel(folder, loop._tpl_loop, p) for p in prefix):
        return None
    return prepare_in_background(f"{SIZE_ONLY}={n_states}", LOOPS_AHEAD)


def prepare_in_background(
    plant: str, specs: Sequence[tuple[int, bool]], *, controller: bool = False
) -> subprocess.Popen[bytes] | None:
    """Start a process compiling the instances ``specs`` of the plant named ``plant`` (a
    registered name, a plant file, or ``--states=N``: every N-state plant's
    plant-independent ones) into the disk cache, in that order, after the discrete
    controller's update when ``controller``; None when the cache is off or nothing is
    asked.  The process is stopped when this one exits.

    Parameters
    ----------
    plant
        A registered name, a plant file, or ``--states=N``.
    specs, controller
        As for :func:`prepare`.

    Returns
    -------
    subprocess.Popen or None
    """
    if not cache_enabled() or not (specs or controller):
        return None
    args = [CONTROLLER] * controller + [f"{'s' if s else 'c'}{w}" for w, s in specs]
    try:
        proc = subprocess.Popen(
            [sys.executable, "-m", "aiofl.engine.build.prepare", plant, *args],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=os.environ.copy(),
        )
    except OSError:
        return None
    atexit.register(_stop, proc)
    return proc


def _stop(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        proc.terminate()
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(timeout=5)


def main(argv: Sequence[str]) -> int:
    """``python -m aiofl.engine.build.prepare PLANT SPEC...`` (see the module notes)."""
    if len(argv) < 2:
        usage = "usage: python -m aiofl.engine.build.prepare PLANT|--states=N SPEC..."
        print(usage, file=sys.stderr)
        return 2
    from aiofl.plants.plant_cache import plant_from_file
    from aiofl.plants.registry import get_plant

    try:
        specs = [parse_spec(a) for a in argv[1:] if a != CONTROLLER]
    except ValueError as exc:
        print(f"aiofl.engine.build.prepare: {exc}", file=sys.stderr)
        return 2
    name = argv[0]
    if name.startswith(f"{SIZE_ONLY}="):
        try:
            n_states = int(name.partition("=")[2])
            if not 1 <= n_states <= MAX_STATES:
                raise ValueError(f"{name}: allowed 1 <= N <= {MAX_STATES}")
            prepare_loops(n_states, specs)
        except ValueError as exc:
            print(f"aiofl.engine.build.prepare: {exc}", file=sys.stderr)
            return 2
        return 0
    plant = plant_from_file(name) if name.endswith(".toml") else get_plant(name)
    prepare(plant, specs, controller=CONTROLLER in argv[1:])
    return 0


if __name__ == "__main__":  # pragma: no cover - run as a process
    raise SystemExit(main(sys.argv[1:]))
