"""A run config from Python objects: ``Plant`` + ``Controller`` + ``Scenario`` -> RunConfig.

:func:`run_config_from_objects` writes the objects as the config dict a TOML file would
give (:func:`config_dict`), validates it with :func:`aiofl.config.parse_config` (so the
objects pass exactly the checks a file does and the CLI makes) and returns the
:class:`~aiofl.config.RunConfig`, whose ``raw`` dict round-trips through ``parse_config``:
tuning (which rebuilds the config from ``raw`` for every spec), ``best.toml`` and the
closed-loop analyses work on it as on a loaded file.

A plant built from a plant file (:func:`aiofl.config.resolve_plant`) is named by that
file's path, so its config runs anywhere.  A plant defined in Python has no file to name:
it is registered in this process under its own name (:func:`register_python_plant`,
:func:`aiofl.plants.register_plant`), and ``raw["plant"]`` names it.  Such a config
therefore resolves only in the process that registered the plant (the local tuner, which
runs every population in one compiled, parallel call, does; Dask workers in other
processes do not: use a plant file there).
"""

from __future__ import annotations

from typing import Any

from aiofl import layout as L
from aiofl.components.metrics import OPIWeights
from aiofl.config.schema import ConfigError
from aiofl.controller import STRUCTURES, Controller
from aiofl.plants.base import Plant
from aiofl.scenario import Scenario
from aiofl.sensor import SENSOR_PRESETS, Sensor

__all__ = [
    "config_dict",
    "controller_table",
    "is_python_plant",
    "plant_entry",
    "register_python_plant",
    "run_config_from_objects",
    "scenario_table",
]

_REGISTERED: dict[str, Plant] = {}  # plants registered here, by name


def register_python_plant(plant: Plant) -> str:
    """Make ``plant`` resolvable by its name in configs of this process; return the name.

    A name registered before by this function is re-registered (a notebook cell run again
    defines a new Plant of the same name); a built-in or otherwise registered plant of the
    same name is refused unless it is this very object.
    """
    from aiofl.plants.registry import available_plants, get_plant, register_plant

    if not isinstance(plant, Plant):
        raise ValueError(f"plant = {plant!r}; allowed: an aiofl.Plant")
    name = plant.name
    if not isinstance(name, str) or not name or name.endswith(".toml"):
        raise ValueError(f"plant.name = {name!r}; allowed: a non-empty name not ending in .toml")
    if name in available_plants() and name not in _REGISTERED:
        if get_plant(name) is plant:
            return name
        raise ValueError(
            f"plant.name = {name!r} is the name of another registered plant; allowed: a name "
            f"not in {', '.join(available_plants())} (or aiofl.get_plant({name!r}) itself)"
        )
    if _REGISTERED.get(name) is not plant:
        _REGISTERED[name] = plant
        register_plant(name, lambda: plant)
    return name


def is_python_plant(name: str) -> bool:
    """Whether ``name`` is a plant defined in Python and registered by
    :func:`register_python_plant` (known in this process only)."""
    return name in _REGISTERED


def plant_entry(plant: Plant) -> str:
    """The config's ``plant``: the file a plant file's plant was built from (so the config
    runs in any process, the command line's too), else its registered name
    (:func:`register_python_plant`)."""
    from aiofl.config.run_config import _FILE_PLANTS  # plant files built in this process

    if not isinstance(plant, Plant):
        raise ValueError(f"plant = {plant!r}; allowed: an aiofl.Plant")
    path = next((p for (p, _), built in _FILE_PLANTS.items() if built is plant), None)
    return path if path is not None else register_python_plant(plant)


def _structure(c: Controller) -> str:
    """The config's ``structure``: the controller's own if it is one of
    :data:`aiofl.controller.STRUCTURES`, else the one with the same kinds, else LESO (the
    kinds are written explicitly anyway)."""
    if c.structure in STRUCTURES:
        return c.structure
    kinds = (c.eso, c.td, c.sef, c.law)
    return next((name for name, k in STRUCTURES.items() if k == kinds), "LESO")


def _vector(c: Controller, prefix: str, length: int) -> list[float]:
    given = [
        int(n[len(prefix) :])
        for n in c.values
        if n[len(prefix) :].isdigit() and n.startswith(prefix)
    ]
    n = max([length, *given])
    return [c.value(f"{prefix}{i}") for i in range(1, n + 1)]


