"""The compiled batched engine: one time loop, compiled per plant, runs a batch of closed loops.

:func:`simulate` runs one member, :func:`simulate_batch` a batch in one compiled call
(:mod:`aiofl.engine.simulation`).  The engine has three floors, each importing only from
the ones below it (``tests/test_architecture.py``):

- what the kernels read: :mod:`~aiofl.engine.batch` (the batch, one record of packed
  arrays) and :mod:`~aiofl.engine.discrete_rows` (the sampled controller's settings,
  :class:`~aiofl.engine.discrete_rows.Sampling`, and its coefficient rows);
- :mod:`aiofl.engine.kernel`: the kernels as written, templates with placeholders (the time
  loop, the lane blocks, the continuous and the sampled controller, the member's constants
  and law, the plant calls, the driven simulation);
- :mod:`aiofl.engine.build`: how a kernel is built and cached (recipes, the compile
  factory, the fingerprint and the disk cache, the instances a batch runs on, lanes or not,
  compiling ahead);
- here, the entry points: :mod:`~aiofl.engine.simulation` (simulate*, the results),
  :mod:`~aiofl.engine.response` (what the loop watched as figures),
  :mod:`~aiofl.engine.observer_gains` (the model-assisted observer's gains),
  :mod:`~aiofl.engine.sample_time` (what a controller run by a user refuses, and its
  faults), :mod:`~aiofl.engine.driven` (a plant driven by a logged input), and the slow,
  deliberately independent scipy paths the tests check the engine against
  (:mod:`~aiofl.engine.reference`, :mod:`~aiofl.engine.reference_sampled`).

The discrete controller stepped from Python is :class:`aiofl.DiscreteController`
(:mod:`aiofl.discrete_controller`, above the configs: it is built from one).
"""

from aiofl.engine.simulation import (
    BatchResult,
    SimulationResult,
    closed_loop_rhs,
    simulate,
    simulate_batch,
)

__all__ = ["BatchResult", "SimulationResult", "closed_loop_rhs", "simulate", "simulate_batch"]
