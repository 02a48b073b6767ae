"""Floquet multipliers, limit cycles and describing functions: facts with known answers.

* a linear time-invariant loop driven by a sine: its monodromy matrix is :math:`e^{AT}`, so
  its Floquet multipliers are :math:`e^{\\lambda_i T}`;
* the Mathieu equation :math:`\\ddot x + (a - 2q\\cos 2t)x = 0`: at q = 0 the multipliers
  are :math:`e^{\\pm i\\sqrt a\\,\\pi}` (modulus 1), and (a, q) = (1, 0.2) lies in the first
  instability tongue around a = 1 (|μ| > 1) while (a, q) = (2.5, 0.2) is stable;
* an ideal relay of height h around :math:`G(s) = K/(s(s+1)(s+2))`: the describing
  function predicts the limit cycle :math:`A = 4h|G(j\\omega_{180})|/\\pi` at
  :math:`\\omega_{180} = \\sqrt 2` (|G| = K/6 there); the harmonic balance returns it, and
  a simulation of the relay loop oscillates within a few per cent of it;
* the shipped frontier-s1-leso: equilibrium unstable, with r held a limit cycle of about
  1e-5 rad at about 71 rad/s (simulation and describing function agree), tracking orbit
  stable (largest multiplier < 1), and one sentence that says all three.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from aiofl.analysis.variational import (
    describing_gain,
    expm_small,
    harmonic_balance,
    measure_oscillation,
    periodic_orbit,
    trajectory,
    variational_flow,
)


def test_expm_small_matches_scipy() -> None:
    from scipy.linalg import expm

    rng = np.random.default_rng(3)
    for scale in (0.01, 1.0, 30.0):
        a = rng.standard_normal((6, 6)) * scale
        a -= 2 * scale * np.eye(6)
        assert np.allclose(expm_small(a), expm(a), rtol=1e-10, atol=1e-12 * np.abs(expm(a)).max())


def test_lti_loop_with_a_sine_has_multipliers_exp_lambda_t() -> None:
    a = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-6.0, -11.0, -6.0]])  # poles -1, -2, -3
    a[0, 0] = -0.2  # poles off the integers
    b = np.array([0.0, 0.0, 1.0])
    omega = 2.0
    period = 2 * math.pi / omega

    def f(t, z):
        return a @ z + b * math.sin(omega * t)

    def jac(t, z):
        return a

    orbit = periodic_orbit(f, jac, np.zeros(3), period, settle=2, max_newton=3, newton=True)
    expect = np.sort(np.abs(np.exp(np.linalg.eigvals(a) * period)))[::-1]
    assert np.allclose(np.abs(orbit.multipliers), expect, rtol=1e-4)
    assert orbit.closing < 1e-5
    # the periodic state: the steady response to the sine, z(t0) with (jωI − A) Z = b
    z_ss = np.linalg.solve(1j * omega * np.eye(3) - a, b)
    t0 = orbit.t0
    expect_z = np.imag(z_ss * np.exp(1j * omega * t0))
    assert np.allclose(orbit.z0, expect_z, atol=1e-5)


@pytest.mark.parametrize(("a", "q", "stable"), [(2.5, 0.2, True), (1.0, 0.2, False)])
def test_mathieu_equation_stability(a: float, q: float, stable: bool) -> None:
    def jac(t, z):
        return np.array([[0.0, 1.0], [-(a - 2 * q * math.cos(2 * t)), 0.0]])

    def f(t, z):
        return jac(t, z) @ z

    # the variational equation of a linear system is the system itself: Φ(π) directly
    _, phi = variational_flow(f, jac, np.array([1e-3, 0.0]), 0.0, math.pi, split=4)
    mu = np.linalg.eigvals(phi)
    assert abs(np.prod(mu)) == pytest.approx(1.0, abs=1e-3)  # Liouville: trace 0
    largest = float(np.max(np.abs(mu)))
    assert (largest < 1 + 1e-3) if stable else (largest > 1.05)


def test_mathieu_at_q0_has_unit_multipliers() -> None:
    a = 2.0

    def jac(t, z):
        return np.array([[0.0, 1.0], [-a, 0.0]])

    _, phi = variational_flow(lambda t, z: jac(t, z) @ z, jac, np.array([1.0, 0.0]), 0.0, math.pi)
    mu = np.linalg.eigvals(phi)
    assert np.allclose(np.abs(mu), 1.0, atol=1e-4)
    assert np.allclose(
        np.sort(np.angle(mu)),
        np.sort([-(math.sqrt(a) * math.pi - 2 * math.pi), math.sqrt(a) * math.pi - 2 * math.pi]),
        atol=1e-4,
    )


def test_describing_gain_of_relay_and_of_fal() -> None:
    from aiofl.components.feedback import fal

    h = 0.7
    for amp in (0.01, 1.0, 5.0):
        assert describing_gain(lambda e: h * math.copysign(1.0, e), amp) == pytest.approx(
            4 * h / (math.pi * amp), rel=1e-9
        )
    # fal inside δ is linear: N(A) = δ^(α−1); far outside it tends to the power law's
    # N(A) = (4/π) A^(α−1) ∫ sin^(1+α) θ dθ over [0, π/2]
    alpha, delta = 0.5, 0.01
    assert describing_gain(lambda e: fal(e, alpha, delta), 0.005, (delta,)) == pytest.approx(
        delta ** (alpha - 1), rel=1e-9
    )
    big = 100.0
    power = (
        4
        / math.pi
        * big ** (alpha - 1)
        * math.gamma(1 + alpha / 2)
        * math.sqrt(math.pi)
        / (2 * math.gamma(1.5 + alpha / 2))
    )
    assert describing_gain(lambda e: fal(e, alpha, delta), big, (delta,)) == pytest.approx(
        power, rel=1e-4
    )


def _relay_plant(k: float):
    # G(s) = K / (s (s + 1) (s + 2)), controllable canonical form, y = K x1
    a = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, -2.0, -3.0]])
    b = np.array([0.0, 0.0, 1.0])
    c = np.array([k, 0.0, 0.0])
    return a, b, c


def test_relay_limit_cycle_describing_function_and_simulation() -> None:
    k, h = 3.0, 1.0
    a, b, c = _relay_plant(k)
    g180 = k / 6.0  # |G(j√2)|
    expect_amp = 4 * h * g180 / math.pi

    # harmonic balance on the quasi-linear loop u = −N(A) y
    def quasi(gains):
        return a - gains[0] * np.outer(b, c)

    lam, vec = np.linalg.eig(quasi([0.5 / g180 * 2]))  # an unstable gain: twice critical
    mode = vec[:, int(np.argmax(lam.real))]
    bal = harmonic_balance(
        quasi, np.array([c]), c, [lambda amp: 4 * h / (math.pi * amp)], mode, a_range=(1e-3, 1e2)
    )
    assert bal is not None
    assert bal.amplitude == pytest.approx(expect_amp, rel=1e-6)
    assert bal.frequency == pytest.approx(math.sqrt(2), rel=1e-6)

    # simulation of the relay loop (a smooth relay, h·tanh(y/1e-4), for the integrator)
    eps = 1e-4

    def f(t, z):
        return a @ z - b * h * math.tanh((c @ z) / eps)

    def jac(t, z):
        s = 1.0 - math.tanh((c @ z) / eps) ** 2
        return a - np.outer(b, c) * h * s / eps

    sol = trajectory(f, jac, np.array([0.1, 0.0, 0.0]), 0.0, 60.0, scale=np.ones(3), rtol=1e-7)
    ts = np.linspace(40.0, 60.0, 8001)
    osc = measure_oscillation(ts, c @ sol.sol(ts))
    # the DF is a first-harmonic approximation: within a few per cent for this plant
    assert osc.amplitude == pytest.approx(expect_amp, rel=0.08)
    assert osc.frequency == pytest.approx(math.sqrt(2), rel=0.08)


@pytest.mark.slow
def test_frontier_s1_leso_reconciled_verdict() -> None:
    from aiofl.analysis.orbit import orbit_analysis
    from aiofl.config import load_config

    cfg = load_config("frontier-s1-leso")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        info = orbit_analysis(cfg, unit="rad", quick=True)
    assert info["equilibrium"] == "unstable" and info["max_real"] > 0
    df = info["limit_cycle"]["describing"]  # quick: the describing-function estimate
    assert 3e-6 < df["amplitude_y"] < 3e-5 and 60 < df["frequency"] < 85
    # the simulation with r held, started on the predicted cycle: it stays there
    from aiofl.analysis.linearize import linearize_closed_loop
    from aiofl.analysis.orbit import _loop, equilibrium_limit_cycle

    lin = linearize_closed_loop(cfg)
    lc = equilibrium_limit_cycle(
        _loop(cfg), lin.z_op, lin.a, max_chunks=2, start_amplitude=df["amplitude_y"]
    )
    assert lc["bounded"]
    assert lc["amplitude_y"] == pytest.approx(df["amplitude_y"], rel=0.3)
    assert lc["frequency"] == pytest.approx(df["frequency"], rel=0.05)
    assert 0.003 < lc["amplitude_u"] < 0.03
    fl = info["floquet"]
    assert fl["largest"] < 1 and max(fl["range"]) < 1
    text = info["verdict"]
    assert text.startswith("equilibrium unstable")
    assert "limit cycle of" in text and "tracking orbit stable" in text
    assert info["short"].startswith("tracking stable (μ = ")


def test_cli_json_carries_the_reconciled_verdict() -> None:
    import json

    from typer.testing import CliRunner

    from aiofl.cli.app import app

    res = CliRunner().invoke(app, ["analyze", "frontier-s1-ladrc", "--closed-loop", "--json"])
    assert res.exit_code == 0, res.output
    info = json.loads(res.stdout)
    orbit = info["orbit"]
    assert orbit["equilibrium"] == info["verdict"] == "stable"
    assert orbit["limit_cycle"] is None and orbit["ftle"] is None
    assert orbit["floquet"]["largest"] < 1e-6  # a fast linear loop: e^{λT}, λ ≈ −28.6
    assert info["reconciled_verdict"] == orbit["verdict"]
    assert (
        orbit["verdict"].startswith("equilibrium stable")
        and "tracking orbit stable" in (orbit["verdict"])
    )


def test_a_diverging_run_has_no_periodic_orbit() -> None:
    from aiofl.analysis.variational import OrbitDiverges

    a = np.array([[1.0]])  # grows e^{2π} ≈ 535-fold per period
    with pytest.raises(OrbitDiverges):
        periodic_orbit(
            lambda t, z: a @ z + math.sin(t), lambda t, z: a, np.array([1.0]), 2 * math.pi
        )


def test_finite_time_lyapunov_of_a_linear_system_is_its_eigenvalues() -> None:
    from aiofl.analysis.variational import finite_time_lyapunov

    a = np.array([[-1.0, 5.0], [0.0, -3.0]])  # non-normal: transient growth, exponents −1, −3
    exps = finite_time_lyapunov(
        lambda t, z: a @ z, lambda t, z: a, np.array([1.0, 1.0]), 0.0, 20.0, renorm=1.0
    )
    assert exps == pytest.approx([-1.0, -3.0], abs=0.05)


def test_an_orbit_that_does_not_settle_across_1_is_not_determined() -> None:
    """The tracking orbit's word comes from the multipliers only when they decide: an orbit
    that did not close and whose largest multiplier went from below 1 to above it over the
    periods analysed (retuned-s1-inleso's quick analysis: 0.9–3.8, closing to 7.5 %) is
    "not determined", in the sentence, the short label, the metrics' ``tracking_orbit`` and
    the reconciliation with the run (which then still starts with the equilibrium); one
    that closes, or stays on one side of 1, keeps its word."""
    from aiofl.analysis.orbit import NOT_DETERMINED, floquet_word, reconciled_text
    from aiofl.reporting.behaviour import Behaviour, orbit_numbers, orbit_stable, reconcile

    def floquet(largest: float, rng: tuple[float, float], closing: float) -> dict:
        return {"largest": largest, "range": list(rng), "closing": closing, "passes": 2}

    unsettled = floquet(0.9, (0.9, 3.8), 0.075)
    assert floquet_word(unsettled) == NOT_DETERMINED
    assert floquet_word(floquet(0.9, (0.9, 3.8), 1e-4)) == "stable"  # it closed
    assert floquet_word(floquet(0.48, (0.46, 0.48), 0.044)) == "stable"  # below 1 throughout
    assert floquet_word(floquet(30.0, (30.0, 48.0), 0.21)) == "unstable"  # above throughout
    assert floquet_word(floquet(0.73, (0.73, 1.0), 1.7)) == NOT_DETERMINED  # reaches 1
    info = {"equilibrium": "unstable", "max_real": 16.3, "floquet": unsettled}
    text, short = reconciled_text(info, "rad")
    assert "tracking orbit not determined" in text and "0.9–3.8" in text
    assert "orbit stable" not in text and "orbit unstable" not in text
    assert short.startswith("tracking not determined (μ 0.9–3.8)")
    verdict = {"verdict": "unstable", "orbit": {**info, "verdict": text, "short": short}}
    assert orbit_numbers(verdict)["tracking_orbit"] == NOT_DETERMINED
    assert orbit_stable(verdict) is None
    run = Behaviour("tracks", 5.0, None, 0.004, 0.004, 6e-5, 0.79, 1.06)
    sentence = reconcile(verdict, run, "rad")
    assert sentence.startswith("Equilibrium unstable") and "decides neither way" in sentence
