"""The driven batched simulation (aiofl.engine.driven) against the independent scipy
simulator (aiofl.identification.synthetic.simulate_log)."""

from __future__ import annotations

import numpy as np
import pytest

from aiofl.engine.driven import simulate_driven
from aiofl.identification.synthetic import simulate_log
from aiofl.plants.registry import get_plant

TS = 1e-3
N = 801


@pytest.fixture(scope="module")
def case() -> tuple:
    plant = get_plant("dcmotor_arm")
    rng = np.random.default_rng(4)
    u = 2.0 * np.repeat(rng.choice([-1.0, 1.0], N // 40 + 1), 40)[:N]
    t = np.arange(N) * TS
    truth = plant.param_vector({"J": 0.025, "b": 0.015})
    return plant, t, u, truth


def test_matches_the_scipy_simulator(case: tuple) -> None:
    plant, t, u, truth = case
    x0 = np.array([0.1, 0.0, 0.0])
    log = simulate_log(plant, t, u, params=truth, x0=x0)
    out = simulate_driven(plant, u, TS, truth, x0=x0)
    assert out.stopped.tolist() == [-1]
    scale = np.max(np.abs(log.y))
    assert np.max(np.abs(out.y[0] - log.y)) < 1e-6 * scale
    assert out.y[0, 0] == pytest.approx(0.1)


def test_a_whole_sample_delay_matches_the_scipy_simulator(case: tuple) -> None:
    plant, t, u, truth = case
    log = simulate_log(plant, t[:300], u[:300], params=truth, delay=3 * TS)
    out = simulate_driven(plant, u[:300], TS, truth, delay_samples=3)
    assert np.max(np.abs(out.y[0] - log.y)) < 1e-6 * np.max(np.abs(log.y))
    assert np.all(out.y[0, :4] == 0.0)  # nothing reaches the output before the input does


def test_members_are_independent_and_deterministic(case: tuple) -> None:
    plant, _, u, truth = case
    scales = np.array([0.8, 1.0, 1.3, 2.0, 0.5])
    params = np.tile(truth, (5, 1))
    params[:, 0] *= scales  # J
    together = simulate_driven(plant, u, TS, params)
    again = simulate_driven(plant, u, TS, params[::-1])
    for m in range(5):
        alone = simulate_driven(plant, u, TS, params[m])
        assert np.array_equal(alone.y[0], together.y[m])
        assert np.array_equal(again.y[4 - m], together.y[m])
    assert not np.array_equal(together.y[0], together.y[1])


def test_a_diverging_member_stops_with_its_status_and_nan_only_after(case: tuple) -> None:
    plant, _, u, truth = case
    bad = truth.copy()
    bad[plant.param_names.index("b")] = -2.0  # negative damping: the arm runs away
    out = simulate_driven(plant, u, TS, np.vstack([truth, bad]), limit=50.0)
    assert out.stopped[0] == -1 and out.stopped[1] > 0
    assert out.diverged.tolist() == [False, True]
    k = out.stopped[1]
    assert np.all(np.isfinite(out.y[1, :k])) and np.all(np.isnan(out.y[1, k:]))
    assert np.all(np.isfinite(out.y[0]))


def test_bad_arguments_are_named(case: tuple) -> None:
    plant, _, u, truth = case
    with pytest.raises(ValueError, match=r"params has shape .*J, b, m"):
        simulate_driven(plant, u, TS, truth[:4])
    with pytest.raises(ValueError, match="x0 has shape"):
        simulate_driven(plant, u, TS, truth, x0=[0.0, 1.0])
    with pytest.raises(ValueError, match="delay_samples"):
        simulate_driven(plant, u, TS, truth, delay_samples=-1)
    with pytest.raises(ValueError, match="substeps"):
        simulate_driven(plant, u, TS, truth, substeps=0)
    with pytest.raises(ValueError, match="y_measured"):
        simulate_driven(plant, u, TS, truth, gain=[1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="non-finite"):
        simulate_driven(plant, u, TS, truth * np.nan)
