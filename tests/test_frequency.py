"""Frequency-domain analysis of the loop broken at the plant input: margins and damping on
loops whose values are known in closed form, the LADRC loop against a hand-derived and an
independently interconnected L(s), and the CLI's --json / --figure."""

from __future__ import annotations

import json
import math

import control
import numpy as np
import pytest
from scipy.optimize import brentq

from aiofl.analysis.frequency import least_damping, loop_margins, loop_transfer
from aiofl.analysis.linearize import linear_eso_statespace, linearize_closed_loop
from aiofl.controller import Controller
from aiofl.plants.symbolic import SymbolicPlant
from aiofl.scenario import Scenario

GAIN = 2.5


def chain(rho: int) -> object:
    """A chain of ρ integrators with input gain GAIN: x_ρ' = GAIN·u, y = x1."""
    states = [f"x{i}" for i in range(1, rho + 1)]
    f = [*states[1:], "0"]
    g = ["0"] * (rho - 1) + ["k"]
    return SymbolicPlant.from_strings(f"chain{rho}", states, {"k": GAIN}, f, g, "x1").to_plant()


def ladrc(rho: int, omega0: float, omega_c: float, b0: float = GAIN) -> Controller:
    """Linear ESO (Gao's binomial gains), exact reference derivatives, linear SEF."""
    ctrl = Controller(eso="linear", td="exact", sef="linear", rho=rho, n_feedback=rho)
    return ctrl.with_values(
        **{"law.b0": b0, "eso.omega0": omega0, "sef.omega_c": omega_c}
    ).with_binomial_alphas()


# ------------------------------------------------------------- closed-form loops
@pytest.mark.parametrize("k", [0.5, 3.0, 40.0])
def test_integrator_with_proportional_gain(k: float) -> None:
    """L(s) = k/s: PM = 90° at ω = k, no phase crossover (GM = ∞), delay margin (π/2)/k,
    S = s/(s + k) so Ms = 1 (approached as ω → ∞), closed-loop pole −k (ζ = 1)."""
    # G(s) = u_p -> u = -k/s, so L = -G = k/s
    loop = loop_transfer([[0.0]], [[1.0]], [[-k]], [[0.0]])
    m = loop_margins(loop, [-k])
    assert m.phase_margin_deg == pytest.approx(90.0, rel=1e-6)
    assert m.gain_crossover == pytest.approx(k, rel=1e-6)
    assert math.isinf(m.gain_margin) and math.isinf(m.gain_margin_db)
    assert m.delay_margin_s == pytest.approx(0.5 * math.pi / k, rel=1e-6)
    assert m.ms == pytest.approx(1.0, rel=1e-6)
    assert m.min_damping == pytest.approx(1.0)
    d = m.to_dict()
    assert d["gain_margin_db"] is None and d["phase_margin_deg"] == pytest.approx(90.0)
    assert any("gain margin infinite" in n for n in d["margin_notes"])


def test_third_order_loop_against_closed_forms() -> None:
    """L(s) = K/(s(s+1)(s+2)): phase crossover at ω = √2 with |L| = K/6, so GM = 6/K;
    the gain crossover solves ω²(ω²+1)(ω²+4) = K²; Ms = 1/min|1 + L|."""
    big_k = 4.0
    sys = control.ss(control.tf([big_k], [1.0, 3.0, 2.0, 0.0]))
    loop = loop_transfer(sys.A, sys.B, -sys.C, -sys.D)
    cl = control.feedback(sys, 1).poles()
    m = loop_margins(loop, cl)
    assert m.phase_crossover == pytest.approx(math.sqrt(2.0), rel=1e-6)
    assert m.gain_margin == pytest.approx(6.0 / big_k, rel=1e-6)
    assert m.gain_margin_db == pytest.approx(20 * math.log10(1.5), rel=1e-6)
    wgc = brentq(lambda w: w * w * (w * w + 1) * (w * w + 4) - big_k**2, 0.1, 10.0)
    phase = -90.0 - math.degrees(math.atan(wgc) + math.atan(wgc / 2))
    assert m.gain_crossover == pytest.approx(wgc, rel=1e-6)
    assert m.phase_margin_deg == pytest.approx(180.0 + phase, rel=1e-6)
    assert m.delay_margin_s == pytest.approx(math.radians(180.0 + phase) / wgc, rel=1e-6)
    w = np.logspace(-2, 2, 200001)
    s = 1j * w
    dist = np.abs(1 + big_k / (s * (s + 1) * (s + 2)))
    assert m.ms == pytest.approx(1.0 / dist.min(), rel=1e-6)


