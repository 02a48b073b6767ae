"""Validated TOML configs and the shipped presets.

A config file (or a preset name such as ``paper-s1-leso``) describes one run: the plant,
the scenario, the controller, the simulation settings and the OPI weights.  Every table
rejects unknown keys; every number is range-checked and strictly typed (``true`` or
``"50 "`` is no number; an integer field takes only an integer); a config must set the
:data:`REQUIRED_KEYS` (an empty or cut-off file is refused, not run with defaults) and
the parameters its controller's kinds use (:data:`~aiofl.config.schema.REQUIRED_BY_KIND`:
LADRC needs ``eso.omega0``, ``td.omega``, ``sef.omega_c``, ``law.b0``); the
horizon must be a whole number of steps, events must fall within it, and the run's size
is bounded before anything is allocated (:mod:`aiofl.limits`).  A bad file raises
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
    rho = 4                          # default: the plant's relative degree
    n_feedback = 2                   # default: rho; 2 behind the Han TD / ITD (LESO, INLESO)
    # allow_rho_mismatch = true      # accept a rho other than the plant's relative degree
    # allow_b0_sign_mismatch = true  # accept a b0 whose sign differs from the plant's beta
    [controller.eso]
    omega0 = 513.8283
    alpha = [8.772, 0.1946, 0.7384, 9.6881e-3, 2.2651e-6]   # default "binomial" (Gao)
    init = "zero"                    # or "output": xi_hat_1(0) = the first measurement
    model = "none"                   # or "nominal": model-assisted (alpha + beta u of the
                                     # nominal plant at x_hat = Phi^-1(xi_hat))
    # gains = "kalman"               # steady-state Kalman gains (then no omega0, alpha):
    # q = 1e12                       #   process-noise intensity on the extended state's
    # r = 1e-7                       #   derivative; measurement-noise intensity (default:
    #                                #   the run's, components.kalman.measurement_noise_
    #                                #   intensity: noise_variance * noise_hold, sampled:
    #                                #   * max(noise_hold, ts) + y_quantum^2/12 * ts)
    [controller.td]
    R = 2408.6918
    [controller.sef]
    alpha = [0.3804, 0.4583]         # one entry per fed-back state (>= n_feedback)
    delta = [16.6108, 14.6238]
    [controller.law]
    b0 = 22.771                      # finite, non-zero, with the sign of the plant's beta
    u_max = inf                      # actuator range [u_min, u_max]; u_min omitted: -u_max
    [controller.discrete]            # optional: run the controller sampled (engine.discrete_rows)
    ts = 1e-3                        # an integer multiple of dt; delay, u_quantum,
                                     # eso = "zoh" | "euler", td = "fhan" | "euler", h0

    [sensor]                         # the measurement: the one place for ts, quantum, noise
    preset = "encoder-12bit"         # ideal | encoder-12bit | encoder-14bit | encoder-16bit
    # ts, quantum, noise_variance, noise_hold, noise_seed override the preset (aiofl.sensor)

    [simulation]
    dt = 1e-4
    method = "rk4"

    [metrics]
    weights = [0.6, 0.2, 0.6]
    normalisers = [10.0, 2.0, 2.7]

**The sensor.**  ``[sensor]`` (:mod:`aiofl.sensor`) is the one place for what the
controller measures: it fills ``[scenario] noise_variance / noise_hold / noise_seed`` and
``[controller.discrete] ts / y_quantum`` (a sensor ``ts`` makes the controller sampled).
The older keys still work, but a quantity set both in ``[sensor]`` and in its old place is
refused, except ``[controller.discrete] ts`` equal to the sensor's.

Vector parameters (``alpha``, ``k``, ``delta`` ...) are lists, numbered from 1 as in the
paper; each maps onto the engine columns of :data:`aiofl.layout.FLOAT_COLUMNS`
(``[controller.sef] delta = [a, b]`` sets ``sef.delta1`` and ``sef.delta2``).
"""

from __future__ import annotations

import copy
import tomllib
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ValidationError

