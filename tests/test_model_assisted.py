"""The model-assisted ESO (``eso.model = "nominal"``): the coordinate change back, the law,
the observer's residual, and the engine against independent paths.

Facts checked: Φ⁻¹(Φ(x)) = x and (α, β)(Φ(x)) = the normal form's α(x), β(x) on random
states for every shipped plant with ρ = n; with the nominal model equal to the true plant
and no noise or disturbance the extended state ξ̂_{ρ+1} (the residual) stays ~0 and the
loop tracks as the classical IOFL law fed the true state does; the compiled engine agrees
with the scipy reference path (which inverts Φ numerically, not with the generated
inverse) and with its own linearisation's operating point; the sampled controller
stepped from Python gives the commands the sampled engine applied; plants without the
normal form in ξ are refused by name.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from aiofl.analysis.closed_loop import ClosedLoop
from aiofl.config.run_config import ConfigError, parse_config
from aiofl.controller import Controller
from aiofl.discrete_controller import DiscreteController
from aiofl.engine.discrete_rows import Sampling, sample_steps
from aiofl.engine.reference import reference_simulate
from aiofl.engine.simulation import simulate
from aiofl.plants.base import Plant
from aiofl.plants.library import symbolic_model
from aiofl.plants.registry import get_plant
from aiofl.scenario import Reference, Scenario

SHIPPED_FULL_DEGREE = ("slfjm", "pendulum", "tank", "dcmotor_arm")


@pytest.fixture(scope="module")
def slfjm() -> Plant:
    return get_plant("slfjm")


def _beta(plant: Plant) -> float:
    return float(plant.normal_form(np.zeros(plant.n_states), plant.param_vector())[-1])


def assisted(plant: Plant, omega0: float = 10.0, omega_c: float = 20.0, **kw) -> Controller:
    """A linear model-assisted loop with exact reference derivatives (the issue's prototype)."""
    values = {"eso.omega0": omega0, "sef.omega_c": omega_c, "law.b0": _beta(plant)}
    values.update(kw.pop("values", {}))
    return Controller(
        eso="linear",
        td="exact",
        sef="linear",
        law="aiofl",
        rho=plant.relative_degree,
        structure="LADRC-MA",
        eso_model="nominal",
        values=values,
        **kw,
    )


# ----------------------------------------------------------------- the inverse
@pytest.mark.parametrize("name", SHIPPED_FULL_DEGREE)
def test_the_inverse_undoes_the_coordinate_change(name: str):
    plant = get_plant(name)
    p = plant.param_vector()
    rho = plant.relative_degree
    assert rho == plant.n_states and plant.state_of_xi is not None
    rng = np.random.default_rng(7)
    for _ in range(50):
        x = rng.uniform(-2.0, 2.0, plant.n_states)
        if name == "tank":
            x = np.abs(x) + 0.1  # a level
        nf = np.asarray(plant.normal_form(x, p))
        xi = nf[:rho]
        np.testing.assert_allclose(plant.state_of_xi(xi, p), x, rtol=1e-12, atol=1e-12)
        ab = np.asarray(plant.alpha_beta_of_xi(xi, p))
        np.testing.assert_allclose(ab, nf[rho:], rtol=1e-11, atol=1e-9 * np.abs(nf[rho:]).max())


def test_a_plant_with_internal_dynamics_has_no_inverse():
    analysis = symbolic_model("flexjoint_hub").analyze()
    assert analysis.rho < analysis.plant.n
    x_of_xi, note = analysis.inverse
    assert x_of_xi is None and "internal dynamics" in note
    assert get_plant("flexjoint_hub").alpha_beta_of_xi is None


# ------------------------------------------------------------------ the loop
def test_with_the_true_model_the_residual_stays_zero_and_it_tracks_like_iofl(slfjm):
    """Nominal model = true plant, no noise, no disturbance: the residual y^(ρ) - α0 - β0 u
    is 0, so ξ̂_{ρ+1} stays ~0 (the model-free ESO's would be the whole β u, ~10⁴), and the
    tracking is IOFL's (which is fed the true state) up to the observer's transient."""
    sc = Scenario(reference=Reference(kind="sine"), t_final=5.0)
    res = simulate(slfjm, assisted(slfjm), sc, decimation=10)
    assert not res.failed
    late = res.t > 1.0
    assert np.max(np.abs(res["xi_hat5"][late])) < 1e-6
    free = simulate(slfjm, dataclasses.replace(assisted(slfjm), eso_model="none"), sc)
    assert np.max(np.abs(free["xi_hat5"][late])) > 1e3  # what the model-free ESO estimates
    iofl = Controller(
        eso="linear", td="exact", sef="linear", law="iofl", rho=4, structure="IOFL",
        values={"sef.omega_c": 20.0, "eso.omega0": 10.0},
    )  # fmt: skip
    ref = simulate(slfjm, iofl, sc, decimation=10)
    np.testing.assert_allclose(res["y"][late], ref["y"][late], atol=1e-7)
    assert res.metrics["itae"] == pytest.approx(ref.metrics["itae"], rel=1e-3)


def test_the_engine_agrees_with_the_reference_path(slfjm):
    """A wrong model (J_l x 1.3 in the true plant), output noise off: the engine's RK4 and
    scipy's RK45 on the independent loop (numerical Φ⁻¹) give the same trajectory."""
    sc = Scenario(reference=Reference(kind="sine"), t_final=0.6, plant_scale={"J_l": 1.3})
    ctrl = assisted(slfjm, omega0=40.0)
    eng = simulate(slfjm, ctrl, sc, dt=1e-4, decimation=50)
    ref = reference_simulate(slfjm, ctrl, sc, t_eval=eng.t, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(eng["y"], ref.y, atol=1e-8)
    np.testing.assert_allclose(eng["u"], ref.u, atol=1e-6 * np.max(np.abs(ref.u)))


def _jacobian(plant: Plant, xi_star: np.ndarray) -> np.ndarray:
    """∂(α + β u*)/∂ξ of the generated (α, β)(ξ) at ξ*, by central differences."""
    p = plant.param_vector()
    a_star, b_star = plant.alpha_beta_of_xi(xi_star, p)
    u_star = -a_star / b_star
    jac = np.zeros(xi_star.size)
    for j in range(xi_star.size):
        d = np.zeros(xi_star.size)
        d[j] = 1e-6
        hi, lo = plant.alpha_beta_of_xi(xi_star + d, p), plant.alpha_beta_of_xi(xi_star - d, p)
        jac[j] = ((hi[0] - lo[0]) + u_star * (hi[1] - lo[1])) / 2e-6
    return jac


@pytest.mark.parametrize("r_star", [0.0, 0.3])
def test_the_linearisation_uses_the_model_and_its_placed_gains(slfjm, r_star):
    """The linearised loop separates into the tracking chain (poles -ω_c, ρ times) and the
    observer's error dynamics, in which the model's Jacobian J* = ∂(α + β u*)/∂ξ at the
    operating point enters the ρ-th row: eig(A + e_ρ [J*, 0] - L C).  The engine places L
    for J at the initial state (the origin): at r* = 0 the observer poles are -ω0 (ρ+1
    times, up to the rounding of a repeated root); at r* = 0.3 J* differs a little."""
    from aiofl.components.model_gains import model_gain

    sc = Scenario(reference=Reference(kind="step", amplitude=r_star), t_final=1.0)
    w0, wc = 15.0, 5.0
    ctrl = assisted(slfjm, omega0=w0, omega_c=wc)
    loop = ClosedLoop(slfjm, ctrl, sc)
    z_star = loop.operating_point()
    assert z_star[0] + z_star[1] == pytest.approx(r_star, abs=1e-9)  # y* = r*
    eig = np.linalg.eigvals(loop.linear_model(z_star)[0])
    binomial = np.array([5.0, 10.0, 10.0, 5.0, 1.0])
    gains = model_gain(_jacobian(slfjm, np.zeros(4)), binomial, w0)
    err = np.diag(np.ones(4), 1) - np.outer(gains, np.eye(5)[0])
    err[3, :4] += _jacobian(slfjm, np.array([r_star, 0.0, 0.0, 0.0]))
    observer = np.linalg.eigvals(err)
    expect = np.r_[np.full(4, -wc), observer]
    # characteristic polynomials (well conditioned, unlike the repeated roots themselves)
    assert np.poly(eig).real == pytest.approx(np.poly(expect).real, rel=1e-5)
    if r_star == 0.0:
        assert np.allclose(observer, -w0, atol=0.05 * w0)
    # Gao's gains without the placement would have left a pole near -0.13 rad/s
    gao = np.diag(np.ones(4), 1) - np.outer(binomial * w0 ** np.arange(1, 6), np.eye(5)[0])
    gao[3, :4] += _jacobian(slfjm, np.zeros(4))
    assert np.min(np.abs(np.linalg.eigvals(gao).real)) < 0.2


def test_the_sampled_engine_runs_the_discrete_controller_update(slfjm):
    samp = Sampling(1e-3, y_quantum=2 * np.pi / 4096)
    ctrl = assisted(slfjm, omega0=10.0)
    n_per = sample_steps(samp.ts, 1e-4)
    res = simulate(slfjm, ctrl, Scenario(t_final=0.5), sampling=samp, decimation=n_per)
    dc = DiscreteController(ctrl, samp, plant=slfjm)
    dc.init(res["y_meas"][0])
    t = res.t[:-1]  # the sine r = (π/4) sin 2t and its derivatives, as the exact TD has them
    rd = np.stack([(np.pi / 4) * 2.0**k * np.sin(2 * t + k * np.pi / 2) for k in range(5)], 1)
    u = np.array([dc.step(r, y) for r, y in zip(rd, res["y_meas"][:-1], strict=True)])
    applied = res["u"][:-1]
    scale = np.max(np.abs(applied))
    assert scale > 0
    np.testing.assert_allclose(applied, u, rtol=0, atol=1e-10 * scale)
    with pytest.raises(ValueError, match="pass plant="):
        DiscreteController(ctrl, samp)


def test_sampled_at_a_short_period_it_approaches_the_continuous_loop(slfjm):
    sc = Scenario(reference=Reference(kind="sine"), t_final=2.0, plant_scale={"K_s": 1.2})
    ctrl = assisted(slfjm, omega0=20.0)
    cont = simulate(slfjm, ctrl, sc, store=False)
    errs = []
    for ts in (4e-4, 2e-4):
        samp = simulate(slfjm, ctrl, sc, store=False, sampling=Sampling(ts))
        errs.append(abs(samp.metrics["itae"] - cont.metrics["itae"]))
    assert errs[1] < 0.7 * errs[0]  # first order in Ts


# ------------------------------------------------------------------ refusals
def test_plants_without_the_model_in_xi_are_refused_by_name():
    hub = get_plant("flexjoint_hub")
    ctrl = dataclasses.replace(assisted(get_plant("slfjm")), rho=2, n_feedback=2)
    with pytest.raises(ValueError, match=r"eso.model = .nominal.(.|\n)*flexjoint_hub"):
        ctrl.check_plant(hub)
    slf = get_plant("slfjm")
    bare = dataclasses.replace(slf, alpha_beta_of_xi=None, state_of_xi=None)
    with pytest.raises(ValueError, match="alpha_beta_of_xi"):
        assisted(slf).check_plant(bare)
    with pytest.raises(ValueError, match="law = 'aiofl'"):
        Controller(law="iofl", eso_model="nominal")
    with pytest.raises(ValueError, match="eso_model"):
        Controller(eso_model="exact")


def _config(**eso) -> dict:
    return {
        "plant": "slfjm",
        "scenario": {"t_final": 1.0},
        "controller": {
            "structure": "LADRC",
            "eso": {"omega0": 10.0, **eso},
            "td": {"omega": 10.0},
            "sef": {"omega_c": 1.0},
            "law": {"b0": 2.68e4},
        },
        "simulation": {"dt": 1e-4},
    }


def test_the_config_key():
    cfg = parse_config(_config(model="nominal"), "ma.toml")
    assert cfg.controller.eso_model == "nominal"
    assert parse_config(_config(), "free.toml").controller.eso_model == "none"
    with pytest.raises(ConfigError, match=r"controller\.eso\.model"):
        parse_config(_config(model="full"), "bad.toml")
