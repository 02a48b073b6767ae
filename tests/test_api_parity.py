"""The Python API checks what the CLI checks, and the notebook API (:class:`aiofl.Design`).

* every case of issue 22 ("the Python API is looser than the CLI") is a ``ValueError``
  naming the field and its range;
* the fuzzers' classes of bad values (wrong type, NaN, ±inf, negative, zero, huge, tiny;
  ``tests/test_fuzz_inputs.py``, ``benchmarks/fuzz_inputs.py``) fed to every numeric field
  are refused by the API exactly when a config with that value is refused, and the API's
  message names the same field as the config's;
* a sample of bad TOML files: ``aiofl simulate --check`` exits 2 naming the field, and the
  same value in Python raises naming it too;
* the manual's notebook block (``docs/guide/simulate.md``) runs as a script: its
  :class:`aiofl.Design` on a plant defined in Python simulates, tunes, runs robustness,
  analyses and exports C that compiles with ``-std=c99 -Wall -Wextra -Werror``.
"""

from __future__ import annotations

import copy
import math
import re
import runpy
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from aiofl import Controller, Design, Plant, Reference, Scenario
from aiofl.cli.app import app
from aiofl.config import ConfigError, parse_config
from aiofl.config.objects import config_dict
from aiofl.controller import _VALUE_RANGES, controller_batch, value_range
from aiofl.engine.simulation import simulate, simulate_batch
from aiofl.export.c_check import CC, WARN, build
from aiofl.plants import get_plant
from aiofl.tuning.space import to_toml

PENDULUM = get_plant("pendulum")
CTRL = Controller.from_structure(
    "LADRC",
    rho=2,
    values={"eso.omega0": 40.0, "sef.omega_c": 5.0, "td.omega": 10.0, "law.b0": 4.0},
)
SCEN = Scenario(reference=Reference(amplitude=0.5, omega=1.0), t_final=0.2)
DT = 1e-3
BASE = config_dict(PENDULUM, CTRL, SCEN, dt=DT)


# ------------------------------------------------------------------ issue 22's cases
def _sim(**kw: Any) -> Any:
    args = {"plant": PENDULUM, "controller": CTRL, "scenario": SCEN, "dt": DT, **kw}
    return simulate(args.pop("plant"), args.pop("controller"), args.pop("scenario"), **args)


ISSUE_CASES = {
    "dt = inf": (lambda: _sim(dt=math.inf), "simulation.dt"),
    "dt > t_final": (lambda: _sim(scenario=Scenario(t_final=0.05), dt=0.1), "simulation.dt"),
    "noise_variance = nan": (lambda: Scenario(noise_variance=math.nan), "scenario.noise_variance"),
    "noise_hold = inf": (lambda: Scenario(noise_hold=math.inf), "scenario.noise_hold"),
    "t_final = inf": (lambda: Scenario(t_final=math.inf), "scenario.t_final"),
    "divergence_threshold = -1": (
        lambda: _sim(divergence_threshold=-1),
        "simulation.divergence_threshold",
    ),
    "divergence_threshold = nan": (
        lambda: _sim(divergence_threshold=math.nan),
        "simulation.divergence_threshold",
    ),
    "no controllers": (lambda: simulate_batch(PENDULUM, [], SCEN, dt=DT), "controllers"),
    "a string for the controllers": (
        lambda: simulate_batch(PENDULUM, "LESO", SCEN, dt=DT),  # type: ignore[arg-type]
        "controllers",
    ),
    "plant parameter 'four'": (
        lambda: Scenario(plant_overrides={"m": "four"}),  # type: ignore[dict-item]
        "scenario.plant_overrides.m",
    ),
    "plant scale 'four'": (
        lambda: Scenario(plant_scale={"m": "four"}),  # type: ignore[dict-item]
        "scenario.plant_scale.m",
    ),
    "decimation = 2.5": (lambda: _sim(decimation=2.5), "simulation.decimation"),
    "dt = 1e-12 with trajectories": (lambda: _sim(dt=1e-12), "simulation.dt"),
    "b0 = -1 (β > 0)": (lambda: _sim(controller=CTRL.with_values(**{"law.b0": -1.0})), "law.b0"),
    "b0 = -1 in a list": (
        lambda: simulate_batch(PENDULUM, [CTRL.with_values(**{"law.b0": -1.0})], SCEN, dt=DT),
        "law.b0",
    ),
    "omega0 = -40": (lambda: CTRL.with_values(**{"eso.omega0": -40.0}), "eso.omega0"),
    "dt not dividing t_final": (lambda: _sim(dt=0.003), "simulation.dt"),
    "a batch too big to store": (
        lambda: simulate_batch(
            PENDULUM, [CTRL] * 3000, Scenario(t_final=100.0), dt=1e-4, store=True
        ),
        "MiB",
    ),
}


