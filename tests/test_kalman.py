"""Kalman-optimal ESO gains (``[controller.eso] gains = "kalman"``, aiofl.components.kalman).

The continuous gains are checked against python-control's ``lqe`` and the Butterworth
pattern of the filter's poles, the sampled gain against ``dlqe`` and against the error
covariance of long seeded simulations of the observer error, and the config / CLI
plumbing against the refusals it must make.
"""

from __future__ import annotations

import copy
import math
import tomllib
from math import factorial
from pathlib import Path
from typing import Any

import control
import numpy as np
import pytest
from scipy.integrate import quad_vec
from scipy.linalg import expm
from typer.testing import CliRunner

from aiofl import layout as L
from aiofl.cli.app import app
from aiofl.components import kalman as K
from aiofl.config import ConfigError, parse_config, preset_text
from aiofl.controller import Controller, controller_batch
from aiofl.engine.discrete_rows import D_L, Sampling, sampling_rows
from aiofl.scenario import Scenario
from aiofl.tuning.space import used_parameters

runner = CliRunner()
RATIOS = [(1.0, 1.0), (2.5e3, 1e-2), (1e8, 1e-6), (3e-2, 4.0)]


# ------------------------------------------------------------------ continuous gains
@pytest.mark.parametrize("rho", [1, 2, 3, 4])
@pytest.mark.parametrize(("q", "r"), RATIOS)
def test_continuous_gain_is_control_lqe(rho: int, q: float, r: float) -> None:
    a, g, c = K.noise_chain(rho)
    l_ref, p_ref, _ = control.lqe(a, g, c, q, r)
    l, p = K.continuous_kalman_gain(rho, q, r)
    np.testing.assert_allclose(l, np.asarray(l_ref).ravel(), rtol=1e-9)
    np.testing.assert_allclose(p, p_ref, rtol=1e-9)


@pytest.mark.parametrize("rho", [1, 2, 3, 4])
@pytest.mark.parametrize(("q", "r"), RATIOS)
def test_continuous_poles_are_butterworth(rho: int, q: float, r: float) -> None:
    a, _, c = K.noise_chain(rho)
    l, _ = K.continuous_kalman_gain(rho, q, r)
    poles = np.linalg.eigvals(a - np.outer(l, c))
    w = (q / r) ** (1.0 / (2 * rho + 2))
    np.testing.assert_allclose(np.abs(poles), w, rtol=1e-6)
    n = rho + 1
    angles = np.sort(np.angle(poles))
    expected = np.sort(np.angle(np.exp(1j * np.pi * (2 * np.arange(1, n + 1) + n - 1) / (2 * n))))
    np.testing.assert_allclose(angles, expected, atol=1e-6)
    # the α are the normalised Butterworth polynomial's coefficients, for every ratio
    np.testing.assert_allclose(
        K.kalman_alphas(rho), np.real(np.poly(K.butterworth_poles(rho, 1.0)))[1:], rtol=1e-12
    )
    alphas, w0 = K.kalman_gain_parameters(rho, q, r)
    np.testing.assert_allclose(alphas * w0 ** np.arange(1, n + 1), l, rtol=1e-12)


def test_kalman_alphas_are_the_butterworth_coefficients_of_every_order() -> None:
    np.testing.assert_allclose(K.kalman_alphas(1), [math.sqrt(2), 1.0], rtol=1e-13)
    np.testing.assert_allclose(K.kalman_alphas(2), [2.0, 2.0, 1.0], rtol=1e-13)
    for rho in range(1, L.RHO_MAX + 1):
        poly = np.real(np.poly(K.butterworth_poles(rho, 1.0)))[1:]
        np.testing.assert_allclose(K.kalman_alphas(rho), poly, rtol=1e-11)