from aiofl import layout as L
from aiofl.components.kalman import measurement_noise_intensity
from aiofl.components.metrics import OPIWeights
from aiofl.config.rig_table import apply_rig, merge_rig
from aiofl.config.schema import REQUIRED_KEYS, ConfigError, ConfigModel, DiscreteModel
from aiofl.config.sensor_table import check_sensor_ts as _check_sensor_ts
from aiofl.config.sensor_table import merge_sensor as _merge_sensor
from aiofl.controller import Controller
from aiofl.engine.discrete_rows import delay_steps
from aiofl.limits import (
    MAX_NOISE_SAMPLES,
    MAX_STEPS,
    MAX_TRAJECTORY_BYTES,
    check_run_size,
)
from aiofl.plants.base import Plant, PlantError
from aiofl.plants.operating_point import holding_input
from aiofl.rig import Rig
from aiofl.scenario import Scenario
from aiofl.sensor import Sensor, check_quantum_range
from aiofl.uncertainty import UncertaintyModel

__all__ = [
    "MAX_NOISE_SAMPLES",
    "MAX_STEPS",
    "MAX_TRAJECTORY_BYTES",
    "REQUIRED_KEYS",
    "ConfigError",
    "PlantFileGiven",
    "RunConfig",
    "check_run_size",
    "list_presets",
    "load_config",
    "parse_config",
    "preset_text",
    "resolve_plant",
]


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
    sampling: Any = None  # aiofl.engine.discrete_rows.Sampling: [controller.discrete], or None
    uncertainty: UncertaintyModel | None = None  # [uncertainty] (aiofl.uncertainty), or None
    sensor: Sensor = field(default_factory=Sensor)  # the measurement ([sensor] or old keys)
    rig: Rig | None = None  # [rig] (aiofl.rig): actuator, friction, delays; None: none
    defaults: tuple[str, ...] = ()  # "KEY = default" for documented defaults it relies on

    @property
    def plant_source(self) -> str:
        """Its ``plant`` key as written (a built-in name or a plant file), else the name."""
        return str(self.raw.get("plant", self.plant.name))

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

    def with_overrides(
        self,
        *,
        t_final: float | None = None,
        dt: float | None = None,
        method: str | None = None,
        source: str = "",
    ) -> RunConfig:
        """This config with ``[scenario] t_final`` and ``[simulation] dt`` / ``method``
        replaced, validated again by :func:`parse_config`: a command-line override passes
        exactly the checks a value in the file does (types, ranges, run size, events within
        the horizon).  Raises :class:`ConfigError`; ``source`` names the override in it.

        Parameters
        ----------
        t_final, dt, method, source
            ``[scenario] t_final`` [s], ``[simulation] dt`` [s] and ``method`` (None: the
            config's); how messages name the new config (default: "NAME (overridden)").

        Returns
        -------
        RunConfig
        """
        data = copy.deepcopy(self.raw)
        for table, key, value in (
            ("scenario", "t_final", t_final),
            ("simulation", "dt", dt),
            ("simulation", "method", method),
        ):
            if value is not None:
                data.setdefault(table, {})[key] = value
        return parse_config(data, source or f"{self.name} (overridden)")

    def with_sample_time(self, ts: float) -> RunConfig:
        """This config with the controller sampled at ``ts`` (the other
        ``[controller.discrete]`` settings kept, or their defaults); raises
        :class:`ConfigError` if ``ts`` is not a positive integer multiple of ``dt``.
        Kalman observer gains whose r comes from the measurement
        (:func:`aiofl.components.kalman.measurement_noise_intensity`) are designed for the
        new sampling."""
        from dataclasses import replace

        if isinstance(self.raw.get("sensor"), dict):  # --ts sets the sensor's sample time
            data = copy.deepcopy(self.raw)
            data["sensor"]["ts"] = ts
            disc = data.get("controller", {}).get("discrete")
            if isinstance(disc, dict) and "ts" in disc:
                disc["ts"] = ts
            return parse_config(data, f"{self.name} with --ts {ts:g}")
        raw = {**self.raw, "controller": dict(self.raw.get("controller", {}))}
        raw["controller"]["discrete"] = {**raw["controller"].get("discrete", {}), "ts": ts}
        try:
            table = DiscreteModel.model_validate(raw["controller"]["discrete"])
        except ValidationError as exc:
            msg = _format_error(exc, "--ts").replace("  ts:", "  controller.discrete.ts:")
            raise ConfigError(msg) from None
        try:
            sampling = table.build()
        except ValueError as exc:
            raise ConfigError(f"invalid config {self.name!r}: {exc}") from None
        controller = self.controller
        eso_table = raw["controller"].get("eso", {})
        if controller.eso_gains == "kalman" and "r" not in eso_table:
            # Kalman gains from the run's measurement noise, as sampled now
            r = measurement_noise_intensity(self.scenario, sampling)
            controller = controller.with_values(**{"eso.r": r})
        sensor = replace(self.sensor, ts=ts, quantum=sampling.y_quantum)
        if self.sensor.preset == "ideal" and sensor.quantum == 0:
            sensor = replace(sensor, preset="custom")
        cfg = replace(self, sampling=sampling, controller=controller, raw=raw, sensor=sensor)
        cfg.check_sampling()
        return cfg

    def with_sensor(self, preset: str, *, source: str = "") -> RunConfig:
        """This config measured by the sensor preset ``preset`` (``--sensor``).

        The ``[sensor]`` table becomes ``preset = ...`` (its ``ts`` and ``quantum`` keys
        dropped, its noise keys kept) and the config is validated again by
        :func:`parse_config`, so a contradiction with ``[controller.discrete]`` is refused
        as in a file.  Raises :class:`ConfigError`.
        """
        data = copy.deepcopy(self.raw)
        old = data.get("sensor") if isinstance(data.get("sensor"), dict) else {}
        data["sensor"] = {
            "preset": preset,
            **{k: v for k, v in old.items() if k.startswith("noise_")},
        }
        return parse_config(data, source or f"{self.name} with --sensor {preset}")

    def with_rig(self, preset: str, *, source: str = "", **fields: Any) -> RunConfig:
        """This config on the rig preset ``preset`` (:data:`aiofl.rig.RIG_PRESETS`) with
        ``fields`` overriding its values (``friction_state="theta_dot"``): its ``[rig]``
        table replaced and the config validated again.  Raises :class:`ConfigError`."""
        data = {**copy.deepcopy(self.raw), "rig": {"preset": preset, **fields}}
        return parse_config(data, source or f"{self.name} with rig {preset}")

    def check_sampling(self) -> None:
        """Raise :class:`ConfigError` unless the sampled controller (if any) can run with this
        config's step ``dt``: Ts an integer multiple of dt, a discretisation that fits the
        controller, finite coefficients."""
        if self.sampling is None:
            return
        from aiofl.controller import controller_batch
        from aiofl.engine.discrete_rows import sampling_rows

        try:
            self.sampling.check_horizon(self.scenario.t_final)
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


