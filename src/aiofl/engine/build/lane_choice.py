r"""Whether a batch runs in lanes: the lane instance at hand, or worth compiling.

A group of 32 lanes runs 5–7 times the member-steps per second of a lone member, but its
instance is compiled per plant, 12–14 s of numba on one core, while the width-1 instance is
shared by every plant of a size (:mod:`aiofl.engine.build.plant_table`) and usually cached.  Both
give a member the same numbers, bit for bit (:mod:`aiofl.engine.kernel.loop`), so the choice is one
of time alone.  A user's ``aiofl robustness`` on a plant file (100 draws of a 5-s scenario
at 1 ms: 5·10⁵ member-steps) ran in 0.1 s at width 1 and waited 13 s for a width-32
compile; a tuning run of thousands of members pays for the compile many times over.

:func:`lanes_worth_it` decides for the members a batch would run in lanes (``engine="auto"``,
the default of :func:`aiofl.engine.simulation.simulate_batch`):

1. **At hand** (:func:`lanes_at_hand`): the plant's width-32 instance of that timing is
   built in this process, or its kernel, compiled from exactly this code, is in the disk
   cache or being compiled into it by another process (its compile lock held;
   :func:`aiofl.engine.build.compile.kernel_at_hand`): lanes.
2. Otherwise the rule of *renting before buying* (the ski-rental problem; Karlin et al.,
   "Competitive randomized algorithms for nonuniform problems", *Algorithmica* 11, 1994):
   the members run at width 1, and their member-steps are added to the plant's *rent* in
   this process, until the rent with this batch's steps would reach the price of the
   compile, :math:`S^* = N_c\,T` member-steps (:data:`LONE_STEPS_PER_COMPILE` :math:`N_c`,
   T the engine's threads: the lone members run on all of them, the compile on one); that
   batch compiles the lanes.  A process's width-1 time before it compiles is then at most
   the compile's time, so no command waits more than twice as long as with the best choice
   in hindsight, and a batch that alone is worth the compile compiles at once.  A run that
   knows its work ahead (a tuning run: population × generations × members per candidate)
   declares it (:func:`expect`) and buys at its first batch when that is worth it.

The member-steps of a batch are its members times the horizon's steps (a member that
diverges early costs less: the estimate errs towards compiling).  ``engine="lanes"`` always
runs the kinds with many members in lanes (the tests that check lanes do so).
"""

from __future__ import annotations

import threading

from aiofl.engine.build import compile as compile_
from aiofl.engine.build import instances
from aiofl.engine.kernel import loop
from aiofl.plants.base import Plant

__all__ = ["LONE_STEPS_PER_COMPILE", "expect", "lanes_at_hand", "lanes_worth_it", "rent"]

LONE_STEPS_PER_COMPILE = 6.0e7
r"""Member-steps a lone member runs on one thread in the time a width-32 instance takes to
compile: 12–14 s of compiling (``docs/benchmarks.md``) at 4.5–6 M member-steps/s alone
(LESO, LADRC; INLESO 2.5, so for it the rule compiles later than ideal, within the factor
2).  Both scale with one core's speed, so their product holds across machines."""

_LOCK = threading.Lock()
_RENT: dict[tuple[int, bool], tuple[Plant, float]] = {}
_EXPECTED: dict[tuple[int, bool], tuple[Plant, float]] = {}


def lanes_at_hand(plant: Plant, sampled_data: bool) -> bool:
    """Whether ``plant``'s width-32 lane instance of that timing costs this process no
    compile: built in this process, stored in the kernel cache under the fingerprint of
    today's code, or being compiled into it by another process now (``aiofl reproduce``
    compiles the instances it needs later in a second process,
    :mod:`aiofl.engine.build.prepare`: waiting for it costs less than renting beside it)."""
    width = loop.WIDTH
    if instances.instance_built(plant, width, sampled_data=sampled_data):
        return True
    return compile_.kernel_at_hand(instances.recipe(plant, width, sampled_data=sampled_data))


def rent(plant: Plant, sampled_data: bool) -> float:
    """The member-steps this process has run at width 1 for ``plant`` at that timing
    instead of compiling its lanes (0 once it compiled them)."""
    with _LOCK:
        owner, steps = _RENT.get((id(plant), sampled_data), (None, 0.0))
        return steps if owner is plant else 0.0


def expect(plant: Plant, sampled_data: bool, member_steps: float) -> None:
    """Declare the member-steps this process is going to run for ``plant`` at that timing
    (a tuning run's whole budget, :class:`aiofl.tuning.evaluate.EvalSpec`): when they reach
    the compile's price, the first batch compiles the lanes instead of renting (a run that
    will pay for them anyway should not pay rent first).  A new declaration replaces the
    last.

    Parameters
    ----------
    plant, sampled_data
        The plant and the timing.
    member_steps
        The member-steps to come.
    """
    with _LOCK:
        _EXPECTED[(id(plant), sampled_data)] = (plant, float(member_steps))


def lanes_worth_it(plant: Plant, sampled_data: bool, member_steps: float) -> bool:
    """Run ``member_steps`` of ``plant`` (members a batch would run in lanes) in lanes?

    True when the lanes are at hand, or when the rent so far and these steps, or the work
    declared by :func:`expect`, reach the compile's price (see the module notes); otherwise
    False, and the steps are added to the rent.

    Parameters
    ----------
    plant, sampled_data
        The plant and the timing.
    member_steps
        The member-steps of this batch.

    Returns
    -------
    bool
    """
    import numba

    if lanes_at_hand(plant, sampled_data):
        return True
    price = LONE_STEPS_PER_COMPILE * max(1, numba.get_num_threads())
    key = (id(plant), sampled_data)
    with _LOCK:
        owner, paid = _RENT.get(key, (None, 0.0))
        paid = paid if owner is plant else 0.0
        owner, planned = _EXPECTED.get(key, (None, 0.0))
        planned = planned if owner is plant else 0.0
        if paid + member_steps >= price or planned >= price:
            _RENT.pop(key, None)
            return True
        _RENT[key] = (plant, paid + member_steps)
        return False