ISSUE_CASES["omega0 = -40 in a packed batch"] = (
    lambda: controller_batch(CTRL, {"eso.omega0": np.array([40.0, -40.0])}),
    "controller.eso.omega0 (member 1)",
)
ISSUE_CASES["b0 = 0 in a packed batch"] = (
    lambda: controller_batch(CTRL, {"law.b0": np.array([0.0])}),
    "controller.law.b0 (member 0)",
)


@pytest.mark.parametrize("case", list(ISSUE_CASES))
def test_issue_cases_are_value_errors_naming_the_field(case: str) -> None:
    fn, field = ISSUE_CASES[case]
    with pytest.raises(ValueError, match=re.escape(field)) as info:
        fn()
    assert "allowed" in str(info.value) or "sign" in str(info.value)


# ---------------------------------------------- every fuzz class through both paths
#: the fuzzers' classes of a bad scalar: wrong types, NaN, ±inf, negative, zero, huge, tiny
EDGES: list[Any] = [math.nan, math.inf, -math.inf, -1.0, 0.0, 0, 1e300, 5e-324, True, "50", None]
EDGES += [2.5, [1.0]]

#: (API field name, how the value goes into the config dict, how into the Python objects)
FIELDS: list[tuple[str, Any, Any]] = []


def _scen_field(name: str) -> None:
    FIELDS.append(
        (
            f"scenario.{name}",
            lambda d, v, n=name: d["scenario"].__setitem__(n, v),
            lambda v, n=name: {"scenario": Scenario(**{**_scen_kwargs(), n: v})},
        )
    )


def _scen_kwargs() -> dict[str, Any]:
    return {"reference": SCEN.reference, "t_final": SCEN.t_final}


for _name in (
    "t_final",
    "disturbance_amplitude",
    "disturbance_time",
    "parameter_change_time",
    "noise_variance",
    "noise_hold",
    "noise_seed",
):
    _scen_field(_name)
for _name in ("amplitude", "omega", "phase", "offset", "t_step"):
    FIELDS.append(
        (
            f"scenario.reference.{_name}",
            lambda d, v, n=_name: d["scenario"]["reference"].__setitem__(n, v),
            lambda v, n=_name: {
                "scenario": Scenario(reference=Reference(**{n: v}), t_final=SCEN.t_final)
            },
        )
    )
for _table in ("plant_scale", "plant_overrides"):
    FIELDS.append(
        (
            f"scenario.{_table}.c",
            lambda d, v, t=_table: d["scenario"].__setitem__(t, {"c": v}),
            lambda v, t=_table: {"scenario": Scenario(**{**_scen_kwargs(), t: {"c": v}})},
        )
    )
