"""The sampled-data closed loop in the compiled engine: ZOH, delay, quantisation, batches
mixing sample times, the update against the engine's discrete controller stepped from
Python, convergence to the continuous loop, divergence, configs and the CLI."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from aiofl.cli.app import app
from aiofl.config import ConfigError, load_config, parse_config
from aiofl.controller import Controller
from aiofl.discrete_controller import DiscreteController
from aiofl.engine.discrete_rows import D_L, Sampling, sample_steps
from aiofl.engine.simulation import simulate, simulate_batch
from aiofl.plants import get_plant
from aiofl.plants.base import Plant
from aiofl.scenario import Scenario

BETA_SLFJM = 1.61 * 0.00767 * 70.0 / (0.0059 * 0.0021 * 2.6)


def ladrc(**values: float) -> Controller:
    """A smooth LADRC on the SLFJM (linear ESO, prefilter, full-state linear SEF)."""
    vals = {
        "law.b0": BETA_SLFJM,
        "eso.omega0": 100.0,
        "sef.omega_c": 10.0,
        "td.omega": 20.0,
        **values,
    }
    return Controller.from_structure("LADRC", n_feedback=4, values=vals).with_binomial_alphas()


@pytest.fixture(scope="module")
def slfjm() -> Plant:
    return get_plant("slfjm")


def _u_at_samples(res, n_per: int) -> np.ndarray:
    """Applied u at the sample instants from a trajectory stored at every step."""
    return res["u"][::n_per]


# ----------------------------------------------------------------------- continuous
def test_continuous_members_are_bitwise_unchanged_in_a_mixed_batch(slfjm):
    """A continuous member's numbers do not depend on sampled members beside it."""
    ctrl = ladrc()
    scen = Scenario(t_final=0.5)
    alone = simulate_batch(slfjm, [ctrl, ctrl.with_values(**{"eso.omega0": 80.0})], scen)
    mixed = simulate_batch(
        slfjm,
        [ctrl, ctrl, ctrl.with_values(**{"eso.omega0": 80.0}), ctrl],
        scen,
        sampling=[None, Sampling(1e-3), None, Sampling(2e-4, delay=1)],
    )
    assert np.array_equal(mixed.metrics[[0, 2]], alone.metrics)
    assert not np.array_equal(mixed.metrics[1], alone.metrics[0])


def test_members_with_different_sample_times_equal_single_runs_bitwise(slfjm):
    ctrl = ladrc()
    scen = Scenario(t_final=0.5)
    samplings = [Sampling(1e-4), Sampling(5e-4, eso="euler"), Sampling(1e-3, delay=1)]
    batch = simulate_batch(slfjm, [ctrl] * 3, scen, sampling=samplings, store=True)
    for i, s in enumerate(samplings):
        one = simulate(slfjm, ctrl, scen, sampling=s)
        assert np.array_equal(batch.metrics[i], [one.metrics[k] for k in one.metrics])
        np.testing.assert_array_equal(batch.member(i)["u"], one["u"])


# ------------------------------------------------------------------------- the hold
def test_command_is_held_between_samples_and_changes_only_at_them(slfjm):
    n_per = 7
    res = simulate(
        slfjm, ladrc(), Scenario(t_final=0.2), dt=1e-4, sampling=Sampling(7e-4), decimation=1
    )
    u = res["u"][:-1]
    k = np.arange(u.size)
    changes = np.flatnonzero(np.diff(u) != 0.0) + 1
    assert changes.size > 50
    assert np.all(changes % n_per == 0)
    # the measurement the controller read is held too, and equals y at the sample
    ym = res["y_meas"][:-1]
    np.testing.assert_array_equal(ym[k % n_per == 0], res["y"][:-1][k % n_per == 0])
    assert np.all(np.diff(ym)[(k[1:] % n_per) != 0] == 0.0)


