"""Grey-box fits (aiofl.identification.grey_box) on logs of the independent scipy simulator:
recovery within the stated 95 % intervals, the correlation matrix, validation fits, residual
verdicts, a closed-loop log of an open-loop-unstable plant, the fitted plant file and the
[uncertainty] box."""

from __future__ import annotations

import json
import math
import tomllib

import numpy as np
import pytest

from aiofl.config.schema import ConfigModel
from aiofl.identification.fitted_plant import fitted_plant_file, uncertainty_table
from aiofl.identification.grey_box import (
    CLOSED_LOOP_INTERVALS,
    OPEN_LOOP_INTERVALS,
    GreyBoxError,
    fit_percent,
    fit_plant,
)
from aiofl.identification.log import Log, LogError
from aiofl.identification.synthetic import measure, simulate_log
from aiofl.plants.base import Plant
from aiofl.plants.registry import get_plant
from aiofl.uncertainty import box_bounds

TS = 1e-3
QUANTUM = 2 * np.pi / 4096  # a 12-bit encoder
TRUTH = {"J": 0.025, "b": 0.015, "K_t": 0.45}


def _prbs(n: int, hold: int, seed: int, amplitude: float) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return amplitude * np.repeat(rng.choice([-1.0, 1.0], n // hold + 1), hold)[:n]


@pytest.fixture(scope="module")
def arm() -> tuple:
    """dcmotor_arm with J, b, K_t off nominal: a 2.5-s estimation log, a 1-s validation log."""
    plant = get_plant("dcmotor_arm")
    truth = plant.param_vector(TRUTH)
    n = 2501
    clean = simulate_log(plant, np.arange(n) * TS, _prbs(n, 100, 1, 2.0), params=truth)
    log = Log(clean.t, clean.u, measure(clean.y, noise_std=2e-3, quantum=QUANTUM, seed=3))
    val = simulate_log(plant, np.arange(1001) * TS, _prbs(1001, 80, 9, 2.0), params=truth)
    val = Log(val.t, val.u, measure(val.y, noise_std=2e-3, quantum=QUANTUM, seed=4))
    fit = fit_plant(log, plant, dict.fromkeys(TRUTH), validation=val, seed=0)
    return plant, log, val, fit


def test_recovers_the_truth_within_the_stated_95_percent_intervals(arm: tuple) -> None:
    _, _, _, fit = arm
    for est in fit.parameters:
        lo, hi = est.interval95
        assert lo <= TRUTH[est.name] <= hi, est
        assert 0 < est.std < 0.01 * abs(est.value)  # a 2.5-s log pins them to < 1 %
        nominal = get_plant("dcmotor_arm").params[est.name]
        assert (est.low, est.high) == pytest.approx((0.2 * nominal, 5.0 * nominal))
    assert fit.plant.params["J"] == fit.estimate("J").value
    assert fit.plant.params["m"] == get_plant("dcmotor_arm").params["m"]  # not free: kept
    assert fit.noise_std == pytest.approx(math.sqrt(2e-3**2 + QUANTUM**2 / 12), rel=0.1)


def test_correlation_matrix_and_fits(arm: tuple) -> None:
    _, log, _, fit = arm
    c = fit.correlation
    assert c.shape == (3, 3)
    assert np.allclose(c, c.T) and np.allclose(np.diag(c), 1.0)
    assert np.all(np.abs(c) <= 1.0 + 1e-12)
    assert np.all(np.linalg.eigvalsh(c) > 0)
    assert fit.fit_percent > 95 and fit.validation_fit_percent > 95
    assert fit.fit_percent == pytest.approx(fit_percent(log.y, fit.y_simulated))
    assert fit.residuals.white and fit.residuals.independent  # the true structure
    assert fit.evaluations >= 25 * 24  # DE generations x population, then the polish
    rec = json.loads(json.dumps(fit.to_record(), allow_nan=False))
    assert set(rec["parameters"]) == set(TRUTH)
    assert set(rec["parameters"]["J"]) >= {"value", "std", "low", "high"}
    assert rec["output"] == "simulation"
    assert rec["intervals"] == OPEN_LOOP_INTERVALS
    assert all(p.bias == 0.0 for p in fit.parameters)


def test_a_held_out_tail_gives_the_validation_fit(arm: tuple) -> None:
    plant, log, _, _ = arm
    fit = fit_plant(log, plant, ["J", "K_t"], holdout=0.3, generations=0)
    assert fit.validation_fit_percent is not None and fit.validation_fit_percent > 90
    assert fit.y_simulated.shape == log.y.shape


def test_a_missing_parameter_is_flagged_by_the_residual_tests(arm: tuple) -> None:
    plant, log, _, _ = arm
    wrong = fit_plant(log, plant, {"J": None, "K_t": None}, generations=0)  # b held at 0.02
    res = wrong.residuals
    assert not (res.white and res.independent)
    assert res.white_statistic > 3 * res.white_threshold


def test_the_same_seed_gives_the_same_fit(arm: tuple) -> None:
    plant, log, _, _ = arm
    short = log.part(0, 800)
    a = fit_plant(short, plant, ["J"], population=8, generations=3, seed=5)
    b = fit_plant(short, plant, ["J"], population=8, generations=3, seed=5)
    assert a.parameters == b.parameters and a.evaluations == b.evaluations


def test_bad_free_names_bounds_and_logs_are_refused_by_name(arm: tuple) -> None:
    plant, log, _, _ = arm
    with pytest.raises(GreyBoxError, match=r"'Jx'.*allowed: J, b, m, g, l, K_t, K_e, R, L"):
        fit_plant(log, plant, ["Jx"])
    with pytest.raises(GreyBoxError, match=r"'J': bounds \(0.1, 0.01\) out of order"):
        fit_plant(log, plant, {"J": (0.1, 0.01)})
    with pytest.raises(GreyBoxError, match="named twice"):
        fit_plant(log, plant, ["J", "J"])
    with pytest.raises(GreyBoxError, match="no parameter"):
        fit_plant(log, plant, [])
    with pytest.raises(GreyBoxError, match="holdout"):
        fit_plant(log, plant, ["J"], holdout=0.9)
    y = log.y.copy()
    y[7] = np.nan
    with pytest.raises(LogError, match="column 'y' row 7"):
        fit_plant(Log(log.t, log.u, y), plant, ["J"])
    t = log.t.copy()
    t[100] += 0.5 * TS
    with pytest.raises(LogError, match="column 't' row 100"):
        fit_plant(Log(t, log.u, log.y), plant, ["J"])
    with pytest.raises(LogError, match="'u' is constant"):
        fit_plant(Log(log.t, 0 * log.u, log.y), plant, ["J"])


def test_uncertainty_table_loads_into_a_box_holding_the_truth(arm: tuple) -> None:
    _, _, _, fit = arm
    table = uncertainty_table(fit, k=2.0)
    model = ConfigModel.model_validate({"plant": "dcmotor_arm", "uncertainty": table})
    assert model.uncertainty is not None
    model.uncertainty.check(fit.plant.param_names, discrete=False, dt=1e-4)
    box = box_bounds(model.uncertainty)
    for est in fit.parameters:
        lo, hi = box[est.name]  # factors on the fitted value
        assert lo * est.value <= TRUTH[est.name] <= hi * est.value
        assert (hi - 1.0) * est.value == pytest.approx(2.0 * est.std)
    with pytest.raises(ValueError, match="k = 0"):
        uncertainty_table(fit, k=0)


PLANT_FILE = """\
# the arm of the rig in room 2 (a user's comment)
name = "arm"
states = ["theta", "omega", "i"]
f = ["omega", "(K_t*i - b*omega - m*g*l*sin(theta))/J", "(-R*i - K_e*omega)/L"]
g = ["0", "0", "1/L"]
h = "theta"

[params]
J = 0.02      # from the CAD model
b = 0.02
m = 0.5
g = 9.81
l = 0.2
K_t = 0.5     # datasheet
K_e = 0.5
R = 2.0
L = 0.05
"""


def test_fitted_plant_file_keeps_comments_and_writes_the_estimates(arm: tuple) -> None:
    _, _, _, fit = arm
    text = fitted_plant_file(fit, PLANT_FILE)
    assert "# the arm of the rig in room 2" in text and "# datasheet" not in text
    data = tomllib.loads(text)
    for est in fit.parameters:
        assert data["params"][est.name] == est.value
    assert data["params"]["R"] == 2.0 and data["f"][0] == "omega"
    assert "95 % interval" in text
    with pytest.raises(ValueError, match="no 'J'"):
        fitted_plant_file(fit, PLANT_FILE.replace("J = 0.02", "Jm = 0.02"))


# ----------------------------------------------------------- a closed loop, unstable plant
def _inv_f(x, p):  # an inverted pendulum: unstable at rest
    return (x[1], p[0] * math.sin(x[0]) - p[1] * x[1])


def _inv_g(x, p):
    return (0.0, p[2])


def _inv_h(x, p):
    return x[0]


class _PD:
    """A sampled PD law on the measured output (filtered difference), as a rig's."""

    def __init__(self, ts: float) -> None:
        self.ts, self.yf = ts, None

    def __call__(self, k: int, r: float, y: float) -> float:
        prev = y if self.yf is None else self.yf
        self.yf = prev + 0.3 * (y - prev)
        return 10.0 * (r - y) - 0.6 * (self.yf - prev) / self.ts


def test_an_open_loop_unstable_plant_from_its_closed_loop_log() -> None:
    plant = Plant("inverted", 2, _inv_f, _inv_g, _inv_h, {"a": 20.0, "c": 1.0, "b": 5.0})
    ts, n = 2e-3, 2001
    r = _prbs(n, 100, 2, 0.2)
    truth = plant.param_vector({"a": 24.0, "b": 4.5})
    log = simulate_log(
        plant, np.arange(n) * ts, r, params=truth, noise_std=1e-3, quantum=QUANTUM, seed=1,
        feedback=_PD(ts),
    )  # fmt: skip
    assert log.r is not None and not np.array_equal(log.u, r)
    fit = fit_plant(log, plant, ["a", "b"], closed_loop=True)
    assert fit.output.startswith("one-step prediction")
    assert fit.estimate("a").value == pytest.approx(24.0, rel=0.02)
    assert fit.estimate("b").value == pytest.approx(4.5, rel=0.02)
    assert fit.fit_percent > 95
    # the stated 95 % intervals include the injection's estimated bias and hold the truth,
    # where the statistical σ alone (the bias taken out) would not
    assert fit.intervals == CLOSED_LOOP_INTERVALS
    assert fit.to_record()["intervals"] == CLOSED_LOOP_INTERVALS
    for name, true in (("a", 24.0), ("b", 4.5)):
        est = fit.estimate(name)
        lo, hi = est.interval95
        assert lo <= true <= hi, est
        statistical = math.sqrt(est.std**2 - est.bias**2)
        assert abs(est.value - true) > 1.96 * statistical, est
        assert est.std < 0.01 * est.value  # still a useful interval (under 2 % wide)
