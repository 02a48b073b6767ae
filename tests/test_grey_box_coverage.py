"""Coverage of the grey-box fit's 95 % intervals (aiofl.identification.grey_box.fit_plant).

One noiseless log of the library pendulum with m, l, c off nominal, made by the independent
scipy simulator; 100 seeded realisations of white Gaussian output noise (no quantisation,
so the white-noise assumption behind s²(JᵀJ)⁻¹ holds); each realisation fitted by the
local stage (least squares with the batched Jacobian) from one global fit's estimate.
Over the realisations each parameter's 95 % interval must hold the truth 90-99 times in
100, and the standardised errors (θ̂ - θ)/σ must look like N(0, 1): a σ that is too
small (or too large), or a biased estimate, fails here.
"""

from __future__ import annotations

import numpy as np
import pytest

from aiofl.identification.grey_box import fit_plant
from aiofl.identification.log import Log
from aiofl.identification.synthetic import measure, simulate_log
from aiofl.plants.registry import get_plant

TRUTH = {"m": 1.2, "l": 0.45, "c": 0.13}  # nominal 1.0, 0.5, 0.1
TS, N, NOISE, REALISATIONS = 2e-3, 601, 1e-2, 100


@pytest.fixture(scope="module")
def realisations() -> dict[str, np.ndarray]:
    """(θ̂ - θ)/σ per parameter over the realisations, and whether each interval held θ."""
    plant = get_plant("pendulum")
    rng = np.random.default_rng(1)
    u = 0.8 * np.repeat(rng.choice([-1.0, 1.0], N // 50 + 1), 50)[:N]
    clean = simulate_log(plant, np.arange(N) * TS, u, params=plant.param_vector(TRUTH))
    bounds = {k: (0.2 * plant.params[k], 5.0 * plant.params[k]) for k in TRUTH}
    first = Log(clean.t, clean.u, measure(clean.y, noise_std=NOISE, seed=10_000))
    start = fit_plant(first, plant, bounds, seed=0).plant  # the global stage, once
    z = {k: [] for k in TRUTH}
    inside = {k: [] for k in TRUTH}
    for seed in range(REALISATIONS):
        log = Log(clean.t, clean.u, measure(clean.y, noise_std=NOISE, seed=seed))
        fit = fit_plant(log, start, bounds, generations=0)
        for est in fit.parameters:
            lo, hi = est.interval95
            z[est.name].append((est.value - TRUTH[est.name]) / est.std)
            inside[est.name].append(lo <= TRUTH[est.name] <= hi)
    return {
        **{f"z_{k}": np.array(v) for k, v in z.items()},
        **{f"in_{k}": np.array(v) for k, v in inside.items()},
    }


@pytest.mark.parametrize("name", list(TRUTH))
def test_the_95_percent_intervals_cover_the_truth_90_to_99_percent(
    realisations: dict[str, np.ndarray], name: str
) -> None:
    covered = int(realisations[f"in_{name}"].sum())
    assert 90 <= covered <= 99, f"{name}: {covered} of {REALISATIONS}"


@pytest.mark.parametrize("name", list(TRUTH))
def test_the_standardised_errors_are_unbiased_with_unit_spread(
    realisations: dict[str, np.ndarray], name: str
) -> None:
    z = realisations[f"z_{name}"]
    assert np.all(np.isfinite(z))
    assert abs(z.mean()) < 0.35  # 3.5 standard errors of the mean of 100 N(0, 1) draws
    assert 0.8 < z.std() < 1.25  # the stated σ is the spread of the estimates