FIELDS.append(
    (
        "scenario.x0",
        lambda d, v: d["scenario"].__setitem__("x0", [v, 0.0]),
        lambda v: {"scenario": Scenario(**{**_scen_kwargs(), "x0": (v, 0.0)})},
    )
)
for _name in ("eso.omega0", "eso.k_alpha", "td.R", "td.a", "td.omega", "law.b0", "law.u_max"):
    FIELDS.append(
        (
            f"controller.{_name}",
            lambda d, v, n=_name: d["controller"][n.split(".")[0]].__setitem__(n.split(".")[1], v),
            lambda v, n=_name: {"controller": CTRL.with_values(**{n: v})},
        )
    )
for _vec in ("eso.alpha", "sef.k", "sef.alpha", "sef.delta", "sef.mu"):
    FIELDS.append(
        (
            f"controller.{_vec}",
            lambda d, v, n=_vec: d["controller"][n.split(".")[0]][n.split(".")[1]].__setitem__(
                0, v
            ),
            lambda v, n=_vec: {"controller": CTRL.with_values(**{f"{n}1": v})},
        )
    )
for _name in ("dt", "decimation", "divergence_threshold"):
    FIELDS.append(
        (
            f"simulation.{_name}",
            lambda d, v, n=_name: d["simulation"].__setitem__(n, v),
            lambda v, n=_name: {n: v},
        )
    )


def _config_outcome(set_value: Any, value: Any) -> str | None:
    data = copy.deepcopy(BASE)
    set_value(data, value)
    try:
        parse_config(data, "parity")
    except ConfigError as exc:
        return str(exc)
    return None


def _api_outcome(build: Any, value: Any) -> str | None:
    try:
        parts = build(value)
        kw = {k: v for k, v in parts.items() if k not in ("scenario", "controller")}
        simulate(
            PENDULUM,
            parts.get("controller", CTRL),
            parts.get("scenario", SCEN),
            **{"dt": DT, **kw},
        )
    except ValueError as exc:
        return str(exc)
    return None


def _names_field(message: str, field: str) -> bool:
    """Whether ``message`` names ``field`` (a vector entry as ``alpha1`` or ``alpha.0``;
    the config calls the controller's values by table, ``controller.eso.omega0``)."""
    flat = re.sub(r"(\w)\.(\d+)", r"\1", message)  # sef.alpha.0 -> sef.alpha
    flat = re.sub(r"\[(\d+)\]", "", flat)  # x0[0] -> x0
    flat = re.sub(r"\.(alpha|k|kb|delta|mu)\d+\b", r".\1", flat)  # sef.alpha1 -> sef.alpha
    table, _, key = field.rpartition(".")
    return field in flat or (table in flat and key in flat)  # controller.law: ... u_max


@pytest.mark.parametrize("field", [f[0] for f in FIELDS])
def test_every_fuzz_class_is_refused_by_the_api_exactly_when_by_the_config(field: str) -> None:
    _, set_value, build = next(f for f in FIELDS if f[0] == field)
    for value in EDGES:
        cfg_error = _config_outcome(set_value, value)
        api_error = _api_outcome(build, value)
        if cfg_error is not None and "after the horizon" in cfg_error:
            # an event after the horizon: refused in a config (a typo guard) and by
            # Design; a bare Scenario allows it, since the tuner runs the first seconds of
            # a scenario whose events may come later
            assert api_error is None, (field, value, api_error)
            with pytest.raises(ValueError, match="after the horizon"):
                Design(PENDULUM, CTRL, build(value)["scenario"], dt=DT)
            continue
        assert (cfg_error is None) == (api_error is None), (field, value, cfg_error, api_error)
        if api_error is not None:
            assert _names_field(api_error, field), (field, value, api_error)
            assert _names_field(cfg_error, field), (field, value, cfg_error)


