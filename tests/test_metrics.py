"""Performance indices (eq. 22): closed forms on known signals, the OPI, and the engine's
integrated metrics against the same integrals of its stored trajectory."""

from __future__ import annotations

import math

import numpy as np
import pytest

from aiofl.components import metrics as M
from aiofl.components.metrics import OPIWeights, opi
from aiofl.controller import Controller
from aiofl.engine.simulation import simulate, simulate_batch
from aiofl.plants import get_plant
from aiofl.scenario import Reference, Scenario

BETA_SLFJM = 1.61 * 0.00767 * 70.0 / (0.0059 * 0.0021 * 2.6)


def test_itae_of_a_constant_error_is_c_t_squared_over_two():
    t = np.linspace(0.0, 3.0, 31)  # the trapezoid rule is exact on t·c
    c = 0.7
    assert M.itae(t, np.full_like(t, 1.0 + c), np.ones_like(t)) == pytest.approx(c * 9 / 2)
    assert M.itae(t, np.full_like(t, 1.0 - c), np.ones_like(t)) == pytest.approx(c * 9 / 2)


def test_iae_and_ise_of_a_ramp_error():
    t = np.linspace(0.0, 1.0, 100_001)
    assert M.iae(t, t, np.zeros_like(t)) == pytest.approx(0.5, rel=1e-12)
    assert M.ise(t, -t, np.zeros_like(t)) == pytest.approx(1.0 / 3.0, rel=1e-9)


def test_isu_and_iau_of_a_sine():
    t = np.linspace(0.0, math.pi, 20_001)
    assert M.isu(t, np.sin(t)) == pytest.approx(math.pi / 2, rel=1e-8)
    t2 = np.linspace(0.0, 2 * math.pi, 40_001)
    assert M.iau(t2, np.sin(t2)) == pytest.approx(4.0, rel=1e-8)
    assert M.iau(t2, -3.0 * np.sin(t2)) == pytest.approx(12.0, rel=1e-8)


def test_opi_is_the_weighted_normalised_sum():
    w = OPIWeights(0.5, 0.3, 0.2, 4.0, 8.0, 16.0)
    assert opi(2.0, 4.0, 8.0, w) == pytest.approx(0.5 * 2 / 4 + 0.3 * 4 / 8 + 0.2 * 8 / 16)
    paper = OPIWeights()  # printed in the text after eq. 22
    assert (paper.w_itae, paper.w_isu, paper.w_iau) == (0.6, 0.2, 0.6)
    assert (paper.n_itae, paper.n_isu, paper.n_iau) == (10.0, 2.0, 2.7)
    assert opi(10.0, 2.0, 2.7) == pytest.approx(1.4)  # weights as printed sum to 1.4
    arr = opi(np.array([1.0, 2.0]), np.array([0.0, 0.0]), np.array([0.0, 0.0]), w)
    np.testing.assert_allclose(arr, [0.125, 0.25])
    with pytest.raises(ValueError, match="w_isu"):
        OPIWeights(w_isu=-0.1)
    with pytest.raises(ValueError, match="n_iau"):
        OPIWeights(n_iau=0.0)


def _idle() -> Controller:
    """A controller whose input to the plant is ~1e-15 of the usual: the SLFJM stays at
    rest, y ≡ 0 (the trivial controller of the report's tables)."""
    return Controller.from_structure(
        "LADRC", n_feedback=4, values={"law.b0": 1e15, "eso.omega0": 10.0}
    ).with_binomial_alphas()


def test_engine_metrics_of_y_identically_zero_equal_closed_forms():
    """With y ≡ 0 and r = A sin ωt over N half periods (T = Nπ/ω, here a whole number of
    steps): ITAE = ∫ t|A sin ωt| = A π N²/ω², IAE = 2 A N/ω, ISE = A² T/2."""
    amp, omega, n_half = math.pi / 4, math.pi, 12
    t_final = n_half * math.pi / omega
    scen = Scenario(t_final=t_final, reference=Reference(amplitude=amp, omega=omega))
    res = simulate(get_plant("slfjm"), _idle(), scen, dt=1e-4, store=True, decimation=1000)
    assert np.max(np.abs(res["y"])) < 1e-10
    m = res.metrics
    assert m["itae"] == pytest.approx(amp * math.pi * n_half**2 / omega**2, rel=1e-7)
    assert m["iae"] == pytest.approx(2 * amp * n_half / omega, rel=1e-7)
    assert m["ise"] == pytest.approx(amp**2 * t_final / 2, rel=1e-7)
    assert m["isu"] < 1e-20 and m["iau"] < 1e-9


def test_engine_integrals_match_the_stored_trajectory():
    """The metrics the engine integrates as RK4 states equal the trapezoid integrals of
    its own trajectory at decimation 1 (to the trapezoid rule's O(dt²))."""
    ctrl = Controller.from_structure(
        "LADRC",
        n_feedback=4,
        values={"law.b0": BETA_SLFJM, "eso.omega0": 100.0, "sef.omega_c": 10.0, "td.omega": 20.0},
    ).with_binomial_alphas()
    scen = Scenario(t_final=2.0, disturbance_amplitude=0.3, disturbance_time=1.0)
    res = simulate(get_plant("slfjm"), ctrl, scen, dt=1e-4, decimation=1)
    t, y, r, u = res.t, res["y"], res["r"], res["u"]
    sampled = {
        "itae": M.itae(t, y, r),
        "iae": M.iae(t, y, r),
        "ise": M.ise(t, y, r),
        "isu": M.isu(t, u),
        "iau": M.iau(t, u),
    }
    for name, value in sampled.items():
        assert res.metrics[name] == pytest.approx(value, rel=1e-6), name
    w = OPIWeights()
    assert res.opi(w) == pytest.approx(
        w.w_itae * sampled["itae"] / 10
        + w.w_isu * sampled["isu"] / 2
        + w.w_iau * sampled["iau"] / 2.7,
        rel=1e-6,
    )
    batch = simulate_batch(get_plant("slfjm"), [ctrl, ctrl], scen)
    np.testing.assert_allclose(batch.opi(w), res.opi(w), rtol=1e-15)
    np.testing.assert_array_equal(batch.metric("isu"), [res.metrics["isu"]] * 2)
