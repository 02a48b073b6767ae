"""Simulation scenarios as data: reference, disturbance, plant change, measurement noise.

The paper's three scenarios (Section V) are instances of :class:`Scenario`:

1. nominal tracking of :math:`r = \\tfrac{\\pi}{4}\\sin 2t` for 20 s;
2. the same with a 0.5 N·m step load torque at t = 10 s and :math:`J_l \\times 1.4` in the
   plant only (the controller is not told);
3. the nominal case with Gaussian output noise of variance :math:`10^{-4}`, held over a
   sample time (1 ms by default, not stated in the paper), seeded.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.checks import check_integer, check_number
from aiofl.limits import T_FINAL_MAX
from aiofl.text import check_text, normal_keys

__all__ = ["DELAY_MAX", "Reference", "Scenario", "noise_sequence", "realisation_seed"]

DELAY_MAX = 1.0
"""Largest input or output transport delay [s] a scenario accepts (the engine's delay
buffer is bounded before it is allocated; see :func:`aiofl.engine.discrete_rows.delay_steps`)."""


#: allowed values of the reference's numbers (as ``[scenario.reference]`` in a config)
_REFERENCE_RANGES: dict[str, dict[str, float]] = {
    "amplitude": {},
    "omega": {"ge": 0.0},
    "phase": {},
    "offset": {},
    "t_step": {"ge": 0.0},
    "sample_dt": {"ge": 0.0},
}
#: allowed values of the scenario's numbers (as ``[scenario]`` in a config)
_SCENARIO_RANGES: dict[str, dict[str, float]] = {
    "t_final": {"gt": 0.0, "le": T_FINAL_MAX},
    "disturbance_amplitude": {},
    "disturbance_time": {"ge": 0.0},
    "parameter_change_time": {"ge": 0.0},
    "noise_variance": {"ge": 0.0},
    "noise_hold": {"gt": 0.0},
    "input_delay": {"ge": 0.0, "le": DELAY_MAX},
    "output_delay": {"ge": 0.0, "le": DELAY_MAX},
    "u_ref": {},
}

ENVELOPE_FACTOR = 10.0
"""The default envelope (:attr:`Scenario.envelope`) in units of the scenario's output
scale: an output ten times farther from the reference than anything the scenario asks for
has left any operating point a design is meant for."""
STEADY_FRACTION = 0.2
"""The steady-state window's default share of the horizon, at its end."""


@dataclass(frozen=True)
class Reference:
    r"""The reference signal r(t).

    ``kind="sine"``: :math:`r = A\sin(\omega t + \varphi) + r_0`;
    ``kind="step"``: :math:`r = r_0 + A\cdot 1(t \ge t_{step})`;
    ``kind="samples"``: linear interpolation of ``samples`` spaced ``sample_dt`` apart
    (held at the last value).
    """

    kind: str = "sine"
    amplitude: float = float(np.pi / 4)
    omega: float = 2.0
    phase: float = 0.0
    offset: float = 0.0
    t_step: float = 0.0
    samples: tuple[float, ...] = ()
    sample_dt: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.kind, str) or self.kind not in L.REF_KINDS:
            raise ValueError(f"reference.kind = {self.kind!r}; allowed: {', '.join(L.REF_KINDS)}")
        # the ranges of the config's [scenario.reference] (aiofl.config.schema.ReferenceModel)
        for name, bounds in _REFERENCE_RANGES.items():
            value = check_number(f"scenario.reference.{name}", getattr(self, name), **bounds)
            object.__setattr__(self, name, value)
        if isinstance(self.samples, (str, bytes)) or not hasattr(self.samples, "__iter__"):
            raise ValueError(
                f"scenario.reference.samples = {self.samples!r}; allowed: a sequence of finite "
                "numbers"
            )
        samples = tuple(
            check_number(f"scenario.reference.samples[{i}]", v) for i, v in enumerate(self.samples)
        )
        if self.kind == "samples" and (len(samples) < 2 or not self.sample_dt > 0):
            raise ValueError(
                "reference.samples needs at least 2 values and reference.sample_dt > 0"
            )
        object.__setattr__(self, "samples", samples)

    def evaluate(self, t: NDArray[np.float64] | float) -> NDArray[np.float64]:
        """r(t), vectorised (the same formula the engine uses)."""
        t = np.asarray(t, dtype=np.float64)
        if self.kind == "sine":
            return self.amplitude * np.sin(self.omega * t + self.phase) + self.offset
        if self.kind == "step":
            return self.offset + self.amplitude * (t >= self.t_step)
        grid = np.arange(len(self.samples)) * self.sample_dt
        return np.interp(t, grid, np.asarray(self.samples))


