"""Discretisations of the dynamic components (aiofl.components.discrete): the ZOH current
observer and forward-Euler ESOs (observer poles), the ZOH of the chain and of the linear
prefilter (exact at the samples), Han's fhan TD (finite-time, no chattering), and the
engine's discrete controller applying Euler to eqs. (18) and (21)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aiofl.components import discrete as D
from aiofl.components.differentiators import han_td_rhs, improved_td_rhs
from aiofl.components.observers import binomial_alphas, eso_gains
from aiofl.config import load_config
from aiofl.controller import Controller
from aiofl.discrete_controller import DiscreteController
from aiofl.engine.discrete_rows import Sampling

PAPER_LESO_ALPHAS = [8.772, 0.1946, 0.7384, 0.0096881, 2.2651e-06]  # printed, distinct roots


def _scaled(m: np.ndarray, ts: float) -> np.ndarray:
    """The error map in the coordinates ξ̃_i = Ts^(i-1) ξ_i (entries of order 1)."""
    s = np.diag(ts ** np.arange(m.shape[0]))
    return s @ m @ np.linalg.inv(s)


def _assert_charpoly_is_power(m: np.ndarray, z: float, atol: float = 1e-9) -> None:
    """char poly of m is (λ - z)^n: the coefficients, and Cayley–Hamilton (m - zI)^n = 0
    (relative to ‖m - zI‖^n, the scale of its rounding errors)."""
    n = m.shape[0]
    np.testing.assert_allclose(np.poly(m), np.poly(np.full(n, z)), rtol=0, atol=atol)
    shifted = m - z * np.eye(n)
    nil = np.linalg.matrix_power(shifted, n)
    assert np.max(np.abs(nil)) < 1e-13 * max(1.0, np.linalg.norm(shifted, 2)) ** n


# ----------------------------------------------------------------------------- the ESO
@pytest.mark.parametrize("rho", range(1, 9))
@pytest.mark.parametrize("w0ts", [1e-4, 0.05, 0.5, 3.0])
def test_zoh_observer_poles_are_exp_minus_omega0_ts(rho, w0ts):
    """With Gao's gains every eigenvalue of the ZOH current observer's error map is
    e^{-ω0 Ts} (ρ+1 times), at any ω0·Ts."""
    ts = 1e-3
    eso = D.eso_current_observer(rho, binomial_alphas(rho), w0ts / ts, 3.0, ts)
    _assert_charpoly_is_power(_scaled(eso.error_map(), ts), math.exp(-w0ts))


@pytest.mark.parametrize("w0ts", [1e-5, 1e-2, 0.3, 2.0])
def test_zoh_observer_gain_equals_miklosovic_closed_forms(w0ts):
    """ρ = 1, 2: L = [1-β², (1-β)²/T] and [1-β³, 3(1-β)²(1+β)/(2T), (1-β)³/T²] with
    β = e^{-ω0 T} (Miklosovic, Radke & Gao 2006; Herbst 2013), to rounding even when
    1 - β is tiny."""
    ts = 2e-4
    b = math.exp(-w0ts)
    om = -math.expm1(-w0ts)  # 1 - β without cancellation
    l1 = D.eso_current_observer(1, binomial_alphas(1), w0ts / ts, 1.0, ts).l
    np.testing.assert_allclose(l1, [-math.expm1(-2 * w0ts), om**2 / ts], rtol=1e-12)
    l2 = D.eso_current_observer(2, binomial_alphas(2), w0ts / ts, 1.0, ts).l
    expect = [-math.expm1(-3 * w0ts), 1.5 * om**2 * (1 + b) / ts, om**3 / ts**2]
    np.testing.assert_allclose(l2, expect, rtol=1e-12)


@pytest.mark.parametrize("rho", range(1, 9))
def test_euler_observer_poles_are_one_minus_omega0_ts(rho):
    ts, w0 = 1e-3, 300.0
    eso = D.eso_forward_euler(rho, eso_gains(w0, binomial_alphas(rho)), 2.0, ts)
    _assert_charpoly_is_power(_scaled(eso.error_map(), ts), 1.0 - w0 * ts)


def test_distinct_poles_map_as_exp_and_as_one_plus_ts_s():
    """Non-binomial gains (the paper's printed LESO set): the ZOH observer's poles are
    e^{s_i Ts}, the Euler observer's 1 + Ts s_i, s_i the continuous poles."""
    rho, w0, ts = 4, 513.8283, 1e-4
    s = np.sort_complex(D.eso_continuous_poles(PAPER_LESO_ALPHAS, w0))
    betas = eso_gains(w0, PAPER_LESO_ALPHAS)
    cont = np.sort_complex(np.linalg.eigvals(np.eye(rho + 1, k=1) - np.outer(betas, np.eye(1, 5))))
    np.testing.assert_allclose(s, cont, rtol=1e-8)
    zoh = D.eso_current_observer(rho, PAPER_LESO_ALPHAS, w0, 1.0, ts)
    eig = np.sort_complex(np.linalg.eigvals(_scaled(zoh.error_map(), ts)))
    np.testing.assert_allclose(eig, np.sort_complex(np.exp(s * ts)), rtol=1e-8)
    eul = D.eso_forward_euler(rho, betas, 1.0, ts)
    eig = np.sort_complex(np.linalg.eigvals(_scaled(eul.error_map(), ts)))
    np.testing.assert_allclose(eig, np.sort_complex(1 + ts * s), rtol=1e-8)


@pytest.mark.parametrize("rho", [1, 3, 8])
def test_zoh_of_the_chain_is_its_exact_solution(rho):
    """Φ_ij = T^(j-i)/(j-i)!, Γ_i = b0 T^(ρ-i+1)/(ρ-i+1)! (the chain driven by a held u)."""
    ts, b0 = 3e-3, 7.0
    phi, gam = D.eso_zoh(rho, b0, ts)
    n = rho + 1
    exact = np.array(
        [
            [ts ** (j - i) / math.factorial(j - i) if j >= i else 0.0 for j in range(n)]
            for i in range(n)
        ]
    )
    np.testing.assert_allclose(phi, exact, rtol=1e-13, atol=0)
    g = [b0 * ts ** (rho - i) / math.factorial(rho - i) for i in range(rho)] + [0.0]
    np.testing.assert_allclose(gam, g, rtol=1e-13, atol=0)


def test_euler_eso_coefficients():
    ts, b0, w0 = 1e-3, 5.0, 40.0
    betas = eso_gains(w0, binomial_alphas(2))
    eso = D.eso_forward_euler(2, betas, b0, ts)
    np.testing.assert_array_equal(eso.phi, np.eye(3) + ts * np.eye(3, k=1))
    np.testing.assert_array_equal(eso.gamma, [0.0, ts * b0, 0.0])
    np.testing.assert_array_equal(eso.k, ts * betas)
    np.testing.assert_array_equal(eso.l, np.zeros(3))


# ------------------------------------------------------------------- the prefilter
@pytest.mark.parametrize("rho", [1, 2, 4])
def test_prefilter_zoh_is_exact_at_the_samples(rho):
    """For a held r the ZOH prefilter lands on the continuous step response
    r_1(t) = 1 - e^{-ωt} Σ_{j<ρ} (ωt)^j/j! at every sample; its poles are e^{-ωTs}."""
    omega, ts = 20.0, 1e-2
    phi, gam = D.linear_prefilter_zoh(rho, omega, ts)
    state = np.zeros(rho)
    for k in range(1, 60):
        state = phi @ state + gam * 1.0
        wt = omega * k * ts
        expect = 1 - math.exp(-wt) * sum(wt**j / math.factorial(j) for j in range(rho))
        assert state[0] == pytest.approx(expect, abs=1e-13)
    _assert_charpoly_is_power(phi, math.exp(-omega * ts), atol=1e-12)


# ------------------------------------------------------------------------ fhan and TDs
def _fsg(x: float, d: float) -> float:
    return (np.sign(x + d) - np.sign(x - d)) / 2


def _fhan_han2009(x1: float, x2: float, r: float, h: float) -> float:
    """fhan as printed branch-free in Han (2009)."""
    d = r * h * h
    a0 = h * x2
    y = x1 + a0
    a1 = math.sqrt(d * (d + 8 * abs(y)))
    a2 = a0 + np.sign(y) * (a1 - d) / 2
    a = (a0 + y) * _fsg(y, d) + a2 * (1 - _fsg(y, d))
    return -r * (a / d) * _fsg(a, d) - r * np.sign(a) * (1 - _fsg(a, d))


@settings(max_examples=300, deadline=None)
@given(
    x1=st.floats(-10, 10),
    x2=st.floats(-50, 50),
    r=st.floats(1.0, 1e4),
    h=st.floats(1e-4, 1e-1),
)
def test_fhan_equals_the_branch_free_form_of_han_2009(x1, x2, r, h):
    got = D.fhan(x1, x2, r, h)
    assert abs(got) <= r * (1 + 1e-12)
    assert got == pytest.approx(_fhan_han2009(x1, x2, r, h), rel=1e-9, abs=1e-9 * r)


@pytest.mark.parametrize("v", [1.0, 0.3, -2.7])
def test_fhan_td_reaches_a_constant_in_minimum_time_and_stays(v):
    """Han's discrete TD moves r_1 to a constant v in about the minimum time 2√(|v|/R) of
    a double integrator with |acceleration| ≤ R and then stays there exactly (no
    chattering); forward Euler on eq. (18) chatters with |r_2| of order R·Ts."""
    big_r, ts = 100.0, 0.01
    r1 = r2 = 0.0
    e1 = e2 = 0.0
    hist, euler = [], []
    for _ in range(400):
        r1, r2 = D.fhan_td_step(r1, r2, v, big_r, ts, ts)
        d1, d2 = han_td_rhs(e1, e2, v, big_r)
        e1, e2 = e1 + ts * d1, e2 + ts * d2
        hist.append((r1, r2))
        euler.append((e1, e2))
    h = np.array(hist)
    arrived = int(np.argmax(np.abs(h[:, 0] - v) < 1e-12))
    t_min = 2 * math.sqrt(abs(v) / big_r)
    assert arrived * ts <= t_min + 2 * ts
    assert np.max(np.abs(h[arrived:, 0] - v)) < 1e-12
    assert np.max(np.abs(h[arrived:, 1])) < 1e-10
    tail = np.array(euler)[-100:]
    assert np.max(np.abs(tail[:, 1])) > 0.5 * big_r * ts


def _paper_inleso_like() -> Controller:
    return load_config("retuned-s1-inleso").controller


@pytest.mark.parametrize("td", ["han-fhan", "han-euler", "improved", "linear"])
def test_discrete_controller_differentiators(td):
    """The engine's discrete controller advances its differentiator by fhan, Euler on
    (18), Euler on (21) or the prefilter's ZOH, sample by sample."""
    ts = 2e-3
    if td.startswith("han"):
        ctrl = load_config("retuned-s1-leso").controller
        samp = Sampling(ts, td=td.split("-")[1])
    elif td == "improved":
        ctrl = _paper_inleso_like()
        samp = Sampling(ts)
    else:
        ctrl = load_config("retuned-s1-ladrc").controller
        samp = Sampling(ts)
    dc = DiscreteController(ctrl, samp)
    dc.init(0.0)
    c = ctrl.value
    s = np.zeros(ctrl.rho)
    pf = D.linear_prefilter_zoh(ctrl.rho, c("td.omega"), ts)
    for k in range(50):
        r = math.sin(2 * k * ts) * 0.7
        dc.step(r, 0.01 * k)
        if td == "han-fhan":
            s[0], s[1] = D.fhan_td_step(s[0], s[1], r, c("td.R"), ts, ts)
        elif td == "han-euler":
            d = han_td_rhs(s[0], s[1], r, c("td.R"))
            s[:2] = s[:2] + ts * np.array(d)
        elif td == "improved":
            d = improved_td_rhs(s[0], s[1], r, c("td.a"), c("td.b"), c("td.c"), c("td.rho"))
            s[:2] = s[:2] + ts * np.array(d)
        else:
            s = pf[0] @ s + pf[1] * r
        n = 2 if td != "linear" else ctrl.rho
        scale = 1e-12 * max(1.0, float(np.max(np.abs(s[:n]))))
        np.testing.assert_allclose(dc.differentiator[:n], s[:n], rtol=1e-12, atol=scale)