def _field_range(loc: tuple[Any, ...]) -> str:
    """'a number, > 0, <= 0.1' for the field at ``loc`` (from its pydantic constraints)."""
    model: Any = ConfigModel
    field: Any = None
    for part in loc:
        if not isinstance(part, str) or model is None:
            return ""
        field = model.model_fields.get(part)
        if field is None:
            return ""
        candidates = (field.annotation, *getattr(field.annotation, "__args__", ()))
        models = [a for a in candidates if isinstance(a, type) and issubclass(a, BaseModel)]
        model = models[0] if models else None
    if field is None:
        return ""
    metadata = list(field.metadata)
    for arg in getattr(field.annotation, "__args__", ()):  # Annotated[...] | None
        metadata += list(getattr(arg, "__metadata__", ()))
        for inner in getattr(arg, "__metadata__", ()):
            metadata += list(getattr(inner, "metadata", ()))
    words = {"gt": ">", "ge": ">=", "lt": "<", "le": "<="}
    bounds = [
        f"{words[k]} {getattr(m, k):g}"
        for m in metadata
        for k in words
        if isinstance(getattr(m, k, None), (int, float))
    ]
    text = repr(field.annotation)
    kind = "an integer" if "int" in text and "float" not in text else "a number"
    if "float" not in text and "int" not in text:
        return ""
    return ", ".join([kind, *bounds])


_BOUNDS = {
    "greater_than": ("gt", "greater than"),
    "greater_than_equal": ("ge", "greater than or equal to"),
    "less_than": ("lt", "less than"),
    "less_than_equal": ("le", "less than or equal to"),
}