# ------------------------------------------------------------------ sampled gains
@pytest.mark.parametrize("rho", [1, 4, 8])
@pytest.mark.parametrize("ts", [1e-4, 1e-2, 0.3])
def test_discrete_process_noise_is_the_integral(rho: int, ts: float) -> None:
    q = 7.0
    a, g, _ = K.noise_chain(rho)
    n = rho + 1
    qd = K.discrete_process_noise(rho, q, ts)
    i = np.arange(1, n + 1)[:, None]
    j = np.arange(1, n + 1)[None, :]
    fact = np.vectorize(factorial)
    closed = q * ts ** (2 * n + 1 - i - j) / (fact(n - i) * fact(n - j) * (2 * n + 1 - i - j))
    np.testing.assert_allclose(qd, closed, rtol=1e-12)
    if ts >= 1e-2 and rho <= 4:  # quadrature, unscaled Van Loan: entries not too small
        integral, _ = quad_vec(lambda s: expm(a * s) @ (q * g @ g.T) @ expm(a.T * s), 0.0, ts)
        np.testing.assert_allclose(qd, integral, rtol=1e-8)
        phi, qd_vl = K.van_loan(a, q * g @ g.T, ts)
        np.testing.assert_allclose(phi, expm(a * ts), rtol=1e-13)
        np.testing.assert_allclose(qd_vl, closed, rtol=1e-9)


@pytest.mark.parametrize("rho", [1, 2, 3, 4])
@pytest.mark.parametrize(("w0", "ts"), [(10.0, 1e-3), (200.0, 1e-3), (1500.0, 1e-3), (50.0, 1e-2)])
def test_discrete_gain_is_control_dlqe_current_estimate(rho: int, w0: float, ts: float) -> None:
    r = 1e-6
    q = r * w0 ** (2 * rho + 2)
    r_d = r / ts
    a, _, c = K.noise_chain(rho)
    n = rho + 1
    phi = expm(a * ts)
    qd = K.discrete_process_noise(rho, q, ts)
    # dlqe returns the *predictor* gain Φ M (x_e[n+1] = A x_e + L (y - C x_e)) and the
    # a-priori covariance P
    l_pred, p_ref, e_ref = control.dlqe(phi, np.eye(n), c, qd, r_d)
    m, p = K.discrete_kalman_gain(rho, q, r_d, ts)
    np.testing.assert_allclose(p, p_ref, rtol=1e-6)
    np.testing.assert_allclose(phi @ m, np.asarray(l_pred).ravel(), rtol=1e-6)
    np.testing.assert_allclose(m, p @ c.T.ravel() / (p[0, 0] + r_d), rtol=1e-12)
    # the current observer's error map has dlqe's eigenvalues and is stable
    err = (np.eye(n) - np.outer(m, c)) @ phi
    assert np.max(np.abs(np.linalg.eigvals(err))) < 1.0
    np.testing.assert_allclose(
        np.sort_complex(np.linalg.eigvals(err)), np.sort_complex(e_ref), atol=1e-6
    )


@pytest.mark.parametrize("rho", [1, 2, 4, 6, 8])
@pytest.mark.parametrize("h", [1e-4, 1e-3, 1e-2, 0.1, 1.0, 5.0])
def test_discrete_gain_is_stable_and_tends_to_the_continuous_one(rho: int, h: float) -> None:
    """Over ω0·T = h (R_d = r/T): the error map is stable (checked in the coordinates
    ξ_i/ω0^(i-1), where it is well conditioned), and as h -> 0 the current-observer gain
    per unit time M/T tends to the Kalman-Bucy gain."""
    ts, r = 1e-3, 1e-4
    w0 = h / ts
    q = r * w0 ** (2 * rho + 2)
    n = rho + 1
    m, _ = K.discrete_kalman_gain(rho, q, r / ts, ts)
    a, _, c = K.noise_chain(rho)
    scale = w0 ** np.arange(n, dtype=np.float64)
    err = (np.eye(n) - np.outer(m / scale, c)) @ expm(a * h)
    assert np.max(np.abs(np.linalg.eigvals(err))) < 1.0
    if h <= 1e-2:
        l, _ = K.continuous_kalman_gain(rho, q, r)
        np.testing.assert_allclose(m / ts, l, rtol=5 * rho * h)


