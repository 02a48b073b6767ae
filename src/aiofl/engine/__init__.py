"""The compiled batched engine: one time loop, compiled per plant, runs a batch of closed loops.

:func:`simulate` runs one member, :func:`simulate_batch` a batch in one compiled call
(:mod:`aiofl.engine.simulation`).  The modules, in the order data flows through them:

- :mod:`~aiofl.engine.batch`: the batch as the loop reads it (one record of packed arrays);
- :mod:`~aiofl.engine.loop`: the time loop, one template for every instance (lane width,
  continuous or sampled, RK4 or Euler as stage tables), with :mod:`~aiofl.engine.lane_blocks`
  (each formula over the lanes of a group) and :mod:`~aiofl.engine.views` (array views);
- :mod:`~aiofl.engine.continuous` and :mod:`~aiofl.engine.sampled`: the controller as it
  plugs into the loop (its blocks in the stage right-hand side; its discrete update at the
  samples, compiled without a plant for :class:`aiofl.DiscreteController` by
  :mod:`~aiofl.engine.controller_update`), with
  :mod:`~aiofl.engine.member` (per-member constants and the law, written once) and
  :mod:`~aiofl.engine.discrete` (the discrete controller's coefficient rows);
- :mod:`~aiofl.engine.bindings`, :mod:`~aiofl.engine.instances`, :mod:`~aiofl.engine.compile`:
  what an instance is compiled with, which instances exist and how a batch runs on them,
  and the one compile factory with its disk cache;
- :mod:`~aiofl.engine.reference`: the slow, deliberately independent scipy path the tests
  check the engine against.
"""

from aiofl.engine.simulation import (
    BatchResult,
    SimulationResult,
    closed_loop_rhs,
    simulate,
    simulate_batch,
)

__all__ = ["BatchResult", "SimulationResult", "closed_loop_rhs", "simulate", "simulate_batch"]
