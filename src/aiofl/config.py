"""Validated TOML configs and the shipped presets.

A config file (or a preset name such as ``paper-s1-leso``) describes one run: the plant,
the scenario, the controller, the simulation settings and the OPI weights.  Every table
rejects unknown keys; every number is range-checked; a bad file raises
:class:`ConfigError` whose message names the field and the allowed range.

.. code-block:: toml

    name = "my-run"
    plant = "slfjm"                  # a registered plant, or a symbolic-plant .toml file

    [scenario]
    t_final = 20.0
    disturbance_amplitude = 0.5      # N·m step at disturbance_time
    disturbance_time = 10.0
    plant_scale = { J_l = 1.4 }      # true plant only
    noise_variance = 0.0
    [scenario.reference]
    kind = "sine"                    # sine | step | samples
    amplitude = 0.7853981633974483   # 45° in rad
    omega = 2.0

    [controller]
    structure = "LESO"               # LESO | INLESO | LADRC | IOFL (sets the kinds)
    rho = 4
    n_feedback = 2
    [controller.eso]
    omega0 = 513.8283
    alpha = [8.772, 0.1946, 0.7384, 9.6881e-3, 2.2651e-6]   # or "binomial"
    [controller.td]
    R = 2408.6918
    [controller.sef]
    alpha = [0.3804, 0.4583]
    delta = [16.6108, 14.6238]
    [controller.law]
    b0 = 22.771
    [controller.discrete]            # optional: run the controller sampled (engine.discrete)
    ts = 1e-3                        # an integer multiple of dt; delay, y_quantum, u_quantum,
                                     # eso = "zoh" | "euler", td = "fhan" | "euler", h0

    [simulation]
    dt = 1e-4
    method = "rk4"

    [metrics]
    weights = [0.6, 0.2, 0.6]
    normalisers = [10.0, 2.0, 2.7]

Vector parameters (``alpha``, ``k``, ``delta`` ...) are lists, numbered from 1 as in the
paper; each maps onto the engine columns of :data:`aiofl.layout.FLOAT_COLUMNS`
(``[controller.sef] delta = [a, b]`` sets ``sef.delta1`` and ``sef.delta2``).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from aiofl import layout as L
from aiofl.components.metrics import OPIWeights
from aiofl.controller import STRUCTURES, Controller
from aiofl.plants.base import Plant, PlantError
from aiofl.scenario import Reference, Scenario

__all__ = [
    "ConfigError",
    "RunConfig",
    "list_presets",
    "load_config",
    "parse_config",
    "preset_text",
    "resolve_plant",
]

PosFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegFloat = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]


class ConfigError(ValueError):
    """A config that cannot be used; the message names the field and the allowed range."""


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


# ---------------------------------------------------------------------- scenario
class ReferenceModel(_Model):
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


class ScenarioModel(_Model):
    name: str = "custom"
    reference: ReferenceModel = Field(default_factory=ReferenceModel)
    t_final: Annotated[float, Field(gt=0, le=1e4)] = 20.0
    disturbance_amplitude: Finite = 0.0
    disturbance_time: NonNegFloat = 0.0
    plant_scale: dict[str, PosFloat] = Field(default_factory=dict)
    plant_overrides: dict[str, Finite] = Field(default_factory=dict)
    parameter_change_time: NonNegFloat = 0.0
    noise_variance: NonNegFloat = 0.0
    noise_hold: PosFloat = 1e-3
    noise_seed: Annotated[int, Field(ge=0)] = 0
    x0: list[Finite] = Field(default_factory=list)

    def build(self) -> Scenario:
        ref = Reference(**{**self.reference.model_dump(), "samples": tuple(self.reference.samples)})
        data = self.model_dump(exclude={"reference"})
        data["x0"] = tuple(self.x0)
        return Scenario(reference=ref, **data)


# -------------------------------------------------------------------- controller
class ESOModel(_Model):
    omega0: PosFloat = 10.0
    alpha: list[NonNegFloat] | Literal["binomial"] = "binomial"
    k_alpha: NonNegFloat = 1.0
    k_beta: NonNegFloat = 0.0
    g_alpha: Annotated[float, Field(gt=0, le=2)] = 1.0
    g_beta: Annotated[float, Field(ge=0, le=2)] = 0.0


class TDModel(_Model):
    R: PosFloat = 100.0
    a: Annotated[float, Field(ge=0, lt=1)] = 0.0
    b: PosFloat = 1.0
    c: PosFloat = 1.0
    rho: PosFloat = 10.0
    omega: PosFloat = 10.0


class SEFModel(_Model):
    k: list[Finite] | None = None
    kb: list[Finite] | None = None
    alpha: list[Annotated[float, Field(gt=0, le=3)]] | None = None
    delta: list[PosFloat] | None = None
    mu: list[NonNegFloat] | None = None
    v_limit: PosFloat = 1.0
    omega_c: PosFloat = 1.0


class LawModel(_Model):
    b0: PosFloat = 1.0
    u_max: Annotated[float, Field(gt=0)] = math.inf


class DiscreteModel(_Model):
    """``[controller.discrete]``: run the controller sampled (:mod:`aiofl.engine.discrete`)."""

    ts: Annotated[float, Field(gt=0, le=1.0, allow_inf_nan=False)]
    delay: Literal[0, 1] = 0
    y_quantum: NonNegFloat = 0.0
    u_quantum: NonNegFloat = 0.0
    eso: Literal["zoh", "euler"] | None = None
    td: Literal["fhan", "euler"] = "fhan"
    h0: PosFloat | None = None

    def build(self) -> Any:
        from aiofl.engine.discrete import Sampling

        return Sampling(**self.model_dump())


class ControllerModel(_Model):
    structure: Literal["LESO", "INLESO", "LADRC", "IOFL"] | None = None
    eso_kind: Literal["linear", "improved"] | None = None
    td_kind: Literal["exact", "han", "improved", "linear"] | None = None
    sef_kind: Literal["nonlinear", "improved", "linear"] | None = None
    law_kind: Literal["aiofl", "iofl"] | None = None
    rho: Annotated[int, Field(ge=1, le=L.RHO_MAX)] | None = None
    n_feedback: Annotated[int, Field(ge=1, le=L.RHO_MAX)] = 2
    eso: ESOModel = Field(default_factory=ESOModel)
    td: TDModel = Field(default_factory=TDModel)
    sef: SEFModel = Field(default_factory=SEFModel)
    law: LawModel = Field(default_factory=LawModel)
    discrete: DiscreteModel | None = None

    def build(self, default_rho: int) -> Controller:
        kinds = dict(
            zip(("eso", "td", "sef", "law"), STRUCTURES[self.structure or "LESO"], strict=True)
        )
        for key in kinds:
            chosen = getattr(self, f"{key}_kind")
            if chosen is not None:
                kinds[key] = chosen
        rho = self.rho or default_rho
        values: dict[str, float] = {}
        eso = self.eso.model_dump()
        alphas = eso.pop("alpha")
        for key, val in eso.items():
            values[f"eso.{key}"] = val
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
        for key, val in self.sef.model_dump().items():
            if isinstance(val, list):
                if len(val) > L.RHO_MAX:
                    raise ValueError(f"controller.sef.{key} has more than {L.RHO_MAX} entries")
                values.update({f"sef.{key}{i}": v for i, v in enumerate(val, 1)})
            elif val is not None:
                values[f"sef.{key}"] = val
        for key, val in self.law.model_dump().items():
            values[f"law.{key}"] = val
        return Controller(
            eso=kinds["eso"],
            td=kinds["td"],
            sef=kinds["sef"],
            law=kinds["law"],
            rho=rho,
            n_feedback=self.n_feedback,
            values=values,
            structure=self.structure or "custom",
        )


# -------------------------------------------------------------------- the rest
class SimulationModel(_Model):
    dt: Annotated[float, Field(gt=0, le=0.1)] = 1e-4
    method: Literal["rk4", "euler"] = "rk4"
    decimation: Annotated[int, Field(ge=1)] = 10
    divergence_threshold: Annotated[float, Field(gt=0)] = 1e10


class MetricsModel(_Model):
    weights: Annotated[list[NonNegFloat], Field(min_length=3, max_length=3)] = [0.6, 0.2, 0.6]
    normalisers: Annotated[list[PosFloat], Field(min_length=3, max_length=3)] = [10.0, 2.0, 2.7]

    def build(self) -> OPIWeights:
        (w1, w2, w3), (n1, n2, n3) = self.weights, self.normalisers
        return OPIWeights(w1, w2, w3, n1, n2, n3)


class ConfigModel(_Model):
    name: str = "custom"
    description: str = ""
    plant: str = "slfjm"
    scenario: ScenarioModel = Field(default_factory=ScenarioModel)
    controller: ControllerModel = Field(default_factory=ControllerModel)
    simulation: SimulationModel = Field(default_factory=SimulationModel)
    metrics: MetricsModel = Field(default_factory=MetricsModel)
    # Tables owned by other features (e.g. [tune]) are validated by those features.
    tune: dict[str, Any] | None = None

    @field_validator("plant")
    @classmethod
    def _plant_name(cls, v: str) -> str:
        from aiofl.plants.registry import available_plants

        if v not in available_plants() and not v.endswith(".toml"):
            raise ValueError(
                f"unknown plant {v!r}; allowed: a symbolic-plant .toml file or one of "
                f"{', '.join(available_plants())}"
            )
        return v


@dataclass(frozen=True)
class RunConfig:
    """A validated config, built into engine objects."""

    name: str
    description: str
    plant: Plant
    scenario: Scenario
    controller: Controller
    dt: float
    method: str
    decimation: int
    divergence_threshold: float
    weights: OPIWeights
    raw: dict[str, Any]
    sampling: Any = None  # aiofl.engine.discrete.Sampling: [controller.discrete], or None

    def simulate(self, *, store: bool = True) -> Any:
        """Run this config once (see :func:`aiofl.engine.simulation.simulate`)."""
        from aiofl.engine.simulation import simulate

        return simulate(
            self.plant,
            self.controller,
            self.scenario,
            dt=self.dt,
            method=self.method,
            store=store,
            decimation=self.decimation,
            divergence_threshold=self.divergence_threshold,
            sampling=self.sampling,
        )

    def with_sample_time(self, ts: float) -> RunConfig:
        """This config with the controller sampled at ``ts`` (the other
        ``[controller.discrete]`` settings kept, or their defaults); raises
        :class:`ConfigError` if ``ts`` is not a positive integer multiple of ``dt``."""
        from dataclasses import replace

        raw = {**self.raw, "controller": dict(self.raw.get("controller", {}))}
        raw["controller"]["discrete"] = {**raw["controller"].get("discrete", {}), "ts": ts}
        try:
            table = DiscreteModel.model_validate(raw["controller"]["discrete"])
        except ValidationError as exc:
            msg = _format_error(exc, "--ts").replace("  ts:", "  controller.discrete.ts:")
            raise ConfigError(msg) from None
        cfg = replace(self, sampling=table.build(), raw=raw)
        cfg.check_sampling()
        return cfg

    def check_sampling(self) -> None:
        """Raise :class:`ConfigError` unless the sampled controller (if any) can run with this
        config's step ``dt``: Ts an integer multiple of dt, a discretisation that fits the
        controller, finite coefficients."""
        if self.sampling is None:
            return
        from aiofl.controller import controller_batch
        from aiofl.engine.discrete import sampling_rows

        try:
            self.sampling.check(self.controller)
            sampling_rows(controller_batch(self.controller), [self.sampling], self.dt)
        except ValueError as exc:
            raise ConfigError(f"invalid config {self.name!r}: {exc}") from None


def _allowed_keys(loc: tuple[Any, ...]) -> list[str]:
    """Field names of the table at ``loc[:-1]`` (walking the config models)."""
    model: Any = ConfigModel
    for part in loc[:-1]:
        field = model.model_fields.get(part) if isinstance(part, str) else None
        if field is None:
            return []
        candidates = (field.annotation, *getattr(field.annotation, "__args__", ()))
        models = [a for a in candidates if isinstance(a, type) and issubclass(a, BaseModel)]
        if not models:
            return []
        model = models[0]
    return list(model.model_fields)


def _format_error(exc: ValidationError, source: str) -> str:
    lines = [f"invalid config {source}:"]
    for err in exc.errors():
        loc = ".".join(str(p) for p in err["loc"])
        msg = err["msg"]
        if err["type"] == "extra_forbidden":
            allowed = _allowed_keys(err["loc"])
            msg = "unknown key" + (f"; allowed: {', '.join(allowed)}" if allowed else "")
        lines.append(f"  {loc}: {msg} (got {err.get('input')!r})")
    return "\n".join(lines)


_FILE_PLANTS: dict[tuple[str, int], Plant] = {}


def resolve_plant(name_or_file: str, base_dir: str | Path | None = None) -> Plant:
    """A registered plant by name, or a symbolic-plant TOML file compiled to a :class:`Plant`.

    A relative file path is taken relative to ``base_dir`` (the config's folder).  A file
    plant is built once per process (per path and modification time), so its kernel
    compiles once.  See :meth:`aiofl.plants.symbolic.SymbolicPlant.from_dict` for the format.
    """
    from aiofl.plants.registry import get_plant

    if not name_or_file.endswith(".toml"):
        return get_plant(name_or_file)
    path = Path(name_or_file)
    if not path.is_absolute() and base_dir is not None:
        path = Path(base_dir) / path
    if not path.is_file():
        raise ConfigError(f"plant: file {str(path)!r} does not exist")
    key = (str(path.resolve()), path.stat().st_mtime_ns)
    if key not in _FILE_PLANTS:
        from aiofl.plants.expressions import SymbolicPlantError
        from aiofl.plants.symbolic import SymbolicPlant

        try:
            _FILE_PLANTS[key] = SymbolicPlant.from_toml(path).to_plant()
        except SymbolicPlantError as exc:
            raise ConfigError(f"plant: {exc}") from None
    return _FILE_PLANTS[key]


def parse_config(
    data: dict[str, Any], source: str = "<dict>", base_dir: str | Path | None = None
) -> RunConfig:
    """Validate a config dict and build the engine objects; raises :class:`ConfigError`.

    ``base_dir`` resolves a relative ``plant = "file.toml"`` (defaults to the working folder).
    """
    try:
        model = ConfigModel.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(_format_error(exc, source)) from None
    plant = resolve_plant(model.plant, base_dir)
    plant_file = Path(model.plant)
    if base_dir is not None and plant_file.suffix == ".toml" and not plant_file.is_absolute():
        # keep raw self-contained: re-parsing it elsewhere (tuning, Dask) finds the same file
        data = {**data, "plant": str((Path(base_dir) / plant_file).resolve())}
    try:
        plant.param_vector(model.scenario.plant_overrides, model.scenario.plant_scale)
        controller = model.controller.build(plant.relative_degree or 1)
        scenario = model.scenario.build()
        if scenario.x0 and len(scenario.x0) != plant.n_states:
            raise ValueError(
                f"scenario.x0 has {len(scenario.x0)} entries; plant {plant.name!r} has "
                f"{plant.n_states} states"
            )
        if controller.law == "iofl" and plant.normal_form is None:
            raise ValueError(
                f"controller.law_kind = 'iofl' needs the plant's normal form; plant "
                f"{plant.name!r} has none"
            )
    except (ValueError, PlantError) as exc:
        raise ConfigError(f"invalid config {source}: {exc}") from None
    sim = model.simulation
    cfg = RunConfig(
        name=model.name,
        description=model.description,
        plant=plant,
        scenario=scenario,
        controller=controller,
        dt=sim.dt,
        method=sim.method,
        decimation=sim.decimation,
        divergence_threshold=sim.divergence_threshold,
        weights=model.metrics.build(),
        raw=data,
    )
    if model.controller.discrete is not None:  # [controller.discrete]: a sampled controller
        try:
            sampling = model.controller.discrete.build()
        except ValueError as exc:
            raise ConfigError(f"invalid config {source}: {exc}") from None
        cfg = replace(cfg, sampling=sampling)
        cfg.check_sampling()
    return cfg


def _presets_dir() -> Any:
    return resources.files("aiofl") / "presets"


def list_presets() -> list[str]:
    """Names of the presets shipped with the package."""
    return sorted(p.name[:-5] for p in _presets_dir().iterdir() if p.name.endswith(".toml"))


def preset_text(name: str) -> str:
    """The TOML text of preset ``name``."""
    path = _presets_dir() / f"{name}.toml"
    if not path.is_file():
        raise ConfigError(f"unknown preset {name!r}; available: {', '.join(list_presets())}")
    return path.read_text(encoding="utf-8")


def load_config(path_or_preset: str | Path) -> RunConfig:
    """Load a TOML file, or a shipped preset by name; raises :class:`ConfigError`."""
    p = Path(path_or_preset)
    if p.suffix == ".toml" or p.exists():
        if not p.is_file():
            raise ConfigError(f"config file {str(p)!r} does not exist")
        text, source, base = p.read_text(encoding="utf-8"), str(p), p.parent
    else:
        text, source, base = preset_text(str(path_or_preset)), f"preset {path_or_preset!r}", None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"malformed TOML in {source}: {exc}") from None
    return parse_config(data, source, base)
