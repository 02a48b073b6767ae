"""The built-in plants: eq. (15) term by term, the relative degree measured numerically, and
the plant interface (parameters, compiled functions, registry)."""

from __future__ import annotations

from math import factorial

import numpy as np
import pytest

from aiofl.plants.base import Plant, PlantError
from aiofl.plants.registry import available_plants, get_plant

# Section V, as printed
KS, JH, M_LINK, G, H, KM, KG, JL, RM = 1.61, 0.0021, 0.403, -9.81, 0.06, 0.00767, 70.0, 0.0059, 2.6


def eq15(x: np.ndarray, jl: float = JL) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """f, b, b_d and y of eq. (15), written out from the paper."""
    x1, x2, x3, x4 = x
    f = np.array(
        [
            x3,
            x4,
            KS / JH * x2 - KM**2 * KG**2 / (RM * JH) * x3,
            -KS / JH * x2
            - KS / jl * x2
            + KM**2 * KG**2 / (RM * JH) * x3
            + M_LINK * G * H / jl * np.sin(x1 + x2),
        ]
    )
    b = np.array([0.0, 0.0, KM * KG / (RM * JH), -KM * KG / (RM * JH)])
    bd = np.array([0.0, 0.0, 1.0 / JH, -1.0 / JH])
    return f, b, bd, x1 + x2


@pytest.mark.parametrize("seed", range(5))
def test_slfjm_is_eq15_term_by_term(seed):
    plant = get_plant("slfjm")
    rng = np.random.default_rng(seed)
    x = rng.normal(0, 2, 4)
    p = plant.param_vector()
    f, b, bd, y = eq15(x)
    np.testing.assert_allclose(plant.f(x, p), f, rtol=1e-14)
    np.testing.assert_allclose(plant.g(x, p), b, rtol=1e-14)
    np.testing.assert_allclose(plant.bd(x, p), bd, rtol=1e-14)
    assert plant.output(x) == pytest.approx(y, rel=1e-15)
    u, d = rng.normal(), rng.normal()
    np.testing.assert_allclose(plant.rhs(x, u, d), f + b * u + bd * d, rtol=1e-13)
    # scenario 2's J_l × 1.4 changes the load terms only
    p14 = plant.param_vector(scale={"J_l": 1.4})
    f14, *_ = eq15(x, jl=1.4 * JL)
    np.testing.assert_allclose(plant.f(x, p14), f14, rtol=1e-14)
    assert plant.param_vector(overrides={"J_l": 1.0})[plant.param_names.index("J_l")] == 1.0


def test_slfjm_printed_constants_and_high_frequency_gain():
    plant = get_plant("slfjm")
    assert dict(plant.params) == {
        "K_s": KS, "J_h": JH, "m": M_LINK, "g": G, "h": H, "K_m": KM, "K_g": KG, "J_l": JL,
        "R_m": RM,
    }  # fmt: skip
    assert plant.relative_degree == 4
    assert pytest.approx(2.6833e4, rel=1e-3) == KS * KM * KG / (JL * JH * RM)


def test_compiled_plant_functions_equal_the_python_ones():
    plant = get_plant("slfjm")
    f, g, h, bd = plant.compiled[:4]
    rng = np.random.default_rng(3)
    x = rng.normal(0, 1, 4)
    p = plant.param_vector()
    np.testing.assert_allclose(f(x, p), plant.f(x, p), rtol=1e-15)
    np.testing.assert_allclose(g(x, p), plant.g(x, p), rtol=1e-15)
    np.testing.assert_allclose(bd(x, p), plant.bd(x, p), rtol=1e-15)
    assert h(x, p) == plant.h(x, p)


# ------------------------------------------------------------------ relative degree
def output_split(plant: Plant, x0: np.ndarray, tau: float, steps: int = 200) -> float:
    """y(τ) for u = +1 minus y(τ) for u = -1, both from x0.

    Integrates x₊ together with δ = x₊ - x₋ (not x₋ itself), so the tiny difference is
    computed directly instead of as the cancellation of two large numbers; classical RK4
    with τ/steps steps (τ is far below the plant's time constants)."""
    n = plant.n_states
    p = plant.param_vector()

    def rhs(s):
        xp, dl = s[:n], s[n:]
        fp = plant.rhs(xp, 1.0, 0.0, p)
        return np.concatenate([fp, fp - plant.rhs(xp - dl, -1.0, 0.0, p)])

    s = np.concatenate([x0, np.zeros(n)])
    h = tau / steps
    for _ in range(steps):
        k1 = rhs(s)
        k2 = rhs(s + 0.5 * h * k1)
        k3 = rhs(s + 0.5 * h * k2)
        k4 = rhs(s + h * k3)
        s = s + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return plant.output(s[:n]) - plant.output(s[:n] - s[n:])


@pytest.mark.parametrize(
    ("name", "rho", "beta"),
    [
        ("slfjm", 4, KS * KM * KG / (JL * JH * RM)),  # L_g L_f^3 h
        ("pendulum", 2, 1.0 / (1.0 * 0.5**2)),  # 1/(m l²)
    ],
)
def test_relative_degree_measured_from_the_output(name, rho, beta):
    """u does not reach y, ẏ, ..., y^(ρ-1): from one state, the outputs for u = ±1 differ
    by 2β τ^ρ/ρ! + O(τ^(ρ+1)).  The log-log slope is ρ, the coefficient 2β/ρ!."""
    plant = get_plant(name)
    rng = np.random.default_rng(11)
    x0 = rng.normal(0, 0.5, plant.n_states)
    taus = np.geomspace(1e-4, 1e-3, 5)
    dy = np.array([output_split(plant, x0, tau) for tau in taus])
    slope = np.polyfit(np.log(taus), np.log(np.abs(dy)), 1)[0]
    assert slope == pytest.approx(rho, abs=0.05)
    assert dy[0] / taus[0] ** rho == pytest.approx(2 * beta / factorial(rho), rel=0.02)
    assert plant.relative_degree == rho


# ------------------------------------------------------------------ the interface
def test_registry_returns_one_shared_instance_and_names_the_choices():
    assert get_plant("slfjm") is get_plant("slfjm")
    assert {"slfjm", "pendulum"} <= set(available_plants())
    with pytest.raises(PlantError, match="slfjm"):
        get_plant("no-such-plant")


def test_unknown_parameter_is_rejected_with_the_allowed_names():
    with pytest.raises(PlantError, match="J_l"):
        get_plant("slfjm").param_vector(scale={"J_x": 2.0})


def test_slfjm_rest_is_an_equilibrium_and_gravity_restores():
    plant = get_plant("slfjm")
    np.testing.assert_array_equal(plant.rhs(np.zeros(4), 0.0), np.zeros(4))
    # with g printed negative, +mgh/J_l·sin(x1 + x2) pulls the link back
    dx = plant.rhs(np.array([0.1, 0.0, 0.0, 0.0]), 0.0)
    assert dx[3] < 0.0