def _bandwidth_twin(kal: Controller) -> Controller:
    """The bandwidth-gain controller with ``kal``'s equivalent ω0 and α."""
    rho = kal.rho
    values = {f"eso.alpha{i}": kal.value(f"eso.alpha{i}") for i in range(1, rho + 2)}
    return Controller.from_structure(
        "LADRC", rho=rho, values={"eso.omega0": kal.value("eso.omega0"), **values}
    )


@pytest.mark.parametrize(("rho", "h"), [(4, 0.05), (2, 5.0)])
def test_sampling_rows_carry_the_discrete_kalman_gain(rho: int, h: float) -> None:
    r, ts = 1e-7, 1e-3
    q = r * (h / ts) ** (2 * rho + 2)  # ω0·Ts = h
    kal = Controller.from_structure(
        "LADRC", rho=rho, eso_gains="kalman", values={"eso.q": q, "eso.r": r}
    )
    row = sampling_rows(controller_batch(kal), [Sampling(ts=ts)], 1e-4)[0]
    m, _ = K.discrete_kalman_gain(rho, q, r / ts, ts)
    np.testing.assert_allclose(row[D_L : D_L + rho + 1], m, rtol=1e-12)
    # against the pole-mapped gain of the same Butterworth poles, z = exp(s_i Ts): the
    # same to ~1e-10 for ω0·Ts well below 1, apart for ω0·Ts of a few
    band = _bandwidth_twin(kal)
    row_b = sampling_rows(controller_batch(band), [Sampling(ts=ts)], 1e-4)[0]
    rel = np.max(np.abs(row_b[D_L : D_L + rho + 1] - m) / np.abs(m))
    assert rel < 1e-9 if h < 0.5 else rel > 0.1
    # Euler: the continuous Kalman-Bucy gains, as for any gains
    row_e = sampling_rows(controller_batch(kal), [Sampling(ts=ts, eso="euler")], 1e-4)[0]
    row_be = sampling_rows(controller_batch(band), [Sampling(ts=ts, eso="euler")], 1e-4)[0]
    np.testing.assert_array_equal(row_e, row_be)


# ------------------------------------------------------- error covariance by simulation
def _check_covariance(samples: np.ndarray, p: np.ndarray, k: float = 4.5) -> None:
    """``samples`` (chains, steps, n): each entry of the sample covariance within k
    standard errors of ``p`` (standard errors from the spread of the chains' means)."""
    prods = samples[..., :, None] * samples[..., None, :]  # (chains, steps, n, n)
    per_chain = prods.mean(axis=1)
    mean = per_chain.mean(axis=0)
    se = per_chain.std(axis=0, ddof=1) / math.sqrt(per_chain.shape[0])
    z = np.abs(mean - p) / se
    assert np.all(z < k), (z, mean / p)


@pytest.mark.parametrize("rho", [1, 2, 3])
def test_discrete_error_covariance_matches_the_riccati_solution(rho: int) -> None:
    """Seeded simulation of the sampled Kalman filter's estimation error,
    e_{k+1} = (I - MC)(Φ e_k + w_k) - M v_{k+1}, w ~ N(0, Q_d), v ~ N(0, R_d): its
    covariance is the current-estimate covariance (I - MC)P."""
    ts, r, w0 = 1e-3, 1e-6, 150.0
    q = r * w0 ** (2 * rho + 2)
    r_d = r / ts
    n = rho + 1
    a, _, c = K.noise_chain(rho)
    phi = expm(a * ts)
    m, p = K.discrete_kalman_gain(rho, q, r_d, ts)
    imc = np.eye(n) - np.outer(m, c)
    p_post = imc @ p
    chol = np.linalg.cholesky(K.discrete_process_noise(rho, q, ts))
    rng = np.random.default_rng(20)
    chains, burn, steps = 400, 300, 600  # 2.4e5 samples after burn-in
    e = np.zeros((chains, n))
    out = np.empty((chains, steps, n))
    f = imc @ phi
    for k in range(burn + steps):
        w = rng.standard_normal((chains, n)) @ chol.T
        v = rng.standard_normal(chains) * math.sqrt(r_d)
        e = e @ f.T + w @ imc.T - np.outer(v, m)
        if k >= burn:
            out[:, k - burn] = e
    _check_covariance(out, p_post)