def test_unstable_closed_loop_has_no_delay_margin() -> None:
    """K = 8 > 6 in K/(s(s+1)(s+2)): GM < 1 (negative dB), the closed loop is unstable and the
    delay margin is undefined (NaN, JSON null)."""
    sys = control.ss(control.tf([8.0], [1.0, 3.0, 2.0, 0.0]))
    loop = loop_transfer(sys.A, sys.B, -sys.C, -sys.D)
    m = loop_margins(loop, control.feedback(sys, 1).poles())
    assert m.gain_margin_db == pytest.approx(20 * math.log10(6.0 / 8.0), rel=1e-6)
    assert m.phase_margin_deg < 0
    assert math.isnan(m.delay_margin_s) and m.to_dict()["delay_margin_s"] is None
    assert m.min_damping is not None and m.min_damping < 0


@pytest.mark.parametrize(("zeta", "wn"), [(0.05, 3.0), (0.3, 10.0), (0.8, 0.5)])
def test_least_damping_of_a_second_order_pair(zeta: float, wn: float) -> None:
    """s² + 2ζω_n s + ω_n²: the pair −ζω_n ± jω_n√(1−ζ²) has damping ratio ζ; a faster real
    pole (ζ = 1) does not change the least; python-control's damp agrees."""
    pair = np.roots([1.0, 2 * zeta * wn, wn * wn])
    eig = np.concatenate([pair, [-5 * wn]])
    z, lam = least_damping(eig)
    assert z == pytest.approx(zeta, rel=1e-12)
    assert lam is not None and abs(lam) == pytest.approx(wn)
    sys = control.ss(control.tf([1.0], np.poly(eig).real))
    _, zetas, _ = control.damp(sys, doprint=False)
    assert min(zetas) == pytest.approx(zeta, rel=1e-9)


def test_pipeline_damping_of_a_placed_pair() -> None:
    """Chain of 2 integrators ÿ = b·u, b0 = b, a fal SEF with α = 1 (linear: v = k1·e1 +
    k2·e2, eq. 14 u = v − ξ̂3/b0): the tracking poles are the roots of s² + b·k2 s + b·k1
    = s² + 2ζω s + ω², observer poles at −ω0; the least damping of the linearised closed
    loop is ζ."""
    zeta, w = 0.3, 5.0
    ctrl = Controller(eso="linear", td="han", sef="nonlinear", rho=2, n_feedback=2)
    ctrl = ctrl.with_values(
        **{
            "law.b0": GAIN,
            "eso.omega0": 60.0,
            "sef.k1": w * w / GAIN,
            "sef.k2": 2 * zeta * w / GAIN,
            "sef.alpha1": 1.0,
            "sef.alpha2": 1.0,
            "sef.delta1": 1.0,
            "sef.delta2": 1.0,
        }
    ).with_binomial_alphas()
    lin = linearize_closed_loop(plant=chain(2), controller=ctrl, scenario=Scenario())
    assert lin.margins.min_damping == pytest.approx(zeta, rel=1e-9)
    assert abs(lin.margins.least_damped) == pytest.approx(w, rel=1e-9)


