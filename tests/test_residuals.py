"""Residual tests (aiofl.identification.residuals): white and independent residuals pass,
a wrong model structure is flagged (Ljung §16.6; MATLAB resid)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from aiofl.identification.residuals import residual_tests

N = 4000


def _arx_residual(y: np.ndarray, u: np.ndarray, na: int) -> np.ndarray:
    """Least-squares ARX(na, na) one-step residual: y_k on y_{k-1..k-na}, u_{k-1..k-na}."""
    rows = [np.concatenate([y[k - na : k][::-1], u[k - na : k][::-1]]) for k in range(na, len(y))]
    phi = np.array(rows)
    theta, *_ = np.linalg.lstsq(phi, y[na:], rcond=None)
    return y[na:] - phi @ theta


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_white_noise_independent_of_a_coloured_input_passes(seed: int) -> None:
    rng = np.random.default_rng(seed)
    e = rng.normal(size=N)
    u = lfilter([1.0], [1.0, -0.9], rng.normal(size=N))  # strongly coloured input
    res = residual_tests(e, u, max_lag=25)
    assert res.white and res.independent
    assert res.band == pytest.approx(2.576 / np.sqrt(N))
    assert res.autocorrelation.shape == (25,) and res.cross_correlation.shape == (51,)
    assert res.lags[0] == -25 and res.lags[-1] == 25


def test_true_structure_passes_and_a_first_order_model_of_second_order_data_is_flagged() -> None:
    rng = np.random.default_rng(7)
    u = np.sign(rng.normal(size=N))  # a random binary input
    # second-order ARX data with white equation noise: y = B/A u + e/A
    a = [1.0, -1.5, 0.7]
    y = lfilter([0.0, 1.0, 0.5], a, u) + lfilter([1.0], a, 0.1 * rng.normal(size=N))
    right = residual_tests(_arx_residual(y, u, 2), u[2:])
    assert right.white and right.independent
    wrong = residual_tests(_arx_residual(y, u, 1), u[1:])
    assert not wrong.white
    assert wrong.white_statistic > 10 * wrong.white_threshold


def test_a_residual_that_still_holds_the_input_is_not_independent() -> None:
    rng = np.random.default_rng(3)
    u = rng.normal(size=N)
    e = rng.normal(size=N) + 0.2 * np.concatenate([[0.0, 0.0, 0.0], u[:-3]])  # u_{k-3} left in
    res = residual_tests(e, u)
    assert res.white and not res.independent
    assert res.cross_correlation[res.lags.tolist().index(3)] > res.band


def test_record_and_bad_inputs() -> None:
    rng = np.random.default_rng(0)
    rec = residual_tests(rng.normal(size=200), rng.normal(size=200), max_lag=10).to_record()
    assert rec["max_lag"] == 10 and len(rec["cross_correlation"]["values"]) == 21
    with pytest.raises(ValueError, match="max_lag"):
        residual_tests(np.ones(40), np.arange(40.0), max_lag=10)
    bad = rng.normal(size=100)
    bad[17] = np.nan
    with pytest.raises(ValueError, match=r"residual\[17\]"):
        residual_tests(bad, rng.normal(size=100), max_lag=5)
    with pytest.raises(ValueError, match="u is constant"):
        residual_tests(rng.normal(size=100), np.ones(100), max_lag=5)
    with pytest.raises(ValueError, match="same length"):
        residual_tests(rng.normal(size=100), rng.normal(size=99), max_lag=5)
