"""The paper's components as functions: ESO poles, fal, TDs, SEFs, laws.

Each test checks an analytic property that a wrong implementation would break; the
differentiators are also run through the engine (the time-domain facts of eq. 18/21 and
of the linear prefilter).
"""

from __future__ import annotations

import math
from math import comb, factorial

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from aiofl.components.differentiators import (
    han_td_rhs,
    improved_td_rhs,
    itd_steady_state,
    linear_prefilter_coefficients,
    linear_prefilter_rhs,
)
from aiofl.components.fastmath import abspow, fast_tanh
from aiofl.components.feedback import fal, improved_sef, linear_sef_gains, nonlinear_sef
from aiofl.components.law import aiofl_law, iofl_law, saturate
from aiofl.components.observers import (
    binomial_alphas,
    eso_error_matrix,
    eso_gains,
    eso_rhs,
    inleso_injection,
)
from aiofl.controller import Controller
from aiofl.engine.simulation import simulate
from aiofl.plants import get_plant
from aiofl.scenario import Reference, Scenario

rhos = st.integers(min_value=1, max_value=8)
pos = st.floats(min_value=0.05, max_value=20.0)


# ------------------------------------------------------------------------------ ESO
def _normalised_coefficients(coeffs: np.ndarray) -> np.ndarray:
    """Coefficients c_k of a monic polynomial scaled to c_k / R^k (R ~ root magnitude),
    so that comparing polynomials is well conditioned whatever the gains' scale."""
    big_r = 1.0 + max(abs(c) ** (1.0 / k) for k, c in enumerate(coeffs[1:], 1))
    return np.array([c / big_r**k for k, c in enumerate(coeffs)])


@settings(max_examples=60, deadline=None)
@given(rho=rhos, omega0=st.floats(0.5, 5.0), data=st.data())
def test_eso_error_poles_are_the_roots_of_the_gain_polynomial(rho, omega0, data):
    """eig(A_e) are the roots of s^(ρ+1) + β1 s^ρ + ... + β_(ρ+1) (eq. 9 and its text)."""
    alphas = np.array(data.draw(st.lists(pos, min_size=rho + 1, max_size=rho + 1)))
    betas = eso_gains(omega0, alphas)
    np.testing.assert_allclose(betas, alphas * omega0 ** np.arange(1, rho + 2), rtol=1e-14)
    a_e = eso_error_matrix(betas)
    eig = np.linalg.eigvals(a_e)
    # the characteristic polynomial rebuilt from the eigenvalues is the gain polynomial
    from_eig = np.real(np.poly(eig))
    target = np.concatenate([[1.0], betas])
    np.testing.assert_allclose(
        _normalised_coefficients(from_eig), _normalised_coefficients(target), atol=1e-9
    )
    # and each eigenvalue is a root of it (normalised residual)
    roots = np.roots(target)
    scale = max(1.0, np.max(np.abs(roots)))
    for lam in eig:
        terms = np.abs(target) * np.abs(lam) ** np.arange(rho + 1, -1, -1)
        assert abs(np.polyval(target, lam)) <= 1e-9 * terms.sum() + 1e-300
    assert np.max(np.abs(np.sort_complex(eig))) <= 1.01 * scale


@settings(max_examples=40, deadline=None)
@given(rho=rhos, data=st.data())
def test_eso_poles_equal_np_roots_for_separated_roots(rho, data):
    """With well-separated poles, sorted eig(A_e) equal sorted np.roots, one by one."""
    base = np.array(
        data.draw(
            st.lists(st.floats(0.5, 3.0), min_size=rho + 1, max_size=rho + 1, unique=True).filter(
                lambda v: min(np.diff(np.sort(v)), default=1.0) > 0.2
            )
        )
    )
    poles = -np.cumsum(base)  # distinct, negative, at least 0.2 apart
    betas = np.real(np.poly(poles))[1:]
    eig = np.sort(np.real(np.linalg.eigvals(eso_error_matrix(betas))))
    roots = np.sort(np.real(np.roots(np.concatenate([[1.0], betas]))))
    np.testing.assert_allclose(eig, roots, rtol=1e-6)
    np.testing.assert_allclose(eig, np.sort(poles), rtol=1e-6)