def test_the_kernel_runs_the_discrete_controller_update(slfjm):
    """Replaying the measurements the engine's sampled loop read through the discrete
    controller stepped from Python gives the commands the engine applied."""
    for ctrl, samp in (
        (ladrc(), Sampling(5e-4)),
        (ladrc(), Sampling(5e-4, eso="euler", delay=1)),
        (load_config("retuned-s1-leso").controller, Sampling(1e-3)),
        (load_config("retuned-s1-inleso").controller, Sampling(2e-4)),
    ):
        n_per = sample_steps(samp.ts, 1e-4)
        res = simulate(slfjm, ctrl, Scenario(t_final=0.3), sampling=samp, decimation=n_per)
        dc = DiscreteController(ctrl, samp)
        dc.init(res["y_meas"][0])
        samples = zip(res["r"][:-1], res["y_meas"][:-1], strict=True)
        u = np.array([dc.step(r, y) for r, y in samples])
        applied = res["u"][:-1]
        expect = np.r_[0.0, u[:-1]] if samp.delay else u
        scale = np.max(np.abs(applied))
        assert scale > 0
        np.testing.assert_allclose(applied, expect, rtol=0, atol=1e-12 * scale)


@pytest.mark.parametrize("preset", ["retuned-s1-leso", "retuned-s1-inleso", "assisted-s1-ladrc"])
def test_run_and_step_each_are_step_bit_for_bit(preset):
    """``DiscreteController.run(n, r, y)`` is n calls of ``step(r, y)``, and ``step_each``
    from several states is ``step`` from each (bit for bit; the controller's own state is
    left alone by step_each)."""
    cfg = load_config(preset)
    plant = cfg.plant if cfg.controller.eso_model != "none" else None
    a, b = (DiscreteController(cfg.controller, Sampling(1e-3), plant) for _ in range(2))
    a.init(0.01)
    b.init(0.01)
    r = [0.3, 0.1, 0.0, 0.0, 0.0]
    us = [a.step(r, 0.02) for _ in range(37)]
    assert b.run(37, r, 0.02) == us[-1]
    np.testing.assert_array_equal(a.state, b.state)
    rng = np.random.default_rng(1)
    states = a.state + 1e-3 * rng.standard_normal((5, a.state.size))
    ys = 0.02 + 1e-3 * rng.standard_normal(5)
    kept = b.state
    nxt, u_each = b.step_each(states, r, ys)
    np.testing.assert_array_equal(b.state, kept)
    for k in range(5):
        b.state = states[k]
        assert b.step(r, ys[k]) == u_each[k]
        np.testing.assert_array_equal(b.state, nxt[k])
    with pytest.raises(ValueError, match="allowed"):
        b.step_each(states[:, :3], r, ys)
    with pytest.raises(ValueError, match="allowed"):
        b.run(0, r, 0.0)


def test_quantised_measurement_and_command(slfjm):
    yq, uq = 1e-3, 0.05
    res = simulate(
        slfjm,
        ladrc(),
        Scenario(t_final=0.5),
        sampling=Sampling(1e-3, y_quantum=yq, u_quantum=uq),
        decimation=10,
    )
    assert not res.failed
    np.testing.assert_allclose(res["y_meas"] / yq, np.round(res["y_meas"] / yq), atol=1e-9)
    np.testing.assert_allclose(res["u"] / uq, np.round(res["u"] / uq), atol=1e-9)
    # stored at the samples (the last row, at t_final, is after the last sample)
    assert np.max(np.abs(res["y_meas"] - res["y"])[:-1]) <= 0.5 * yq + 1e-12
    assert len(np.unique(res["u"])) > 5


# ------------------------------------------------------------------ convergence, limits
def test_sampled_loop_converges_to_the_continuous_loop_first_order(slfjm):
    """A ZOH adds a delay of about Ts/2: on a smooth loop the difference to the continuous
    loop falls about 10x per 10x smaller Ts (first order)."""
    dt = 1e-5
    scen = Scenario(t_final=1.0)
    tss = [1e-3, 1e-4, 1e-5]
    for eso in ("zoh", "euler"):
        res = simulate_batch(
            slfjm,
            [ladrc()] * 4,
            scen,
            dt=dt,
            store=True,
            decimation=10,
            sampling=[None, *(Sampling(t, eso=eso) for t in tss)],
        )
        assert not res.failed.any()
        y = res.trajectories[:, :, 2]
        diff = [float(np.max(np.abs(y[i] - y[0]))) for i in (1, 2, 3)]
        ratios = [diff[0] / diff[1], diff[1] / diff[2]]
        assert all(7.0 < r < 13.0 for r in ratios), (eso, diff)