# ------------------------------------------------------------ LADRC loops
def test_ladrc_rho1_loop_matches_the_hand_derived_transfer_function() -> None:
    r"""ρ = 1, plant b/s: with r = 0 the ESO and law give u = −C(s)y with
    C(s) = [(k1β1 + β2)s + k1β2] / [b0 s (s + β1 + k1)] (ξ̂2 cancels from ξ̂1's equation),
    so L(s) = (b/b0)[(k1β1 + β2)s + k1β2] / [s²(s + β1 + k1)].  The pipeline's L(jω) equals
    it, and its margins equal those of the hand formula (python-control's polynomial method
    on the low-order transfer function)."""
    w0, wc, b0 = 20.0, 4.0, 2.0  # b0 ≠ b: the loop is not the nominal one
    lin = linearize_closed_loop(
        plant=chain(1), controller=ladrc(1, w0, wc, b0), scenario=Scenario()
    )
    b1, b2, k1 = 2 * w0, w0 * w0, wc
    hand = control.tf(
        [GAIN / b0 * (k1 * b1 + b2), GAIN / b0 * k1 * b2], np.polymul([1, 0, 0], [1, b1 + k1])
    )
    loop = lin.loop_transfer()
    w = np.logspace(-2, 3, 41)
    assert np.allclose(loop(1j * w).ravel(), hand(1j * w).ravel(), rtol=1e-10, atol=0)
    gm, pm, _, _, wgc, _ = control.stability_margins(hand, method="poly")
    m = lin.margins
    assert m.phase_margin_deg == pytest.approx(pm, rel=1e-6)
    assert m.gain_crossover == pytest.approx(wgc, rel=1e-6)
    assert m.delay_margin_s == pytest.approx(math.radians(pm) / wgc, rel=1e-6)
    assert math.isinf(gm) == math.isinf(m.gain_margin)
    # closing L gives back the closed-loop eigenvalues
    cl = np.sort_complex(control.feedback(hand, 1).poles())
    assert np.allclose(cl, np.sort_complex(lin.eigenvalues), rtol=1e-6)


@pytest.mark.parametrize("rho", [2, 3])
def test_ladrc_loop_matches_an_interconnection_of_python_control_blocks(rho: int) -> None:
    """The loop broken at the plant input, built independently from python-control blocks
    (the chain plant, :func:`linear_eso_statespace`, the static law u = −(k·ξ̂_{1..ρ} +
    ξ̂_{ρ+1})/b0) with :func:`control.interconnect`, has the same L(jω) and margins."""
    w0, wc, b0 = 30.0, 5.0, 3.0
    ctrl = ladrc(rho, w0, wc, b0)
    lin = linearize_closed_loop(plant=chain(rho), controller=ctrl, scenario=Scenario())
    a = np.eye(rho, k=1)
    bp = np.zeros((rho, 1))
    bp[-1, 0] = GAIN
    cp = np.zeros((1, rho))
    cp[0, 0] = 1.0
    plant = control.ss(a, bp, cp, 0, inputs=["up"], outputs=["y"], name="plant")
    alphas = [float(ctrl.value(f"eso.alpha{i}")) for i in range(1, rho + 2)]
    eso = linear_eso_statespace(rho, w0, alphas, b0)
    names = [f"xh{i}" for i in range(1, rho + 2)]
    eso = control.ss(eso.A, eso.B, eso.C, eso.D, inputs=["u", "y"], outputs=names, name="eso")
    k = np.array([math.comb(rho, i - 1) * wc ** (rho - i + 1) for i in range(1, rho + 1)])
    law = control.ss([], [], [], [[*(-k / b0), -1.0 / b0]], inputs=names, outputs=["u"])
    # u_p -> plant -> y -> ESO (with the controller's own u) -> law -> u; L = -(u_p -> u)
    g = control.interconnect([plant, eso, law], inputs="up", outputs="u")
    w = np.logspace(-2, 3, 41)
    ref = -np.asarray(g(1j * w)).ravel()
    assert np.allclose(lin.loop_transfer()(1j * w).ravel(), ref, rtol=1e-9, atol=0)
    independent = loop_margins(control.ss(-g), control.feedback(-g, 1).poles())
    m = lin.margins
    assert m.phase_margin_deg == pytest.approx(independent.phase_margin_deg, rel=1e-6)
    assert m.gain_margin_db == pytest.approx(independent.gain_margin_db, rel=1e-6)
    assert m.ms == pytest.approx(independent.ms, rel=1e-6)


