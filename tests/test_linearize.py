"""Closed-loop linearisation: separation principle, IOFL poles, agreement with the engine and
with nonlinear simulation, python-control interop, and the paper presets' verdicts."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pytest

from aiofl.analysis.closed_loop import ClosedLoop
from aiofl.analysis.linearize import (
    closed_loop_verdict,
    eso_statespace,
    format_linearization_text,
    group_eigenvalues,
    linear_eso_statespace,
    linearize_closed_loop,
)
from aiofl.config import load_config
from aiofl.controller import Controller
from aiofl.plants.registry import get_plant
from aiofl.plants.symbolic import SymbolicPlant
from aiofl.scenario import Reference, Scenario

GAIN = 2.5


def chain(rho: int) -> object:
    """A pure chain of ρ integrators with input gain GAIN: x_ρ' = GAIN·u, y = x1."""
    states = [f"x{i}" for i in range(1, rho + 1)]
    f = [*states[1:], "0"]
    g = ["0"] * (rho - 1) + ["k"]
    return SymbolicPlant.from_strings(f"chain{rho}", states, {"k": GAIN}, f, g, "x1").to_plant()


def observer(rho: int, omega0: float) -> tuple[list[float], np.ndarray]:
    """Non-binomial ESO alphas whose error poles are distinct: −ω0·(1, 1.3, 1.6, ...)."""
    poles = -omega0 * (1.0 + 0.3 * np.arange(rho + 1))
    coeffs = np.poly(poles)[1:]  # β_1..β_{ρ+1}
    alphas = [float(c / omega0 ** (i + 1)) for i, c in enumerate(coeffs)]
    return alphas, poles


def rel_poly_close(a: np.ndarray, b: np.ndarray, rtol: float = 1e-6) -> bool:
    return bool(np.all(np.abs(a - b) <= rtol * np.maximum(np.abs(b), 1e-300) + 1e-12))


@pytest.mark.parametrize("rho", [1, 2, 3, 4])
@pytest.mark.parametrize("td", ["exact", "linear"])
def test_separation_principle_on_a_chain_of_integrators(rho: int, td: str) -> None:
    """Chain of ρ integrators, b0 equal to its gain, linear ESO and linear feedback: the closed
    loop's eigenvalues are the controller poles (−ω_c, multiplicity ρ), the observer poles
    (roots of the ESO polynomial) and, with the linear prefilter in the state, its poles
    (−ω_r, multiplicity ρ)."""
    omega0, omega_c, omega_r = 30.0, 5.0, 12.0
    alphas, obs_poles = observer(rho, omega0)
    values = {"law.b0": GAIN, "eso.omega0": omega0, "sef.omega_c": omega_c, "td.omega": omega_r}
    values.update({f"eso.alpha{i}": a for i, a in enumerate(alphas, 1)})
    ctrl = Controller(eso="linear", td=td, sef="linear", law="aiofl", rho=rho, n_feedback=rho)
    ctrl = ctrl.with_values(**values)
    lin = linearize_closed_loop(
        plant=chain(rho),
        controller=ctrl,
        scenario=Scenario(reference=Reference(kind="step", amplitude=0.3)),
    )
    expected = np.polymul(np.poly([-omega_c] * rho), np.poly(obs_poles))
    if td == "linear":
        expected = np.polymul(expected, np.poly([-omega_r] * rho))
    assert len(lin.eigenvalues) == len(expected) - 1
    assert rel_poly_close(np.poly(lin.a), expected)
    for p in obs_poles:  # distinct poles: each is an eigenvalue
        assert np.min(np.abs(lin.eigenvalues - p)) < 1e-6 * abs(p)
    assert lin.verdict() == "stable"
    assert lin.r_op == pytest.approx(0.3)
    assert lin.z_op[0] == pytest.approx(0.3)  # y settles on r*
    # python-control interop: the ESO's integral action gives unit DC gain r -> y
    import control

    sys = lin.statespace()
    assert isinstance(sys, control.StateSpace)
    assert float(control.dcgain(sys)[0, 0]) == pytest.approx(1.0, rel=1e-6)


