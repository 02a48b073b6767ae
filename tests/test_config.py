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
        ({"controller__law__b0": -2.0}, ["controller.law.b0", "greater than 0"]),
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