@pytest.mark.parametrize("rho", [1, 2])
def test_continuous_error_covariance_matches_the_riccati_solution(rho: int) -> None:
    """Euler-Maruyama simulation of de = (A - LC)e dt + G dW_q - L dW_r (intensities q, r)
    with ω0·dt = 2e-3: its covariance is the Riccati solution P (to O(ω0 dt))."""
    q, r = 1.0, 1.0  # ω0 = 1
    n = rho + 1
    a, g, c = K.noise_chain(rho)
    l, p = K.continuous_kalman_gain(rho, q, r)
    dt = 2e-3
    f = np.eye(n) + dt * (a - np.outer(l, c))
    rng = np.random.default_rng(7)
    chains, burn, steps, every = 400, 8000, 20000, 20
    e = np.zeros((chains, n))
    out = np.empty((chains, steps // every, n))
    for k in range(burn + steps):
        dw = rng.standard_normal(chains) * math.sqrt(q * dt)
        dv = rng.standard_normal(chains) * math.sqrt(r * dt)
        e = e @ f.T + np.outer(dw, g[:, 0]) - np.outer(dv, l)
        if k >= burn and (k - burn) % every == 0:
            out[:, (k - burn) // every] = e
    _check_covariance(out, p)


# ------------------------------------------------------------------ measurement noise
def test_measurement_noise_intensity() -> None:
    scen = Scenario(t_final=1.0, noise_variance=1e-4, noise_hold=1e-3)
    assert K.measurement_noise_intensity(scen) == pytest.approx(1e-7, rel=1e-15)
    s = Sampling(ts=1e-3, y_quantum=1e-3)
    assert K.measurement_noise_intensity(scen, s) == pytest.approx(
        1e-4 * 1e-3 + 1e-6 / 12 * 1e-3, rel=1e-15
    )
    # noise held shorter than a sample: independent samples of variance σ², held over Ts
    assert K.measurement_noise_intensity(scen, Sampling(ts=1e-2)) == pytest.approx(1e-6)
    # held longer: its own spectral density σ² h
    long = Scenario(t_final=1.0, noise_variance=1e-4, noise_hold=1e-2)
    assert K.measurement_noise_intensity(long, Sampling(ts=1e-3)) == pytest.approx(1e-6)
    assert K.measurement_noise_intensity(Scenario(t_final=1.0)) == 0.0
    assert K.measurement_noise_intensity(Scenario(t_final=1.0), Sampling(ts=1e-3)) == 0.0


# ------------------------------------------------------------------ controller
def test_controller_rows_hold_the_equivalent_bandwidth() -> None:
    rho, q, r = 3, 1e9, 1e-7
    c = Controller.from_structure(
        "LADRC", rho=rho, eso_gains="kalman", values={"eso.q": q, "eso.r": r}
    )
    row = c.float_row()
    alphas, w0 = K.kalman_gain_parameters(rho, q, r)
    assert row[L.F_OMEGA0] == w0 == c.value("eso.omega0")
    np.testing.assert_array_equal(row[L.F_ESO_ALPHA : L.F_ESO_ALPHA + rho + 1], alphas)
    assert c.int_row()[L.I_ESO_GAINS] == L.ESO_GAINS_KALMAN
    # a population over q: each member's ω0 from its own q
    qs = np.array([1e6, 1e9, 1e12])
    batch = controller_batch(c, {"eso.q": qs})
    np.testing.assert_allclose(batch.floats[:, L.F_OMEGA0], (qs / r) ** (1 / (2 * rho + 2)))
    assert {"eso.q", "eso.r"} <= used_parameters(c)
    assert "eso.omega0" not in used_parameters(c)
    with pytest.raises(ValueError, match=r"eso\.omega0"):
        controller_batch(c, {"eso.omega0": np.array([1.0, 2.0])})
    with pytest.raises(ValueError, match=r"controller\.eso\.q"):
        controller_batch(c, {"eso.q": np.array([1.0, -1.0])})


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"values": {"eso.q": 1.0}}, "controller.eso.r"),
        ({"values": {"eso.r": 1.0}}, "controller.eso.q"),
        ({"values": {"eso.q": 1.0, "eso.r": 1.0, "eso.alpha1": 3.0}}, "eso.alpha1"),
        ({"values": {"eso.q": 1.0, "eso.r": 1.0, "eso.omega0": 3.0}}, "eso.omega0"),
        ({"values": {"eso.q": 0.0, "eso.r": 1.0}}, "controller.eso.q"),
        ({"values": {"eso.q": 1.0, "eso.r": 1.0}, "eso": "improved"}, "INLESO"),
    ],
)
def test_controller_refuses_contradicting_kalman_settings(
    kwargs: dict[str, Any], field: str
) -> None:
    with pytest.raises(ValueError, match=field):
        Controller(rho=2, eso_gains="kalman", **kwargs)


