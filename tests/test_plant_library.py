"""The extra plants (relative degree 1, 3, and 2 < n with stable zero dynamics): registered,
well formed, and controlled by AIOFL knowing only ρ and a rough b0."""

from __future__ import annotations

import numpy as np
import pytest

from aiofl.config import load_config
from aiofl.plants.library import EXTRA_PLANTS, SPECS
from aiofl.plants.registry import available_plants, get_plant

PRESETS = {
    "tank": "tank-ladrc",
    "dcmotor_arm": "dcmotor-arm-ladrc",
    "flexjoint_hub": "flexjoint-hub-ladrc",
}
TRUE_BETA = {"tank": 0.02 / 0.5, "dcmotor_arm": 0.5 / (0.02 * 0.05), "flexjoint_hub": 1 / 0.01}


@pytest.mark.parametrize("name", EXTRA_PLANTS)
def test_extra_plants_are_registered_and_well_formed(name: str) -> None:
    assert name in available_plants()
    plant = get_plant(name)
    plant.check()
    assert plant.n_states == len(SPECS[name]["states"])
    assert plant.normal_form is not None
    x = np.full(plant.n_states, 0.3)
    nf = plant.normal_form(x, plant.param_vector())
    assert nf[-1] == pytest.approx(TRUE_BETA[name])  # β (constant for these plants)


@pytest.mark.parametrize("name", EXTRA_PLANTS)
def test_input_first_appears_in_the_rho_th_output_derivative(name: str) -> None:
    """Numerically, without sympy: for random x, the derivatives y, ẏ, …, y^(ρ−1) computed
    from the generated ξ do not change with u, and y^(ρ) changes by β·Δu."""
    plant = get_plant(name)
    rho, p = plant.relative_degree, plant.param_vector()
    assert rho is not None
    rng = np.random.default_rng(3)
    for _ in range(3):
        x = rng.uniform(0.2, 1.0, plant.n_states)
        derivs = []
        for u in (-1.0, 1.0):
            xdot = plant.rhs(x, u, p=p)
            eps = 1e-6 / max(1.0, float(np.max(np.abs(xdot))))
            nf_p = np.asarray(plant.normal_form(x + eps * xdot, p))[:rho]
            nf_m = np.asarray(plant.normal_form(x - eps * xdot, p))[:rho]
            derivs.append((nf_p - nf_m) / (2 * eps))  # (ẏ, ÿ, …, y^(ρ))
        diff = derivs[1] - derivs[0]
        scale = max(1.0, float(np.max(np.abs(derivs[0]))))
        assert np.all(np.abs(diff[:-1]) < 1e-5 * scale)
        assert diff[-1] == pytest.approx(2.0 * TRUE_BETA[name], rel=1e-5)


@pytest.mark.slow
@pytest.mark.parametrize("name", EXTRA_PLANTS)
def test_aiofl_tracks_each_extra_plant_knowing_only_rho_and_b0(name: str) -> None:
    """The shipped preset (linear ESO + linear feedback, b0 off by 20–25 %) tracks: no
    divergence, ITAE below 5 % of that of an output left at its initial value, and the late
    error below 5 % of the reference amplitude."""
    cfg = load_config(PRESETS[name])
    assert cfg.plant.name == name
    assert cfg.controller.rho == cfg.plant.relative_degree
    b0 = cfg.controller.value("law.b0")
    assert 0.5 < b0 / TRUE_BETA[name] < 1.5 and b0 != TRUE_BETA[name]
    res = cfg.simulate()
    assert not res.failed
    assert res.metrics is not None
    t, r, y = res.t, res["r"], res["y"]
    ref = cfg.scenario.reference
    trivial = np.trapezoid(t * np.abs(r - y[0]), t)  # ITAE of an output left at y(0)
    assert res.metrics["itae"] < 0.05 * trivial
    assert np.max(np.abs(y - r)[t > 10.0]) < 0.05 * ref.amplitude
    # the closed loop linearised at the operating point agrees: stable
    from aiofl.analysis.linearize import closed_loop_verdict

    assert closed_loop_verdict(cfg)["verdict"] == "stable"


@pytest.mark.slow
def test_internal_dynamics_stay_bounded_under_iofl_and_aiofl() -> None:
    """flexjoint_hub (ρ = 2 < n = 4, minimum phase): classical IOFL on the nominal model makes
    the motor angle exact after the transient while the link (the zero dynamics) stays bounded
    and follows; the AIOFL preset keeps the link bounded too."""
    from dataclasses import replace

    from aiofl.controller import Controller
    from aiofl.engine.simulation import simulate

    cfg = load_config("flexjoint-hub-ladrc")
    iofl = Controller.from_structure("IOFL", rho=2, n_feedback=2).with_values(
        **{"sef.omega_c": 20.0, "eso.omega0": 100.0, "law.b0": 80.0}
    )
    res = simulate(cfg.plant, iofl.with_binomial_alphas(), replace(cfg.scenario, t_final=10.0))
    assert not res.failed
    err = np.abs(res["y"] - res["r"])
    assert np.max(err[res.t > 3.0]) < 1e-10
    assert np.max(np.abs(res["x2"])) < 3.0  # link angle bounded
    aio = cfg.simulate()
    assert np.max(np.abs(aio["x2"])) < 3.0