@pytest.mark.parametrize("rho", range(1, 9))
def test_binomial_alphas_put_every_observer_pole_at_minus_omega0(rho):
    """Gao's α_i = C(ρ+1, i) give (s + ω0)^(ρ+1)."""
    omega0 = 3.0
    alphas = binomial_alphas(rho)
    assert alphas.tolist() == [comb(rho + 1, i) for i in range(1, rho + 2)]
    a_e = eso_error_matrix(eso_gains(omega0, alphas))
    eig = np.linalg.eigvals(a_e)
    np.testing.assert_allclose(np.real(np.poly(eig)), np.poly(np.full(rho + 1, -omega0)), rtol=1e-9)
    # a defective eigenvalue of multiplicity k is computed to about eps^(1/k)
    assert np.max(np.abs(eig + omega0)) < 0.05 * omega0


def test_printed_scenario1_leso_gains_have_right_half_plane_poles():
    """A fact about the paper's printed LESO set (Section V), not about this code: its
    error polynomial has roots with positive real part, so the LESO is unstable on its own.
    """
    alphas = [8.772, 0.1946, 0.7384, 9.6881e-3, 2.2651e-6]
    roots = np.roots(np.concatenate([[1.0], eso_gains(513.8283, alphas)]))
    assert np.max(roots.real) > 0.0


def test_eso_rhs_is_eq5():
    """ξ̂'_i = ξ̂_(i+1) + β_i e, ξ̂'_ρ gets + b0 u, ξ̂'_(ρ+1) = β_(ρ+1) e, e = y - ξ̂_1."""
    rng = np.random.default_rng(1)
    rho = 4
    xi = rng.normal(size=rho + 1)
    betas = rng.uniform(1, 5, rho + 1)
    b0, y, u = 2.5, 0.3, -1.2
    out = np.zeros(rho + 1)
    eso_rhs(xi, out, rho, betas, b0, y, u, False, 1.0, 0.0, 1.0, 0.0)
    e = y - xi[0]
    expected = np.array([xi[1], xi[2], xi[3], xi[4] + b0 * u, 0.0]) + betas * e
    np.testing.assert_allclose(out, expected, rtol=1e-14)
    # the improved ESO replaces e by g(e) (eq. 19)
    eso_rhs(xi, out, rho, betas, b0, y, u, True, 0.7, 0.2, 0.5, 0.3)
    g = 0.7 * abs(e) ** 0.5 * np.sign(e) + 0.2 * abs(e) ** 0.3 * e
    expected = np.array([xi[1], xi[2], xi[3], xi[4] + b0 * u, 0.0]) + betas * g
    np.testing.assert_allclose(out, expected, rtol=1e-13)


@settings(max_examples=100, deadline=None)
@given(
    e=st.floats(-50, 50),
    ka=st.floats(0, 5),
    kb=st.floats(0, 5),
    a=st.floats(0.05, 2),
    b=st.floats(0, 2),
)
def test_inleso_injection_is_odd_and_eq19(e, ka, kb, a, b):
    g = inleso_injection(e, ka, kb, a, b)
    assert g == pytest.approx(ka * abs(e) ** a * np.sign(e) + kb * abs(e) ** b * e, rel=1e-12)
    assert inleso_injection(-e, ka, kb, a, b) == pytest.approx(-g, rel=1e-14, abs=1e-300)


# ------------------------------------------------------------------------------ fal
@settings(max_examples=200, deadline=None)
@given(alpha=st.floats(0.05, 2.0), delta=st.floats(1e-3, 50.0), frac=st.floats(0.0, 1.0))
def test_fal_is_continuous_at_delta_odd_and_linear_inside(alpha, delta, frac):
    """fal (17), corrected form: e·δ^(α-1) for |e| ≤ δ, |e|^α sign(e) beyond."""
    edge = delta**alpha
    for side in (1.0, -1.0):
        assert fal(side * delta, alpha, delta) == pytest.approx(side * edge, rel=1e-12)
        for eps in (1e-9, 1e-7):
            above = fal(side * delta * (1 + eps), alpha, delta)
            below = fal(side * delta * (1 - eps), alpha, delta)
            assert above == pytest.approx(side * edge, rel=10 * eps)
            assert below == pytest.approx(side * edge, rel=10 * eps)
    e = frac * delta
    assert fal(e, alpha, delta) == pytest.approx(e * delta ** (alpha - 1.0), rel=1e-12, abs=0)
    assert fal(-e, alpha, delta) == -fal(e, alpha, delta)
    outside = delta * (1.0 + 3.0 * frac) + 1e-6
    assert fal(outside, alpha, delta) == pytest.approx(outside**alpha, rel=1e-12)
    assert fal(-outside, alpha, delta) == pytest.approx(-(outside**alpha), rel=1e-12)