def test_separation_breaks_when_b0_is_wrong() -> None:
    """The same loop with b0 = 2·gain no longer has the separated poles (the test is sharp)."""
    rho, omega0, omega_c = 2, 30.0, 5.0
    alphas, obs_poles = observer(rho, omega0)
    ctrl = Controller(eso="linear", td="exact", sef="linear", rho=rho, n_feedback=rho)
    ctrl = ctrl.with_values(
        **{"law.b0": 2 * GAIN, "eso.omega0": omega0, "sef.omega_c": omega_c},
        **{f"eso.alpha{i}": a for i, a in enumerate(alphas, 1)},
    )
    lin = linearize_closed_loop(plant=chain(rho), controller=ctrl, scenario=Scenario())
    expected = np.polymul(np.poly([-omega_c] * rho), np.poly(obs_poles))
    assert not rel_poly_close(np.poly(lin.a), expected, rtol=1e-3)


def test_iofl_poles_are_controller_observer_and_zero_dynamics_poles() -> None:
    """IOFL on the nominal flexjoint_hub (ρ = 2 < n = 4): the output dynamics get (s + ω_c)²,
    the internal dynamics keep the zero-dynamics poles J_l s² + b_l s + k + Mgd, and the
    (unused) ESO keeps its own poles."""
    plant = get_plant("flexjoint_hub")
    wc, w0 = 7.0, 40.0
    ctrl = Controller.from_structure("IOFL", rho=2, n_feedback=2).with_values(
        **{"sef.omega_c": wc, "eso.omega0": w0, "law.b0": 100.0}
    )
    ctrl = ctrl.with_binomial_alphas()
    lin = linearize_closed_loop(plant=plant, controller=ctrl, scenario=Scenario())
    p = dict(plant.params)
    zd = np.array([1.0, p["b_l"] / p["J_l"], (p["k"] + p["M"] * p["g"] * p["d"]) / p["J_l"]])
    expected = np.polymul(np.polymul(np.poly([-wc, -wc]), zd), np.poly([-w0] * 3))
    assert rel_poly_close(np.poly(lin.a), expected, rtol=1e-6)
    # the same zero-dynamics eigenvalues as the symbolic analysis
    from aiofl.plants.library import symbolic_model

    zd_sym = symbolic_model("flexjoint_hub").analyze().zero_dynamics
    assert zd_sym is not None
    for z in zd_sym.eigenvalues:
        assert np.min(np.abs(lin.eigenvalues - z)) < 1e-5


def test_paper_presets_verdicts_and_json() -> None:
    """Printed parameter sets: scenario 1-2 LESO loops are unstable at the operating point
    (they diverge in simulation), the scenario-3 LESO loop is stable; IOFL's eigenvalues are
    (s + 20)⁴ and its monitoring ESO's (s + 100)⁵."""
    v1 = closed_loop_verdict(load_config("paper-s1-leso"))
    assert v1["verdict"] == "unstable"
    assert v1["max_real"] > 0.5
    assert closed_loop_verdict(load_config("paper-s2-leso"))["verdict"] == "unstable"
    v3 = closed_loop_verdict(load_config("paper-s3-leso"))
    assert v3["verdict"] == "stable"
    assert set(v3["verdicts_by_amplitude"].values()) == {"stable"}
    json.dumps(v3)  # JSON-ready
    assert all(len(e) == 2 for e in v3["eigenvalues"])
    vi = linearize_closed_loop(load_config("iofl-s1"))
    assert rel_poly_close(
        np.poly(vi.a), np.polymul(np.poly([-20.0] * 4), np.poly([-100.0] * 5)), rtol=1e-6
    )
    # INLESO: fractional powers, verdict reported per error amplitude
    vn = closed_loop_verdict(load_config("paper-s1-inleso"))
    assert set(vn["verdicts_by_amplitude"]) == {"0.0001", "0.001", "0.01", "0.1"}
    assert any("INLESO g(e)" in n for n in vn["notes"])


