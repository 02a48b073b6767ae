"""What a run did, in words: its verdict (with why a lost plant was lost), its step
response and its command.

The engine decides the verdict (:mod:`aiofl.engine.kernel.loop`: *ok*, *lost*, *diverged*) and
keeps the figures (:mod:`aiofl.engine.response`); this module says them as a user reads
them, for the ``aiofl simulate`` summary and the report.
"""

from __future__ import annotations

import math
from typing import Any

from aiofl.engine.response import screaming

__all__ = ["command_text", "lost_reason", "step_text", "verdict_text"]


def _num(x: float, unit: str = "") -> str:
    text = f"{x:.4g}"
    return f"{text} {unit}" if unit else text


def lost_reason(cfg: Any, result: Any) -> str | None:
    """Which bound a lost run left, from its last stored point (None if unknown)."""
    if not result.lost or result.t.size == 0:
        return None
    plant = cfg.plant
    unit = plant.output_unit
    y, r = float(result["y"][-1]), float(result["r"][-1])
    x0_y = 0.0
    if cfg.scenario.x0:
        try:
            x0_y = float(plant.h(list(cfg.scenario.x0), plant.param_vector()))
        except Exception:
            x0_y = 0.0
    env = cfg.scenario.resolved_envelope(x0_y if math.isfinite(x0_y) else 0.0)
    if abs(y - r) > env:
        return f"|y - r| = {_num(abs(y - r), unit)} beyond the envelope {_num(env, unit)}"
    if plant.output_range is not None:
        lo, hi = plant.output_range
        if not lo <= y <= hi:
            return f"y = {_num(y, unit)} outside the output range [{lo:g}, {hi:g}]"
    for name, (lo, hi) in plant.state_bounds.items():
        key = name if name in result.signals else f"x{plant.state_names.index(name) + 1}"
        if key in result.signals:
            v = float(result[key][-1])
            if not lo <= v <= hi:
                return f"{name} = {v:.4g} outside its range [{lo:g}, {hi:g}]"
    return None


def verdict_text(cfg: Any, result: Any) -> str:
    """``ok``, ``lost at t = 0.312 s: z = 0.0009 outside its range [0.001, 0.03]`` or
    ``diverged at t = ... s (the numbers blew up)``."""
    if result.status == "ok":
        return "ok (the plant stayed within its envelope)"
    if result.status == "lost":
        why = lost_reason(cfg, result)
        return f"lost at t = {result.stopped_at:.4g} s" + (f": {why}" if why else "")
    return f"diverged at t = {result.stopped_at:.4g} s (the numbers blew up)"


def step_text(result: Any, output_unit: str = "") -> str | None:
    """The step metrics, or None when the run had no step (or stopped before it)."""
    r = result.response
    if not r or math.isnan(r.get("overshoot", math.nan)):
        return None
    settle = r["settling_time"]
    parts = [
        f"overshoot {r['overshoot']:.3g} %",
        "rise " + ("n/a" if math.isnan(r["rise_time"]) else f"{r['rise_time']:.4g} s"),
        "settling (2 %) " + ("not settled" if math.isnan(settle) else f"{settle:.4g} s"),
    ]
    if not math.isnan(r["steady_error"]):
        parts.append(f"steady-state error {_num(r['steady_error'], output_unit)}")
    return "step: " + ", ".join(parts)


def command_text(result: Any, t_final: float, input_unit: str = "") -> str | None:
    """Peak |u|, its standard deviation at steady state (how much noise reaches the
    actuator) and the time at the actuator's limit.

    Parameters
    ----------
    result
        The run.
    t_final
        The horizon [s].
    input_unit
        The plant's input unit.

    Returns
    -------
    str or None
        None without step metrics.
    """
    r = result.response
    if not r:
        return None
    parts = [f"peak |u| {_num(r['u_peak'], input_unit)}"]
    if not math.isnan(r["u_std"]):
        parts.append(f"std of u at steady state {_num(r['u_std'], input_unit)}")
        parts.append(f"its white-noise part {_num(r['u_noise'], input_unit)}")
    sat = r["saturated_time"]
    parts.append(f"saturated {sat:.4g} s ({100.0 * sat / t_final:.3g} % of the run)")
    text = "command: " + ", ".join(parts)
    if screaming(r):
        text += (
            f"\ncommand SCREAMING: at steady state its white-noise part ("
            f"{_num(r['u_noise'], input_unit)}) is {100 * r['u_noise'] / r['u_rms']:.0f} % "
            "of its RMS: the actuator mostly receives the sensor's noise or quantum"
        )
    return text