def test_fal_printed_form_would_be_discontinuous():
    """The printed inner branch e/δ^(α-1) jumps at e = δ (the erratum fal corrects)."""
    alpha, delta = 0.5, 4.0
    printed_inside = delta / delta ** (alpha - 1.0)
    assert abs(printed_inside - delta**alpha) > 1.0
    assert fal(delta, alpha, delta) == pytest.approx(delta**alpha)


# ------------------------------------------------------------------------------ SEF
def test_nonlinear_sef_sums_fal_terms():
    e = np.array([0.3, -20.0, 1.5])
    k = np.array([2.0, 0.5, 1.0])
    alpha = np.array([0.4, 0.6, 1.2])
    delta = np.array([1.0, 5.0, 0.1])
    expected = sum(k[i] * fal(e[i], alpha[i], delta[i]) for i in range(3))
    assert nonlinear_sef(e, 3, k, alpha, delta) == pytest.approx(expected, rel=1e-14)
    assert nonlinear_sef(e, 1, k, alpha, delta) == pytest.approx(2.0 * 0.3, rel=1e-14)


@example(e1=0.1, e2=-2.956247882615261, v_limit=1.0, mu=0.1)  # the terms cancel
@settings(max_examples=100, deadline=None)
@given(
    e1=st.floats(-5, 5),
    e2=st.floats(-5, 5),
    v_limit=st.floats(0.1, 10),
    mu=st.floats(0, 20),
)
def test_improved_sef_is_eq20_bounded_and_odd(e1, e2, v_limit, mu):
    e = np.array([e1, e2])
    k1 = np.array([1.7741, 0.00115])
    k2 = np.array([1.2147, 0.3312])
    mus = np.array([mu, 2.0 * mu])
    alpha = np.array([0.8244, 1.8079])
    v = improved_sef(e, 2, k1, k2, mus, alpha, v_limit)
    terms = [
        (k1[i] + k2[i] / (1.0 + math.exp(min(mus[i] * e[i] ** 2, 700.0))))
        * abs(e[i]) ** alpha[i]
        * np.sign(e[i])
        for i in range(2)
    ]
    total = sum(terms)
    # rounding is relative to the terms, not to their sum: e1 = 0.1, e2 = -2.956 (mu = 0.1)
    # cancel to 7.3e-6, where the compiled and this Python sum differ by 1e-17
    scale = sum(abs(x) for x in terms)
    assert v == pytest.approx(
        v_limit * math.tanh(total / v_limit), rel=1e-12, abs=1e-13 * scale + 1e-300
    )
    assert abs(v) <= v_limit
    assert improved_sef(-e, 2, k1, k2, mus, alpha, v_limit) == pytest.approx(-v, abs=1e-15)


@pytest.mark.parametrize("rho", range(1, 9))
def test_linear_gains_place_poles_at_minus_omega(rho):
    """k_i = C(ρ, i-1) ω^(ρ-i+1): s^ρ + k_ρ s^(ρ-1) + ... + k_1 = (s + ω)^ρ."""
    omega = 2.5
    k = linear_sef_gains(rho, omega)
    poly = np.concatenate([[1.0], k[::-1]])
    np.testing.assert_allclose(poly, np.poly(np.full(rho, -omega)), rtol=1e-12)
    np.testing.assert_allclose(linear_prefilter_coefficients(rho, omega), k, rtol=1e-14)