def test_operating_point_away_from_zero() -> None:
    """Tank preset: r* = 1 m (the sine's offset); the level settles there with the pump
    supplying the Torricelli outflow, u* = a√(2g)/k_p."""
    cfg = load_config("tank-ladrc")
    lin = linearize_closed_loop(cfg)
    assert lin.r_op == 1.0
    assert lin.z_op[0] == pytest.approx(1.0, abs=1e-9)
    loop = ClosedLoop(cfg.plant, cfg.controller, cfg.scenario)
    u = loop.rhs(lin.z_op)[2]
    p = dict(cfg.plant.params)
    assert u == pytest.approx(p["a"] * math.sqrt(2 * p["g"]) / p["k_p"], rel=1e-6)
    assert lin.verdict() == "stable"


def test_linear_eso_statespace() -> None:
    """The linear ESO (16) as a control.StateSpace: poles = roots of
    s^{ρ+1} + β_1 s^ρ + … + β_{ρ+1}; the paper's scenario-1 LESO has two RHP poles."""
    import control

    sys = linear_eso_statespace(2, 10.0, [3.0, 3.0, 1.0], 4.0)
    assert isinstance(sys, control.StateSpace)
    assert np.allclose(np.sort(np.real(sys.poles())), [-10.0] * 3, atol=1e-3)
    assert list(sys.input_labels) == ["u", "y"]
    # a constant y = 1 with u = 0 is estimated as ξ̂1 = 1
    assert float(control.dcgain(sys)[0, 1]) == pytest.approx(1.0)
    cfg = load_config("paper-s1-leso")
    poles = eso_statespace(cfg.controller).poles()
    assert np.max(poles.real) == pytest.approx(0.137, abs=5e-3)
    with pytest.raises(ValueError, match="linear ESO"):
        eso_statespace(load_config("paper-s1-inleso").controller)
    with pytest.raises(ValueError, match="rho \\+ 1 = 3"):
        linear_eso_statespace(2, 10.0, [1.0], 1.0)