def _format_error(exc: ValidationError, source: str) -> str:
    lines = [f"invalid config {source}:"]
    for err in exc.errors():
        loc = ".".join(str(p) for p in err["loc"])
        msg = err["msg"].removeprefix("Value error, ")
        bound = _BOUNDS.get(err["type"])
        if bound is not None and bound[0] in err.get("ctx", {}):  # pydantic prints 1e300 in full
            msg = f"Input should be {bound[1]} {err['ctx'][bound[0]]:g}"
        if err["type"] == "extra_forbidden":
            allowed = _allowed_keys(err["loc"])
            msg = "unknown key" + (f"; allowed: {', '.join(allowed)}" if allowed else "")
        elif err["type"].endswith(("_type", "_parsing", "from_float", "finite_number")):
            allowed = _field_range(err["loc"])
            msg += f"; allowed: {allowed}" if allowed else ""
        if isinstance(err.get("input"), dict) and err["type"] == "value_error":
            # a table's own check: its message names the fields and values
            lines.append(f"  {msg}" if msg.startswith(f"{loc}.") else f"  {loc}: {msg}")
            continue
        got = repr(err.get("input"))
        got = got if len(got) <= 100 else got[:97] + "..."
        lines.append(f"  {loc or 'config'}: {msg} (got {got})")
    return "\n".join(lines)


def _missing_keys(data: dict[str, Any]) -> list[str]:
    """The :data:`REQUIRED_KEYS` that ``data`` does not set."""
    missing = []
    for key in REQUIRED_KEYS:
        node: Any = data
        for part in key.split("."):
            node = node.get(part) if isinstance(node, dict) else None
        if node is None:
            missing.append(key)
    return missing


def _missing_text(missing: list[str]) -> str:
    return (
        f"  missing required key(s) {', '.join(missing)}; a config sets at least "
        f"{', '.join(REQUIRED_KEYS)} (an empty or cut-off file is refused rather than run "
        "with defaults)"
    )


_FILE_PLANTS: dict[tuple[str, int], Plant] = {}