# ------------------------------------------------------------------------------ laws
@settings(max_examples=50, deadline=None)
@given(v=st.floats(-1e3, 1e3), xi=st.floats(-1e3, 1e3), b0=st.floats(0.1, 1e4))
def test_aiofl_law_cancels_the_estimated_disturbance(v, xi, b0):
    """u = v - ξ̂_(ρ+1)/b0 (14), so that ξ̂_(ρ+1) + b0 u = b0 v."""
    u = aiofl_law(v, xi, b0)
    assert u == v - xi / b0
    assert xi + b0 * u == pytest.approx(b0 * v, rel=1e-9, abs=1e-9 * (abs(xi) + 1))


def test_iofl_law_and_saturation():
    assert iofl_law(3.0, 1.0, 4.0) == pytest.approx((-1.0 + 3.0) / 4.0)
    assert saturate(5.0, 2.0) == 2.0
    assert saturate(-5.0, 2.0) == -2.0
    assert saturate(1.5, 2.0) == 1.5
    assert saturate(1e300, math.inf) == 1e300
    assert math.isnan(saturate(math.nan, 1.0))


# ------------------------------------------------------------------------ TD formulas
def test_han_td_switching_curve_uses_2R():
    """(18) corrected: on the curve r1 - r = -r2|r2|/(2R) the switching function is 0, and
    the bang-bang law is -R·sign(r1 - r + r2|r2|/(2R))."""
    big_r = 32.0
    r2 = 4.0
    r1 = 1.0 - r2 * abs(r2) / (2 * big_r)  # 0.75, exact in binary
    assert han_td_rhs(r1, r2, 1.0, big_r) == (r2, 0.0)
    assert han_td_rhs(r1 + 1e-6, r2, 1.0, big_r) == (r2, -big_r)
    assert han_td_rhs(r1 - 1e-6, r2, 1.0, big_r) == (r2, big_r)


@settings(max_examples=50, deadline=None)
@given(
    a=st.floats(0.01, 0.99),
    b=st.floats(0.1, 10),
    c=st.floats(0.01, 2),
    rho=st.floats(0.5, 50),
    r=st.floats(-2, 2),
)
def test_itd_equilibrium_is_one_minus_a_r_over_b(a, b, c, rho, r):
    """(21): ṙ1 = ṙ2 = 0 exactly at r1 = (1-a) r/b, r2 = 0."""
    r1 = itd_steady_state(r, a, b)
    assert r1 == pytest.approx((1 - a) * r / b)
    d1, d2 = improved_td_rhs(r1, 0.0, r, a, b, c, rho)
    assert d1 == 0.0
    assert abs(d2) <= 1e-12 * rho * rho


def test_linear_prefilter_rhs_is_the_companion_form_of_the_filter():
    """ω^ρ/(s+ω)^ρ: at rest at r1 = r its derivative is 0; its state matrix has all poles
    at -ω; the returned value is r1^(ρ)."""
    rho, omega = 4, 3.0
    st0 = np.array([0.7, 0.0, 0.0, 0.0])
    d = np.zeros(rho)
    top = linear_prefilter_rhs(st0, d, rho, 0.7, omega)
    np.testing.assert_allclose(d, 0.0, atol=1e-12)
    assert top == d[-1]
    a_mat = np.zeros((rho, rho))
    for j in range(rho):
        e = np.zeros(rho)
        e[j] = 1.0
        linear_prefilter_rhs(e, d, rho, 0.0, omega)
        a_mat[:, j] = d
    np.testing.assert_allclose(np.real(np.poly(np.linalg.eigvals(a_mat))), np.poly([-omega] * rho))


# --------------------------------------------------------- TDs in the engine, on a step
def _open_loop(td: str, **values: float) -> Controller:
    """A controller whose plant input is negligible (b0 huge): only the TD matters."""
    vals = {"law.b0": 1e15, "eso.omega0": 5.0, **values}
    return Controller(eso="linear", td=td, sef="linear", rho=4, n_feedback=2, values=vals)


def _step(t_final: float, amplitude: float = 1.0) -> Scenario:
    return Scenario(t_final=t_final, reference=Reference(kind="step", amplitude=amplitude))


