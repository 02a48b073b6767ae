r"""The measurement as a user has it: one sensor model (the ``[sensor]`` table).

A real controller never sees :math:`y`: it reads a sensor at a sample time, quantised and
noisy.  :class:`Sensor` describes that measurement in one place:

.. code-block:: toml

    [sensor]
    preset = "encoder-12bit"   # ideal | encoder-12bit | encoder-14bit | encoder-16bit
    # explicit keys override the preset's values:
    ts = 1e-3                  # sample time [s]: the controller runs sampled at ts
    quantum = 0.0015339807878856412   # rad; an encoder of N counts/rev has 2π/N
    noise_variance = 0.0       # Gaussian output noise (rad²), held over noise_hold
    noise_hold = 1e-3          # [s]; default: ts, else 1 ms
    noise_seed = 0

The sensor fills what the engine already has (:meth:`Sensor.apply`): the scenario's
``noise_variance``, ``noise_hold``, ``noise_seed`` and the sampled controller's ``ts`` and
``y_quantum`` (:class:`aiofl.engine.discrete_rows.Sampling`, ADC
:math:`Q_q(v) = q\lfloor v/q + 1/2\rfloor`).  A quantum needs a sample time (the
continuous loop has no ADC).  The older places of these quantities, ``[scenario]
noise_*`` and ``[controller.discrete] ts`` / ``y_quantum``, still work; a config that sets
one quantity in two places is refused (:mod:`aiofl.config.run_config`), except a
``[controller.discrete] ts`` that agrees with the sensor's.

**Noise realisations.**  :func:`realisation_seed` derives the seed of realisation ``k``
of a base seed (realisation 0 is the base seed itself): the robustness draws and the noise
realisations of tuning use it, so every draw or realisation has its own, reproducible noise
sequence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from aiofl.engine.discrete_rows import QUANTUM_MIN, Sampling
from aiofl.scenario import realisation_seed

__all__ = [
    "SENSOR_PRESETS",
    "Sensor",
    "check_quantum_range",
    "encoder_quantum",
    "output_range",
    "realisation_seed",
]


def encoder_quantum(bits: int) -> float:
    """The quantum [rad] of an encoder with ``2**bits`` counts per revolution: 2π/2^bits."""
    return 2.0 * math.pi / float(2**bits)


#: the named presets: their fields (ideal: nothing)
SENSOR_PRESETS: dict[str, dict[str, float]] = {
    "ideal": {},
    "encoder-12bit": {"ts": 1e-3, "quantum": encoder_quantum(12)},
    "encoder-14bit": {"ts": 1e-3, "quantum": encoder_quantum(14)},
    "encoder-16bit": {"ts": 1e-3, "quantum": encoder_quantum(16)},
}

#: the Sensor fields a preset or an explicit key may set
FIELDS = ("ts", "quantum", "noise_variance", "noise_hold", "noise_seed")
#: largest sample time [s] (as [controller.discrete] ts)
TS_MAX = 1.0
#: largest measurement quantum accepted whatever the scenario (:func:`check_quantum_range`)
QUANTUM_MAX = 1e6


def output_range(scenario: Any, plant: Any = None) -> float:
    """The largest absolute value the output is asked to take in ``scenario``: the reference over
    the horizon (4097 points, and a samples reference's values) and, given ``plant``, the
    initial output :math:`h(x_0)`."""
    ref = scenario.reference
    t = np.linspace(0.0, scenario.t_final, 4097)
    values = [float(np.max(np.abs(ref.evaluate(t))))]
    if ref.kind == "samples":
        n = min(len(ref.samples), int(scenario.t_final / ref.sample_dt) + 1)
        values.append(float(np.max(np.abs(ref.samples[:n]))))
    if plant is not None:
        try:
            y0 = float(plant.output(np.asarray(scenario.x0 or [0.0] * plant.n_states)))
        except (ValueError, ArithmeticError, TypeError):
            y0 = 0.0
        values.append(abs(y0) if math.isfinite(y0) else 0.0)
    return max(values)


def check_quantum_range(key: str, quantum: float, scenario: Any, plant: Any = None) -> None:
    """Refuse a measurement quantum larger than every value the output takes in ``scenario``
    (:func:`output_range`; ``[sensor] quantum = 1e300`` ran, every reading 0): such a
    sensor measures nothing.  ``key`` names the field in the message.  A scenario whose
    output stays at 0 (regulation at 0 from rest) has no range to compare with: only
    :data:`QUANTUM_MAX` applies.

    Parameters
    ----------
    key
        The config field, for the message.
    quantum
        The quantum.
    scenario
        The scenario whose output range is compared with.
    plant
        Its plant (None: the range of the reference alone, no unit in the message).

    Raises
    ------
    ValueError
        Naming ``key``, its value and the allowed range.
    """
    span = output_range(scenario, plant)
    limit = min(span, QUANTUM_MAX) if span > 0 else QUANTUM_MAX
    if quantum > limit:
        unit = f" {plant.output_unit}" if plant is not None and plant.output_unit else ""
        why = (
            f"larger than the output's range in this scenario (|r| and |y(0)| <= {span:.4g}"
            f"{unit}): every reading would be 0 or one count"
            if span > 0 and span <= QUANTUM_MAX
            else f"larger than {QUANTUM_MAX:g}"
        )
        raise ValueError(
            f"{key} = {quantum:g} is {why}; allowed: 0 (none) or {QUANTUM_MIN:g} <= quantum "
            f"<= {limit:.4g}"
        )


def _number(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"sensor.{name} = {value!r}; allowed: a number")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"sensor.{name} = {value!r}; allowed: a finite number")
    return v


@dataclass(frozen=True)
class Sensor:
    """The measurement a controller gets (see the module docstring).

    Use :meth:`from_preset` to start from a named preset; the constructor checks every
    field as strictly as the ``[sensor]`` table (a bool or string is no number; ranges).

    Parameters
    ----------
    preset
        The preset this sensor came from (a label; ``"custom"`` for none).
    ts
        Sample time [s], ``0 < ts <= 1``; None: the controller is not sampled by the sensor.
    quantum
        Measurement quantum (0: none, else >= :data:`aiofl.engine.discrete_rows.QUANTUM_MIN`).
    noise_variance
        Variance of the Gaussian output noise, >= 0.
    noise_hold
        How long a noise sample is held [s], > 0; None: ``ts``, else 1 ms.
    noise_seed
        Seed of the noise sequence, ``0 <= seed < 2**63``.
    unit
        The unit of the measured output (the plant's ``output_unit``; ``""``: not
        declared): :meth:`describe` writes the quantum in it, as 2π/N only for ``rad``.
    """

    preset: str = "ideal"
    ts: float | None = None
    quantum: float = 0.0
    noise_variance: float = 0.0
    noise_hold: float | None = None
    noise_seed: int = 0
    unit: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.preset, str):
            raise ValueError(f"sensor.preset = {self.preset!r}; allowed: a name")
        if not isinstance(self.unit, str):
            raise ValueError(f"sensor.unit = {self.unit!r}; allowed: a unit's text")
        if self.ts is not None:
            ts = _number("ts", self.ts)
            if not 0 < ts <= TS_MAX:
                raise ValueError(f"sensor.ts = {self.ts!r}; allowed: 0 < ts <= {TS_MAX:g} s")
            object.__setattr__(self, "ts", ts)
        q = _number("quantum", self.quantum)
        if q < 0 or 0 < q < QUANTUM_MIN:
            raise ValueError(
                f"sensor.quantum = {self.quantum!r}; allowed: 0 (none) or >= {QUANTUM_MIN:g} "
                "(an encoder of N counts per revolution: 2π/N rad)"
            )
        object.__setattr__(self, "quantum", q)
        nv = _number("noise_variance", self.noise_variance)
        if nv < 0:
            raise ValueError(f"sensor.noise_variance = {self.noise_variance!r}; allowed: >= 0")
        object.__setattr__(self, "noise_variance", nv)
        if self.noise_hold is not None:
            nh = _number("noise_hold", self.noise_hold)
            if not nh > 0:
                raise ValueError(f"sensor.noise_hold = {self.noise_hold!r}; allowed: > 0 s")
            object.__setattr__(self, "noise_hold", nh)
        seed = self.noise_seed
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
            raise ValueError(f"sensor.noise_seed = {seed!r}; allowed: an integer")
        if not 0 <= int(seed) < 2**63:
            raise ValueError(f"sensor.noise_seed = {seed!r}; allowed: 0 <= seed < 2**63")
        object.__setattr__(self, "noise_seed", int(seed))

    @classmethod
    def from_preset(cls, preset: str = "ideal", **overrides: Any) -> Sensor:
        """The preset ``preset`` (:data:`SENSOR_PRESETS`) with ``overrides`` (fields of
        :class:`Sensor`) replacing its values; raises ``ValueError`` for an unknown preset
        or field, or an out-of-range value."""
        if preset not in SENSOR_PRESETS:
            raise ValueError(f"sensor.preset = {preset!r}; allowed: {', '.join(SENSOR_PRESETS)}")
        unknown = sorted(set(overrides) - set(FIELDS))
        if unknown:
            raise ValueError(
                f"sensor: unknown key(s) {', '.join(unknown)}; allowed: preset, {', '.join(FIELDS)}"
            )
        given = {k: v for k, v in overrides.items() if v is not None}
        return cls(preset=preset, **{**SENSOR_PRESETS[preset], **given})

    @property
    def effective_noise_hold(self) -> float:
        """The hold of a noise sample [s]: ``noise_hold``, else ``ts``, else 1 ms."""
        if self.noise_hold is not None:
            return self.noise_hold
        return self.ts if self.ts is not None else 1e-3

    @property
    def is_ideal(self) -> bool:
        """True for the continuous, unquantised, noise-free measurement."""
        return self.ts is None and self.quantum == 0 and self.noise_variance == 0

    @property
    def label(self) -> str:
        """What this sensor is called: ``"ideal"`` for the ideal measurement, the preset's
        name for a (possibly overridden) encoder preset, else ``"custom"`` (a sensor set by
        its keys alone is no "ideal" one)."""
        if self.is_ideal:
            return "ideal"
        if self.preset in SENSOR_PRESETS and self.preset != "ideal":
            return self.preset
        return "custom"

    def describe(self) -> str:
        """One line: ``encoder-12bit (sampled at 1 ms, quantum 2π/4096 = 0.001534 rad, no
        noise)``; the quantum of an output that is no angle is written in its unit
        (``custom (sampled at 1 ms, quantum 1e-05 m, no noise)``)."""
        parts = []
        parts.append("continuous" if self.ts is None else f"sampled at {1e3 * self.ts:g} ms")
        if self.quantum > 0:
            unit = f" {self.unit}" if self.unit and self.unit != "-" else ""
            counts = 2.0 * math.pi / self.quantum
            if self.unit == "rad" and abs(counts - round(counts)) < 1e-6 * counts:
                parts.append(f"quantum 2π/{round(counts)} = {self.quantum:.4g} rad")
            else:
                parts.append(f"quantum {self.quantum:.4g}{unit}")
        else:
            parts.append("not quantised")
        if self.noise_variance > 0:
            parts.append(
                f"noise variance {self.noise_variance:g} held {1e3 * self.effective_noise_hold:g}"
                f" ms, seed {self.noise_seed}"
            )
        else:
            parts.append("no noise")
        return f"{self.label} ({', '.join(parts)})"

    def apply(self, scenario: Any, sampling: Any = None) -> tuple[Any, Any]:
        """``(scenario, sampling)`` with this sensor's noise and sample time / quantum.

        ``scenario`` is an :class:`aiofl.scenario.Scenario`; ``sampling`` an
        :class:`aiofl.engine.discrete_rows.Sampling` or None (a sensor with ``ts`` makes one).
        Raises ``ValueError`` when the sampling's ts contradicts the sensor's, or for a
        quantum without any sample time.
        """
        scenario = replace(
            scenario,
            noise_variance=self.noise_variance,
            noise_hold=self.effective_noise_hold,
            noise_seed=self.noise_seed,
        )
        if self.ts is not None:
            if sampling is None:
                sampling = Sampling(ts=self.ts)
            elif not math.isclose(sampling.ts, self.ts, rel_tol=1e-12):
                raise ValueError(
                    f"sensor.ts = {self.ts:g} s contradicts controller.discrete.ts = "
                    f"{sampling.ts:g} s; set one of them (or the same value in both)"
                )
        if self.quantum > 0:
            if sampling is None:
                raise ValueError(
                    f"sensor.quantum = {self.quantum:g} needs a sample time: set sensor.ts "
                    "(or [controller.discrete] ts)"
                )
            sampling = replace(sampling, y_quantum=self.quantum)
        return scenario, sampling

    @classmethod
    def of_run(
        cls, scenario: Any, sampling: Any = None, preset: str = "custom", unit: str = ""
    ) -> Sensor:
        """The sensor a scenario and sampling setting amount to (their noise, ts and
        y_quantum); ``preset`` labels it (``"ideal"`` when it is the ideal measurement),
        ``unit`` is the measured output's.

        Parameters
        ----------
        scenario
            The scenario (its noise).
        sampling
            The sampling setting (ts, y_quantum); None: continuous, no quantum.
        preset
            The label (default ``"custom"``).
        unit
            The measured output's unit.

        Returns
        -------
        Sensor
        """
        sensor = cls(
            preset=preset,
            unit=unit,
            ts=None if sampling is None else sampling.ts,
            quantum=0.0 if sampling is None else sampling.y_quantum,
            noise_variance=scenario.noise_variance,
            noise_hold=scenario.noise_hold,
            noise_seed=scenario.noise_seed,
        )
        if preset == "custom" and sensor.is_ideal:
            sensor = replace(sensor, preset="ideal")
        return sensor
