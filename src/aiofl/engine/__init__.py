"""The compiled batched engine: one numba kernel per plant runs a batch of closed loops.

:func:`simulate` runs one member, :func:`simulate_batch` a batch in one compiled call;
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