def test_han_td_reaches_a_step_in_minimum_time_without_overshoot():
    """Han's TD is the time-optimal double integrator with |r̈1| ≤ R: from rest it reaches a
    step A in 2·sqrt(A/R), with no overshoot (the 2R form; /(2r) would not be optimal)."""
    big_r, amp = 100.0, 1.0
    res = simulate(
        get_plant("slfjm"),
        _open_loop("han", **{"td.R": big_r}),
        _step(0.5, amp),
        dt=1e-4,
        decimation=1,
    )
    t, r1, r2 = res.t, res["r1"], res["r2"]
    t_opt = 2.0 * math.sqrt(amp / big_r)
    assert np.max(r1) <= amp * (1 + 2e-3)
    after = t >= t_opt + 0.02
    assert np.max(np.abs(r1[after] - amp)) < 2e-3
    assert np.max(np.abs(r2[after])) < big_r * 1e-4 * 3  # chattering of order R·dt
    # at half the optimal time it is at the switching point: r1 = A/2, r2 = sqrt(A R)
    k = np.searchsorted(t, t_opt / 2)
    assert r1[k] == pytest.approx(amp / 2, rel=0.01)
    assert r2[k] == pytest.approx(math.sqrt(amp * big_r), rel=0.01)


def test_linear_prefilter_step_response_is_the_erlang_formula():
    """ω^ρ/(s+ω)^ρ step response: r1 = 1 - e^(-ωt) Σ_{k<ρ} (ωt)^k/k!, and its derivative."""
    omega, rho = 8.0, 4
    res = simulate(
        get_plant("slfjm"),
        _open_loop("linear", **{"td.omega": omega}),
        _step(3.0),
        dt=1e-4,
        decimation=50,
    )
    t = res.t
    wt = omega * t
    r1 = 1.0 - np.exp(-wt) * sum(wt**k / factorial(k) for k in range(rho))
    r2 = omega**rho * t ** (rho - 1) * np.exp(-wt) / factorial(rho - 1)
    np.testing.assert_allclose(res["r1"], r1, atol=1e-9)
    np.testing.assert_allclose(res["r2"], r2, atol=1e-8)
    assert res["r1"][-1] == pytest.approx(1.0, abs=1e-6)
    for i in range(2, rho + 1):
        assert abs(res[f"r{i}"][-1]) < 1e-4


@pytest.mark.parametrize(("a", "b"), [(0.5, 2.0), (0.9153, 8.7141)])
def test_itd_settles_at_one_minus_a_r_over_b(a, b):
    """(21) tracks (1-a) r/b, not r (0.0097 r for the paper's printed a, b)."""
    amp = 0.8
    ctrl = _open_loop("improved", **{"td.a": a, "td.b": b, "td.c": 0.0813, "td.rho": 22.89})
    res = simulate(get_plant("slfjm"), ctrl, _step(4.0, amp), dt=1e-4, store=True, decimation=100)
    assert res["r1"][-1] == pytest.approx(itd_steady_state(amp, a, b), rel=1e-6)
    assert abs(res["r2"][-1]) < 1e-6


# ------------------------------------------------------------------ shared fast math
def test_fast_tanh_and_power_agree_with_libm():
    """The cheaper tanh and |x|^a of the components and the engine (aiofl.components.fastmath) agree
    with numpy to 2 ulp / 1e-14."""
    rng = np.random.default_rng(0)
    xs = np.concatenate(
        [
            rng.uniform(-1, 1, 3000),
            rng.uniform(-30, 30, 3000),
            10.0 ** rng.uniform(-300, 0, 1000),
            [0.0, -0.0, 0.625, -0.625, 20.0, 1e308],
        ]
    )
    got = np.array([fast_tanh(float(x)) for x in xs])
    want = np.tanh(xs)
    ulp = np.spacing(np.maximum(np.abs(want), np.finfo(float).tiny))
    assert np.max(np.abs(got - want) / ulp) <= 2.0
    assert math.isnan(fast_tanh(math.nan))
    assert fast_tanh(-math.inf) == -1.0
    for a in (0.0, 0.188, 0.69, 1.0, 1.8):
        for x in (0.0, 1e-12, 0.3, 7.0, 1e5):
            lx = math.log(x) if x > 0 else -math.inf
            assert abspow(x, a, lx) == pytest.approx(x**a, rel=1e-14, abs=0.0)