def resolve_plant(name_or_file: str, base_dir: str | Path | None = None) -> Plant:
    """A registered plant by name, or a symbolic-plant TOML file compiled to a :class:`Plant`.

    A relative file path is taken relative to ``base_dir`` (the config's folder).  A file
    plant is built once per process (per path and modification time) and cached on disk
    across processes with its compiled kernel (:mod:`aiofl.plants.plant_cache`).  See
    :meth:`aiofl.plants.symbolic.SymbolicPlant.from_dict` for the format.
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
        from aiofl.plants.plant_cache import plant_from_file

        _prepare_loops_ahead(path)
        try:  # a cached plant file needs no sympy: its error class is imported only here
            _FILE_PLANTS[key] = plant_from_file(path)
        except Exception as exc:
            from aiofl.plants.expressions import SymbolicPlantError

            if isinstance(exc, SymbolicPlantError):
                raise ConfigError(f"plant: {exc}") from None
            raise
    return _FILE_PLANTS[key]


def _prepare_loops_ahead(path: Path) -> None:
    """A plant file the cache has never seen: start compiling the loops of its number of
    states in a second process while sympy builds it, if the cache has none
    (:func:`aiofl.engine.build.prepare.prepare_loops_ahead`)."""
    from aiofl.plants.plant_cache import declared_states, plant_module_path

    module = plant_module_path(path)
    n_states = declared_states(path) if module is not None and not module.exists() else None
    if n_states is not None:
        from aiofl.engine.build.prepare import prepare_loops_ahead

        prepare_loops_ahead(n_states)


class PlantFileGiven(ConfigError):
    """A plant file (states, f, g, h, [params]) given where a run config is wanted."""


_PLANT_FILE_KEYS = ("states", "f", "g", "h")
_CONFIG_TABLES = ("plant", "scenario", "controller", "simulation")


def _plant_file_keys(data: dict[str, Any]) -> list[str]:
    """The plant-file keys ``data`` sets if it looks like a plant file rather than a run
    config (two or more of states, f, g, h and none of plant, [scenario], [controller],
    [simulation]); empty otherwise."""
    keys = [k for k in _PLANT_FILE_KEYS if k in data]
    return keys if len(keys) >= 2 and not any(k in data for k in _CONFIG_TABLES) else []


def parse_config(
    data: dict[str, Any], source: str = "<dict>", base_dir: str | Path | None = None
) -> RunConfig:
    """Validate a config dict and build the engine objects; raises :class:`ConfigError`.

    Types are strict (no bool or string coercion into numbers), the :data:`REQUIRED_KEYS`
    must be set (a plant file is refused as such: :class:`PlantFileGiven`), and the run's
    size is bounded before anything is allocated (:func:`check_run_size`).

    Parameters
    ----------
    data, source, base_dir
        The config as :func:`tomllib.loads` gives it; how messages name it; the folder that
        resolves a relative ``plant = "file.toml"`` (default: the working folder).

    Returns
    -------
    RunConfig
    """
    if not isinstance(data, dict):
        raise ConfigError(f"invalid config {source}: a TOML table expected, got {type(data)}")
    plant_keys = _plant_file_keys(data)
    if plant_keys:
        raise PlantFileGiven(
            f"invalid config {source}: this is a plant file (it sets {', '.join(plant_keys)}), "
            'not a run config; a run config names it (plant = "file.toml", relative to the '
            "config's folder) and sets [scenario], [controller] and [simulation] (see "
            "`aiofl show tank-ladrc` for the format)"
        )
    missing = _missing_keys(data)
    note = "\n" + _missing_text(missing) if missing else ""
    original, rig = data, None
    if "rig" in data:  # [rig] fills [sensor], the delays and dt (aiofl.config.rig_table)
        try:
            rig_table = ConfigModel.model_validate({"rig": data["rig"]}).rig
        except ValidationError as exc:
            raise ConfigError(_format_error(exc, source) + note) from None
        data, rig = merge_rig(data, rig_table, source)
    sensor_table: Any = None
    if "sensor" in data:  # the table alone first: its errors name sensor.KEY
        try:
            sensor_table = ConfigModel.model_validate({"sensor": data["sensor"]}).sensor
        except ValidationError as exc:
            raise ConfigError(_format_error(exc, source) + note) from None
    merged = _merge_sensor(data, sensor_table, source) if sensor_table is not None else data
    try:
        model = ConfigModel.model_validate(merged)
    except ValidationError as exc:
        raise ConfigError(_format_error(exc, source) + note) from None
    sim, sc = model.simulation, model.scenario
    if sensor_table is not None:  # its ts fills noise_hold: name it before noise_hold is checked
        _check_sensor_ts(sensor_table.build().ts, sim.dt, source)
    try:
        check_run_size(sc.t_final, sim.dt, noise_hold=sc.noise_hold)
    except ValueError as exc:
        raise ConfigError(f"invalid config {source}: {exc}{note}") from None
    plant = resolve_plant(model.plant, base_dir)
    plant_file = Path(model.plant)
    if base_dir is not None and plant_file.suffix == ".toml" and not plant_file.is_absolute():
        # keep raw self-contained: re-parsing it elsewhere (tuning, Dask) finds the same file
        data = {**data, "plant": str((Path(base_dir) / plant_file).resolve())}
    try:
        plant.param_vector(model.scenario.plant_overrides, model.scenario.plant_scale)
        scenario = model.scenario.build()
        if rig is not None:  # the actuator and friction in the plant's state
            plant, scenario = apply_rig(plant, scenario, rig)
        discrete = model.controller.discrete
        sampling = discrete.build() if discrete is not None else None
        for key in ("input_delay", "output_delay"):  # k·dt, bounded, held by sampled runs only
            delay_steps(key, getattr(scenario, key), sim.dt, sampled=sampling is not None)
        if sampling is not None and sampling.y_quantum > 0:  # a quantum the output can use
            from_sensor = sensor_table is not None and sensor_table.build().quantum > 0
            quantum_key = "sensor.quantum" if from_sensor else "controller.discrete.y_quantum"
            check_quantum_range(quantum_key, sampling.y_quantum, scenario, plant)
        # the default r of Kalman observer gains: this run's measurement noise
        noise_r = measurement_noise_intensity(scenario, sampling)
        controller = model.controller.build(plant.relative_degree or 1, measurement_r=noise_r)
        if scenario.x0 and len(scenario.x0) != plant.n_states:
            raise ValueError(
                f"scenario.x0 has {len(scenario.x0)} entries; plant {plant.name!r} has "
                f"{plant.n_states} states"
            )
        # the plant's functions are finite at the initial state; rho vs the relative degree,
        # IOFL's normal form, the sign of b0 (Controller.check_plant)
        plant.check(scenario.x0 or [0.0] * plant.n_states)
        controller.check_plant(plant, scenario.x0 or None)
        if model.scenario.u_ref == "trim":  # ISU, IAU about the holding input
            scenario = replace(scenario, u_ref=holding_input(plant, scenario))
        if model.controller.eso.u0 == "trim":  # a start at the holding input
            u_e = holding_input(plant, scenario, "controller.eso.u0")
            controller = controller.with_values(**{"eso.u0": u_e})
        if model.controller.eso.delay == "rig":  # told the rig's measurement delay
            if rig is None:
                raise ValueError(
                    'controller.eso.delay = "rig" needs a [rig] table (its measurement_delay); '
                    "allowed: a delay in seconds, a whole number of the controller's ts"
                )
            controller = controller.with_values(**{"eso.delay": rig.measurement_delay})
        columns = len(L.trajectory_columns(plant.n_states))
        check_run_size(sc.t_final, sim.dt, trajectory_columns=columns, decimation=sim.decimation)
    except (ValueError, PlantError) as exc:
        raise ConfigError(f"invalid config {source}: {exc}{note}") from None
    if missing:
        raise ConfigError(f"invalid config {source}:{note}")
    if model.uncertainty is not None:  # plant parameters by name; ts needs a sampled controller
        try:
            model.uncertainty.check(
                plant.param_names, discrete=model.controller.discrete is not None, dt=sim.dt
            )
        except ValueError as exc:
            raise ConfigError(f"invalid config {source}: {exc}") from None
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
        raw=data if rig is None else {**original, "plant": data["plant"]},
        uncertainty=model.uncertainty,
        rig=rig,
        defaults=tuple(model.defaults_used()),
    )
    if sampling is not None:  # [controller.discrete]: a sampled controller
        cfg = replace(cfg, sampling=sampling)
        cfg.check_sampling()
    given = sensor_table is not None and "preset" in data["sensor"]  # else custom, not ideal
    label = sensor_table.preset if given else "custom"
    return replace(cfg, sensor=Sensor.of_run(cfg.scenario, cfg.sampling, label, plant.output_unit))


def _presets_dir() -> Any:
    return resources.files("aiofl") / "presets"


#: the sets of shipped presets: (key, folder under presets/, title).  A preset's set is a
#: measured fact (the rig table, tests/test_report_rig.py): "designs" hold on the servo-1khz
#: rig (analysis.rig_check), "paper" is the paper as printed (an ideal world: a continuous
#: controller, an exact measurement), "limits" are tuned for an ideal world a rig defeats.
PRESET_SETS: tuple[tuple[str, str, str], ...] = (
    ("designs", "", "Designs for a rig (hold on the servo-1khz rig)"),
    ("paper", "paper", "The paper's designs (the reproduction: an ideal world)"),
    ("limits", "limits", "Ideal-world limits (tuned for an exact model and sensor; fail a rig)"),
)


def preset_sets() -> dict[str, list[str]]:
    """The shipped presets' names by set (:data:`PRESET_SETS`), each sorted."""
    out: dict[str, list[str]] = {}
    for key, folder, _ in PRESET_SETS:
        base = _presets_dir() / folder if folder else _presets_dir()
        files = base.iterdir() if base.is_dir() else ()
        names = [p.name[:-5] for p in files if p.is_file() and p.name.endswith(".toml")]
        out[key] = sorted(names)
    return out


