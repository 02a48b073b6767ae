"""The model-free route: ρ, b0 (± its interval) and the delay recovered from synthetic logs.

The logs come from :func:`aiofl.identification.synthetic.simulate_log` (scipy's solve_ivp,
independent of the fitted model's code) with a 12-bit encoder's quantisation
(2π/4096 rad); the truths are known, so every assertion can fail on a wrong estimator.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from aiofl.identification.chain import ChainEstimate, identify_chain
from aiofl.identification.first_config import (
    DELAY_PRODUCT,
    chain_plant_file,
    first_config,
    omega0_rules,
)
from aiofl.identification.log import Log, LogError
from aiofl.identification.offline_eso import offline_eso
from aiofl.identification.synthetic import measure, simulate_log
from aiofl.plants.base import Plant

TS = 1e-3
QUANTUM = 2 * math.pi / 4096  # a 12-bit encoder


def chain_plant(rho: int, b0: float, pole: float, friction: float = 0.0) -> Plant:
    """y^(ρ) = b0 u - (coefficients of (s + pole)^ρ) · (y, ..., y^(ρ-1)) [- Fc tanh(ẏ/0.01)]."""
    a = np.poly(np.full(rho, -pole))[1:][::-1]

    def f(x, p):
        acc = -sum(a[i] * x[i] for i in range(rho))
        if friction:
            acc -= friction * math.tanh(x[1] / 0.01)
        return (*[x[i + 1] for i in range(rho - 1)], acc)

    def g(x, p):
        return (*([0.0] * (rho - 1)), b0)

    return Plant(name=f"chain{rho}", n_states=rho, f=f, g=g, h=lambda x, p: x[0], params={"b0": b0})


def prbs(n: int, clock: int, seed: int = 0) -> np.ndarray:
    """A ±1 random binary input switching every ``clock`` samples at most."""
    rng = np.random.default_rng(seed)
    return np.repeat(rng.integers(0, 2, n // clock + 2) * 2.0 - 1.0, clock)[:n]


def make_log(rho, b0, pole, *, seconds=2.0, delay=0.0, friction=0.0, noise=0.0, seed=0):
    n = round(seconds / TS) + 1
    t = np.arange(n) * TS
    plant = chain_plant(rho, b0, pole, friction)
    return simulate_log(
        plant, t, prbs(n, 20), delay=delay, noise_std=noise, quantum=QUANTUM, seed=seed
    )


@pytest.fixture(scope="module")
def chains() -> dict[int, tuple[Log, float]]:
    """Chains of order 1-3 (poles at -2 rad/s, b0 = 5·2^ρ), 2 s at 1 kHz, 12-bit encoder."""
    return {rho: (make_log(rho, 5.0 * 2**rho, 2.0), 5.0 * 2**rho) for rho in (1, 2, 3)}


@pytest.fixture(scope="module")
def estimates(chains) -> dict[int, ChainEstimate]:
    return {rho: identify_chain(log) for rho, (log, _) in chains.items()}


@pytest.mark.parametrize("rho", [1, 2, 3])
def test_the_order_is_found_and_b0_is_inside_its_interval(chains, estimates, rho):
    _, b0 = chains[rho]
    est = estimates[rho]
    assert est.rho == rho, [(c.rho, c.score) for c in est.candidates]
    assert est.criterion == "BIC"
    assert [c.rho for c in est.candidates] == [1, 2, 3, 4]
    best = min(est.candidates, key=lambda c: c.score)
    assert best.rho == rho
    assert abs(est.b0 - b0) <= 1.96 * est.b0_std, (est.b0, est.b0_std, b0)
    assert est.b0_std < 0.01 * b0  # and the interval is informative
    assert est.delay <= TS  # no delay in the truth: within one sample of 0
    # the residual is the encoder's quantisation noise, q/sqrt(12)
    assert est.noise_std == pytest.approx(QUANTUM / math.sqrt(12), rel=0.2)
    assert est.fit_percent > 99.0
    # the chain's coefficients: (s + 2)^rho
    np.testing.assert_allclose(est.coefficients, np.poly(np.full(rho, -2.0))[1:][::-1], rtol=0.05)


def test_a_delay_is_found_within_one_sample():
    log = make_log(1, 10.0, 2.0, delay=0.0123)
    est = identify_chain(log, rho=1, delay_max=0.03)
    assert est.criterion == "given"
    assert abs(est.delay - 0.0123) < TS
    assert abs(est.delay - 0.0123) <= 3 * est.delay_std + 1e-5
    assert abs(est.b0 - 10.0) <= 1.96 * est.b0_std


def test_the_b0_interval_covers_the_truth_95_percent_of_the_time():
    """200 noise realisations of one 1-s experiment (σ = 2 encoder steps, quantised): the
    95 % interval b0 ± 1.96 std must cover the truth 90-99 % of the time (measured: 195;
    600 realisations of two experiments, with the friction term tried, gave 96.2 %)."""
    b0 = 20.0
    n = 1001
    t = np.arange(n) * TS
    truth = simulate_log(chain_plant(2, b0, 2.0), t, prbs(n, 20, seed=3))
    covered = 0
    for seed in range(200):
        y = measure(truth.y, noise_std=2 * QUANTUM, quantum=QUANTUM, seed=seed)
        est = identify_chain(Log(t, truth.u, y), rho=2, delay_max=0.005, friction=False)
        covered += abs(est.b0 - b0) <= 1.96 * est.b0_std
    assert 180 <= covered <= 198


def test_coulomb_friction_does_not_bias_b0():
    """A double integrator with a Coulomb friction of 15 % of b0·|u|: the friction term keeps
    b0 within 5 %; without it b0 is biased, its interval missing the truth."""
    log = make_log(2, 20.0, 0.0, friction=3.0, seconds=2.0)
    est = identify_chain(log, rho=2)
    assert abs(est.b0 / 20.0 - 1.0) < 0.05
    assert est.friction == pytest.approx(3.0, rel=0.2)
    plain = identify_chain(log, rho=2, friction=False)
    assert plain.friction == 0.0
    assert abs(plain.b0 - 20.0) > 3 * plain.b0_std
    assert abs(est.b0 - 20.0) < abs(plain.b0 - 20.0) / 3


def test_offline_eso_tells_a_wrong_b0(chains, estimates):
    log, b0 = chains[2]
    right = offline_eso(log, 2, estimates[2].b0, 100.0)
    assert right.verdict == "small and smooth"
    assert right.disturbance.shape == log.y.shape
    for wrong in (3.0 * b0, b0 / 3.0):
        bad = offline_eso(log, 2, wrong, 100.0)
        assert bad.rms > 2.0 * right.rms
        assert "follows u" in bad.verdict
        assert ("too large" in bad.verdict) == (wrong > b0)
    # a wrong order: a disturbance far larger than with the right one
    assert offline_eso(log, 3, b0, 100.0).rms > 5 * right.rms


def test_first_config_is_a_valid_run_config(tmp_path, chains, estimates):
    from aiofl.config import load_config

    log, _ = chains[2]
    est = estimates[2]
    (tmp_path / "identified-chain.toml").write_text(chain_plant_file(est, log))
    (tmp_path / "first.toml").write_text(first_config(est, log))
    cfg = load_config(str(tmp_path / "first.toml"))
    assert cfg.controller.rho == 2
    assert cfg.plant.relative_degree == 2
    assert cfg.plant.params["b0"] == pytest.approx(est.b0)
    text = (tmp_path / "first.toml").read_text()
    assert "set by the noise rule" in text  # no delay: the noise sets omega0


def test_the_delay_caps_omega0():
    log = make_log(1, 10.0, 2.0, delay=0.0123, seconds=1.0)
    est = identify_chain(log, rho=1, delay_max=0.03)
    w0, notes = omega0_rules(est, log)
    assert w0 == pytest.approx(DELAY_PRODUCT / est.delay)
    assert any("set by the delay rule" in n for n in notes)


def test_the_record_is_json(estimates):
    rec = json.loads(json.dumps(estimates[2].to_record()))
    for key in ("rho", "b0", "b0_std", "delay", "delay_std", "noise_std", "criterion"):
        assert key in rec
    assert [c["rho"] for c in rec["candidates"]] == [1, 2, 3, 4]
    assert set(rec["candidates"][0]) == {"rho", "b0", "b0_std", "delay", "score", "fit_percent"}


def test_bad_logs_and_arguments_are_refused_by_name():
    n = 400
    t = np.arange(n) * TS
    u = prbs(n, 20)
    y = np.cumsum(u) * TS
    with pytest.raises(LogError, match="column 'u': constant input"):
        identify_chain(Log(t, np.ones(n), y))
    bad = y.copy()
    bad[17] = np.nan
    with pytest.raises(LogError, match="column 'y', row 17"):
        identify_chain(Log(t, u, bad))
    jitter = t.copy()
    jitter[50] += 0.5 * TS
    with pytest.raises(LogError, match="column 't', row 50: step"):
        identify_chain(Log(jitter, u, y))
    with pytest.raises(LogError, match="at least"):
        identify_chain(Log(t[:30], u[:30], y[:30]))
    with pytest.raises(ValueError, match="rho_max = 9"):
        identify_chain(Log(t, u, y), rho_max=9)
    with pytest.raises(ValueError, match="delay_max"):
        identify_chain(Log(t, u, y), delay_max=10.0)
    with pytest.raises(ValueError, match="omega0"):
        offline_eso(Log(t, u, y), 1, 1.0, 1e6)
    with pytest.raises(ValueError, match="b0"):
        offline_eso(Log(t, u, y), 1, 0.0, 10.0)