def test_an_euler_observer_beyond_its_stability_limit_diverges_as_data(slfjm):
    """Forward Euler puts the observer poles at 1 - ω0 Ts: beyond ω0 Ts = 2 the loop
    diverges, reported with its time; the ZOH observer at the same Ts does not."""
    ctrl = ladrc(**{"eso.omega0": 2500.0, "sef.omega_c": 5.0})
    res = simulate_batch(
        slfjm,
        [ctrl, ctrl],
        Scenario(t_final=1.0),
        sampling=[Sampling(1e-3, eso="euler"), Sampling(1e-3, eso="zoh")],
    )
    assert res.failed[0] and 0 < res.stopped_at[0] < 1.0
    assert np.isnan(res.metric("itae")[0])
    assert not res.failed[1]


def test_sample_time_must_be_a_multiple_of_dt(slfjm):
    assert sample_steps(3e-4, 1e-4) == 3
    with pytest.raises(ValueError, match=r"controller\.discrete\.ts = 0\.00015 s"):
        simulate(slfjm, ladrc(), Scenario(t_final=0.1), sampling=Sampling(1.5e-4))
    with pytest.raises(ValueError, match="allowed: the integer 0 or 1"):
        Sampling(1e-3, delay=2)
    with pytest.raises(ValueError, match="needs the linear ESO"):
        simulate(
            slfjm,
            load_config("retuned-s1-inleso").controller,
            Scenario(t_final=0.1),
            sampling=Sampling(1e-3, eso="zoh"),
        )


# ---------------------------------------------------------------------- config, CLI
def _config(**discrete: object) -> dict[str, object]:
    import tomllib

    from aiofl.config import preset_text

    data = tomllib.loads(preset_text("retuned-s1-leso"))
    data.pop("tune")
    data["controller"]["discrete"] = discrete
    return data


def test_config_discrete_table_is_validated_with_field_names():
    cfg = parse_config(_config(ts=1e-3, delay=1, y_quantum=1e-4))
    assert cfg.sampling == Sampling(1e-3, delay=1, y_quantum=1e-4)
    for table, needle in (
        ({"ts": 1.5e-4}, "controller.discrete.ts = 0.00015 s is not an integer multiple"),
        ({"ts": -1.0}, "controller.discrete.ts"),
        ({"ts": 1e-3, "delay": 3}, "controller.discrete.delay"),
        ({"ts": 1e-3, "eso": "tustin"}, "controller.discrete.eso"),
        ({"ts": 1e-3, "rate": 2}, "unknown key"),
    ):
        with pytest.raises(ConfigError, match=needle.replace(".", r"\.")):
            parse_config(_config(**table))


def test_simulate_ts_runs_sampled_and_bad_ts_exits_2_writing_nothing(tmp_path: Path):
    runner = CliRunner()
    out = tmp_path / "run"
    res = runner.invoke(app, ["simulate", "retuned-s1-leso", "--ts", "1e-3", "--out", str(out)])
    assert res.exit_code == 0, res.output
    rec = json.loads((out / "metrics.json").read_text())
    assert rec["sample_time"] == 1e-3
    cfg = load_config("retuned-s1-leso")
    direct = simulate(cfg.plant, cfg.controller, cfg.scenario, sampling=Sampling(1e-3))
    assert rec["itae"] == pytest.approx(direct.metrics["itae"], rel=1e-12)
    bad = tmp_path / "bad"
    for args in (["--ts", "1.5e-4"], ["--ts", "0"], ["--ts", "1e-3", "--dt", "4e-4"]):
        res = runner.invoke(app, ["simulate", "retuned-s1-leso", *args, "--out", str(bad)])
        assert res.exit_code == 2, (args, res.output)
        assert "controller.discrete.ts" in res.output
        assert not bad.exists()


