"""Config validation (every bad input names its field) and the shipped presets (each loads,
and the paper's presets carry the numbers printed in Section V)."""

from __future__ import annotations

import math
import tomllib

import pytest

from aiofl.config import ConfigError, list_presets, load_config, parse_config, preset_text

PAPER_PRESETS = [f"paper-s{s}-{k}" for s in (1, 2, 3) for k in ("leso", "inleso")]


def _paper_dict(**changes: object) -> dict:
    """paper-s1-leso as a dict, with dotted-path changes applied."""
    data = tomllib.loads(preset_text("paper-s1-leso"))
    for path, value in changes.items():
        node = data
        *parents, leaf = path.split("__")
        for key in parents:
            node = node.setdefault(key, {})
        node[leaf] = value
    return data


@pytest.mark.parametrize(
    ("changes", "needles"),
    [
        ({"controller__eso__omega": 5.0}, ["controller.eso.omega", "unknown key", "omega0"]),
        ({"scenario__colour": "red"}, ["scenario.colour", "unknown key", "allowed: name,"]),
        ({"scenario__reference__ampl": 1.0}, ["scenario.reference.ampl", "amplitude"]),
        ({"controler": {}}, ["controler", "allowed:", "controller"]),
        ({"controller__td__a": 1.5}, ["controller.td.a", "less than 1"]),
        ({"simulation__dt": 0.0}, ["simulation.dt", "greater than 0"]),
        ({"simulation__method": "rk45"}, ["simulation.method", "rk4", "euler"]),
        ({"scenario__noise_variance": -1e-4}, ["scenario.noise_variance", "greater than or equal"]),
        ({"controller__law__b0": -2.0}, ["controller.law.b0", "opposite sign", "β"]),
        ({"controller__law__b0": 0.0}, ["controller.law.b0", "non-zero"]),
        ({"controller__sef__alpha": [0.5, 4.0]}, ["controller.sef.alpha", "3"]),
        ({"controller__rho": 12}, ["controller.rho", "8"]),
        ({"metrics__weights": [0.6, 0.2]}, ["metrics.weights", "3"]),
        ({"controller__eso__alpha": [1.0, 2.0, 3.0]}, ["controller.eso.alpha", "rho+1 = 5"]),
        ({"plant": "no-such-plant"}, ["plant", "slfjm"]),
        ({"scenario__plant_scale": {"J_x": 1.4}}, ["J_x", "J_l"]),
        ({"controller__n_feedback": 3}, ["n_feedback", "1..2"]),
        ({"scenario__x0": [0.0, 0.0]}, ["x0", "4"]),
        ({"controller__structure": "PID"}, ["controller.structure", "LESO"]),
    ],
)
def test_bad_config_raises_config_error_naming_the_field(changes, needles):
    with pytest.raises(ConfigError) as err:
        parse_config(_paper_dict(**changes), "test.toml")
    msg = str(err.value)
    for needle in needles:
        assert needle in msg, f"{needle!r} not in {msg!r}"


