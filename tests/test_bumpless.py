"""The bumpless start (``eso.init = "bumpless"``): the ESO at (y0, 0, ..., 0) and the
differentiator / prefilter at rest at y0, in the continuous engine, the scipy reference, the
sampled engine and :class:`aiofl.DiscreteController` (``init`` with the config's start,
``reset`` bumpless at any sample, ``from_config``)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import aiofl
from aiofl.config import load_config
from aiofl.discrete_controller import DiscreteController
from aiofl.engine.discrete_rows import Sampling, sample_steps
from aiofl.engine.reference import reference_simulate
from aiofl.engine.simulation import simulate, simulate_batch
from aiofl.scenario import Reference

H0 = 1.0  # the tank's level at rest and the reference


@pytest.fixture(scope="module")
def tank():
    """The tank (ρ = 1) at rest at h = 1 m with r = 1 m: holding it needs the pump's
    u_hold = a sqrt(2 g h) / k_p (the outflow), found as the plant's α/β at rest."""
    cfg = load_config("tank-ladrc")
    scen = dataclasses.replace(
        cfg.scenario, t_final=0.5, x0=(H0,), reference=Reference(amplitude=0.0, offset=H0)
    )
    return cfg, scen


def _with_td(ctrl, td: str):
    values = {"linear": {"td.omega": 8.0}, "han": {"td.R": 50.0}, "exact": {}}[td]
    return dataclasses.replace(ctrl, td=td).with_values(**values)


def _u_hold(plant) -> float:
    """u that holds the tank at rest at H0: 0 = α(x) + β(x) u (normal form at x = H0)."""
    nf = plant.normal_form(np.array([H0]), plant.param_vector())
    return -nf[-2] / nf[-1]


@pytest.mark.parametrize("td", ["linear", "han"])
def test_bumpless_start_of_the_continuous_engine_equals_the_reference(tank, td):
    """Started bumpless, ξ̂1(0) = r_1(0) = y(0) and the whole run matches the scipy
    reference path (its own implementation of the start); the zero start is another run."""
    cfg, scen = tank
    ctrl = dataclasses.replace(_with_td(cfg.controller, td), eso_init="bumpless")
    eng = simulate(cfg.plant, ctrl, scen, decimation=10)
    assert eng["xi_hat1"][0] == H0 == eng["y"][0]
    assert eng["r1"][0] == H0
    ref = reference_simulate(cfg.plant, ctrl, scen, t_eval=eng.t, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(eng["y"], ref.y, atol=1e-8)
    np.testing.assert_allclose(eng["u"], ref.u, atol=1e-6 * max(1.0, np.max(np.abs(ref.u))))
    zero = simulate(cfg.plant, dataclasses.replace(ctrl, eso_init="zero"), scen, decimation=10)
    assert np.max(np.abs(zero["u"] - eng["u"])) > 1.0


@pytest.mark.parametrize("td", ["linear", "han", "exact"])
def test_a_plant_at_rest_sees_no_command_step(tank, td):
    """The plant at rest at y0 = r: the bumpless start commands u(t0) = 0 (e = 0 and
    ξ̂_{ρ+1} = 0), no more than the u_hold > 0 holding y0 needs; the zero start saturates
    the pump (|u(t0)| = u_max) and the output strays from y0 before settling."""
    cfg, scen = tank
    ctrl = _with_td(cfg.controller, td)
    u_hold = _u_hold(cfg.plant)
    assert 0.0 < u_hold < cfg.controller.value("law.u_max")
    samp = Sampling(1e-3)
    bumpless = DiscreteController(ctrl, samp)
    bumpless.reset(H0)
    first = bumpless.step([H0, 0.0], H0)
    assert abs(first) <= u_hold and first == 0.0
    zero = DiscreteController(dataclasses.replace(ctrl, eso_init="zero"), samp)
    zero.init(H0)
    assert abs(zero.step([H0, 0.0], H0)) == cfg.controller.value("law.u_max")
    runs = simulate_batch(
        cfg.plant,
        [dataclasses.replace(ctrl, eso_init=i) for i in ("bumpless", "zero")],
        scen,
        sampling=samp,
        store=True,
        decimation=10,
    )
    stray = np.max(np.abs(runs.trajectories[:, :, 2] - H0), axis=1)  # |y - y0| over the run
    assert stray[0] < 0.1 * stray[1], stray


def test_sampled_engine_runs_the_discrete_controllers_bumpless_start(tank):
    """The engine's sampled loop with eso.init = "bumpless" gives the commands of the
    DiscreteController started bumpless and fed the run's measurements (≤ 1e-12)."""
    cfg, scen = tank
    ctrl = dataclasses.replace(_with_td(cfg.controller, "linear"), eso_init="bumpless")
    scen = dataclasses.replace(scen, reference=Reference(amplitude=0.2, omega=3.0, offset=H0))
    samp = Sampling(1e-3)
    run = simulate_batch(cfg.plant, [ctrl], scen, sampling=samp, store=True, decimation=1).member(0)
    n_per = sample_steps(samp.ts, cfg.dt)
    dc = DiscreteController(ctrl, samp)
    dc.init(run["y_meas"][0])
    r, ym = run["r"][:-1:n_per], run["y_meas"][:-1:n_per]
    u = np.array([dc.step(a, b) for a, b in zip(r, ym, strict=True)])
    np.testing.assert_allclose(run["u"][:-1:n_per], u, rtol=0, atol=1e-12 * 10.0)


def test_reset_mid_run_is_a_fresh_bumpless_start(tank):
    """reset(y) at any sample leaves the controller exactly as a new one started bumpless at
    y: the same states, then the same commands."""
    cfg, _ = tank
    ctrl = _with_td(cfg.controller, "han")
    samp = Sampling(1e-3)
    dc = DiscreteController(ctrl, samp)
    dc.init(0.2)
    for k in range(50):
        dc.step(0.8, 0.2 + 0.01 * k)
    dc.reset(0.7)
    fresh = DiscreteController(dataclasses.replace(ctrl, eso_init="bumpless"), samp)
    fresh.init(0.7)
    np.testing.assert_array_equal(dc.state, fresh.state)
    for k in range(20):
        y = 0.7 + 0.002 * k
        assert dc.step(0.9, y) == fresh.step(0.9, y)


def test_from_config_is_the_engines_controller_of_the_design(tank, tmp_path):
    """DiscreteController.from_config(preset or path, ts=) is the constructor's controller;
    the sample time comes from the config when it has one, and is refused by name when
    missing or out of range; it is importable from the package root."""
    cfg, _ = tank
    assert aiofl.DiscreteController is DiscreteController  # one class, one name
    a = aiofl.DiscreteController.from_config("tank-ladrc", ts=2e-3)
    b = DiscreteController(cfg.controller, Sampling(2e-3))
    a.init(0.5)
    b.init(0.5)
    for k in range(30):
        r = [1.0 + 0.1 * math.sin(0.1 * k), 0.01 * math.cos(0.1 * k)]
        assert a.step(r, 0.5 + 0.01 * k) == b.step(r, 0.5 + 0.01 * k)
    with pytest.raises(ValueError, match="ts"):
        aiofl.DiscreteController.from_config(cfg)
    for bad in (0.0, -1e-3, 2.0, float("nan")):
        with pytest.raises(ValueError, match="allowed: a number of seconds, 1e-09 <= ts <= 1"):
            aiofl.DiscreteController.from_config(cfg, ts=bad)
    sampled = load_config("assisted-s1-ladrc")  # its [sensor] samples at 1 ms
    assert aiofl.DiscreteController.from_config(sampled).sampling == sampled.sampling