def controller_table(c: Controller) -> dict[str, Any]:
    """The ``[controller]`` table of ``c`` (every parameter the engine reads, explicitly)."""
    eso: dict[str, Any] = {
        "init": c.eso_init,
        "model": c.eso_model,
        "gains": c.eso_gains,
        **{k: c.value(f"eso.{k}") for k in ("k_alpha", "k_beta", "g_alpha", "g_beta")},
    }
    if c.value("eso.u0") != 0.0:  # a start at a held command
        eso["u0"] = c.value("eso.u0")
    if c.value("eso.delay") != 0.0:  # a known measurement delay
        eso["delay"] = c.value("eso.delay")
    if c.eso_gains == "kalman":
        eso.update(q=c.value("eso.q"), r=c.value("eso.r"))
    else:
        alpha = [c.value(f"eso.alpha{i}") for i in range(1, c.rho + 2)]
        eso.update(omega0=c.value("eso.omega0"), alpha=alpha)
    m = int(c.n_feedback)  # type: ignore[arg-type]
    sef: dict[str, Any] = {
        v: _vector(c, f"sef.{v}", m) for v in ("k", "kb", "alpha", "delta", "mu")
    }
    sef.update({k: c.value(f"sef.{k}") for k in ("v_limit", "omega_c")})
    law = {"b0": c.value("law.b0"), "u_max": c.value("law.u_max")}
    if "law.u_min" in c.values:
        law["u_min"] = c.value("law.u_min")
    return {
        "structure": _structure(c),
        "eso_kind": c.eso,
        "td_kind": c.td,
        "sef_kind": c.sef,
        "law_kind": c.law,
        "rho": c.rho,
        "n_feedback": m,
        "allow_rho_mismatch": bool(c.allow_rho_mismatch),
        "allow_b0_sign_mismatch": bool(c.allow_b0_sign_mismatch),
        "eso": eso,
        "td": {k: c.value(f"td.{k}") for k in ("R", "a", "b", "c", "rho", "omega")},
        "sef": sef,
        "law": law,
    }


def scenario_table(s: Scenario) -> dict[str, Any]:
    """The ``[scenario]`` table of ``s``."""
    ref = s.reference
    return {
        "name": s.name,
        "t_final": s.t_final,
        "disturbance_amplitude": s.disturbance_amplitude,
        "disturbance_time": s.disturbance_time,
        "plant_scale": dict(s.plant_scale),
        "plant_overrides": dict(s.plant_overrides),
        "parameter_change_time": s.parameter_change_time,
        "noise_variance": s.noise_variance,
        "noise_hold": s.noise_hold,
        "noise_seed": s.noise_seed,
        "x0": list(s.x0),
        "reference": {
            "kind": ref.kind,
            "amplitude": ref.amplitude,
            "omega": ref.omega,
            "phase": ref.phase,
            "offset": ref.offset,
            "t_step": ref.t_step,
            "samples": list(ref.samples),
            "sample_dt": ref.sample_dt,
        },
    }


def _sensor_table(sensor: Sensor | str) -> dict[str, Any]:
    if isinstance(sensor, str):
        return {"preset": sensor}
    if not isinstance(sensor, Sensor):
        raise ValueError(f"sensor = {sensor!r}; allowed: a preset name or an aiofl.sensor.Sensor")
    table: dict[str, Any] = {
        "preset": sensor.preset if sensor.preset in SENSOR_PRESETS else "ideal"
    }
    for key in ("ts", "quantum", "noise_variance", "noise_hold", "noise_seed"):
        value = getattr(sensor, key)
        if value is not None:
            table[key] = value
    return table


_NOISE_KEYS = ("noise_variance", "noise_hold", "noise_seed")


def _leave_noise_to_sensor(
    scen: dict[str, Any], sensor: dict[str, Any], scenario: Scenario
) -> None:
    """Drop from the ``[scenario]`` table ``scen`` the noise keys the sensor decides.

    With a sensor, the measurement's noise is the sensor's: a scenario noise key left at
    :class:`~aiofl.scenario.Scenario`'s default, or equal to the sensor's value, is not
    written (a ``[sensor]`` table with the scenario's noise keys is refused as "set
    twice", as a TOML file is); a scenario value that differs from the sensor's is a real
    contradiction, refused naming both.
    """
    default = Scenario()
    for key in _NOISE_KEYS:
        mine = getattr(scenario, key)
        if key in sensor and mine != sensor[key] and mine != getattr(default, key):
            raise ConfigError(
                f"{key} is set twice: the sensor's {key} = {sensor[key]!r} and "
                f"scenario.{key} = {mine!r}; set it in the Sensor only (the sensor is the "
                "measurement)"
            )
        if key in sensor or mine == getattr(default, key):
            scen.pop(key, None)


def _sampling_table(sampling: Any) -> dict[str, Any]:
    from aiofl.engine.discrete_rows import Sampling

    if not isinstance(sampling, Sampling):
        raise ValueError(f"sampling = {sampling!r}; allowed: None or an aiofl Sampling")
    return {k: v for k, v in vars(sampling).items() if v is not None}