def test_the_controller_ranges_are_the_config_schemas() -> None:
    """Every range of :data:`aiofl.controller._VALUE_RANGES` is the schema's: a value just
    outside it is refused by both, one at the edge (where allowed) accepted by both."""
    checked = 0
    for name, bounds in _VALUE_RANGES.items():
        build = next((f for f in FIELDS if f[0] == f"controller.{name}"), None)
        if build is None:
            continue  # needs another controller (Kalman gains, INLESO, improved SEF)
        for key, edge in bounds.items():
            outside = {"gt": edge, "ge": edge - 1e-9, "lt": edge, "le": edge + 1e-9}[key]
            assert _config_outcome(build[1], outside) is not None, (name, outside)
            assert _api_outcome(build[2], outside) is not None, (name, outside)
            checked += 1
    assert checked >= 8
    assert value_range("sef.alpha7") == ({"gt": 0.0, "le": 3.0}, True)
    assert value_range("law.u_max") == ({}, False)


# ---------------------------------------------------- bad TOML files: CLI vs Python
BAD_TOML = [
    # (dotted path in the config, TOML-expressible value, the field both name, Python call)
    (("scenario", "t_final"), math.inf, "scenario.t_final", lambda v: Scenario(t_final=v)),
    (
        ("scenario", "noise_variance"),
        math.nan,
        "scenario.noise_variance",
        lambda v: Scenario(noise_variance=v),
    ),
    (("scenario", "noise_hold"), -1.0, "scenario.noise_hold", lambda v: Scenario(noise_hold=v)),
    (
        ("scenario", "plant_overrides"),
        {"m": "four"},
        "scenario.plant_overrides.m",
        lambda v: Scenario(plant_overrides=v),
    ),
    (
        ("controller", "eso", "omega0"),
        -40.0,
        "controller.eso.omega0",
        lambda v: CTRL.with_values(**{"eso.omega0": v}),
    ),
    (
        ("controller", "td", "a"),
        1.0,
        "controller.td.a",
        lambda v: CTRL.with_values(**{"td.a": v}),
    ),
    (("simulation", "dt"), math.inf, "simulation.dt", lambda v: _sim(dt=v)),
    (("simulation", "decimation"), 2.5, "simulation.decimation", lambda v: _sim(decimation=v)),
    (
        ("simulation", "divergence_threshold"),
        -1.0,
        "simulation.divergence_threshold",
        lambda v: _sim(divergence_threshold=v),
    ),
]


@pytest.mark.parametrize("case", BAD_TOML, ids=lambda c: c[2])
def test_a_bad_toml_and_the_same_value_in_python_name_the_same_field(
    case: Any, tmp_path: Path
) -> None:
    path, value, field, call = case
    data = copy.deepcopy(BASE)
    node = data
    for part in path[:-1]:
        node = node[part]
    node[path[-1]] = value
    (tmp_path / "bad.toml").write_text(to_toml(data))
    res = CliRunner().invoke(app, ["simulate", str(tmp_path / "bad.toml"), "--check"])
    assert res.exit_code == 2, res.output
    assert field in res.stderr, res.stderr
    with pytest.raises(ValueError) as info:
        call(value)
    assert field in str(info.value), str(info.value)


# ----------------------------------------------------------------- the notebook API
def _f(x: Any, p: Any) -> Any:
    return (x[1], -p[0] * np.sin(x[0]) - p[1] * x[1])


def _g(x: Any, p: Any) -> Any:
    return (0.0, p[2])


def _h(x: Any, p: Any) -> Any:
    return x[0]


def _my_plant(name: str = "nb_pendulum") -> Plant:
    return Plant(
        name=name,
        n_states=2,
        f=_f,
        g=_g,
        h=_h,
        params={"g_over_l": 19.62, "c": 0.4, "b": 4.0},
        relative_degree=2,
    )


def _design(plant: Plant | None = None, **kw: Any) -> Design:
    settings = {
        "dt": 1e-3,
        "uncertainty": {"draws": 4, "parameters": {"c": {"uniform": 0.5}, "b": {"uniform": 0.2}}},
        **kw,
    }
    scenario = Scenario(reference=Reference(amplitude=0.5, omega=1.0), t_final=1.0)
    return Design(plant or _my_plant(), CTRL, scenario, **settings)


