"""The compiled batched engine: one numba kernel per plant runs a batch of closed loops.

:func:`simulate` runs one member, :func:`simulate_batch` a batch in one compiled call
(:mod:`aiofl.engine.simulation`).  :mod:`aiofl.engine.kernel` holds the kernel templates
(the closed-loop right-hand side and the time loop), :mod:`aiofl.engine.build` compiles
them for a plant, caches the result on disk and runs the members on threads.
:mod:`aiofl.engine.reference` is the slow, deliberately independent scipy path the tests
check the kernel against.
"""

from aiofl.engine.simulation import (
    BatchResult,
    SimulationResult,
    closed_loop_rhs,
    simulate,
    simulate_batch,
)

__all__ = ["BatchResult", "SimulationResult", "closed_loop_rhs", "simulate", "simulate_batch"]
