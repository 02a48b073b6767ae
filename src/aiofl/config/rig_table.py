"""The ``[rig]`` table: validated, and merged into the tables it fills (:mod:`aiofl.rig`).

.. code-block:: toml

    [rig]
    preset = "servo-1khz"          # ideal | servo-1khz (aiofl.rig.RIG_PRESETS)
    friction_state = "theta_dot"   # the plant's velocity state (needed with friction)
    # measurement_delay, computation_delay, lag, lag2, rate_limit, rate_filter, coulomb,
    # viscous, smoothing, sensor override the preset's values

What the rig fills (:func:`merge_rig`, before the ``[sensor]`` table is merged):

* ``[sensor] preset``: the rig's sensor, when the config has no ``[sensor]`` table or one
  without a preset (its other keys then override the sensor preset's); a ``[sensor]
  preset`` that differs from the rig's is refused (set it in one place);
* ``[scenario] output_delay`` = ``measurement_delay`` and ``input_delay`` =
  ``computation_delay``; a scenario that sets either itself is refused;
* ``[simulation] dt``: a delay the step does not divide is held exactly at a finer step,
  :math:`dt' = dt/k` with the smallest integer :math:`1 \\le k \\le` :data:`REFINE_MAX`
  for which every delay is an integer multiple of dt' (the decimation is multiplied by k, so
  the stored trajectory keeps its rate); none such: refused naming the delay.

The plant becomes :func:`aiofl.plants.actuated.with_rig` of itself (:func:`apply_rig`) and
its initial state gets the actuator at rest at 0.
"""

from __future__ import annotations

import copy
import math
from dataclasses import replace
from typing import Any

from aiofl.config.schema import ConfigError, RigModel
from aiofl.plants.actuated import rig_x0, with_rig
from aiofl.plants.base import Plant
from aiofl.rig import Rig
from aiofl.scenario import Scenario

__all__ = ["REFINE_MAX", "apply_rig", "merge_rig", "refined_step"]

REFINE_MAX = 16
"""Largest factor k by which the step is divided to hold a delay exactly (dt/k)."""


def refined_step(dt: float, delays: dict[str, float]) -> int:
    """The smallest k (1 .. :data:`REFINE_MAX`) for which every delay is an integer
    multiple of dt/k (within 1e-9 relative); ValueError naming the first delay for which
    none is."""

    def on_grid(tau: float, step: float) -> bool:
        return abs(tau / step - round(tau / step)) <= 1e-9 * max(tau / step, 1.0)

    for k in range(1, REFINE_MAX + 1):
        if all(on_grid(tau, dt / k) for tau in delays.values()):
            return k
    bad = next(key for key, tau in delays.items() if not on_grid(tau, dt))
    raise ValueError(
        f"{bad} = {delays[bad]:g} s is not an integer multiple of dt/k for any k = 1 .. "
        f"{REFINE_MAX} (dt = {dt:g} s); allowed: a delay on the grid of dt/k (e.g. "
        f"{round(delays[bad] / dt) * dt:g} s)"
    )


def merge_rig(data: dict[str, Any], table: RigModel, source: str) -> tuple[dict[str, Any], Rig]:
    """``data`` without its ``[rig]`` table, with the tables the rig fills (module
    docstring), and the :class:`~aiofl.rig.Rig`; raises :class:`ConfigError` naming a
    quantity set twice or a delay no refined step holds.

    Parameters
    ----------
    data
        The config dict.
    table
        Its validated ``[rig]`` table.
    source
        The config's name, for messages.

    Returns
    -------
    data : dict
    rig : Rig
    """

    def refuse(msg: str) -> ConfigError:
        return ConfigError(f"invalid config {source}:\n  {msg}")

    rig = table.build()
    out = {k: copy.deepcopy(v) for k, v in data.items() if k != "rig"}
    sensor = out.get("sensor")
    if rig.sensor != "ideal" or "sensor" in table.explicit():
        if sensor is None:
            out["sensor"] = {"preset": rig.sensor}
        elif isinstance(sensor, dict):
            if "preset" in sensor and sensor["preset"] != rig.sensor:
                raise refuse(
                    f"sensor.preset = {sensor['preset']!r} contradicts rig.sensor = "
                    f"{rig.sensor!r} (rig preset {rig.preset!r} or the table); set the sensor "
                    "in one place (or the same preset in both)"
                )
            out["sensor"] = {"preset": rig.sensor, **sensor}
    scen = out.get("scenario")
    delays = {
        "rig.measurement_delay": ("output_delay", rig.measurement_delay),
        "rig.computation_delay": ("input_delay", rig.computation_delay),
    }
    for key, (target, tau) in delays.items():
        if tau > 0.0 and isinstance(scen, dict):
            if target in scen:
                raise refuse(
                    f"{key} = {tau:g} s and scenario.{target} = {scen[target]!r}: the same "
                    "delay set twice; set it in [rig] only"
                )
            scen[target] = tau
    given = {key: tau for key, (_, tau) in delays.items() if tau > 0.0}
    sim = out.get("simulation")
    if given and isinstance(sim, dict):
        dt = sim.get("dt", 1e-4)
        if (
            isinstance(dt, (int, float))
            and not isinstance(dt, bool)
            and dt > 0
            and math.isfinite(dt)
        ):
            try:
                k = refined_step(float(dt), given)
            except ValueError as exc:
                raise refuse(str(exc)) from None
            if k > 1:
                sim["dt"] = dt / k
                dec = sim.get("decimation", 10)
                if isinstance(dec, int) and not isinstance(dec, bool):
                    sim["decimation"] = dec * k
    return out, rig


def apply_rig(plant: Plant, scenario: Scenario, rig: Rig) -> tuple[Plant, Scenario]:
    """The plant on the rig (:func:`~aiofl.plants.actuated.with_rig`) and the scenario with
    its initial state extended by the actuator's (at rest at 0).

    Parameters
    ----------
    plant, scenario
        The config's plant and scenario.
    rig
        The rig.

    Returns
    -------
    plant : Plant
    scenario : Scenario
    """
    rigged = with_rig(plant, rig)
    if rigged is plant:
        return plant, scenario
    return rigged, replace(scenario, x0=rig_x0(plant, rigged, scenario.x0))