def list_presets() -> list[str]:
    """Names of the presets shipped with the package, every set (:func:`preset_sets`)."""
    return sorted(n for names in preset_sets().values() for n in names)


def preset_text(name: str) -> str:
    """The TOML text of preset ``name`` (searched in every set)."""
    if not name or "/" in name or "\\" in name or name.startswith("."):
        raise ConfigError(f"unknown preset {name!r}; available: {', '.join(list_presets())}")
    for _, folder, _ in PRESET_SETS:
        base = _presets_dir() / folder if folder else _presets_dir()
        path = base / f"{name}.toml"
        if path.is_file():
            return path.read_text(encoding="utf-8")
    raise ConfigError(f"unknown preset {name!r}; available: {', '.join(list_presets())}")


def load_config(path_or_preset: str | Path) -> RunConfig:
    """Load a TOML file, or a shipped preset by name; raises :class:`ConfigError`."""
    p = Path(path_or_preset)
    if p.suffix == ".toml" or p.exists():
        if not p.is_file():
            raise ConfigError(f"config file {str(p)!r} does not exist")
        source, base = str(p), p.parent
        try:
            text = p.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise ConfigError(f"config file {source!r} cannot be read: {exc}") from None
    else:
        text, source, base = preset_text(str(path_or_preset)), f"preset {path_or_preset!r}", None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:  # its message names the line and column
        raise ConfigError(f"malformed TOML in {source}: {exc}") from None
    return parse_config(data, source, base)
