"""How the engine's kernels are built and cached: from a template (:mod:`aiofl.engine.kernel`)
and what it is compiled with to a compiled, disk-cached kernel.

Every kernel is described by a *recipe* (:class:`~aiofl.engine.build.compile.Recipe`: the
templates, the globals they are compiled with, the entry a caller runs, the source files
its code comes from) and built by the one factory, :func:`~aiofl.engine.build.compile.build`.
The recipes, one module per kind of kernel, are where a template's placeholders are filled:

- :mod:`~aiofl.engine.build.instances`: the time loop's instances (per plant, lane width
  and timing, or per number of states), and running a batch's groups on them;
- :mod:`~aiofl.engine.build.plant_table`: a plant's table entries and their addresses, and
  the bindings a template calls the plant by;
- :mod:`~aiofl.engine.build.controller_update`: the discrete controller's update compiled
  without a plant (what :class:`aiofl.DiscreteController` steps);
- :mod:`~aiofl.engine.build.driven_kernel`: the driven simulation's kernel.

What they share: :mod:`~aiofl.engine.build.bindings` (the controller's and the plant's
functions as a kernel binds them: private, uncached copies; the source files of every
kernel), :mod:`~aiofl.engine.build.compile` (the factory, the fingerprint of everything a
kernel's code depends on), :mod:`~aiofl.engine.build.code_fingerprint` (a plant function's
code and what it reads), :mod:`~aiofl.engine.build.kernel_cache` (numba's disk cache with
sealed files that heal); and when to build: :mod:`~aiofl.engine.build.lane_choice` (whether
a batch is worth the lane instance's compile), :mod:`~aiofl.engine.build.prepare`
(compiling ahead in a second process).
"""