# ------------------------------------------------------------------ configs and the CLI
def _tank(**eso: Any) -> dict[str, Any]:
    data = tomllib.loads(preset_text("tank-ladrc"))
    data["scenario"]["t_final"] = 1.0
    data["scenario"]["noise_variance"] = 1e-6
    data["controller"]["eso"] = {"gains": "kalman", "q": 1.6e-4, **eso}
    return data


def test_config_derives_r_from_the_runs_measurement() -> None:
    cfg = parse_config(_tank())
    assert cfg.controller.value("eso.r") == pytest.approx(1e-6 * 1e-3)
    assert cfg.controller.value("eso.omega0") == pytest.approx(20.0, rel=1e-12)
    given = parse_config(_tank(r=4e-9)).controller
    assert given.value("eso.r") == 4e-9
    sampled = _tank()
    sampled["controller"]["discrete"] = {"ts": 2e-3, "y_quantum": 1e-3}
    r_s = parse_config(sampled).controller.value("eso.r")
    assert r_s == pytest.approx(1e-6 * 2e-3 + 1e-6 / 12 * 2e-3)
    # a sample time given later is designed for as well
    later = parse_config(_tank()).with_sample_time(2e-3).controller.value("eso.r")
    assert later == pytest.approx(1e-6 * 2e-3)


BAD = {
    "alpha": ({"alpha": [2.0, 1.0]}, ["controller.eso.alpha", "controller.eso.gains"]),
    "omega0": ({"omega0": 30.0}, ["controller.eso.omega0", "controller.eso.gains"]),
    "q_zero": ({"q": 0.0}, ["controller.eso.q"]),
    "q_negative": ({"q": -1.0}, ["controller.eso.q"]),
    "q_huge": ({"q": 1e301}, ["controller.eso.q"]),
    "r_zero": ({"r": 0.0}, ["controller.eso.r"]),
    "q_missing": ({"q": None}, ["controller.eso.q"]),
    "q_on_bandwidth": ({"gains": "bandwidth"}, ["controller.eso.q", "bandwidth"]),
}


def _write(tmp_path: Path, data: dict[str, Any]) -> Path:
    from aiofl.tuning.space import to_toml

    path = tmp_path / "kalman.toml"
    path.write_text(to_toml(data))
    return path


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_kalman_configs_exit_2_naming_the_field(tmp_path: Path, case: str) -> None:
    eso, fields = BAD[case]
    data = _tank(**eso)
    data["controller"]["eso"] = {
        k: v for k, v in data["controller"]["eso"].items() if v is not None
    }
    res = runner.invoke(
        app, ["simulate", str(_write(tmp_path, data)), "--out", str(tmp_path / "o")]
    )
    assert res.exit_code == 2, res.stdout
    for field in fields:
        assert field in res.stderr
    assert "Traceback" not in res.stderr + res.stdout


