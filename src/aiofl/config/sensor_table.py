"""The ``[sensor]`` table merged into the tables it fills: ``[scenario]`` (noise) and
``[controller.discrete]`` (ts, y_quantum); see :mod:`aiofl.sensor` for the model.

A quantity set both in ``[sensor]`` and in its old place is refused, except
``[controller.discrete] ts`` equal to the sensor's; a quantum without a sample time is
refused (a continuous loop has no ADC).
"""

from __future__ import annotations

from typing import Any

from aiofl.config.schema import ConfigError

__all__ = ["SENSOR_NOISE", "check_sensor_ts", "merge_sensor"]


def check_sensor_ts(ts: float | None, dt: float, source: str) -> None:
    """Refuse a ``[sensor]`` sample time shorter than the step (e.g. 5e-324), naming
    ``sensor.ts`` (it also becomes the noise hold, whose own check would name that).

    Parameters
    ----------
    ts
        ``[sensor] ts`` [s] (None: not set).
    dt
        ``[simulation] dt`` [s].
    source
        The config's name, for the message.
    """
    if ts is not None and ts < dt * (1 - 1e-9):
        raise ConfigError(
            f"invalid config {source}:\n  sensor.ts = {ts!r} s is shorter than the step "
            f"simulation.dt = {dt:g} s; allowed: an integer multiple of dt, dt <= ts <= 1 s"
        )


SENSOR_NOISE = ("noise_variance", "noise_hold", "noise_seed")


def merge_sensor(data: dict[str, Any], table: Any, source: str) -> dict[str, Any]:
    """``data`` with the ``[sensor]`` table's quantities filled into ``[scenario]`` (noise)
    and ``[controller.discrete]`` (ts, y_quantum); raises :class:`ConfigError` for a
    quantity set in two places (a discrete ts equal to the sensor's is accepted) or a
    quantum without a sample time.

    Parameters
    ----------
    data
        The config dict.
    table
        Its validated ``[sensor]`` table.
    source
        The config's name, for messages.

    Returns
    -------
    dict
    """

    def refuse(msg: str) -> ConfigError:
        return ConfigError(f"invalid config {source}:\n  {msg}")

    try:
        sensor = table.build()
    except ValueError as exc:
        raise refuse(str(exc)) from None
    explicit = table.explicit()
    out = dict(data)
    scen = dict(out.get("scenario") or {}) if isinstance(out.get("scenario"), dict) else None
    if scen is not None or any(k in explicit for k in SENSOR_NOISE):
        scen = scen if scen is not None else {}
        for key in SENSOR_NOISE:
            if key in explicit:
                if key in scen:
                    raise refuse(
                        f"{key} is set twice: sensor.{key} = {explicit[key]!r} and scenario.{key}"
                        f" = {scen[key]!r}; set it in [sensor] only"
                    )
                scen[key] = explicit[key]
        if sensor.ts is not None and "noise_hold" not in scen:
            scen["noise_hold"] = sensor.ts  # a noise sample per measurement
        out["scenario"] = scen
    ctrl = out.get("controller")
    if not isinstance(ctrl, dict):
        ctrl = {}
    disc = ctrl.get("discrete")
    if sensor.ts is None and sensor.quantum == 0:
        return out
    if disc is not None and not isinstance(disc, dict):
        return out  # the schema reports the malformed table
    disc = dict(disc or {})
    if sensor.ts is not None:
        if "ts" in disc and disc["ts"] != sensor.ts:
            raise refuse(
                f"sensor.ts = {sensor.ts!r} (preset {sensor.preset!r} or the table) contradicts "
                f"controller.discrete.ts = {disc['ts']!r}; set the sample time in one place "
                "(or the same value in both)"
            )
        disc["ts"] = sensor.ts
    elif "ts" not in disc:
        raise refuse(
            f"sensor.quantum = {sensor.quantum:g} needs a sample time: set sensor.ts (or "
            "[controller.discrete] ts); a continuous loop has no ADC"
        )
    if sensor.quantum > 0 or "quantum" in explicit:
        if "y_quantum" in disc:
            raise refuse(
                f"the measurement quantum is set twice: sensor.quantum = {sensor.quantum!r} "
                f"(preset {sensor.preset!r} or the table) and controller.discrete.y_quantum = "
                f"{disc['y_quantum']!r}; set it in [sensor] only"
            )
        disc["y_quantum"] = sensor.quantum
    out["controller"] = {**ctrl, "discrete": disc}
    return out