def test_cli_closed_loop() -> None:
    from typer.testing import CliRunner

    from aiofl.cli.app import app

    runner = CliRunner()
    # a stable LESO design whose tracking-orbit analysis is quick (2 s; paper-s3-leso's
    # takes ~40 s, and test_orbit covers the orbit analysis itself)
    res = runner.invoke(app, ["analyze", "frontier-s3-leso", "--closed-loop", "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["verdict"] == "stable" and isinstance(data["eigenvalues"][0], list)
    res = runner.invoke(app, ["analyze", "paper-s1-leso", "--closed-loop"])
    assert res.exit_code == 0
    assert "verdict: UNSTABLE" in res.stdout and "slowest mode" in res.stdout
    res = runner.invoke(app, ["analyze", "paper-s1-leso", "--closed-loop", "--latex"])
    assert res.exit_code == 2
    res = runner.invoke(app, ["analyze", "no-such-preset", "--closed-loop"])
    assert res.exit_code == 2 and "unknown preset" in res.stderr


# ----------------------------------------------------- agreement with the engine


def _python_trajectory(loop: ClosedLoop, z0: np.ndarray, t_end: float, dt: float) -> np.ndarray:
    """RK4 of the Python closed loop with the sine reference and its derivatives."""
    ref = loop.scenario.reference

    def rd(t: float) -> list[float]:
        return [
            ref.amplitude * ref.omega**k * math.sin(ref.omega * t + ref.phase + 0.5 * math.pi * k)
            + (ref.offset if k == 0 else 0.0)
            for k in range(loop.rho + 1)
        ]

    z = z0.copy()
    for k in range(round(t_end / dt)):
        t = k * dt
        k1 = loop.rhs(z, rd(t))[0]
        k2 = loop.rhs(z + 0.5 * dt * k1, rd(t + 0.5 * dt))[0]
        k3 = loop.rhs(z + 0.5 * dt * k2, rd(t + 0.5 * dt))[0]
        k4 = loop.rhs(z + dt * k3, rd(t + dt))[0]
        z = z + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return z


@pytest.mark.slow
@pytest.mark.parametrize(
    ("preset", "td"),
    [
        ("paper-s1-leso", None),  # LESO, Han TD, NLSEF
        ("paper-s2-inleso", None),  # INLESO, ITD, INLSEF, J_l x 1.4, disturbance
        ("iofl-s2", None),  # IOFL, exact derivatives, nominal model vs changed plant
        ("dcmotor-arm-ladrc", "linear"),  # linear ESO, linear prefilter, linear SEF, rho = 3
    ],
)
def test_python_closed_loop_matches_the_engine(preset: str, td: str | None) -> None:
    """ClosedLoop(mode="exact") integrates to the engine's state (same equations)."""
    from dataclasses import replace

    from aiofl.engine.simulation import simulate

    cfg = load_config(preset)
    ctrl = cfg.controller
    if td is not None:
        ctrl = replace(ctrl, td=td).with_values(**{"td.omega": 25.0})
    n = cfg.plant.n_states
    x0 = (0.01,) + (0.0,) * (n - 1)  # start off the reference so every block is exercised
    scen = replace(cfg.scenario, t_final=0.03, disturbance_time=0.0, x0=x0)  # disturbance on
    if preset.startswith("dcmotor"):
        scen = replace(scen, disturbance_amplitude=0.2)
    loop = ClosedLoop(cfg.plant, ctrl, scen, mode="exact")
    z0 = np.zeros(loop.n_z)
    z0[:n] = x0
    res = simulate(cfg.plant, ctrl, scen, dt=1e-4, decimation=1)
    z = _python_trajectory(loop, z0, 0.03, 1e-4)
    engine = [res[f"x{i}"][-1] for i in range(1, n + 1)]
    engine += [res[f"r{i}"][-1] for i in range(1, loop.n_td + 1)]
    engine += [res[f"xi_hat{i}"][-1] for i in range(1, ctrl.rho + 2)]
    assert np.allclose(z, engine, rtol=1e-8, atol=1e-10)


@pytest.mark.slow
def test_verdicts_agree_with_nonlinear_simulation() -> None:
    """From a small perturbation of the operating point (r ≡ 0): the loop linearised as
    stable (paper-s3-leso) returns, the one linearised as unstable (paper-s1-leso) departs."""
    from aiofl.engine.simulation import simulate

    for preset, x1, stable in (("paper-s3-leso", 1e-3, True), ("paper-s1-leso", 1e-6, False)):
        cfg = load_config(preset)
        assert (closed_loop_verdict(cfg)["verdict"] == "stable") is stable
        scen = Scenario(
            reference=Reference(kind="step", amplitude=0.0), t_final=10.0, x0=(x1, 0, 0, 0)
        )
        res = simulate(cfg.plant, cfg.controller, scen)
        late = np.max(np.abs(res["y"][res.t > 6.0])) if not res.failed else math.inf
        if stable:
            assert late < 0.05 * x1
        else:
            assert late > 100 * x1


# ------------------------------------------- exact Jacobians and repeated eigenvalues


def gao_ladrc(rho: int, omega0: float, omega_c: float, td: str = "exact") -> Controller:
    """Gao's LADRC: binomial ESO gains (poles −ω0), linear SEF (poles −ω_c), b0 = gain."""
    ctrl = Controller(eso="linear", td=td, sef="linear", law="aiofl", rho=rho, n_feedback=rho)
    return ctrl.with_values(
        **{"law.b0": GAIN, "eso.omega0": omega0, "sef.omega_c": omega_c}
    ).with_binomial_alphas()


@pytest.mark.parametrize("rho", [1, 2, 3, 4])
def test_gao_ladrc_eigenvalues_are_exactly_repeated(rho: int) -> None:
    """On a chain of integrators with b0 = its gain, Gao's LADRC has the closed-loop
    eigenvalues −ω_c (ρ times) and −ω0 (ρ+1 times) exactly (separation principle).  With
    the exact (complex-step) Jacobian and the grouping of numerically repeated eigenvalues
    they come out as two groups with those multiplicities, to ~1e-9 relative; the text
    prints each once with its multiplicity.  (A finite-difference Jacobian split −50 ×3
    into −50.0075 ± 0.013j; the eigenvalues of even an exact matrix are a cluster of radius
    ~ε^{1/k}, here up to 7e-3 relative for k = 4, 5.)"""
    omega0, omega_c = 50.0, 7.0
    lin = linearize_closed_loop(
        plant=chain(rho),
        controller=gao_ladrc(rho, omega0, omega_c),
        scenario=Scenario(reference=Reference(kind="step", amplitude=0.3)),
    )
    groups = lin.eigenvalue_groups
    assert [k for _, k in groups] == [rho, rho + 1]
    assert groups[0][0] == pytest.approx(-omega_c, rel=1e-9)
    assert groups[1][0] == pytest.approx(-omega0, rel=1e-9)
    assert groups[0][0].imag == 0.0 and groups[1][0].imag == 0.0
    assert np.allclose(np.sort(lin.eigenvalues.real), [-omega0] * (rho + 1) + [-omega_c] * rho)
    text = format_linearization_text(lin)
    assert f"-7 ×{rho}" in text or (rho == 1 and "    -7   decays" in text)
    assert f"-50 ×{rho + 1}" in text
    # the Jacobian is exact: A's characteristic polynomial is (s + ω_c)^ρ (s + ω0)^(ρ+1)
    expected = np.polymul(np.poly([-omega_c] * rho), np.poly([-omega0] * (rho + 1)))
    assert rel_poly_close(np.poly(lin.a), expected, rtol=1e-10)


def test_group_eigenvalues_merges_jordan_blocks_only() -> None:
    """A matrix similar to diag(J3(−50), J2(−3 ± 4j) as a real block, −1, −1·(1 + 1e-6)):
    the Jordan blocks are merged into (−50, 3) and (−3 ± 4j, 2 each); the two simple
    eigenvalues 1e-6 apart (well-conditioned) stay separate."""
    j3 = -50.0 * np.eye(3) + np.eye(3, k=1)
    rot = np.array([[-3.0, 4.0], [-4.0, -3.0]])
    j2c = np.block([[rot, np.eye(2)], [np.zeros((2, 2)), rot]])  # real Jordan form, size 2
    simple = np.diag([-1.0, -1.0 - 1e-6])
    m = np.zeros((7 + 0, 7))
    m[:3, :3], m[3:7, 3:7] = j3, j2c
    m = np.block([[m, np.zeros((7, 2))], [np.zeros((2, 7)), simple]])
    t = np.random.default_rng(3).standard_normal((9, 9)) + 3 * np.eye(9)
    a = t @ m @ np.linalg.inv(t)
    assert np.max(np.abs(np.linalg.eigvals(a) + 50).min()) > 1e-7  # raw eigvals do split
    groups = dict((complex(round(g.real, 6), round(g.imag, 6)), k) for g, k in group_eigenvalues(a))
    assert groups == {-50: 3, complex(-3, 4): 2, complex(-3, -4): 2, -1: 1, -1.000001: 1}
    means = {k: g for g, k in group_eigenvalues(a) if k == 3}
    assert means[3] == pytest.approx(-50.0, rel=1e-9)


@pytest.mark.slow
def test_every_shipped_preset_has_an_operating_point_and_margins() -> None:
    """`aiofl analyze NAME --closed-loop` works on every shipped preset (it failed on
    retuned-s2-ladrc and retuned-s2-leso with the old unscaled Newton).  Each result carries
    the damping and margin keys; the least damping equals python-control's damp of A (up to
    the spread of a repeated cluster); closing L gives back the closed loop's eigenvalues."""
    import control

    from aiofl.config import list_presets

    names = list_presets()
    assert {"retuned-s2-ladrc", "retuned-s2-leso", "tank-ladrc"} <= set(names)
    for name in names:
        cfg = load_config(name)
        lin = linearize_closed_loop(cfg)
        info = closed_loop_verdict(cfg, linearization=lin)
        json.dumps(info)
        for key in ("gain_margin_db", "phase_margin_deg", "delay_margin_s", "ms", "min_damping"):
            assert key in info, (name, key)
        assert info["verdict"] in ("stable", "unstable"), name
        _, zetas, _ = control.damp(lin.statespace(), doprint=False)
        assert info["min_damping"] == pytest.approx(float(np.min(zetas)), abs=2e-3), name
        cl = control.feedback(lin.loop_transfer(), 1).poles()
        spread = np.min(np.abs(cl[:, None] - lin.eigenvalues[None, :]), axis=1)
        assert np.all(spread <= 1e-2 * np.maximum(1.0, np.abs(cl))), name
        if info["verdict"] == "stable":
            assert info["delay_margin_s"] is not None and info["delay_margin_s"] > 0, name
        else:
            assert info["delay_margin_s"] is None, name


def test_operating_point_with_a_large_disturbance_estimate() -> None:
    """retuned-s2-ladrc at r* = 0 with τ_d = 0.5 N·m: the plant holds y = 0 with x = 0 and
    u* = −τ_d R_m/(K_m K_g); the ESO's extended state then estimates ξ̂5 = −b0 u* ≈ 1.2e6,
    which an absolute tolerance had rejected (residual 37.6 on terms of size 1e16)."""
    cfg = load_config("retuned-s2-ladrc")
    lin = linearize_closed_loop(cfg)
    p = dict(cfg.plant.params)
    u_star = -0.5 * p["R_m"] / (p["K_m"] * p["K_g"])
    b0 = cfg.controller.value("law.b0")
    assert lin.z_op[-1] == pytest.approx(-b0 * u_star, rel=1e-12)
    assert np.allclose(lin.z_op[:4], 0.0, atol=1e-12)
    assert lin.verdict() == "stable"


def test_no_equilibrium_is_a_clear_error() -> None:
    """ẋ = c + k·u with the actuator limited to |u| ≤ 0.2 < c/k: ẋ > 0 everywhere, so the
    loop has no equilibrium; the search says so (and the CLI exits 2).  (Where one exists
    with the actuator saturated — the tank's pump at its limit holding a lower level — it
    is found.)"""
    plant = SymbolicPlant.from_strings("drift", ["x1"], {"c": 1.0, "k": GAIN}, ["c"], ["k"], "x1")
    ctrl = gao_ladrc(1, 20.0, 4.0).with_values(**{"law.u_max": 0.2})
    with pytest.raises(ValueError, match="no closed-loop operating point found"):
        linearize_closed_loop(plant=plant.to_plant(), controller=ctrl, scenario=Scenario())
    cfg = load_config("tank-ladrc")
    ctrl = cfg.controller.with_values(**{"law.u_max": 0.5})
    lin = linearize_closed_loop(plant=cfg.plant, controller=ctrl, scenario=cfg.scenario)
    p = dict(cfg.plant.params)
    level = (0.5 * p["k_p"] / p["a"]) ** 2 / (2 * p["g"])  # a√(2gH) = k_p·u_max
    assert lin.z_op[0] == pytest.approx(level, rel=1e-10)


# --------------------------------------------------- exact TD: r's derivatives


@pytest.mark.parametrize("rho", [1, 2, 3, 4])
def test_exact_td_tracking_model_is_exactly_one(rho: int) -> None:
    """With the exact reference derivatives, b0 equal to the chain's gain and a linear ESO,
    the estimation error is not excited by r and the tracking error obeys
    e^(ρ) + k_ρ e^(ρ−1) + … + k_1 e = 0, so Y/R = 1 at every frequency.  The r → y model
    carries the derivatives' feed-forward (holding them at zero gave a wrong r → y), and
    the direct sum Σ (jω)^k G_k(jω) agrees."""
    lin = linearize_closed_loop(
        plant=chain(rho),
        controller=gao_ladrc(rho, 40.0, 6.0),
        scenario=Scenario(reference=Reference(kind="step", amplitude=0.3)),
    )
    assert lin.input_names == ("r", *(f"r_d{k}" for k in range(1, rho + 1)), "d", "n")
    w = np.logspace(-3, 3, 61)
    t = lin.tracking_statespace()
    assert np.max(np.abs(t(1j * w).ravel() - 1.0)) < 1e-9
    w_direct = w[w <= 100.0]
    assert np.max(np.abs(lin.reference_response(w_direct)[0] - 1.0)) < 1e-9
    if rho > 1:  # the derivatives matter: r alone (derivatives held at 0) is not 1
        g0 = lin.statespace()[0, 0]
        assert abs(complex(g0(1j * 6.0)) - 1.0) > 0.1


def test_iofl_tracks_exactly_in_the_linearised_model() -> None:
    """Classical IOFL on its own nominal model (iofl-s1): r → y = 1 at every frequency."""
    lin = linearize_closed_loop(load_config("iofl-s1"))
    w = np.logspace(-2, 3, 26)
    assert np.max(np.abs(lin.tracking_statespace()(1j * w).ravel() - 1.0)) < 1e-9


@pytest.mark.slow
def test_tank_tracking_model_matches_the_nonlinear_simulation() -> None:
    """tank-ladrc (b0 = 0.05 vs true 0.04, Torricelli outflow): a small sine around 1 m at
    ω = 2 rad/s.  The steady-state gain and phase of the simulated level equal the
    linearised r → y model with the derivatives fed forward (~1.00, ~0°), not the model with
    them held at zero."""
    from dataclasses import replace

    from aiofl.engine.simulation import simulate

    cfg = load_config("tank-ladrc")
    omega, amp = 2.0, 0.002
    lin = linearize_closed_loop(cfg)
    predicted = complex(lin.tracking_statespace()(1j * omega))
    held = complex(lin.statespace()[0, 0](1j * omega))
    scen = replace(
        cfg.scenario,
        reference=Reference(kind="sine", amplitude=amp, omega=omega, offset=1.0),
        x0=(1.0,),
        t_final=30.0,
    )
    res = simulate(cfg.plant, cfg.controller, scen, dt=1e-3, decimation=1)
    sel = res.t >= 15.0
    t, y = res.t[sel], res["y"][sel] - 1.0
    basis = np.column_stack([np.sin(omega * t), np.cos(omega * t), np.ones_like(t)])
    (s_c, c_c, _), *_ = np.linalg.lstsq(basis, y, rcond=None)
    measured = complex(s_c, c_c) / amp  # y = Im(G e^{jωt}) amp → G = (s + jc)/amp
    assert abs(measured - predicted) < 2e-3 * abs(predicted)
    assert abs(measured - held) > 10 * abs(measured - predicted)


# ---------------------------------------------------- plant derivatives fallback


def tank_f_abs(x: np.ndarray, p: np.ndarray) -> tuple[float]:
    """A one-tank plant's f, −a√|H|, with the built-in abs (re-bound: exact complex step)."""
    return (-p[0] * math.sqrt(abs(x[0])),)


def tank_f_numpy_abs(x: np.ndarray, p: np.ndarray) -> tuple[float]:
    """The same f with numpy.abs: the modulus of a complex step, whose derivative is lost."""
    return (-p[0] * np.sqrt(np.abs(x[0])),)


def tank_f_erf(x: np.ndarray, p: np.ndarray) -> tuple[float]:
    """The same f plus 1e-3·erf(H − 1): math.erf has no complex version (finite differences)."""
    return (-p[0] * math.sqrt(abs(x[0])) + 1e-3 * (math.erf(x[0] - 1.0)),)


def tank_plant(name: str, f: Any) -> Any:
    """The one-tank plant ``f`` with g = k, y = H (parameters a = 0.2, k = 0.04)."""
    from aiofl.plants.base import Plant

    def g(x: np.ndarray, p: np.ndarray) -> tuple[float]:
        return (p[1],)

    def h(x: np.ndarray, p: np.ndarray) -> float:
        return x[0]

    return Plant(name, 1, f, g, h, {"a": 0.2, "k": 0.04}, relative_degree=1)


def test_plant_without_complex_support_falls_back_to_finite_differences() -> None:
    """A plant written with numpy.abs (the modulus on complex numbers, so the complex step
    would lose the derivative) is caught by the check against finite differences: its
    Jacobian comes from scipy.differentiate (noted), and agrees with the same plant written
    with abs (re-bound, exact) to ~1e-8.  A plant calling math.erf (no complex version)
    falls back the same way."""
    cfg = load_config("tank-ladrc")
    results = {}
    for name, f in (("builtin", tank_f_abs), ("numpy", tank_f_numpy_abs), ("erf", tank_f_erf)):
        plant = tank_plant(name, f)
        results[name] = linearize_closed_loop(
            plant=plant, controller=cfg.controller, scenario=cfg.scenario
        )
    assert not any("finite differences" in n for n in results["builtin"].notes)
    assert any("finite differences" in n for n in results["numpy"].notes)
    assert np.allclose(results["builtin"].a, results["numpy"].a, rtol=1e-8, atol=1e-10)
    assert any("ComplexWarning" in n for n in results["erf"].notes)
    # d/dH of 1e-3·erf(H − 1) at H = 1 is 1e-3·2/√π
    erf_slope = 1e-3 * 2 / math.sqrt(math.pi)
    assert results["erf"].a[0, 0] == pytest.approx(-0.1 + erf_slope, rel=1e-8)
    # ∂(−a√H)/∂H = −a/(2√H) at H = 1 (u depends on the ESO states only): exact with abs
    assert results["builtin"].a[0, 0] == pytest.approx(-0.1, rel=1e-14)


# -------------------------------------------------------------- zero dynamics


def test_no_zero_dynamics_verdict_where_beta_vanishes() -> None:
    """ẋ1 = −a x1, ẋ2 = x1·u, y = x2: β = x1, so ρ = 1 only where x1 ≠ 0; the zero dynamics
    (y ≡ 0) rest at x_e = 0 where β = 0: no verdict.  With β = 1 + x1 (≠ 0 at x_e) the same
    zero dynamics ẋ1 = −a x1 are minimum phase."""

    def plant(g2: str) -> SymbolicPlant:
        f = ["-a*x1", "0"]
        return SymbolicPlant.from_strings("bz", ["x1", "x2"], {"a": 1.0}, f, ["0", g2], "x2")

    an = plant("x1").analyze()
    assert an.zero_dynamics is None
    assert "ρ is not defined at x_e; no verdict" in an.zero_dynamics_note
    assert "minimum phase" not in an.zero_dynamics_note
    zd = plant("1 + x1").analyze().zero_dynamics
    assert zd is not None and zd.verdict == "minimum phase"
    assert np.allclose(zd.eigenvalues, [-1.0])


def test_close_distinct_poles_stay_distinct() -> None:
    """LADRC with ρ = 2 on ÿ = GAIN·u, ω0 = 10, ω_c = 10.1: the observer's −10 ×3 and the
    tracking −10.1 ×2 are 0.1 apart, far more than the computed eigenvalues' own accuracy
    (~5e-3 here), so they are two groups (a perturbation level of 1000 ε‖A‖ merged them
    into −10.04 ×5); ω_c = ω0 = 10 is one genuinely repeated pole of multiplicity 5."""
    scenario = Scenario(reference=Reference(kind="step", amplitude=0.3))
    lin = linearize_closed_loop(
        plant=chain(2), controller=gao_ladrc(2, 10.0, 10.1), scenario=scenario
    )
    groups = lin.eigenvalue_groups
    assert [k for _, k in groups] == [3, 2]
    assert groups[0][0] == pytest.approx(-10.0, rel=1e-6)
    assert groups[1][0] == pytest.approx(-10.1, rel=1e-6)
    text = format_linearization_text(lin)
    assert "-10 ×3" in text and "-10.1 ×2" in text
    same = linearize_closed_loop(
        plant=chain(2), controller=gao_ladrc(2, 10.0, 10.0), scenario=scenario
    )
    assert [k for _, k in same.eigenvalue_groups] == [5]
    assert same.eigenvalue_groups[0][0] == pytest.approx(-10.0, rel=1e-9)