def test_kalman_needs_a_measurement_noise(tmp_path: Path) -> None:
    data = _tank()
    data["scenario"]["noise_variance"] = 0.0
    res = runner.invoke(
        app, ["simulate", str(_write(tmp_path, data)), "--out", str(tmp_path / "o")]
    )
    assert res.exit_code == 2
    assert "controller.eso.r" in res.stderr and "measurement noise" in res.stderr
    with pytest.raises(ConfigError, match=r"controller\.eso\.r"):
        sampled = copy.deepcopy(data)
        sampled["controller"]["discrete"] = {"ts": 1e-3}  # no y_quantum: still ideal
        parse_config(sampled)


def test_kalman_with_the_improved_eso_is_refused(tmp_path: Path) -> None:
    data = tomllib.loads(preset_text("paper-s1-inleso"))
    eso = {k: v for k, v in data["controller"]["eso"].items() if k not in ("omega0", "alpha")}
    data["controller"]["eso"] = {**eso, "gains": "kalman", "q": 1e12, "r": 1e-7}
    res = runner.invoke(
        app, ["simulate", str(_write(tmp_path, data)), "--out", str(tmp_path / "o")]
    )
    assert res.exit_code == 2
    assert "controller.eso.gains" in res.stderr and "INLESO" in res.stderr


@pytest.mark.slow
@pytest.mark.parametrize("ts", [None, 1e-3])
def test_kalman_config_runs_through_simulate(tmp_path: Path, ts: float | None) -> None:
    import json

    data = _tank()
    if ts is not None:
        data["controller"]["discrete"] = {"ts": ts}
    out = tmp_path / "run"
    res = runner.invoke(app, ["simulate", str(_write(tmp_path, data)), "--out", str(out)])
    assert res.exit_code == 0, res.stderr
    rec = json.loads((out / "metrics.json").read_text())
    assert not rec["failed"]
    direct = parse_config(data).simulate(store=False)
    assert rec["itae"] == direct.metrics["itae"]


# ------------------------------------------------------------------ tuning eso.q
def _tank_tune(parameters: dict[str, Any]) -> dict[str, Any]:
    data = _tank()
    data["tune"] = {
        "algorithm": "ga",
        "objective": "itae",
        "t_final": 0.3,
        "population": 4,
        "generations": 2,
        "parameters": parameters,
    }
    return data


def test_tuning_samples_q_log_uniformly_and_writes_it_back() -> None:
    from aiofl.tuning.search import prepare, tune

    bounds = {"eso.q": {"lo": 1e-6, "hi": 1e-2, "log": True}}
    cfg = parse_config(_tank_tune(bounds))
    prep = prepare(cfg)
    assert prep.space.names == ("eso.q",) and prep.space.log.all()
    # the unit cube's midpoint is the geometric mean: a log-uniform equivalent bandwidth
    assert prep.space.decode(np.array([[0.5]]))[0, 0] == pytest.approx(1e-4, rel=1e-12)
    res = tune(cfg, progress=False)
    q = res.best_values["eso.q"]
    assert 1e-6 <= q <= 1e-2
    best = parse_config(res.config)
    assert best.controller.value("eso.q") == q
    r = best.controller.value("eso.r")
    assert best.controller.value("eso.omega0") == pytest.approx((q / r) ** 0.25, rel=1e-12)


@pytest.mark.parametrize(
    ("bounds", "needle"),
    [
        ({"eso.omega0": {"lo": 1.0, "hi": 100.0}}, "no effect"),
        ({"eso.q": {"lo": -1.0, "hi": 1.0}}, "controller.eso.q"),
        ({"eso.q": {"lo": 1.0, "hi": 1e305}}, "controller.eso.q"),
    ],
)
def test_tuning_refuses_what_kalman_gains_do_not_use(bounds: dict[str, Any], needle: str) -> None:
    from aiofl.tuning.search import prepare

    with pytest.raises(ConfigError, match=needle):
        prepare(parse_config(_tank_tune(bounds)))