@dataclass(frozen=True)
class Scenario:
    """Everything about a run that is not the controller.

    Parameters
    ----------
    name
        Label.
    reference
        The reference r(t).
    t_final
        Horizon [s].
    disturbance_amplitude, disturbance_time
        Step input disturbance :math:`\\tau_d` through :math:`b_d` (N·m for the SLFJM).
    plant_scale, plant_overrides
        Changes to the *true* plant's parameters (e.g. ``{"J_l": 1.4}``), effective from
        ``parameter_change_time``; the controller's nominal model is not changed.
    noise_variance, noise_hold, noise_seed
        Gaussian output noise, held constant over ``noise_hold`` seconds, seeded.
    x0
        Initial plant state (zeros if empty).
    input_delay, output_delay
        Transport delays [s], :math:`0 \\le \\tau \\le` :data:`DELAY_MAX`: the plant sees
        :math:`u(t - \\tau_{in})` (0 before :math:`t = \\tau_{in}`) and the controller's ADC
        reads :math:`y(t - \\tau_{out})` (:math:`y(0)` before :math:`t = \\tau_{out}`) plus the
        noise at t.  Each must be an integer multiple of the step dt: the sampled engine
        holds them exactly, the continuous controller by the method of steps
        (:func:`aiofl.engine.discrete_rows.delay_steps`).
    envelope
        The operating envelope: a run whose :math:`|y - r|` exceeds it is *lost* (stopped
        and reported with the time; ``inf`` switches it off).  None (default):
        :data:`ENVELOPE_FACTOR` times the scenario's output scale, the largest of
        :math:`|r(t)|` and :math:`|y(0)|` (:meth:`default_envelope`); no envelope when
        that scale is 0.  A plant may also declare ranges of its states and output
        (:attr:`aiofl.plants.base.Plant.state_bounds`, ``output_range``).
    u_ref
        ISU and IAU measure :math:`u - u_{ref}` (default 0): the holding input at the
        operating point (:func:`aiofl.plants.operating_point.trim`), so that holding the plant
        there costs nothing and a tuner weighs only the control effort beyond it.
    steady_from
        The steady-state window starts here [s] (its noise in u and steady-state error);
        None (default): the last :data:`STEADY_FRACTION` of the horizon.
    """

    name: str = "custom"
    reference: Reference = field(default_factory=Reference)
    t_final: float = 20.0
    disturbance_amplitude: float = 0.0
    disturbance_time: float = 0.0
    plant_scale: Mapping[str, float] = field(default_factory=dict)
    plant_overrides: Mapping[str, float] = field(default_factory=dict)
    parameter_change_time: float = 0.0
    noise_variance: float = 0.0
    noise_hold: float = 1e-3
    noise_seed: int = 0
    x0: tuple[float, ...] = ()
    input_delay: float = 0.0
    output_delay: float = 0.0
    envelope: float | None = None
    u_ref: float = 0.0
    steady_from: float | None = None

    def __post_init__(self) -> None:
        check_text("scenario.name", self.name)
        if not isinstance(self.reference, Reference):
            raise ValueError(
                f"scenario.reference = {self.reference!r}; allowed: an aiofl.Reference"
            )
        # the ranges of the config's [scenario] (aiofl.config.schema.ScenarioModel)
        for name, bounds in _SCENARIO_RANGES.items():
            object.__setattr__(
                self, name, check_number(f"scenario.{name}", getattr(self, name), **bounds)
            )
        seed = check_integer("scenario.noise_seed", self.noise_seed, ge=0, lt=2**63)
        object.__setattr__(self, "noise_seed", seed)
        for table, bounds in (("plant_scale", {"gt": 0.0}), ("plant_overrides", {})):
            given = getattr(self, table)
            if not isinstance(given, Mapping):
                raise ValueError(
                    f"scenario.{table} = {given!r}; allowed: a mapping of plant parameter "
                    "names to numbers"
                )
            checked = {}
            for key, value in normal_keys(f"scenario.{table}", given).items():
                checked[key] = check_number(f"scenario.{table}.{key}", value, **bounds)
            object.__setattr__(self, table, MappingProxyType(checked))
        if isinstance(self.x0, (str, bytes)) or not hasattr(self.x0, "__iter__"):
            raise ValueError(f"scenario.x0 = {self.x0!r}; allowed: a sequence of finite numbers")
        x0 = tuple(check_number(f"scenario.x0[{i}]", v) for i, v in enumerate(self.x0))
        object.__setattr__(self, "x0", x0)
        if self.envelope is not None:
            env = check_number("scenario.envelope", self.envelope, gt=0.0, finite=False)
            object.__setattr__(self, "envelope", env)
        if self.steady_from is not None:
            start = check_number("scenario.steady_from", self.steady_from, ge=0.0)
            if start >= self.t_final:
                raise ValueError(
                    f"scenario.steady_from = {self.steady_from!r}; allowed: >= 0 and below "
                    f"the horizon t_final = {self.t_final:g} s"
                )
            object.__setattr__(self, "steady_from", start)

    def output_scale(self, y0: float = 0.0) -> float:
        """The largest of :math:`|r(t)|` over the horizon and :math:`|y_0|`: the size of
        the outputs this scenario asks for (its default envelope's unit)."""
        ref = self.reference
        if ref.kind == "sine":
            r_max = abs(ref.offset) + abs(ref.amplitude)
        elif ref.kind == "step":
            r_max = max(abs(ref.offset), abs(ref.offset + ref.amplitude))
        else:
            r_max = max((abs(v) for v in ref.samples), default=0.0)
        return max(r_max, abs(float(y0)) if math.isfinite(y0) else 0.0)

    def default_envelope(self, y0: float = 0.0) -> float:
        """The envelope used when :attr:`envelope` is None: :data:`ENVELOPE_FACTOR` times
        :meth:`output_scale` (``inf``, no envelope, when the scale is 0)."""
        scale = self.output_scale(y0)
        return ENVELOPE_FACTOR * scale if scale > 0.0 else math.inf

    def resolved_envelope(self, y0: float = 0.0) -> float:
        """The envelope a run uses: :attr:`envelope`, or :meth:`default_envelope`."""
        return self.envelope if self.envelope is not None else self.default_envelope(y0)

    @property
    def steady_start(self) -> float:
        """Where the steady-state window starts [s] (:attr:`steady_from` or its default)."""
        if self.steady_from is not None:
            return self.steady_from
        return (1.0 - STEADY_FRACTION) * self.t_final

    @property
    def noise_samples(self) -> int:
        """Held noise samples the engine stores over the horizon: one per ``noise_hold``
        interval, plus the last partial interval and the sample at ``t_final``."""
        return math.ceil(self.t_final / self.noise_hold) + 2

    def initial_value(self) -> float:
        """r(0): where the scenario starts the plant's output (the operating point a trim,
        a bumpless start or ``u_ref = "trim"`` refers to)."""
        ref = self.reference
        if ref.kind == "sine":
            return float(ref.offset + ref.amplitude * math.sin(ref.phase))
        if ref.kind == "step":
            return float(ref.offset + (ref.amplitude if ref.t_step <= 0.0 else 0.0))
        return float(ref.samples[0]) if ref.samples else 0.0

    def row(self) -> NDArray[np.float64]:
        """The engine's scenario row (:mod:`aiofl.layout` ``S_*`` columns)."""
        ref = self.reference
        row = np.zeros(L.N_SCEN)
        row[L.S_REF_KIND] = L.REF_KINDS[ref.kind]
        row[L.S_REF_A] = ref.amplitude
        row[L.S_REF_OMEGA] = ref.omega
        row[L.S_REF_PHASE] = ref.phase
        row[L.S_REF_OFFSET] = ref.offset
        row[L.S_REF_TSTEP] = ref.t_step
        row[L.S_REF_DT] = ref.sample_dt
        row[L.S_DIST_AMP] = self.disturbance_amplitude
        row[L.S_DIST_TIME] = self.disturbance_time
        row[L.S_PCHANGE_TIME] = self.parameter_change_time
        row[L.S_NOISE_STD] = np.sqrt(self.noise_variance)
        row[L.S_NOISE_HOLD] = self.noise_hold
        row[L.S_IN_DELAY] = self.input_delay
        row[L.S_OUT_DELAY] = self.output_delay
        row[L.S_ENVELOPE] = self.resolved_envelope()
        row[L.S_U_REF] = self.u_ref
        row[L.S_STEADY_FROM] = self.steady_start
        return row


def noise_sequence(seed: int, n: int) -> NDArray[np.float64]:
    """``n`` standard normal samples from ``numpy.random.default_rng(seed)``.

    The engine scales them by the scenario's standard deviation and holds sample k over
    ``[k·hold, (k+1)·hold)``; the same seed always gives the same noise.
    """
    return np.random.default_rng(seed).standard_normal(n)


def realisation_seed(seed: int, k: int) -> int:
    """The noise seed of realisation ``k`` of base seed ``seed``.

    ``k = 0`` gives ``seed`` itself (one realisation is today's run); ``k >= 1`` gives
    ``SeedSequence(seed, spawn_key=(k,))``'s first 63-bit word: deterministic, different
    for every ``k`` and independent of how many realisations are drawn.
    """
    if k == 0:
        return int(seed)
    word = np.random.SeedSequence(int(seed), spawn_key=(int(k),)).generate_state(1, np.uint64)[0]
    return int(word) >> 1
