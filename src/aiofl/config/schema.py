"""The TOML schema of a run config: one validated pydantic model per table.

Every table rejects unknown keys (the error lists the allowed ones); numbers are strict (no
bool or string coercion) and range-checked, so a bad file fails with a message that names
the field and its allowed range.  The models build the engine's descriptions
(:class:`~aiofl.scenario.Scenario`, :class:`~aiofl.controller.Controller`, the OPI weights);
reading files, presets and the checks that need the plant are in
:mod:`aiofl.config.run_config`.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import Field, field_validator, model_validator

from aiofl import layout as L
from aiofl.components.metrics import OPIWeights
from aiofl.controller import STRUCTURES, Controller
from aiofl.limits import (
    DT_MAX,
    MAX_STEPS,
    T_FINAL_MAX,
)
from aiofl.rig import LAG_MAX, RIG_PRESETS, Rig
from aiofl.scenario import DELAY_MAX, Reference, Scenario
from aiofl.sensor import SENSOR_PRESETS, Sensor
from aiofl.table_model import TableModel
from aiofl.text import MAX_DESCRIPTION_CHARS, MAX_PATH_CHARS, check_text, normal_keys
from aiofl.uncertainty import UncertaintyModel

__all__ = [
    "REQUIRED_KEYS",
    "ConfigError",
    "ConfigModel",
    "ControllerModel",
    "DiscreteModel",
    "RigModel",
    "ScenarioModel",
    "SensorModel",
]

#: keys every config must set (an empty or cut-off file is refused, not run with defaults)
REQUIRED_KEYS = ("plant", "scenario.t_final", "controller.structure", "simulation.dt")

PosFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegFloat = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]
#: a noise intensity (eso.q, eso.r): positive, at most 1e300 (q/r and its root stay finite)
Intensity = Annotated[float, Field(gt=0, le=1e300, allow_inf_nan=False)]


class ConfigError(ValueError):
    """A config that cannot be used; the message names the field and the allowed range."""


# ---------------------------------------------------------------------- scenario
class ReferenceModel(TableModel):
    kind: Literal["sine", "step", "samples"] = "sine"
    amplitude: Finite = math.pi / 4
    omega: NonNegFloat = 2.0
    phase: Finite = 0.0
    offset: Finite = 0.0
    t_step: NonNegFloat = 0.0
    samples: list[Finite] = Field(default_factory=list)
    sample_dt: NonNegFloat = 0.0

    @model_validator(mode="after")
    def _samples(self) -> ReferenceModel:
        if self.kind == "samples" and (len(self.samples) < 2 or self.sample_dt <= 0):
            raise ValueError("kind = 'samples' needs >= 2 samples and sample_dt > 0")
        return self


class ScenarioModel(TableModel):
    name: str = "custom"
    reference: ReferenceModel = Field(default_factory=ReferenceModel)
    t_final: Annotated[float, Field(gt=0, le=T_FINAL_MAX, allow_inf_nan=False)] = 20.0
    disturbance_amplitude: Finite = 0.0
    disturbance_time: NonNegFloat = 0.0
    plant_scale: dict[str, PosFloat] = Field(default_factory=dict)
    plant_overrides: dict[str, Finite] = Field(default_factory=dict)
    parameter_change_time: NonNegFloat = 0.0
    noise_variance: NonNegFloat = 0.0
    noise_hold: PosFloat = 1e-3
    noise_seed: Annotated[int, Field(ge=0, lt=2**63)] = 0
    x0: list[Finite] = Field(default_factory=list)
    # transport delays [s] (sampled controllers; integer multiples of simulation.dt)
    input_delay: Annotated[float, Field(ge=0, le=DELAY_MAX, allow_inf_nan=False)] = 0.0
    output_delay: Annotated[float, Field(ge=0, le=DELAY_MAX, allow_inf_nan=False)] = 0.0
    # the operating envelope: |y - r| above it makes a run lost (inf: none; absent: ten
    # times the scenario's output scale, aiofl.scenario.Scenario.envelope)
    envelope: Annotated[float, Field(gt=0)] | None = None
    # ISU and IAU of u - u_ref; "trim": the holding input at the reference's first value
    # (aiofl.plants.operating_point)
    u_ref: Finite | Literal["trim"] = 0.0
    # the steady-state window's start [s] (absent: the last 20 % of the horizon)
    steady_from: NonNegFloat | None = None

    @model_validator(mode="after")
    def _envelope_not_nan(self) -> ScenarioModel:
        if self.envelope is not None and math.isnan(self.envelope):
            raise ValueError("scenario.envelope = nan; allowed: a number > 0 (inf: no envelope)")
        if self.steady_from is not None and self.steady_from >= self.t_final:
            raise ValueError(
                f"scenario.steady_from = {self.steady_from:g} s; allowed: 0 <= steady_from < "
                f"t_final = {self.t_final:g} s"
            )
        return self

    @field_validator("name")
    @classmethod
    def _name(cls, v: str) -> str:
        return check_text("scenario.name", v)

    @field_validator("plant_scale", "plant_overrides")
    @classmethod
    def _parameter_names(cls, v: dict[str, float], info: Any) -> dict[str, float]:
        # plant parameter names, read as the plant declares them (Unicode NFKC)
        return normal_keys(f"scenario.{info.field_name}", v)

    @model_validator(mode="after")
    def _events_within_horizon(self) -> ScenarioModel:
        # an event after the horizon never happens: refused, so a typo (10 for 1.0, or a
        # 10-s event in a 5-s run) is not silently ignored
        events = {
            "disturbance_time": self.disturbance_time,
            "parameter_change_time": self.parameter_change_time,
            "reference.t_step": self.reference.t_step,
        }
        for key, t in events.items():
            if t > self.t_final:
                raise ValueError(
                    f"scenario.{key} = {t:g} s is after the horizon t_final = "
                    f"{self.t_final:g} s; allowed: 0 <= {key} <= t_final"
                )
        # a delay as long as the horizon: no command (input) or no measurement (output)
        # ever arrives within the run
        for key in ("input_delay", "output_delay"):
            tau = getattr(self, key)
            if tau > 0 and tau >= self.t_final:
                raise ValueError(
                    f"scenario.{key} = {tau:g} s is not shorter than the horizon t_final = "
                    f"{self.t_final:g} s: nothing it delays arrives within the run; allowed: "
                    f"0 <= {key} < t_final"
                )
        return self

    def build(self) -> Scenario:
        ref = Reference(**{**self.reference.model_dump(), "samples": tuple(self.reference.samples)})
        data = self.model_dump(exclude={"reference"})
        data["x0"] = tuple(self.x0)
        if data["u_ref"] == "trim":  # resolved with the plant (aiofl.config.run_config)
            data["u_ref"] = 0.0
        return Scenario(reference=ref, **data)


# -------------------------------------------------------------------- controller
#: the parameters each component kind uses that have no sensible default: a config whose
#: controller uses the kind must give them ([controller.TABLE] KEY); the kinds come from
#: ``structure`` (STRUCTURES) or the ``*_kind`` keys
REQUIRED_BY_KIND: dict[tuple[str, str], tuple[str, ...]] = {
    ("eso", "linear"): ("omega0",),  # bandwidth gains; Kalman gains need q instead
    ("eso", "improved"): ("omega0", "k_alpha", "k_beta", "g_alpha", "g_beta"),
    ("td", "han"): ("R",),
    ("td", "improved"): ("a", "b", "c", "rho"),
    ("td", "linear"): ("omega",),
    ("td", "exact"): (),
    ("sef", "nonlinear"): ("alpha", "delta"),
    ("sef", "improved"): ("k", "kb", "mu", "alpha"),
    ("sef", "linear"): ("omega_c",),
    ("law", "aiofl"): ("b0",),
    ("law", "iofl"): ("b0",),
}

#: documented defaults of parameters a kind uses, printed by ``aiofl simulate --check``
#: when the config leaves them out: (table, key, kinds that use it, the default in words)
DOCUMENTED_DEFAULTS: tuple[tuple[str, str, tuple[str, ...], str], ...] = (
    ("eso", "alpha", ("linear", "improved"), '"binomial" (Gao: all observer poles at -omega0)'),
    ("sef", "k", ("nonlinear",), "1 for every fed-back state"),
    ("sef", "v_limit", ("improved",), "1"),
    ("law", "u_max", ("aiofl", "iofl"), "inf (no actuator limit)"),
)


def controller_kinds(structure: str | None, chosen: dict[str, str | None]) -> dict[str, str]:
    """The component kinds (eso, td, sef, law) of ``structure`` with the ``*_kind`` keys
    ``chosen`` (None: the structure's)."""
    kinds = dict(zip(("eso", "td", "sef", "law"), STRUCTURES[structure or "LESO"], strict=True))
    kinds.update({k: v for k, v in chosen.items() if v is not None})
    return kinds


class ESOModel(TableModel):
    omega0: PosFloat = 10.0
    alpha: list[NonNegFloat] | Literal["binomial"] = "binomial"
    k_alpha: NonNegFloat = 1.0
    k_beta: NonNegFloat = 0.0
    g_alpha: Annotated[float, Field(gt=0, le=2)] = 1.0
    g_beta: Annotated[float, Field(ge=0, le=2)] = 0.0
    # "zero": xi_hat(0) = 0; "output": xi_hat_1(0) = y_meas(0), the first measurement;
    # "bumpless": "output" and the differentiator / prefilter at rest at y_meas(0)
    init: Literal["zero", "output", "bumpless"] = "zero"
    # the command held at the start (output / bumpless start): the extended state starts at
    # -b0 u0, so u(0) = u0; "trim": the holding input at the scenario's initial output
    u0: Finite | Literal["trim"] = 0.0
    # a known measurement delay [s], a whole number (<= 8) of the sampled controller's ts:
    # the ESO is fed the command that many samples older and the reference is delayed as
    # much (aligned with the measurement); "rig": the [rig]'s measurement_delay
    delay: Annotated[float, Field(ge=0, le=1)] | Literal["rig"] = 0.0
    # what the observer is given besides rho and b0: "none" (model-free, eq. 5) or
    # "nominal" (model-assisted: the plant's nominal alpha + beta u at x_hat = Phi^-1(xi_hat))
    model: Literal["none", "nominal"] = "none"
    # "bandwidth": beta_i = alpha_i omega0^i; "kalman": steady-state Kalman gains from q, r
    # (aiofl.components.kalman); omega0 and alpha are then derived and may not be given
    gains: Literal["bandwidth", "kalman"] = "bandwidth"
    q: Intensity | None = None  # process-noise intensity on the extended state's derivative
    r: Intensity | None = None  # measurement-noise intensity; default: from the scenario

    @model_validator(mode="after")
    def _gains(self) -> ESOModel:
        given = self.model_fields_set
        if self.gains == "bandwidth":
            extra = [f"controller.eso.{k}" for k in ("q", "r") if getattr(self, k) is not None]
            if extra:
                raise ValueError(
                    f"{', '.join(extra)} set but controller.eso.gains = 'bandwidth' (the "
                    "gains are alpha_i*omega0^i); allowed: gains = 'kalman' to use them"
                )
            return self
        fixed = [f"controller.eso.{k}" for k in ("alpha", "omega0") if k in given]
        if fixed:
            raise ValueError(
                f"controller.eso.gains = 'kalman' derives the observer gains (and the "
                f"equivalent omega0, alpha) from q and r; {' and '.join(fixed)} given too: "
                "remove it, or use gains = 'bandwidth'"
            )
        if self.q is None:
            raise ValueError(
                "controller.eso.gains = 'kalman' needs controller.eso.q, the process-noise "
                "intensity on the extended state's derivative; allowed: a number > 0"
            )
        return self


class TDModel(TableModel):
    R: PosFloat = 100.0
    a: Annotated[float, Field(ge=0, lt=1)] = 0.0
    b: PosFloat = 1.0
    c: PosFloat = 1.0
    rho: PosFloat = 10.0
    omega: PosFloat = 10.0


class SEFModel(TableModel):
    k: list[Finite] | None = None
    kb: list[Finite] | None = None
    alpha: list[Annotated[float, Field(gt=0, le=3)]] | None = None
    delta: list[PosFloat] | None = None
    mu: list[NonNegFloat] | None = None
    v_limit: PosFloat = 1.0
    omega_c: PosFloat = 1.0


class LawModel(TableModel):
    b0: Finite = 1.0  # non-zero; negative for a plant whose high-frequency gain is negative
    u_max: float = math.inf  # actuator range [u_min, u_max]; u_min omitted: [-u_max, u_max]
    u_min: float | None = None

    @field_validator("b0")
    @classmethod
    def _b0(cls, v: float) -> float:
        if v == 0.0:
            raise ValueError(
                "b0 = 0; allowed: finite and non-zero (negative for a plant "
                "whose high-frequency gain is negative)"
            )
        return v

    @model_validator(mode="after")
    def _range(self) -> LawModel:
        lo, hi = self.u_min, self.u_max
        if math.isnan(hi) or (lo is not None and math.isnan(lo)):
            raise ValueError("u_min / u_max must be numbers (inf for no limit), not nan")
        if lo is None and not hi > 0:
            raise ValueError(
                f"u_max = {hi}; allowed: > 0 (the range is [-u_max, u_max] unless u_min is given)"
            )
        if lo is not None and not lo < hi:
            raise ValueError(f"u_min = {lo} must be < u_max = {hi}")
        return self


class DiscreteModel(TableModel):
    """``[controller.discrete]``: run the controller sampled (:mod:`aiofl.engine.discrete_rows`).

    ``delay`` is the integer 0 or 1 (``true`` is refused); ``h0`` is bounded by the sample
    time (:data:`aiofl.engine.discrete_rows.H0_RANGE`, checked with dt); the sample count over
    the horizon with the scenario (:meth:`aiofl.engine.discrete_rows.Sampling.check_horizon`).
    """

    ts: Annotated[float, Field(gt=0, le=1.0, allow_inf_nan=False)]
    delay: Annotated[int, Field(ge=0, le=1)] = 0  # strict: an int, never a bool
    y_quantum: NonNegFloat = 0.0
    u_quantum: NonNegFloat = 0.0
    eso: Literal["zoh", "euler"] | None = None
    td: Literal["fhan", "euler"] = "fhan"
    h0: PosFloat | None = None

    @field_validator("y_quantum", "u_quantum")
    @classmethod
    def _quantum(cls, v: float) -> float:
        from aiofl.engine.discrete_rows import QUANTUM_MIN

        if 0 < v < QUANTUM_MIN:  # 1/q overflows for subnormal q: NaN in the quantiser
            raise ValueError(f"allowed: 0 (none) or a quantum >= {QUANTUM_MIN:g}")
        return v

    def build(self) -> Any:
        from aiofl.engine.discrete_rows import Sampling

        return Sampling(**self.model_dump())


class ControllerModel(TableModel):
    structure: Literal["LESO", "INLESO", "LADRC", "IOFL"] | None = None
    eso_kind: Literal["linear", "improved"] | None = None
    td_kind: Literal["exact", "han", "improved", "linear"] | None = None
    sef_kind: Literal["nonlinear", "improved", "linear"] | None = None
    law_kind: Literal["aiofl", "iofl"] | None = None
    rho: Annotated[int, Field(ge=1, le=L.RHO_MAX)] | None = None
    # default: rho, or the paper's 2 behind the Han TD / ITD (controller.default_n_feedback)
    n_feedback: Annotated[int, Field(ge=1, le=L.RHO_MAX)] | None = None
    allow_rho_mismatch: bool = False  # run a rho other than the plant's relative degree
    allow_b0_sign_mismatch: bool = False  # run a b0 whose sign differs from the plant's beta
    eso: ESOModel = Field(default_factory=ESOModel)
    td: TDModel = Field(default_factory=TDModel)
    sef: SEFModel = Field(default_factory=SEFModel)
    law: LawModel = Field(default_factory=LawModel)
    discrete: DiscreteModel | None = None

    def kinds(self) -> dict[str, str]:
        """The component kinds this table selects (``structure`` and the ``*_kind`` keys)."""
        chosen = {key: getattr(self, f"{key}_kind") for key in ("eso", "td", "sef", "law")}
        return controller_kinds(self.structure, chosen)

    @model_validator(mode="after")
    def _required(self) -> ControllerModel:
        # the parameters the chosen kinds use must be given: no silent b0 = 1, omega0 = 10
        if self.structure is None:  # REQUIRED_KEYS reports it
            return self
        missing = []
        kinds = self.kinds()
        for part, kind in kinds.items():
            table = getattr(self, part)
            needed = REQUIRED_BY_KIND.get((part, kind), ())
            if part == "eso" and self.eso.gains == "kalman":
                needed = tuple(k for k in needed if k != "omega0")  # derived from q, r
            missing += [
                f"controller.{part}.{key}" for key in needed if key not in table.model_fields_set
            ]
        if missing:
            parts = ", ".join(f"{v} {k}" for k, v in kinds.items())
            raise ValueError(
                f"{', '.join(missing)}: missing; the {self.structure} controller ({parts}) "
                "uses them and they have no default, so give every one (`aiofl show "
                "frontier-s1-ladrc` prints a complete config)"
            )
        return self

    def defaults_used(self) -> list[str]:
        """``controller.TABLE.KEY = default`` for every documented default the chosen kinds
        use and this table leaves out (:data:`DOCUMENTED_DEFAULTS`)."""
        kinds = self.kinds()
        out = []
        for part, key, used_by, words in DOCUMENTED_DEFAULTS:
            if kinds[part] not in used_by or key in getattr(self, part).model_fields_set:
                continue
            if part == "eso" and key == "alpha" and self.eso.gains == "kalman":
                continue  # derived from q and r
            out.append(f"controller.{part}.{key} = {words}")
        return out

    def build(self, default_rho: int, measurement_r: float = 0.0) -> Controller:
        """The :class:`Controller`; ``measurement_r`` is the run's measurement noise
        intensity (:func:`aiofl.components.kalman.measurement_noise_intensity`), the
        default of ``[controller.eso] r`` with Kalman gains."""
        kinds = self.kinds()
        rho = self.rho or default_rho
        values: dict[str, float] = {}
        eso = self.eso.model_dump()
        alphas = eso.pop("alpha")
        eso_init = eso.pop("init")
        eso_model = eso.pop("model")
        gains = eso.pop("gains")
        q, r = eso.pop("q"), eso.pop("r")
        if eso["u0"] == "trim":  # the holding input: aiofl.config.run_config resolves it
            eso["u0"] = 0.0
        if eso["delay"] == "rig":  # the rig's measurement delay: run_config resolves it
            eso["delay"] = 0.0
        if gains == "kalman":
            eso.pop("omega0")  # derived from q and r
            if r is None and not measurement_r > 0:
                raise ValueError(
                    "controller.eso.gains = 'kalman' needs a measurement noise: set "
                    "controller.eso.r (the measurement-noise intensity), or give the "
                    "scenario a measurement noise (scenario.noise_variance > 0, or a sampled "
                    "controller's y_quantum); this run's sensor is ideal (r = 0)"
                )
            values["eso.q"] = q
            values["eso.r"] = r if r is not None else measurement_r
        for key, val in eso.items():
            values[f"eso.{key}"] = val
        if gains != "kalman":  # Kalman gains: alpha derived from q and r
            if alphas == "binomial":
                from aiofl.components.observers import binomial_alphas

                alphas = list(binomial_alphas(rho))
            if len(alphas) != rho + 1:
                raise ValueError(
                    f"controller.eso.alpha has {len(alphas)} entries; the ESO of order rho+1 "
                    f"needs rho+1 = {rho + 1}"
                )
            values.update({f"eso.alpha{i}": a for i, a in enumerate(alphas, 1)})
        for key, val in self.td.model_dump().items():
            values[f"td.{key}"] = val
        vectors = {k: v for k, v in self.sef.model_dump().items() if isinstance(v, list)}
        for key, val in self.sef.model_dump().items():
            if isinstance(val, list):
                if len(val) > L.RHO_MAX:
                    raise ValueError(f"controller.sef.{key} has more than {L.RHO_MAX} entries")
                values.update({f"sef.{key}{i}": v for i, v in enumerate(val, 1)})
            elif val is not None:
                values[f"sef.{key}"] = val
        for key, val in self.law.model_dump().items():
            if val is not None:  # u_min omitted: the symmetric range [-u_max, u_max]
                values[f"law.{key}"] = val
        controller = Controller(
            eso=kinds["eso"],
            td=kinds["td"],
            sef=kinds["sef"],
            law=kinds["law"],
            rho=rho,
            n_feedback=self.n_feedback,  # None: rho, or 2 behind the Han TD / ITD
            values=values,
            structure=self.structure or "custom",
            eso_init=eso_init,
            eso_model=eso_model,
            allow_rho_mismatch=self.allow_rho_mismatch,
            allow_b0_sign_mismatch=self.allow_b0_sign_mismatch,
            eso_gains=gains,
        )
        m = controller.n_feedback
        for key, val in vectors.items():  # a short vector is refused, never padded
            if len(val) < m:  # type: ignore[operator]
                raise ValueError(
                    f"controller.sef.{key} has {len(val)} entries; allowed: one per fed-back "
                    f"state, {m}..{L.RHO_MAX} (n_feedback = {m}; missing entries are not "
                    "filled in)"
                )
        return controller


# ------------------------------------------------------------------------ sensor
class SensorModel(TableModel):
    """``[sensor]``: the measurement as a user has it (:mod:`aiofl.sensor`).

    ``preset`` names a :data:`aiofl.sensor.SENSOR_PRESETS` entry; a key given here
    overrides the preset's value (None: not set here).
    """

    preset: str = "ideal"
    ts: Annotated[float, Field(gt=0, le=1.0, allow_inf_nan=False)] | None = None
    quantum: NonNegFloat | None = None
    noise_variance: NonNegFloat | None = None
    noise_hold: PosFloat | None = None
    noise_seed: Annotated[int, Field(ge=0, lt=2**63)] | None = None

    @field_validator("preset")
    @classmethod
    def _preset(cls, v: str) -> str:
        if v not in SENSOR_PRESETS:
            raise ValueError(f"unknown sensor preset {v!r}; allowed: {', '.join(SENSOR_PRESETS)}")
        return v

    @field_validator("quantum")
    @classmethod
    def _quantum(cls, v: float | None) -> float | None:
        from aiofl.engine.discrete_rows import QUANTUM_MIN

        if v is not None and 0 < v < QUANTUM_MIN:
            raise ValueError(
                f"allowed: 0 (none) or a quantum >= {QUANTUM_MIN:g} (an encoder of N counts "
                "per revolution: 2π/N rad)"
            )
        return v

    def explicit(self) -> dict[str, Any]:
        """The keys set in the table (besides ``preset``)."""
        return {k: v for k, v in self.model_dump(exclude={"preset"}).items() if v is not None}

    def build(self) -> Sensor:
        """The :class:`~aiofl.sensor.Sensor`: the preset with the explicit keys."""
        return Sensor.from_preset(self.preset, **self.explicit())


# --------------------------------------------------------------------------- rig
_Delay = Annotated[float, Field(ge=0, le=DELAY_MAX, allow_inf_nan=False)]
_Amount = Annotated[float, Field(ge=0, le=1e6, allow_inf_nan=False)]


class RigModel(TableModel):
    """``[rig]``: what a real loop adds to the plant (:class:`aiofl.rig.Rig`); a key given
    here overrides the preset's value (None: not set here)."""

    preset: str = "ideal"
    sensor: str | None = None
    measurement_delay: _Delay | None = None
    computation_delay: _Delay | None = None
    lag: Annotated[float, Field(ge=0, le=LAG_MAX, allow_inf_nan=False)] | None = None
    lag2: Annotated[list[float], Field(min_length=2, max_length=2)] | None = None
    rate_limit: Annotated[float, Field(gt=0)] | None = None  # inf: none
    rate_filter: Annotated[float, Field(gt=0, le=LAG_MAX, allow_inf_nan=False)] | None = None
    coulomb: _Amount | None = None
    viscous: _Amount | None = None
    friction_state: str | None = None
    smoothing: Annotated[float, Field(gt=0, le=1e6, allow_inf_nan=False)] | None = None

    @field_validator("preset")
    @classmethod
    def _preset(cls, v: str) -> str:
        if v not in RIG_PRESETS:
            raise ValueError(f"unknown rig preset {v!r}; allowed: {', '.join(RIG_PRESETS)}")
        return v

    @field_validator("sensor")
    @classmethod
    def _sensor(cls, v: str | None) -> str | None:
        from aiofl.sensor import SENSOR_PRESETS

        if v is not None and v not in SENSOR_PRESETS:
            raise ValueError(f"unknown sensor preset {v!r}; allowed: {', '.join(SENSOR_PRESETS)}")
        return v

    @model_validator(mode="after")
    def _whole(self) -> RigModel:
        try:
            self.build()
        except ValueError as exc:
            raise ValueError(str(exc)) from None
        return self

    def explicit(self) -> dict[str, Any]:
        """The keys set in the table (besides ``preset``)."""
        return {k: v for k, v in self.model_dump(exclude={"preset"}).items() if v is not None}

    def build(self) -> Rig:
        """The :class:`~aiofl.rig.Rig`: the preset with the explicit keys."""
        given = self.explicit()
        if "lag2" in given:
            given["lag2"] = tuple(given["lag2"])
        return Rig.from_preset(self.preset, **given)


# -------------------------------------------------------------------- the rest
class SimulationModel(TableModel):
    dt: Annotated[float, Field(gt=0, le=DT_MAX, allow_inf_nan=False)] = 1e-4
    method: Literal["rk4", "euler"] = "rk4"
    decimation: Annotated[int, Field(ge=1, le=MAX_STEPS)] = 10
    # finite: an infinite threshold would switch divergence detection off
    divergence_threshold: Annotated[float, Field(gt=0, le=1e300, allow_inf_nan=False)] = 1e10


class MetricsModel(TableModel):
    weights: list[NonNegFloat] = Field([0.6, 0.2, 0.6], min_length=3, max_length=3)
    normalisers: list[PosFloat] = Field([10.0, 2.0, 2.7], min_length=3, max_length=3)

    def build(self) -> OPIWeights:
        (w1, w2, w3), (n1, n2, n3) = self.weights, self.normalisers
        return OPIWeights(w1, w2, w3, n1, n2, n3)


class ConfigModel(TableModel):
    name: str = "custom"
    description: str = ""
    plant: str = "slfjm"
    scenario: ScenarioModel = Field(default_factory=ScenarioModel)
    controller: ControllerModel = Field(default_factory=ControllerModel)
    simulation: SimulationModel = Field(default_factory=SimulationModel)
    metrics: MetricsModel = Field(default_factory=MetricsModel)
    # Tables owned by other features (e.g. [tune]) are validated by those features.
    tune: dict[str, Any] | None = None
    # [uncertainty]: model error as data (aiofl.uncertainty); plant names checked in run_config
    uncertainty: UncertaintyModel | None = None
    # [sensor]: the measurement (aiofl.sensor); merged into [scenario] / [controller.discrete]
    sensor: SensorModel | None = None
    # [rig]: actuator, friction, delays (aiofl.rig); merged in run_config before [sensor]
    rig: RigModel | None = None

    def defaults_used(self) -> list[str]:
        """``KEY = default`` for every documented default this config relies on: the
        paper's reference (π/4)·sin 2t when ``[scenario.reference]`` leaves it out, and the
        controller's (:meth:`ControllerModel.defaults_used`); printed by ``--check``."""
        ref = self.scenario.reference
        given = ref.model_fields_set
        out = []
        if not given:
            out.append(
                'scenario.reference = the paper\'s (π/4)·sin 2t (kind = "sine", amplitude = '
                f"{ref.amplitude:.6g}, omega = {ref.omega:g})"
            )
        else:
            keys = {"sine": ("amplitude", "omega"), "step": ("amplitude",)}.get(ref.kind, ())
            out += [
                f"scenario.reference.{k} = {getattr(ref, k):.6g}" for k in keys if k not in given
            ]
        return out + self.controller.defaults_used()

    @field_validator("name")
    @classmethod
    def _name(cls, v: str) -> str:
        return check_text("name", v)

    @field_validator("description")
    @classmethod
    def _description(cls, v: str) -> str:
        return check_text("description", v, max_chars=MAX_DESCRIPTION_CHARS)

    @field_validator("plant")
    @classmethod
    def _plant_name(cls, v: str) -> str:
        from aiofl.plants.registry import available_plants, python_plant_hint

        check_text("plant", v, max_chars=MAX_PATH_CHARS)
        if v not in available_plants() and not v.endswith(".toml"):
            raise ValueError(
                f"unknown plant {v!r}; allowed: a symbolic-plant .toml file or one of "
                f"{', '.join(available_plants())}; {python_plant_hint(v)}"
            )
        return v
