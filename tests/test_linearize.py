"""Closed-loop linearisation: separation principle, IOFL poles, agreement with the engine and
with nonlinear simulation, python-control interop, and the paper presets' verdicts."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from aiofl.analysis.closed_loop import ClosedLoop
from aiofl.analysis.linearize import (
    closed_loop_verdict,
    eso_statespace,
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
    res = runner.invoke(app, ["analyze", "paper-s3-leso", "--closed-loop", "--json"])
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
        late = np.max(np.abs(res["y"][res.t > 6.0])) if not res.diverged else math.inf
        if stable:
            assert late < 0.05 * x1
        else:
            assert late > 100 * x1