def config_dict(
    plant: Plant,
    controller: Controller,
    scenario: Scenario,
    *,
    dt: float = 1e-4,
    method: str = "rk4",
    decimation: int = 10,
    divergence_threshold: float = 1e10,
    sampling: Any = None,
    sensor: Sensor | str | None = None,
    uncertainty: Any = None,
    weights: OPIWeights | None = None,
    name: str = "design",
    description: str = "",
) -> dict[str, Any]:
    """The config dict (as a TOML file would give) of these objects; see the module notes.

    ``sampling`` (:class:`aiofl.engine.discrete_rows.Sampling`) becomes ``[controller.discrete]``,
    ``sensor`` (a preset name or a :class:`~aiofl.sensor.Sensor`) ``[sensor]``,
    ``uncertainty`` (an :class:`aiofl.uncertainty.UncertaintyModel` or its dict)
    ``[uncertainty]``.  Nothing is validated here (:func:`run_config_from_objects` does).

    Parameters
    ----------
    plant
        The plant: a registered plant's name is kept, a plant file's path too.
    controller, scenario
        A :class:`~aiofl.controller.Controller` and a :class:`~aiofl.scenario.Scenario`.
    dt, method, decimation, divergence_threshold
        ``[simulation]``: fixed step [s], ``"rk4"`` or ``"euler"``, the stored-step interval
        and the divergence bound (as for :func:`aiofl.engine.simulate_batch`).
    sampling
        ``[controller.discrete]``; None: a continuous controller.
    sensor
        ``[sensor]``: a preset name or a :class:`~aiofl.sensor.Sensor`; None: no sensor table.
    uncertainty
        ``[uncertainty]``: a model or its dict; None: none.
    weights
        ``[objective]`` weights (default :class:`~aiofl.components.metrics.OPIWeights()`).
    name, description
        The config's name and its one-line description.

    Returns
    -------
    dict
        The config's tables, as :func:`tomllib.loads` would give them.

    Raises
    ------
    ValueError
        For a controller, scenario or weights of the wrong type.
    """
    if not isinstance(controller, Controller):
        raise ValueError(f"controller = {controller!r}; allowed: an aiofl.Controller")
    if not isinstance(scenario, Scenario):
        raise ValueError(f"scenario = {scenario!r}; allowed: an aiofl.Scenario")
    w = weights if weights is not None else OPIWeights()
    if not isinstance(w, OPIWeights):
        raise ValueError(f"weights = {weights!r}; allowed: an aiofl.OPIWeights")
    data: dict[str, Any] = {
        "name": name,
        "description": description,
        "plant": plant_entry(plant),
        "scenario": scenario_table(scenario),
        "controller": controller_table(controller),
        "simulation": {
            "dt": dt,
            "method": method,
            "decimation": decimation,
            "divergence_threshold": divergence_threshold,
        },
        "metrics": {
            "weights": [w.w_itae, w.w_isu, w.w_iau],
            "normalisers": [w.n_itae, w.n_isu, w.n_iau],
        },
    }
    if sampling is not None:
        data["controller"]["discrete"] = _sampling_table(sampling)
    if sensor is not None:
        data["sensor"] = _sensor_table(sensor)
        _leave_noise_to_sensor(data["scenario"], data["sensor"], scenario)
    if uncertainty is not None:
        dump = getattr(uncertainty, "model_dump", None)
        data["uncertainty"] = dump(exclude_none=True) if dump else dict(uncertainty)
    return data


def run_config_from_objects(
    plant: Plant, controller: Controller, scenario: Scenario, **kw: Any
) -> Any:
    """The validated :class:`~aiofl.config.RunConfig` of these objects (keywords as for
    :func:`config_dict`); raises :class:`~aiofl.config.ConfigError` naming the field, as a
    file with these values would.  The rebuilt controller is checked to be the given one
    (same kinds and parameter values): a value the config cannot carry is refused.

    Parameters
    ----------
    plant, controller, scenario
        As for :func:`config_dict`.
    **kw
        The keywords of :func:`config_dict`.

    Returns
    -------
    RunConfig

    Raises
    ------
    ConfigError
        For a value the config refuses or cannot carry (naming the field).
    """
    from aiofl.config.run_config import parse_config

    data = config_dict(plant, controller, scenario, **kw)
    cfg = parse_config(data, f"design {data['name']!r}")
    built = cfg.controller
    if not (built.int_row() == controller.int_row()).all():
        raise ConfigError(f"controller {controller!r} has no config form (rebuilt as {built!r})")
    differ = [
        n
        for n in L.FLOAT_COLUMNS
        if not _same(
            built.float_row()[L.FLOAT_COLUMNS[n]], controller.float_row()[L.FLOAT_COLUMNS[n]]
        )
    ]
    if differ:
        raise ConfigError(
            f"controller value(s) {', '.join(differ)} have no config form (not used by this "
            f"controller: ρ = {controller.rho}, n_feedback = {controller.n_feedback}); remove them"
        )
    return cfg


def _same(a: float, b: float) -> bool:
    return a == b or (a != a and b != b)  # NaN (an unset law.u_min) equals NaN
