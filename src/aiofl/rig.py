r"""A rig as data: what a real loop adds to the plant model (the ``[rig]`` table).

A design tuned on a model meets, on a rig, dynamics nobody told it about: the
measurement arrives late, the command is applied late, the actuator (amplifier, motor
current loop, valve) follows the command with a lag and a bounded rate, and friction at
the plant's input eats part of the command.  :class:`Rig` holds these quantities in one
place:

.. code-block:: toml

    [rig]
    preset = "servo-1khz"        # ideal | servo-1khz
    # explicit keys override the preset's values:
    measurement_delay = 1e-3     # [s]: the ADC reads y(t - τ_m)
    computation_delay = 0.0      # [s]: the plant gets u(t - τ_c)
    lag = 1e-3                   # [s]: first-order actuator τ_a u̇_a = u - u_a
    lag2 = [2000.0, 0.7]         # (ω_n [rad/s], ζ): second-order actuator (instead of lag)
    rate_limit = 500.0           # |u̇_a| <= R [input units / s] (needs lag)
    coulomb = 0.1                # F_c [input units]: u_eff = u_a - F_c tanh(v/ε) - b_v v
    viscous = 0.0                # b_v [input units per unit of v]
    friction_state = "x3"        # the plant state that is v (required with friction)
    smoothing = 1e-3             # ε [units of v]
    sensor = "encoder-12bit"     # the [sensor] preset the rig pairs with

**The model** (:func:`aiofl.plants.actuated.with_rig`, by augmenting the plant's state;
the controller is not told, it still designs for the bare plant):

* actuator, first order: :math:`\tau_a \dot u_a = u - u_a`; second order:
  :math:`\ddot u_a = \omega_n^2 (u - u_a) - 2\zeta\omega_n \dot u_a`;
* rate limit (first-order actuator only): :math:`\dot u_a = \operatorname{clip}((w - u_a)
  /\tau_a, -R, R)` with :math:`\tau_w \dot w = u - w` a fast input filter,
  :math:`\tau_w` = ``rate_filter`` (default :math:`\tau_a/10`): the plant interface is
  affine in u, a clip of u is not, so the command reaches the clip through :math:`w`
  (:math:`w \to u` as :math:`\tau_w \to 0`; the clip itself is exact, not smoothed);
* friction at the plant input, in the input's units: :math:`u_{eff} = u_a - F_c
  \tanh(v/\varepsilon) - b_v v`, :math:`v` the state named ``friction_state``;
  :math:`\tanh(v/\varepsilon)` is the smooth approximation of :math:`\operatorname{sign}
  (v)` (Olsson, Åström, Canudas de Wit, Gäfvert & Lischinsky, *Friction models and friction
  compensation*, Eur. J. Control 4(3), 1998, §3: the classical Coulomb + viscous model);
  it converges to the discontinuous model as :math:`\varepsilon \to 0` wherever
  :math:`v \ne 0`;
* delays: ``measurement_delay`` becomes the scenario's ``output_delay`` (the ADC reads
  :math:`y(t - \tau_m)`), ``computation_delay`` its ``input_delay`` (the plant gets
  :math:`u(t - \tau_c)`); the sampled engine holds both exactly at integer multiples of its
  step, the continuous controller by the method of steps
  (:func:`aiofl.engine.discrete_rows.delay_steps`).  The controller's own one-sample
  computation delay, ``[controller.discrete] delay = 1``, is a delay the controller *knows*
  (its ESO is fed the applied command); the rig's is not known to it.
  A delay that is not a multiple of the step is held exactly at a finer step
  (:func:`aiofl.config.rig_table.refined_step`).

**Presets** (:data:`RIG_PRESETS`): ``"ideal"`` adds nothing; ``"servo-1khz"`` is a 1 kHz
servo rig: the ``encoder-12bit`` sensor (Ts = 1 ms, quantum 2π/4096), one sample of
measurement delay (1 ms), a 1 ms first-order actuator lag and Coulomb friction
:math:`F_c` = 0.01 input units, i.e. 1 % of a unit input (1 V for the SLFJM: 2.1 mN·m at
the hub, 0.87 % of its gravity torque :math:`m g h` = 0.237 N·m), smoothed over
:math:`\varepsilon` = 1e-3 (rad/s for the SLFJM's hub rate).  With it the shipped
assisted S1 design measures nominal ITAE 0.197 @ ISU 18.3, the independent check's 0.195
@ 18.2 (issue 36); 1 % of a ±10 V full scale (:math:`F_c` = 0.1) would double its ITAE.
Friction needs the name of the velocity state, which no preset can know: give
``friction_state``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

from aiofl.checks import check_number
from aiofl.scenario import DELAY_MAX
from aiofl.text import check_text

__all__ = ["LAG_MAX", "RIG_FIELDS", "RIG_PRESETS", "RIG_RANGES", "Rig"]

LAG_MAX = 1.0
"""Largest actuator time constant [s] (and smallest ω_n = 1/LAG_MAX rad/s)."""

#: the named presets: their fields (ideal: nothing).  servo-1khz's F_c: 1 % of one input unit.
RIG_PRESETS: dict[str, dict[str, Any]] = {
    "ideal": {},
    "servo-1khz": {
        "sensor": "encoder-12bit",
        "measurement_delay": 1e-3,
        "lag": 1e-3,
        "coulomb": 0.01,
        "smoothing": 1e-3,
    },
}

#: allowed values of the rig's numbers (check_number's bounds); lag2 and rate_limit apart
RIG_RANGES: dict[str, dict[str, float]] = {
    "measurement_delay": {"ge": 0.0, "le": DELAY_MAX},
    "computation_delay": {"ge": 0.0, "le": DELAY_MAX},
    "lag": {"ge": 0.0, "le": LAG_MAX},
    "coulomb": {"ge": 0.0, "le": 1e6},
    "viscous": {"ge": 0.0, "le": 1e6},
    "smoothing": {"gt": 0.0, "le": 1e6},
}
WN_RANGE = (1.0 / LAG_MAX, 1e6)  #: ω_n of the second-order actuator [rad/s]
ZETA_RANGE = (1e-3, 10.0)  #: its damping ratio ζ
RATE_RANGE = (1e-9, 1e12)  #: rate limit R [input units/s] (inf: none)


@dataclass(frozen=True)
class Rig:
    """What a real loop adds to the plant (see the module docstring for the model).

    Parameters
    ----------
    preset
        The preset's name (``"custom"`` when built from fields alone).
    sensor
        The ``[sensor]`` preset the rig pairs with (:data:`aiofl.sensor.SENSOR_PRESETS`).
    measurement_delay, computation_delay
        Transport delays [s], 0 .. :data:`aiofl.scenario.DELAY_MAX`.
    lag
        First-order actuator time constant τ_a [s], 0 (none) .. :data:`LAG_MAX`.
    lag2
        ``(ω_n, ζ)`` of a second-order actuator, or None; not together with ``lag``.
    rate_limit
        R [input units/s], ``inf`` for none; needs ``lag``.
    rate_filter
        τ_w [s] of the input filter the rate limit reads (None: τ_a/10).
    coulomb, viscous
        F_c [input units], b_v [input units per unit of v], >= 0.
    friction_state
        Name of the plant state v that friction opposes (checked against the plant when
        applied, :func:`aiofl.plants.actuated.with_rig`).
    smoothing
        ε [units of v] of :math:`\\tanh(v/\\varepsilon)`.
    """

    preset: str = "custom"
    sensor: str = "ideal"
    measurement_delay: float = 0.0
    computation_delay: float = 0.0
    lag: float = 0.0
    lag2: tuple[float, float] | None = None
    rate_limit: float = math.inf
    rate_filter: float | None = None
    coulomb: float = 0.0
    viscous: float = 0.0
    friction_state: str = ""
    smoothing: float = 1e-3

    def __post_init__(self) -> None:
        check_text("rig.preset", self.preset)
        check_text("rig.sensor", self.sensor)
        check_text("rig.friction_state", self.friction_state)
        for name, bounds in RIG_RANGES.items():
            object.__setattr__(
                self, name, check_number(f"rig.{name}", getattr(self, name), **bounds)
            )
        rate = check_number("rig.rate_limit", self.rate_limit, gt=0.0, finite=False)
        if math.isfinite(rate) and not RATE_RANGE[0] <= rate <= RATE_RANGE[1]:
            raise ValueError(
                f"rig.rate_limit = {rate:g}; allowed: {RATE_RANGE[0]:g} .. {RATE_RANGE[1]:g} "
                "input units/s, or inf (none)"
            )
        object.__setattr__(self, "rate_limit", rate)
        if self.lag2 is not None:
            pair = self.lag2
            if isinstance(pair, (str, bytes)) or not hasattr(pair, "__len__") or len(pair) != 2:
                raise ValueError(f"rig.lag2 = {pair!r}; allowed: a pair [omega_n, zeta]")
            wn = check_number("rig.lag2[0] (omega_n)", pair[0], ge=WN_RANGE[0], le=WN_RANGE[1])
            zeta = check_number("rig.lag2[1] (zeta)", pair[1], ge=ZETA_RANGE[0], le=ZETA_RANGE[1])
            object.__setattr__(self, "lag2", (wn, zeta))
            if self.lag > 0.0:
                raise ValueError(
                    f"rig.lag = {self.lag:g} and rig.lag2 = {list(self.lag2)} are both set; "
                    "allowed: one actuator model (lag: first order, lag2: second order)"
                )
        if math.isfinite(self.rate_limit) and not self.lag > 0.0:
            raise ValueError(
                f"rig.rate_limit = {self.rate_limit:g} needs a first-order actuator (rig.lag > "
                "0): the limit bounds its rate; allowed: inf without lag"
            )
        if self.rate_filter is not None:
            tau_w = check_number("rig.rate_filter", self.rate_filter, gt=0.0, le=LAG_MAX)
            object.__setattr__(self, "rate_filter", tau_w)
        if self.has_friction and not self.friction_state:
            raise ValueError(
                "rig.coulomb / rig.viscous need rig.friction_state: the name of the plant "
                "state that is the velocity friction opposes"
            )

    @classmethod
    def from_preset(cls, preset: str = "ideal", **overrides: Any) -> Rig:
        """The preset ``preset`` (:data:`RIG_PRESETS`) with ``overrides`` (fields of
        :class:`Rig`); ValueError naming an unknown preset or field."""
        if preset not in RIG_PRESETS:
            raise ValueError(f"rig.preset = {preset!r}; allowed: {', '.join(RIG_PRESETS)}")
        unknown = sorted(set(overrides) - set(RIG_FIELDS))
        if unknown:
            raise ValueError(
                f"rig: unknown field(s) {', '.join(unknown)}; allowed: {', '.join(RIG_FIELDS)}"
            )
        return cls(preset=preset, **{**RIG_PRESETS[preset], **overrides})

    @property
    def has_friction(self) -> bool:
        """Whether friction is modelled (F_c > 0 or b_v > 0)."""
        return self.coulomb > 0.0 or self.viscous > 0.0

    @property
    def has_rate_limit(self) -> bool:
        """Whether the actuator's rate is bounded."""
        return math.isfinite(self.rate_limit)

    @property
    def actuator_order(self) -> int:
        """States the actuator adds: 0 (none), 1 (lag), 2 (lag2), +1 for the rate limit's
        input filter."""
        order = 2 if self.lag2 is not None else (1 if self.lag > 0.0 else 0)
        return order + (1 if self.has_rate_limit else 0)

    @property
    def effective_rate_filter(self) -> float:
        """τ_w [s]: ``rate_filter``, or τ_a/10."""
        return self.rate_filter if self.rate_filter is not None else self.lag / 10.0

    @property
    def augments_plant(self) -> bool:
        """Whether the plant's model changes (an actuator or friction)."""
        return self.actuator_order > 0 or self.has_friction

    def describe(self) -> str:
        """One line per quantity that is set."""
        lines = [f"rig {self.preset!r}: sensor {self.sensor!r}"]
        if self.measurement_delay:
            lines.append(f"measurement delay {self.measurement_delay:g} s")
        if self.computation_delay:
            lines.append(f"computation delay {self.computation_delay:g} s")
        if self.lag:
            lines.append(f"first-order actuator lag τ_a = {self.lag:g} s")
        if self.lag2 is not None:
            lines.append(
                f"second-order actuator ω_n = {self.lag2[0]:g} rad/s, ζ = {self.lag2[1]:g}"
            )
        if self.has_rate_limit:
            lines.append(
                f"rate limit |du_a/dt| <= {self.rate_limit:g} /s (input filter "
                f"τ_w = {self.effective_rate_filter:g} s)"
            )
        if self.has_friction:
            lines.append(
                f"friction on {self.friction_state}: F_c = {self.coulomb:g}, b_v = "
                f"{self.viscous:g}, tanh smoothing ε = {self.smoothing:g}"
            )
        return "\n".join(lines)


RIG_FIELDS: tuple[str, ...] = tuple(f.name for f in fields(Rig) if f.name != "preset")
"""The fields a ``[rig]`` table or an override may set (beside ``preset``)."""