@pytest.mark.parametrize("preset", ["paper-s1-leso", "retuned-s1-ladrc"])
def test_margins_are_exact_crossings_independent_of_the_grid(preset: str) -> None:
    """Resonant loops (paper-s1-leso: L has poles 0.14 ± 149j; retuned-s1-ladrc: ζ = 0.049):
    every reported crossing is one on the exact response (|L(jω_gc)| = 1, L(jω_pc) on the
    negative real axis), and a 40001-point grid gives the same margins as the default one.
    (python-control's spline interpolation of sampled data reported a phase crossover at
    150 rad/s on paper-s1-leso where L(jω) crosses the *positive* real axis.)"""
    from aiofl.analysis.frequency import frequency_grid
    from aiofl.config import load_config

    lin = linearize_closed_loop(load_config(preset))
    loop = lin.loop_transfer()
    m = lin.margins
    if math.isfinite(m.gain_crossover):
        assert abs(complex(loop(1j * m.gain_crossover))) == pytest.approx(1.0, rel=1e-10)
    if math.isfinite(m.phase_crossover):
        lpc = complex(loop(1j * m.phase_crossover))
        assert lpc.real < 0 and abs(lpc.imag) < 1e-10 * abs(lpc)
    dense = np.unique(np.concatenate([frequency_grid(loop.poles()), np.logspace(-3, 5, 40001)]))
    fine = loop_margins(loop, lin.eigenvalues, omega=dense)
    for key in ("gain_margin", "phase_margin_deg", "delay_margin_s", "ms"):
        a, b = getattr(m, key), getattr(fine, key)
        if np.isfinite(a) and np.isfinite(b):
            assert a == pytest.approx(b, rel=1e-9), key
        else:  # inf or nan (undefined) on both
            assert str(a) == str(b), key
    if preset == "paper-s1-leso":
        assert math.isinf(m.gain_margin) and m.open_loop_rhp_poles == 2


# ------------------------------------------------------------------ CLI
def test_cli_json_carries_margins_and_writes_a_figure(tmp_path: object) -> None:
    from pathlib import Path

    from typer.testing import CliRunner

    from aiofl.cli.app import app

    out = Path(str(tmp_path))
    runner = CliRunner()
    fig = out / "loop.png"
    res = runner.invoke(
        app, ["analyze", "tank-ladrc", "--closed-loop", "--json", "--figure", str(fig)]
    )
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    for key in ("gain_margin_db", "phase_margin_deg", "delay_margin_s", "ms", "min_damping"):
        assert key in data
    assert data["verdict"] == "stable" and data["phase_margin_deg"] > 0
    assert data["delay_margin_s"] == pytest.approx(
        math.radians(data["phase_margin_deg"]) / data["gain_crossover_rad_s"], rel=1e-9
    )
    assert fig.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    res = runner.invoke(app, ["analyze", "retuned-s2-ladrc", "--closed-loop"])
    assert res.exit_code == 0, res.output
    assert "phase margin" in res.stdout and "least damping: ζ =" in res.stdout
    assert "-368.607 ×4" in res.stdout  # the linear prefilter's (s + ω_r)⁴, one line
    # refused before any work, nothing written
    for args in (
        ["--figure", str(out / "x.jpg")],
        ["--figure", str(out / "missing" / "x.png")],
        ["--figure", str(out)],
    ):
        res = runner.invoke(app, ["analyze", "tank-ladrc", "--closed-loop", *args])
        assert res.exit_code == 2 and "--figure" in res.stderr
    res = runner.invoke(app, ["analyze", "slfjm", "--figure", str(out / "y.png")])
    assert res.exit_code == 2 and "--closed-loop" in res.stderr
    assert sorted(p.name for p in out.iterdir()) == ["loop.png"]


def test_a_loop_with_an_unbounded_gain_margin_is_reported_not_a_crash():
    """The model-based IOFL loop (iofl-s1) cancels the plant exactly: its disk margin is
    α = 2 (the unit disk of perturbations), whose gain margin (1 + α/2)/(1 − α/2) has no
    bound.  ``analyze --closed-loop`` said so with a TypeError; it prints ∞."""
    from typer.testing import CliRunner

    from aiofl.cli.app import app

    res = CliRunner().invoke(app, ["analyze", "iofl-s1", "--closed-loop"])
    assert res.exit_code == 0, res.output
    line = next(s for s in res.stdout.splitlines() if "disk margin (continuous loop" in s)
    assert "α = 2," in line and "gain ×/÷ ∞ dB" in line and "phase ± 90°" in line