def test_tune_ts_tunes_the_sampled_controller_and_writes_it(tmp_path: Path):
    out = tmp_path / "tune"
    args = ["tune", "retuned-s1-leso", "--ts", "1e-3", "--population", "4"]
    res = CliRunner().invoke(app, [*args, "--generations", "1", "--quiet", "--out", str(out)])
    assert res.exit_code == 0, res.output
    best = load_config(out / "best.toml")
    assert best.sampling == Sampling(1e-3)
    full = json.loads((out / "summary.json").read_text())["full_horizon"]
    again = best.simulate(store=False)  # sampled, from the written table
    assert again.failed == full["failed"]
    if again.failed:
        assert again.stopped_at == pytest.approx(full["stopped_at"], rel=1e-12)
    else:
        assert again.metrics["itae"] == pytest.approx(full["itae"], rel=1e-12)
    bad = CliRunner().invoke(app, [*args, "--ts", "1.5e-4", "--out", str(tmp_path / "b")])
    assert bad.exit_code == 2 and "controller.discrete.ts" in bad.output
    assert not (tmp_path / "b").exists()


# ------------------------------------------------------------------ the observer's start
def test_discrete_eso_starts_as_eso_init_says():
    """Before the first sample the ESO's prediction is p_0 = 0 ("zero", the default) or
    (y0, 0, ..., 0) ("output"); the first correction ξ̂_0 = p_0 + L φ(y0 - p_{0,1}) is then
    L y0 (the ZOH current observer's gain; 0 for Euler, whose L = 0) or exactly (y0, 0, ...)."""
    y0 = 0.3
    assert ladrc().eso_init == "zero"
    for samp in (Sampling(1e-3), Sampling(1e-3, eso="euler")):
        for init in ("zero", "output"):
            dc = DiscreteController(dataclasses.replace(ladrc(), eso_init=init), samp)
            dc.init(y0)
            dc.step(0.0, y0)
            n = 5
            gain = dc.row[D_L : D_L + n]
            assert np.all(gain == 0.0) if samp.eso == "euler" else np.all(gain > 0.0)
            expect = np.r_[y0, np.zeros(n - 1)] if init == "output" else gain * y0
            np.testing.assert_allclose(dc.estimate, expect, rtol=1e-14, atol=1e-15)


def test_sampled_loop_starts_its_observer_like_the_continuous_loop():
    """The tank starts at y0 = 1: the ESO's start matters.  Sampled at Ts = 1 ms, each
    setting of eso.init tracks the continuous loop with the same setting (output 100x closer
    to it than to the other one's), and the engine's sampled loop runs the discrete
    controller's start (replaying its measurements gives its commands)."""
    cfg = load_config("tank-ladrc")
    scen = dataclasses.replace(cfg.scenario, t_final=0.2, x0=(1.0,))
    ctrls = [dataclasses.replace(cfg.controller, eso_init=i) for i in ("zero", "output")]
    samp = Sampling(1e-3)
    res = simulate_batch(
        cfg.plant, ctrls * 2, scen, store=True, decimation=1, sampling=[None, None, samp, samp]
    )
    assert not res.failed.any()
    y = res.trajectories[:, :, 2]
    assert np.all(y[:, 0] == 1.0)
    for s, same, other in ((2, 0, 1), (3, 1, 0)):
        d_same = np.max(np.abs(y[s] - y[same]))
        d_other = np.max(np.abs(y[s] - y[other]))
        assert d_same < 0.01 * d_other, (s, d_same, d_other)
    n_per = sample_steps(samp.ts, 1e-4)
    for i, ctrl in enumerate(ctrls):
        run = res.member(2 + i)
        dc = DiscreteController(ctrl, samp)
        dc.init(run["y_meas"][0])
        ref = scen.reference  # exact TD: r and ṙ of the sine at the samples
        t = run.t[:-1:n_per]
        rd = ref.amplitude * ref.omega * np.cos(ref.omega * t + ref.phase)
        r, ym = run["r"][:-1:n_per], run["y_meas"][:-1:n_per]
        u = np.array([dc.step([a, b], c) for a, b, c in zip(r, rd, ym, strict=True)])
        np.testing.assert_allclose(run["u"][:-1:n_per], u, rtol=0, atol=1e-12 * 10.0)