def test_a_design_round_trips_through_parse_config() -> None:
    d = _design(sampling=None, sensor="encoder-16bit")
    again = parse_config(copy.deepcopy(d.config.raw), "again")
    assert again.plant is d.plant
    assert np.array_equal(again.controller.float_row(), CTRL.float_row(), equal_nan=True)
    assert again.scenario == d.config.scenario and again.dt == d.dt
    assert d.config.sampling is not None and d.config.sampling.ts == 1e-3  # the sensor's


def test_design_refuses_what_the_config_refuses() -> None:
    with pytest.raises(ValueError, match=r"simulation\.dt"):
        _design(dt=0.3)
    with pytest.raises(ValueError, match=r"scenario\.disturbance_time"):
        Design(_my_plant(), CTRL, Scenario(t_final=1.0, disturbance_time=2.0), dt=1e-3)
    with pytest.raises(ValueError, match=r"uncertainty\.parameters"):
        _design(uncertainty={"parameters": {"nope": {"uniform": 0.1}}})
    with pytest.raises(ValueError, match="another registered plant"):
        _design(plant=_my_plant("slfjm"))
    with pytest.raises(ValueError, match=r"eso\.alpha7"):
        Design(_my_plant(), CTRL.with_values(**{"eso.alpha7": 2.0}), SCEN, dt=1e-3)
    with pytest.raises(ValueError, match="uncertainty"):
        Design(_my_plant(), CTRL, SCEN, dt=1e-3).robustness()


def test_a_redefined_python_plant_replaces_the_old_one() -> None:
    """Running a notebook cell again defines a new Plant of the same name: it is used."""
    first, second = _my_plant("nb_again"), _my_plant("nb_again")
    assert Design(first, CTRL, SCEN, dt=1e-3).config.plant is first
    d = Design(second, CTRL, SCEN, dt=1e-3)
    assert parse_config(copy.deepcopy(d.config.raw)).plant is second


def test_the_manual_s_notebook_block_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The manual's notebook block (docs/guide/simulate.md), run as a script (a file, as a
    user's would be: its plant's kernel is cached on disk), and the notebook path it shows
    on a plant defined in Python: the design simulates, tunes (best.toml), runs robustness
    over its draws, analyses, and exports C that compiles with ``-std=c99 -Wall -Wextra
    -Werror``."""
    page = Path(__file__).resolve().parents[1] / "docs" / "guide" / "simulate.md"
    blocks = re.findall(r"```python\n(.*?)```", page.read_text(encoding="utf-8"), flags=re.S)
    block = next(b for b in blocks if "Design(" in b)
    script = tmp_path / "notebook_block.py"
    script.write_text(block, encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    namespace = runpy.run_path(str(script))
    tuned, result, rob = namespace["design"], namespace["result"], namespace["rob"]
    first = tuned.with_values({"eso.omega0": 40.0, "sef.omega_c": 5.0})  # the block's own
    res = first.simulate()
    assert not res.failed and res.metrics["itae"] > 0 and res["y"].size > 10
    assert set(result.best_values) == {"eso.omega0", "sef.omega_c"}
    assert (tmp_path / "out" / "tune" / "best.toml").is_file()
    assert tuned.controller.value("eso.omega0") == result.best_values["eso.omega0"]
    assert len(rob.itae) == 8 and 0 <= rob.stable_fraction <= 1
    assert tuned.analyze()["verdict"] in ("stable", "unstable", "marginal")
    out_c = tmp_path / "out" / "c"
    texts = {p.name: p.read_text() for p in out_c.iterdir()}
    assert set(texts) == {"aiofl_controller.h", "aiofl_controller.c", "aiofl_params.c"}
    if CC is not None:
        assert "-Werror" in WARN
        build(tmp_path / "lib", texts)
