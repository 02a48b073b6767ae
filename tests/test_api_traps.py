"""API traps closed: defaults that make a working controller, and clear errors otherwise.

* ``n_feedback`` defaults to ρ (full state feedback of the chain), 2 only behind Han's TD /
  the ITD (the paper's LESO and INLESO structures);
* unset ESO α are Gao's binomial ones in Python as in TOML;
* ρ is checked against the plant's known relative degree (override: ``allow_rho_mismatch``);
* a negative ``b0`` is allowed (Python and TOML) and checked against the sign of the plant's
  high-frequency gain β (override: ``allow_b0_sign_mismatch``);
* short SEF vectors are refused, never padded;
* ``eso.init = "output"`` starts the observer at the first measurement;
* ``law.u_min`` / ``law.u_max`` give an asymmetric actuator range;
* an IOFL law on a plant without a normal form (or where β(x0) = 0) is refused at build time.

The engine's new paths are cross-checked against the independent scipy reference path.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from math import comb
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aiofl import layout as L
from aiofl.components.feedback import linear_sef_gains
from aiofl.components.law import saturate, saturate_range
from aiofl.components.observers import eso_error_matrix, eso_gains
from aiofl.config import ConfigError, load_config, parse_config, preset_text
from aiofl.controller import Controller, controller_batch, default_n_feedback
from aiofl.engine.reference import reference_simulate
from aiofl.engine.simulation import simulate, simulate_batch
from aiofl.plants import get_plant
from aiofl.plants.base import Plant
from aiofl.scenario import Reference, Scenario
from chain_plant import chain3, chain_h

# ------------------------------------------------------------------------ test plants
CHAIN3 = chain3(0.0, 0.0, 2.0)
"""d³y/dt³ = b u: a chain of three integrators, β = b = 2 (ρ = 3; tests/chain_plant.py with
a = c = 0, so it shares its kernel with test_engine's chain)."""


def _bilinear_f(x: Any, p: Any) -> tuple[float, float]:
    return (x[1], 0.0)


def _bilinear_g(x: Any, p: Any) -> tuple[float, float]:
    return (0.0, x[0])


def _bilinear_nf(x: Any, p: Any) -> tuple[float, float, float, float]:
    return (x[0], x[1], 0.0, x[0])


BILINEAR = Plant(
    name="bilinear_api",
    n_states=2,
    f=_bilinear_f,
    g=_bilinear_g,
    h=chain_h,
    params={},
    relative_degree=2,
    normal_form=_bilinear_nf,
)
"""y'' = y u: β(x) = x1, zero at the origin (the relative degree is not defined there)."""

NO_NORMAL_FORM = chain3(0.0, 0.0, 2.0, name="no_nf_api", normal_form=False)

NEGATIVE_PLANT = """
name = "cooler_api"
description = "first-order plant with a negative input gain: more u, lower y"
states = ["T"]
f = ["-a*T - c*T**3"]
g = ["-k"]
h = "T"
[params]
a = 0.5
c = 0.1
k = 2.0
"""
"""Ṫ = -aT - cT³ - k u, y = T: ρ = 1, β = -k = -2."""

NEGATIVE_RUN = """
plant = "cooler.toml"
[scenario]
t_final = 6.0
x0 = [0.5]
[scenario.reference]
kind = "sine"
amplitude = 0.5
omega = 1.0
[controller]
structure = "LADRC"
td_kind = "exact"
[controller.eso]
omega0 = 40.0
[controller.sef]
omega_c = 5.0
[controller.law]
b0 = {b0}
[simulation]
dt = 1e-4
"""

LADRC_VALUES = {"law.b0": 1.5, "eso.omega0": 60.0, "sef.omega_c": 5.0, "td.omega": 10.0}
"""A moderate LADRC for CHAIN3 with a wrong b0 (1.5 for the true 2)."""


def _paper(**changes: Any) -> dict[str, Any]:
    """The paper-s1-leso preset as a dict, with ``controller__law__b0``-style changes."""
    data = tomllib.loads(preset_text("paper-s1-leso"))
    for key, val in changes.items():
        *path, last = key.split("__")
        node = data
        for part in path:
            node = node.setdefault(part, {})
        if val is None:
            node.pop(last, None)
        else:
            node[last] = val
    return data


# ------------------------------------------------------------------- n_feedback
@pytest.mark.parametrize("rho", range(1, L.RHO_MAX + 1))
def test_n_feedback_defaults_to_rho_except_behind_the_two_state_differentiators(rho: int):
    for structure, want in (
        ("LADRC", rho),
        ("IOFL", rho),
        ("LESO", min(2, rho)),  # Han's TD supplies r1, r2 only: the paper's 2
        ("INLESO", min(2, rho)),
    ):
        c = Controller.from_structure(structure, rho=rho)
        assert c.n_feedback == want, structure
        assert c.int_row()[L.I_NFB] == want
    assert Controller(td="linear", sef="nonlinear", rho=rho).n_feedback == rho
    assert default_n_feedback(rho, "exact") == rho


def test_toml_n_feedback_default_matches_python():
    data = tomllib.loads(preset_text("dcmotor-arm-ladrc"))
    del data["controller"]["n_feedback"]
    assert parse_config(data).controller.n_feedback == 3
    leso = _paper(controller__n_feedback=None)
    assert parse_config(leso).controller.n_feedback == 2


@pytest.mark.parametrize("rho", range(1, L.RHO_MAX + 1))
def test_default_linear_feedback_places_every_tracking_pole_at_minus_omega_c(rho: int):
    """With the ESO converged the tracking error obeys e^(ρ) = -Σ_{i≤m} k_i e^(i-1): its
    polynomial is (s + ω_c)^ρ only when all m = ρ states are fed back (the default); with
    m < ρ a coefficient is 0 and (for ρ ≥ 2) the loop is not Hurwitz."""
    wc = 7.0
    c = Controller.from_structure("LADRC", rho=rho)
    k = linear_sef_gains(rho, wc)[: c.n_feedback]
    poly = np.zeros(rho + 1)
    poly[0] = 1.0
    for i, ki in enumerate(k):  # k_i multiplies e^(i-1): coefficient of s^(i-1)
        poly[rho - i] = ki
    np.testing.assert_allclose(poly, np.poly(np.full(rho, -wc)), rtol=1e-12)


@pytest.mark.slow  # the chain plant's kernel (shared with test_engine), unless cached
def test_default_ladrc_converges_where_the_old_defaults_did_not():
    """ρ = 3 chain, initial error 0.3, b0 20 % low.  The default controller (n_feedback = ρ,
    binomial α) drives y onto the differentiator's profile r1; the old defaults, n_feedback
    = 2 (error grows) or α = 0 (the ESO never corrects), do not."""
    new = Controller.from_structure("LADRC", rho=3, values=LADRC_VALUES)
    old_m = Controller.from_structure("LADRC", rho=3, n_feedback=2, values=LADRC_VALUES)
    zeros = {f"eso.alpha{i}": 0.0 for i in range(1, 5)}
    old_alpha = Controller.from_structure("LADRC", rho=3, values={**LADRC_VALUES, **zeros})
    sc = Scenario(t_final=10.0, reference=Reference(amplitude=0.5, omega=1.0), x0=(0.3, 0, 0))
    res = simulate_batch(CHAIN3, [new, old_m, old_alpha], sc, store=True)

    def window_max(i: int, a: float, b: float) -> float:
        m = res.member(i)
        w = (m.t > a) & (m.t <= b)
        return float(np.max(np.abs(m["y"][w] - m["r1"][w])))

    assert not res.failed.any()
    assert window_max(0, 8, 10) < 1e-3 * 0.3
    assert window_max(1, 8, 10) > 2 * window_max(1, 4, 6) > 0.1  # growing oscillation
    assert window_max(2, 8, 10) > 0.1


# ------------------------------------------------------------------------- alphas
@pytest.mark.parametrize("rho", range(1, L.RHO_MAX + 1))
def test_unset_alphas_are_binomial_and_put_every_observer_pole_at_minus_omega0(rho: int):
    w0 = 30.0
    c = Controller.from_structure("LADRC", rho=rho, values={"eso.omega0": w0})
    alphas = [c.value(f"eso.alpha{i}") for i in range(1, rho + 2)]
    assert alphas == [comb(rho + 1, i) for i in range(1, rho + 2)]
    row = c.float_row()
    np.testing.assert_array_equal(row[L.F_ESO_ALPHA : L.F_ESO_ALPHA + rho + 1], alphas)
    assert not row[L.F_ESO_ALPHA + rho + 1 : L.F_ESO_ALPHA + L.RHO_MAX + 1].any()
    # characteristic polynomial of the ESO error (eq. 9) is (s + ω0)^(ρ+1)
    a_e = eso_error_matrix(eso_gains(w0, alphas))
    np.testing.assert_allclose(np.poly(a_e), np.poly(np.full(rho + 1, -w0)), rtol=1e-9)
    # an explicit value still wins
    assert c.with_values(**{"eso.alpha2": 0.5}).value("eso.alpha2") == 0.5


def test_python_and_toml_defaults_build_the_same_engine_rows():
    data = {
        "plant": "pendulum",
        "scenario": {"t_final": 1.0},
        "simulation": {"dt": 1e-3},
        "controller": {
            "structure": "LADRC",
            "eso": {"omega0": 40.0},
            "sef": {"omega_c": 6.0},
            "td": {"omega": 12.0},
            "law": {"b0": 4.0},
        },
    }
    toml_c = parse_config(data).controller
    py_c = Controller.from_structure(
        "LADRC",
        rho=2,
        values={"eso.omega0": 40.0, "sef.omega_c": 6.0, "td.omega": 12.0, "law.b0": 4.0},
    )
    np.testing.assert_array_equal(toml_c.int_row(), py_c.int_row())
    tr, pr = toml_c.float_row(), py_c.float_row()
    same = (tr == pr) | (np.isnan(tr) & np.isnan(pr))
    assert same.all(), [n for n, i in L.FLOAT_COLUMNS.items() if not same[i]]


# ---------------------------------------------------------------- rho vs the plant
def test_toml_rho_other_than_the_relative_degree_is_refused_unless_allowed():
    data: dict[str, Any] = {
        "plant": "pendulum",
        "scenario": {"t_final": 1.0},
        "simulation": {"dt": 1e-3},
        "controller": {
            "structure": "LADRC",
            "rho": 3,
            "eso": {"omega0": 40.0},
            "sef": {"omega_c": 6.0},
            "td": {"omega": 12.0},
            "law": {"b0": 4.0},
        },
    }
    with pytest.raises(ConfigError) as err:
        parse_config(data, "rho.toml")
    msg = str(err.value)
    for needle in ("controller.rho = 3", "relative degree 2", "allow_rho_mismatch"):
        assert needle in msg
    data["controller"]["allow_rho_mismatch"] = True
    assert parse_config(data).controller.rho == 3


def test_python_rho_mismatch_is_refused_before_anything_compiles():
    pend = get_plant("pendulum")
    c = Controller.from_structure("LADRC", rho=4)
    with pytest.raises(ValueError, match=r"controller.rho = 4 .* relative degree 2"):
        simulate(pend, c, Scenario(t_final=0.01))
    with pytest.raises(ValueError, match="relative degree 2"):
        reference_simulate(pend, c, Scenario(t_final=0.01))
    Controller.from_structure("LADRC", rho=4, allow_rho_mismatch=True).check_plant(pend)
    Controller.from_structure("LADRC", rho=2).check_plant(pend)


def test_iofl_needs_rho_equal_to_the_relative_degree_even_with_the_override():
    c = Controller.from_structure("IOFL", rho=3, allow_rho_mismatch=True)
    with pytest.raises(ValueError, match=r"IOFL law .* needs them equal"):
        c.check_plant(get_plant("pendulum"))


# --------------------------------------------------------------- IOFL normal form
def test_iofl_without_a_normal_form_is_refused_at_build_time():
    c = Controller.from_structure("IOFL", rho=3)
    with pytest.raises(ValueError, match="needs the plant's normal form"):
        simulate(NO_NORMAL_FORM, c, Scenario(t_final=0.01))
    # AIOFL needs only rho and b0: the same plant passes the check
    Controller.from_structure("LADRC", rho=3).check_plant(NO_NORMAL_FORM)


def test_iofl_where_beta_vanishes_is_refused_and_elsewhere_accepted():
    c = Controller.from_structure("IOFL", rho=2)
    with pytest.raises(ValueError, match=r"β .* = 0.0 at x0 = \[0.0, 0.0\]"):
        c.check_plant(BILINEAR)
    c.check_plant(BILINEAR, (1.0, 0.0))
    assert c.plant_beta(BILINEAR, (-0.5, 0.0)) == -0.5
    # AIOFL from the singular point: β's sign is unknown there, nothing to refuse
    Controller.from_structure("LADRC", rho=2).check_plant(BILINEAR)


# ------------------------------------------------------------------ negative b0
def test_python_b0_must_be_finite_and_non_zero_and_may_be_negative():
    assert Controller(values={"law.b0": -3.0}).value("law.b0") == -3.0
    for bad in (0.0, math.inf, math.nan):
        with pytest.raises(ValueError, match=r"controller\.law\.b0"):
            Controller(values={"law.b0": bad})


def test_b0_sign_is_checked_against_the_plants_beta():
    slfjm = get_plant("slfjm")
    c = Controller.from_structure("LESO", values={"law.b0": -20.0})
    with pytest.raises(ValueError, match=r"b0 = -20 has the opposite sign .* β .* = 26833"):
        c.check_plant(slfjm)
    dataclasses.replace(c, allow_b0_sign_mismatch=True).check_plant(slfjm)


@pytest.fixture
def cooler(tmp_path: Path) -> Path:
    (tmp_path / "cooler.toml").write_text(NEGATIVE_PLANT)
    return tmp_path


def test_toml_negative_b0_for_a_negative_gain_plant(cooler: Path):
    run = cooler / "run.toml"
    run.write_text(NEGATIVE_RUN.format(b0=-1.6))
    cfg = load_config(run)
    assert cfg.controller.value("law.b0") == -1.6
    assert cfg.controller.plant_beta(cfg.plant) == -2.0
    run.write_text(NEGATIVE_RUN.format(b0=1.6))
    with pytest.raises(ConfigError, match=r"b0 = 1.6 has the opposite sign .* β .* = -2"):
        load_config(run)
    text = NEGATIVE_RUN.format(b0=1.6).replace(
        'td_kind = "exact"', 'td_kind = "exact"\nallow_b0_sign_mismatch = true'
    )
    run.write_text(text)
    assert load_config(run).controller.allow_b0_sign_mismatch
    run.write_text(NEGATIVE_RUN.format(b0=0.0))
    with pytest.raises(ConfigError, match=r"controller\.law\.b0"):
        load_config(run)


@pytest.mark.slow  # compiles a kernel for the plant file (~6 s)
def test_negative_b0_loop_tracks_and_matches_the_reference_path(cooler: Path):
    run = cooler / "run.toml"
    run.write_text(NEGATIVE_RUN.format(b0=-1.6))
    cfg = load_config(run)
    res = cfg.simulate()
    assert not res.failed
    late = res.t > 4.0
    assert np.max(np.abs(res["y"][late] - res["r"][late])) < 0.01 * 0.5
    # the same loop with b0 of the wrong sign (allowed explicitly) feeds back positively:
    # y runs away until the cubic loss holds it, far from r
    wrong = dataclasses.replace(cfg.controller, values={**cfg.controller.values, "law.b0": 1.6})
    with pytest.raises(ValueError, match="opposite sign"):
        wrong.check_plant(cfg.plant)
    wrong = dataclasses.replace(wrong, allow_b0_sign_mismatch=True)
    bad = simulate(cfg.plant, wrong, cfg.scenario)
    assert bad.failed or np.min(np.abs(bad["y"][late] - bad["r"][late])) > 0.5
    short = dataclasses.replace(cfg.scenario, t_final=1.0)
    eng = simulate(cfg.plant, cfg.controller, short, dt=1e-4, decimation=100)
    ref = reference_simulate(cfg.plant, cfg.controller, short, t_eval=eng.t, rtol=1e-10)
    np.testing.assert_allclose(eng["y"], ref.y, atol=1e-8)
    np.testing.assert_allclose(eng["u"], ref.u, atol=1e-6 * np.max(np.abs(ref.u)))


# ------------------------------------------------------------------- SEF vectors
@pytest.mark.parametrize("key", ["k", "alpha", "delta"])
def test_a_short_sef_vector_is_refused_not_padded(key: str):
    data = _paper(**{f"controller__sef__{key}": [0.5]})
    with pytest.raises(ConfigError) as err:
        parse_config(data, "short.toml")
    msg = str(err.value)
    for needle in (f"controller.sef.{key}", "1 entries", "2..8", "n_feedback = 2"):
        assert needle in msg
    data["controller"]["n_feedback"] = 1  # one fed-back state: one entry is enough
    assert parse_config(data).controller.value(f"sef.{key}1") == 0.5


# ---------------------------------------------------------------------- eso.init
def test_toml_eso_init():
    c = parse_config(_paper(controller__eso__init="output")).controller
    assert c.eso_init == "output" and c.int_row()[L.I_ESO_INIT] == L.ESO_INIT_OUTPUT
    assert parse_config(_paper()).controller.int_row()[L.I_ESO_INIT] == L.ESO_INIT_ZERO
    with pytest.raises(ConfigError) as err:
        parse_config(_paper(controller__eso__init="first"), "init.toml")
    assert "controller.eso.init" in str(err.value) and "'output'" in str(err.value)
    with pytest.raises(ValueError, match="eso_init"):
        Controller(eso_init="measured")


@pytest.mark.slow  # the chain plant's kernel (shared with test_engine), unless cached
def test_eso_starts_at_the_first_measurement_in_the_engine_and_the_reference():
    c = Controller.from_structure("LADRC", rho=3, values=LADRC_VALUES, eso_init="output")
    sc = Scenario(t_final=1.0, reference=Reference(amplitude=0.5, omega=1.0), x0=(0.3, 0, 0))
    eng = simulate(CHAIN3, c, sc, decimation=100)
    assert eng["xi_hat1"][0] == 0.3 == eng["y"][0]
    assert eng["xi_hat2"][0] == 0.0
    ref = reference_simulate(CHAIN3, c, sc, t_eval=eng.t, rtol=1e-10, atol=1e-12)
    assert ref.xi[0, 0] == 0.3
    for i in range(4):
        scale = np.max(np.abs(ref.xi[:, i]))
        np.testing.assert_allclose(eng[f"xi_hat{i + 1}"], ref.xi[:, i], atol=1e-7 * scale)
    np.testing.assert_allclose(eng["y"], ref.y, atol=1e-9)
    # started at zero the observer has an output error of 0.3 to work off: another loop
    zero = simulate(CHAIN3, dataclasses.replace(c, eso_init="zero"), sc, decimation=100)
    assert zero["xi_hat1"][0] == 0.0
    assert np.max(np.abs(zero["u"] - eng["u"])) > 1.0
    # with measurement noise the first measurement includes it: ξ̂1(0) = y(0) + n(0)
    noisy = dataclasses.replace(sc, noise_variance=1e-4, noise_seed=3, t_final=0.01)
    res = simulate(CHAIN3, c, noisy, decimation=1)
    assert res["y_meas"][0] != res["y"][0]
    assert res["xi_hat1"][0] == res["y_meas"][0]
    ref_noisy = reference_simulate(CHAIN3, c, noisy, t_eval=res.t[:1])
    assert ref_noisy.xi[0, 0] == res["y_meas"][0]


# ------------------------------------------------------------- actuator range
@settings(max_examples=200, deadline=None)
@given(
    u=st.floats(allow_nan=False),
    lo=st.floats(-1e6, 1e6),
    width=st.floats(1e-9, 1e6),
)
def test_saturate_range_is_the_clip_and_symmetric_saturate_is_a_special_case(u, lo, width):
    hi = lo + width
    assert saturate_range(u, lo, hi) == min(max(u, lo), hi)
    assert saturate_range(u, -abs(hi), abs(hi)) == saturate(u, abs(hi))
    assert saturate_range(u, -math.inf, math.inf) == u
    assert math.isnan(saturate_range(math.nan, lo, hi))


def test_python_actuator_range():
    assert Controller().u_range() == (-math.inf, math.inf)
    c = Controller(values={"law.u_max": 3.0})
    assert c.u_range() == (-3.0, 3.0)
    assert math.isnan(c.float_row()[L.F_UMIN])  # the kernel mirrors u_max
    assert Controller(values={"law.u_min": 0.0, "law.u_max": 10.0}).u_range() == (0.0, 10.0)
    assert Controller(values={"law.u_min": -1.0}).u_range() == (-1.0, math.inf)
    with pytest.raises(ValueError, match=r"u_min = 2.0 must be < u_max = 1.0"):
        Controller(values={"law.u_min": 2.0, "law.u_max": 1.0})
    with pytest.raises(ValueError, match=r"u_max = -1.0; allowed: > 0"):
        Controller(values={"law.u_max": -1.0})
    with pytest.raises(ValueError, match=r"law\.u_min"):
        Controller(values={"law.u_min": math.nan})


@pytest.mark.parametrize(
    ("law", "needle"),
    [
        ({"u_min": 1.0, "u_max": 0.5}, "u_min = 1.0 must be < u_max = 0.5"),
        ({"u_max": 0.0}, "u_max = 0.0; allowed: > 0"),
        ({"u_min": math.nan}, "not nan"),
    ],
)
def test_toml_bad_actuator_range_is_refused_naming_the_field(law: dict[str, float], needle: str):
    data = _paper(**{f"controller__law__{k}": v for k, v in law.items()})
    with pytest.raises(ConfigError) as err:
        parse_config(data, "range.toml")
    assert "controller.law" in str(err.value) and needle in str(err.value)


def test_toml_actuator_range():
    c = parse_config(_paper(controller__law__u_min=-0.5, controller__law__u_max=2.0)).controller
    assert c.u_range() == (-0.5, 2.0)
    c = parse_config(_paper(controller__law__u_max=4.0)).controller
    assert c.u_range() == (-4.0, 4.0) and "law.u_min" not in c.values


@pytest.mark.slow  # the chain plant's kernel (shared with test_engine), unless cached
def test_asymmetric_saturation_in_the_engine_and_the_reference():
    base = Controller.from_structure("LADRC", rho=3, values=LADRC_VALUES)
    sc = Scenario(t_final=2.0, reference=Reference(amplitude=0.5, omega=1.0), x0=(0.3, 0, 0))
    free = simulate(CHAIN3, base, sc, decimation=10)
    lo, hi = -0.2 * np.max(-free["u"]), 0.5 * np.max(free["u"])
    assert lo < 0 < hi and np.min(free["u"]) < lo and np.max(free["u"]) > hi
    c = base.with_values(**{"law.u_min": lo, "law.u_max": hi})
    eng = simulate(CHAIN3, c, sc, decimation=10)
    assert np.min(eng["u"]) == lo and np.max(eng["u"]) == hi  # both limits reached
    # the reference path (adaptive, exact at the saturation corners) agrees as dt -> 0:
    # RK4 straddling a corner is only low order (dt = 1e-4: 2e-5 in y; 1e-5: 3e-8)
    fine = simulate(CHAIN3, c, sc, dt=1e-5, decimation=100)
    ref = reference_simulate(CHAIN3, c, sc, t_eval=fine.t, rtol=1e-11, atol=1e-13)
    np.testing.assert_allclose(fine["y"], ref.y, atol=1e-6)
    np.testing.assert_allclose(fine["u"], ref.u, atol=1e-3 * (hi - lo))
    # an explicit u_min = -u_max is the symmetric range: bit-identical to u_max alone
    sym = base.with_values(**{"law.u_max": hi})
    both = base.with_values(**{"law.u_min": -hi, "law.u_max": hi})
    res = simulate_batch(CHAIN3, controller_batch([sym, both]), sc)
    np.testing.assert_array_equal(res.metrics[0], res.metrics[1])
    # a batch varying only u_max (the tuner's way) stays symmetric per member
    tuned = simulate_batch(
        CHAIN3, controller_batch(base, {"law.u_max": np.array([hi, 2 * hi])}), sc, store=True
    )
    for i, um in enumerate((hi, 2 * hi)):
        u = tuned.member(i)["u"]
        assert np.min(u) >= -um and np.max(u) <= um
