"""The engine's kernels as written: templates, plain Python that the compile factory turns
into compiled code (:mod:`aiofl.engine.build`).

A *template* (``_tpl_*``, or ``_blk_*`` for a lane block) reads its collaborators as module
globals: the lane width, the plant's functions, the controller's component functions, the
other templates.  In this package those globals are *placeholders*, stand-ins so a module
imports (``_W = 32``, ``_PFG = None``), declared in one block per module whose comments say
which function of :mod:`aiofl.engine.build` fills them (``aiofl/engine/build/instances.py:
recipe``, ...) and with what, and listed in the module's ``PLACEHOLDERS``: a recipe starts
from a module's globals without them (:func:`~aiofl.engine.build.compile.template_globals`)
and the compile factory refuses one that leaves a placeholder a template reads unbound,
naming it (:func:`~aiofl.engine.build.compile.unbound_placeholders`).  Nothing here
compiles, caches or runs anything, and nothing here imports :mod:`aiofl.engine.build`.

Read in this order:

- :mod:`~aiofl.engine.kernel.loop`: the time loop, one template for every instance (lane
  width 32 or 1, continuous or sampled, RK4 or Euler as stage tables), the per-lane signal
  rows (``S_*``);
- :mod:`~aiofl.engine.kernel.lane_blocks`: each formula of the closed loop over the lanes
  of a group (the loops LLVM vectorizes);
- :mod:`~aiofl.engine.kernel.continuous`: the continuous controller, its blocks in the
  stage right-hand side;
- :mod:`~aiofl.engine.kernel.sampled`: the discrete controller at the samples (ADC, update,
  DAC, transport delays) and its state layout (``C_*``);
- :mod:`~aiofl.engine.kernel.member`: one member's packed constants and the law, written
  once for both controllers;
- :mod:`~aiofl.engine.kernel.plant_calls`: how a kernel calls the plant's functions,
  inlined or through a table of addresses;
- :mod:`~aiofl.engine.kernel.views`: array views as numba intrinsics;
- :mod:`~aiofl.engine.kernel.driven_plant`: a plant driven by a logged input, for a
  population of parameter sets (grey-box identification).

The data the kernels read sit one floor down, in :mod:`aiofl.engine.batch` (the batch
record) and :mod:`aiofl.engine.discrete_rows` (the discrete coefficient rows).
"""
