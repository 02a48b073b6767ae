r"""The controller object for test rigs and hardware in the loop: ``u = ctrl.step(r, y)``.

:class:`DiscreteController` is the engine's discrete controller
(:class:`aiofl.engine.sampled.DiscreteController`: the compiled update ``aiofl simulate
--ts`` runs and the exported C is checked against) with a constructor from a config::

    ctrl = aiofl.DiscreteController.from_config("assisted-s1-ladrc")   # its sensor's Ts
    ctrl.reset(y0)                       # bumpless start at the first measurement
    while running:                       # every Ts
        u = ctrl.step(r, y)              # r (or r, r', ..., r^(rho)) and y at t_k

The arguments are (r, y), in the order of the exported C's ``NAME_step(s, p, r, y)``.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

from aiofl.config import RunConfig, load_config
from aiofl.engine import sampled
from aiofl.engine.discrete import Sampling

__all__ = ["DiscreteController"]


class DiscreteController(sampled.DiscreteController):
    __doc__ = sampled.DiscreteController.__doc__

    @classmethod
    def from_config(cls, config: Any, ts: float | None = None) -> DiscreteController:
        r"""The discrete controller of a design.

        ``u = ctrl.step(r, y)`` once per sample, after ``ctrl.init(y0)`` (the config's
        ``eso.init``) or ``ctrl.reset(y0)`` (a bumpless start): the same numbers as
        ``aiofl simulate --ts`` and the exported C.

        Parameters
        ----------
        config
            A loaded config (:class:`aiofl.config.RunConfig`), a preset name or the path
            of a TOML config.
        ts
            Sample time [s]; default the config's (``[sensor] ts`` or
            ``[controller.discrete] ts``).  The config's discretisation options are kept.

        Raises
        ------
        ValueError
            Without a sample time, for ``0 < ts <= 1`` violated, or for a controller the
            discrete update cannot run (the IOFL law).
        aiofl.config.ConfigError
            For a config that does not load.
        """
        cfg = config if isinstance(config, RunConfig) else load_config(config)
        if ts is None:
            if cfg.sampling is None:
                raise ValueError(
                    f"{cfg.name!r} has no sample time ([sensor] ts); pass ts= "
                    "(allowed: 0 < ts <= 1 [s])"
                )
            sampling = cfg.sampling
        else:
            if not (isinstance(ts, (int, float)) and math.isfinite(ts) and 0 < ts <= 1.0):
                raise ValueError(f"ts = {ts!r}; allowed: 0 < ts <= 1 [s]")
            sampling = replace(cfg.sampling or Sampling(float(ts)), ts=float(ts))
        return cls(cfg.controller, sampling, plant=cfg.plant, x0=cfg.scenario.x0)