def test_malformed_toml_and_missing_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\n[scenario\nt_final = 2\n', encoding="utf-8")
    with pytest.raises(ConfigError, match="malformed TOML"):
        load_config(bad)
    with pytest.raises(ConfigError, match="does not exist"):
        load_config(tmp_path / "missing.toml")
    with pytest.raises(ConfigError, match="paper-s1-leso"):
        load_config("no-such-preset")


def test_a_file_config_equals_its_preset(tmp_path):
    path = tmp_path / "copy.toml"
    path.write_text(preset_text("paper-s2-inleso"), encoding="utf-8")
    a, b = load_config(path), load_config("paper-s2-inleso")
    assert a.controller == b.controller and a.scenario == b.scenario
    assert (a.dt, a.method, a.weights) == (b.dt, b.method, b.weights)


def test_binomial_alpha_and_defaults():
    data = _paper_dict(controller__eso__alpha="binomial")
    rc = parse_config(data)
    assert [rc.controller.value(f"eso.alpha{i}") for i in range(1, 6)] == [5, 10, 10, 5, 1]


@pytest.mark.parametrize("name", list_presets())
def test_every_shipped_preset_loads(name):
    rc = load_config(name)
    assert rc.name == name
    assert rc.scenario.t_final > 0 and rc.dt > 0
    assert rc.controller.rho >= 1


def test_the_six_paper_presets_ship():
    assert set(PAPER_PRESETS) <= set(list_presets())


# Section V, printed after eq. (22) and for scenario 3
LESO_S12 = {
    "eso.omega0": 513.8283,
    "eso.alpha": [8.772, 0.1946, 0.7384, 9.6881e-3, 2.2651e-6],
    "law.b0": 22.771,
    "td.R": 2408.6918,
    "sef.delta": [16.6108, 14.6238],
    "sef.alpha": [0.3804, 0.4583],
}
INLESO_S12 = {
    "eso.omega0": 104.6131,
    "eso.alpha": [0.1364, 0.6691, 0.6893, 0.0155, 14.3801e-6],
    "law.b0": 8.745,
    "eso.k_alpha": 0.3682,
    "eso.k_beta": 0.1290,
    "eso.g_alpha": 0.6906,
    "eso.g_beta": 0.1880,
    "td.a": 0.9153,
    "td.b": 8.7141,
    "td.c": 0.0813,
    "td.rho": 22.89333,
    "sef.k": [1.7741, 0.00115],
    "sef.kb": [1.2147, 0.3312],
    "sef.mu": [3.8297, 10.9415],
    "sef.alpha": [0.8244, 1.8079],
    "sef.v_limit": 3.3900,
}
PRINTED = {
    "paper-s1-leso": LESO_S12,
    "paper-s2-leso": LESO_S12,
    "paper-s1-inleso": INLESO_S12,
    "paper-s2-inleso": INLESO_S12,
    "paper-s3-leso": {
        **LESO_S12,
        "eso.omega0": 851.0106,
        "eso.alpha": [5.40326, 0.2871, 0.7644, 0.01, 1.22e-6],
        "law.b0": 33.7432,
    },
    "paper-s3-inleso": {
        **INLESO_S12,
        "eso.omega0": 121.020,
        "eso.alpha": [0.205, 0.6, 0.42, 0.0232, 7.19e-6],
        "law.b0": 9.7,
    },
}


@pytest.mark.parametrize("name", PAPER_PRESETS)
def test_paper_presets_carry_the_printed_numbers(name):
    rc = load_config(name)
    c, sc = rc.controller, rc.scenario
    for key, want in PRINTED[name].items():
        values = want if isinstance(want, list) else [want]
        names = (
            [f"{key}{i}" for i in range(1, len(values) + 1)] if isinstance(want, list) else [key]
        )
        for n, v in zip(names, values, strict=True):
            assert c.value(n) == pytest.approx(v, rel=1e-12), (name, n)
    assert c.rho == 4 and c.n_feedback == 2
    assert c.structure == ("LESO" if name.endswith("-leso") else "INLESO")
    assert sc.t_final == 20.0
    assert sc.reference.amplitude == pytest.approx(math.pi / 4) and sc.reference.omega == 2.0
    scenario = int(name[len("paper-s")])
    assert (sc.disturbance_amplitude, sc.disturbance_time) == (
        (0.5, 10.0) if scenario == 2 else (0.0, sc.disturbance_time)
    )
    assert dict(sc.plant_scale) == ({"J_l": 1.4} if scenario == 2 else {})
    assert sc.noise_variance == (1e-4 if scenario == 3 else 0.0)
    w = rc.weights
    assert (w.w_itae, w.w_isu, w.w_iau, w.n_itae, w.n_isu, w.n_iau) == (0.6, 0.2, 0.6, 10, 2, 2.7)


# ------------------------------------------------------------- strict types and sizes
def _text_config(tmp_path, text: str):
    path = tmp_path / "run.toml"
    path.write_text(text, encoding="utf-8")
    return load_config(path)


MINIMAL = 'plant = "slfjm"\n[scenario]\nt_final = 2.0\n[controller]\nstructure = "LADRC"\n'
MINIMAL += "[controller.eso]\nomega0 = 50.0\n[controller.td]\nomega = 10.0\n"
MINIMAL += "[controller.sef]\nomega_c = 5.0\n[controller.law]\nb0 = 1.0\n"
MINIMAL += "[simulation]\ndt = 1e-3\n"


@pytest.mark.parametrize(
    ("changes", "needles"),
    [
        ({"scenario__t_final": True}, ["scenario.t_final", "valid number", "True"]),
        ({"scenario__t_final": "20"}, ["scenario.t_final", "valid number", "<= 10000"]),
        ({"simulation__dt": "1e-4 "}, ["simulation.dt", "valid number", "<= 0.1"]),
        ({"controller__rho": 4.0}, ["controller.rho", "valid integer", ">= 1, <= 8"]),
        ({"controller__rho": True}, ["controller.rho", "valid integer"]),
        ({"simulation__decimation": False}, ["simulation.decimation", "integer"]),
        ({"scenario__x0": [0.0, True, 0.0, 0.0]}, ["scenario.x0.1", "valid number"]),
        ({"metrics__weights": [0.6, "0.2", 0.6]}, ["metrics.weights.1", "valid number"]),
        ({"scenario__plant_scale": {"J_l": True}}, ["plant_scale.J_l", "valid number"]),
    ],
)
def test_no_bool_or_string_coercion_into_numbers(changes, needles):
    with pytest.raises(ConfigError) as err:
        parse_config(_paper_dict(**changes), "test.toml")
    for needle in needles:
        assert needle in str(err.value), (needle, str(err.value))


def test_an_integer_is_a_valid_float_but_a_float_is_no_integer():
    rc = parse_config(_paper_dict(scenario__t_final=2, scenario__disturbance_amplitude=1), "i")
    assert isinstance(rc.scenario.t_final, float) and rc.scenario.t_final == 2.0


@pytest.mark.parametrize(
    ("changes", "needles"),
    [
        # steps: 20 / 1e-9 = 2e10 > 2e7
        ({"simulation__dt": 1e-9}, ["2e+10 steps", "at most 2e+07 steps"]),
        # noise table: 20 / 1e-9 + 2 samples > 2e7
        ({"scenario__noise_hold": 1e-9}, ["noise_hold", "2e+10 noise samples", "2e+07"]),
        # trajectory: (1e7 + 1) points x 27 columns x 8 bytes = 2060 MiB > 512 MiB
        (
            {"scenario__t_final": 1000.0, "simulation__decimation": 1},
            ["2060 MiB", "10000001 points x 27 columns", "at most 512 MiB", "decimation"],
        ),
        ({"simulation__decimation": 10**30}, ["simulation.decimation", "2e+07"]),
        # the smallest float: t_final/dt and t_final/noise_hold overflow to inf
        ({"simulation__dt": 5e-324}, ["inf steps", "at most 2e+07 steps"]),
        ({"scenario__noise_hold": 5e-324}, ["inf noise samples", "2e+07"]),
    ],
)
def test_sizes_are_bounded_with_the_limit_in_the_message(changes, needles):
    with pytest.raises(ConfigError) as err:
        parse_config(_paper_dict(**changes), "big.toml")
    for needle in needles:
        assert needle in str(err.value), (needle, str(err.value))


def test_the_largest_allowed_run_is_accepted_without_allocating():
    from aiofl.limits import MAX_STEPS, check_run_size

    # exactly the limit passes; one step more does not
    assert check_run_size(MAX_STEPS * 1e-4, 1e-4) == MAX_STEPS
    with pytest.raises(ValueError, match="at most 2e\\+07 steps"):
        check_run_size((MAX_STEPS + 1) * 1e-4, 1e-4)
    rc = parse_config(_paper_dict(scenario__t_final=1000.0), "long")  # 1e7 steps, 216 MiB
    assert rc.scenario.t_final == 1000.0


@pytest.mark.parametrize(
    ("t_final", "dt", "needles"),
    [
        (0.05, 0.1, ["simulation.dt = 0.1", "longer than scenario.t_final = 0.05"]),
        (5e-324, 1e-4, ["simulation.dt = 0.0001", "t_final = 4.94066e-324"]),
        (1.00005, 1e-4, ["t_final = 1.00005", "dt = 0.0001", "10000.5", "integer multiple"]),
        (20.0, 3e-4, ["t_final = 20.0", "dt = 0.0003", "66666.666666"]),
    ],
)
def test_degenerate_horizons_are_refused_naming_both_values(t_final, dt, needles):
    with pytest.raises(ConfigError) as err:
        parse_config(_paper_dict(scenario__t_final=t_final, simulation__dt=dt), "h.toml")
    for needle in needles:
        assert needle in str(err.value), (needle, str(err.value))


def test_a_horizon_within_rounding_of_a_whole_number_of_steps_is_accepted():
    # 0.3 / 0.1 = 2.9999999999999996 in floating point: three steps, not refused
    rc = parse_config(_paper_dict(scenario__t_final=0.3, simulation__dt=0.1), "ok")
    assert rc.scenario.t_final == 0.3


@pytest.mark.parametrize(
    ("changes", "needles"),
    [
        ({"scenario__disturbance_time": 1e7}, ["disturbance_time = 1e+07 s", "t_final = 20"]),
        ({"scenario__parameter_change_time": 20.5}, ["parameter_change_time", "after"]),
        ({"scenario__reference__t_step": 21.0}, ["reference.t_step", "t_final"]),
        ({"scenario__disturbance_time": math.inf}, ["disturbance_time", "finite"]),
        ({"simulation__divergence_threshold": math.inf}, ["divergence_threshold", "finite"]),
        ({"simulation__divergence_threshold": 1e301}, ["divergence_threshold", "1e+300"]),
        ({"scenario__noise_seed": 2**64}, ["noise_seed", "less than 9.22337e+18"]),
    ],
)
def test_event_times_and_threshold_are_finite_and_in_range(changes, needles):
    with pytest.raises(ConfigError) as err:
        parse_config(_paper_dict(**changes), "ev.toml")
    for needle in needles:
        assert needle in str(err.value), (needle, str(err.value))


def test_an_event_at_the_horizon_is_accepted():
    rc = parse_config(_paper_dict(scenario__disturbance_time=20.0), "edge")
    assert rc.scenario.disturbance_time == 20.0


def test_empty_or_cut_off_file_is_refused_not_run_with_defaults(tmp_path):
    from aiofl.config import REQUIRED_KEYS

    with pytest.raises(ConfigError, match="missing required key") as err:
        _text_config(tmp_path, "")
    for key in REQUIRED_KEYS:
        assert key in str(err.value)
    full = preset_text("paper-s1-leso")
    cut = full[: full.index("[simulation]")]  # everything up to the [simulation] table
    with pytest.raises(ConfigError, match=r"missing required key.*simulation\.dt"):
        _text_config(tmp_path, cut)
    assert _text_config(tmp_path, MINIMAL).controller.structure == "LADRC"
    for name in list_presets():  # every preset sets the required keys
        data = tomllib.loads(preset_text(name))
        assert all(k.split(".")[-1] in str(data) for k in REQUIRED_KEYS), name


def test_malformed_toml_names_the_line(tmp_path):
    with pytest.raises(ConfigError, match=r"malformed TOML.*line 5"):
        _text_config(tmp_path, MINIMAL.replace("[controller]", "[controller]\nrho = = 4"))
    bad = tmp_path / "latin1.toml"
    bad.write_bytes(b'name = "caf\xe9"\n')
    with pytest.raises(ConfigError, match="cannot be read"):
        load_config(bad)


def test_overrides_pass_the_same_checks_as_the_file():
    rc = load_config("paper-s1-leso")
    short = rc.with_overrides(t_final=0.5, dt=1e-3, method="euler")
    assert (short.scenario.t_final, short.dt, short.method) == (0.5, 1e-3, "euler")
    assert short.controller == rc.controller
    with pytest.raises(ConfigError, match=r"with --dt 1e-12.*at most 2e\+07 steps"):
        rc.with_overrides(dt=1e-12, source="paper-s1-leso with --dt 1e-12")
    with pytest.raises(ConfigError, match="not a whole number of steps"):
        rc.with_overrides(dt=3e-4)
    with pytest.raises(ConfigError, match="disturbance_time = 10 s is after"):
        load_config("paper-s2-leso").with_overrides(t_final=5.0)


def test_analyze_resolves_a_run_configs_plant_file_from_the_configs_folder(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from aiofl.cli.app import app

    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "pend.toml").write_text(
        'name = "pend_sub"\nstates = ["q", "w"]\nf = ["w", "-k*sin(q)"]\ng = ["0", "b"]\n'
        'h = "q"\n[params]\nk = 9.81\nb = 4.0\n'
    )
    (tmp_path / "sub" / "run.toml").write_text(MINIMAL.replace('"slfjm"', '"pend.toml"'))
    monkeypatch.chdir(tmp_path)  # the plant file is not in the working folder
    res = CliRunner().invoke(app, ["analyze", "sub/run.toml", "--json"])
    assert res.exit_code == 0, res.output
    assert '"pend_sub"' in res.stdout and '"rho": 2' in res.stdout


def test_plant_source_is_the_plant_key_as_written():
    """What the C export and the design report name as the plant: the config's ``plant`` key
    as written (a built-in name here), and the plant's own name when no key is given."""
    cfg = load_config("paper-s1-leso")
    assert cfg.plant_source == "slfjm" == cfg.raw["plant"]
    raw = {k: v for k, v in cfg.raw.items() if k != "plant"}
    assert cfg.__class__(**{**cfg.__dict__, "raw": raw}).plant_source == cfg.plant.name
