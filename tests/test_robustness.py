"""Uncertainty as data (``[uncertainty]``), its draws, aggregates and ``aiofl robustness``."""

from __future__ import annotations

import copy
import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from aiofl.analysis.robustness_draws import run_robustness, simulate_draws
from aiofl.cli.app import app
from aiofl.config import ConfigError, parse_config, preset_text
from aiofl.engine.simulation import simulate, simulate_batch
from aiofl.uncertainty import (
    Distribution,
    UncertaintyModel,
    aggregate,
    cvar,
    sample_draws,
)

FOUR = ("J_l", "K_s", "R_m", "J_h")


def _config(preset: str, uncertainty: dict, t_final: float = 1.0) -> dict:
    data = tomllib.loads(preset_text(preset))
    data["scenario"]["t_final"] = t_final
    data["uncertainty"] = copy.deepcopy(uncertainty)
    return data


# ------------------------------------------------------------------------- draws
def test_draws_are_reproducible_per_seed_and_prefix_stable() -> None:
    spec = UncertaintyModel(parameters={k: Distribution(uniform=0.2) for k in FOUR})
    a = sample_draws(spec, draws=100, seed=7)
    b = sample_draws(spec, draws=100, seed=7)
    c = sample_draws(spec, draws=100, seed=8)
    short = sample_draws(spec, draws=10, seed=7)
    for k in FOUR:
        np.testing.assert_array_equal(a.factors[k], b.factors[k])
        assert not np.allclose(a.factors[k], c.factors[k])
        np.testing.assert_array_equal(short.factors[k], a.factors[k][:10])
    # the streams are independent and named: two parameters never share draws
    assert not np.allclose(a.factors["J_l"], a.factors["K_s"])


def test_adding_a_parameter_does_not_change_the_others() -> None:
    two = UncertaintyModel(parameters={"J_l": {"uniform": 0.2}, "R_m": {"normal": 0.05}})
    three = UncertaintyModel(
        parameters={"J_l": {"uniform": 0.2}, "R_m": {"normal": 0.05}, "K_s": {"uniform": 0.1}}
    )
    a, b = sample_draws(two, draws=50), sample_draws(three, draws=50)
    for k in ("J_l", "R_m"):
        np.testing.assert_array_equal(a.factors[k], b.factors[k])


def test_draws_are_identical_across_designs() -> None:
    """Common random numbers: two designs see exactly the same plants."""
    unc = {"draws": 8, "seed": 5, "parameters": {k: {"uniform": 0.2} for k in FOUR}}
    results = [
        run_robustness(parse_config(_config(p, unc, 0.2), p))
        for p in ("retuned-s1-leso", "retuned-s1-ladrc")
    ]
    a, b = (r.draws for r in results)
    for k in FOUR:
        np.testing.assert_array_equal(a.factors[k], b.factors[k])
    assert not np.array_equal(results[0].itae, results[1].itae)  # the designs differ


def test_uniform_draws_bounds_and_moments() -> None:
    p, n = 0.2, 20_000
    f = sample_draws(UncertaintyModel(parameters={"J_l": {"uniform": p}}), draws=n).factors["J_l"]
    assert f.min() >= 1 - p and f.max() <= 1 + p
    assert f.min() < 1 - 0.99 * p and f.max() > 1 + 0.99 * p  # the whole range is used
    sd = p / math.sqrt(3)  # U[1-p, 1+p]: variance p^2/3
    assert abs(f.mean() - 1) < 5 * sd / math.sqrt(n)
    assert abs(f.std() / sd - 1) < 0.03


def test_log_uniform_draws_bounds_and_moments() -> None:
    a, b, n = 0.5, 2.0, 20_000
    spec = UncertaintyModel(parameters={"R_m": {"log_uniform": [a, b]}})
    f = sample_draws(spec, draws=n).factors["R_m"]
    assert f.min() >= a and f.max() <= b
    logf = np.log(f)  # U[ln a, ln b]: mean (ln a + ln b)/2, sd (ln b - ln a)/sqrt(12)
    sd = (math.log(b) - math.log(a)) / math.sqrt(12)
    assert abs(logf.mean() - 0.5 * (math.log(a) + math.log(b))) < 5 * sd / math.sqrt(n)
    assert abs(logf.std() / sd - 1) < 0.03


@pytest.mark.parametrize("sigma", [0.05, 0.5])
def test_normal_draws_sigma_and_positivity(sigma: float) -> None:
    from scipy.stats import truncnorm

    n = 20_000
    f = sample_draws(UncertaintyModel(parameters={"K_s": {"normal": sigma}}), draws=n).factors[
        "K_s"
    ]
    assert f.min() > 0 and f.max() < 2  # truncated to |z| < 1/sigma: 0 < f < 2
    # the truncated normal's sd (sigma itself up to the truncation at 1/sigma)
    sd = sigma * truncnorm.std(-1 / sigma, 1 / sigma)
    assert abs(f.mean() - 1) < 5 * sd / math.sqrt(n)
    assert abs(f.std() / sd - 1) < 0.03  # sampling error of the sd ~ 1/sqrt(2n) = 0.5 %


def test_sample_time_and_noise_draws() -> None:
    spec = UncertaintyModel(ts=[5e-4, 2e-3], noise_variance=[1e-6, 1e-4])
    d = sample_draws(spec, draws=2000, dt=1e-4)
    k = d.ts / 1e-4
    np.testing.assert_allclose(k, np.round(k), atol=1e-9)  # multiples of dt
    assert set(np.round(k).astype(int)) == set(range(5, 21))  # every multiple in range
    assert d.noise_variance.min() >= 1e-6 and d.noise_variance.max() <= 1e-4


# -------------------------------------------------------------------- aggregates
values = st.lists(st.floats(min_value=0, max_value=1e6, allow_nan=False), min_size=1, max_size=40)


@settings(max_examples=200, deadline=None)
@given(values, st.floats(min_value=0.0, max_value=0.99))
def test_aggregates_equal_their_definitions(v: list[float], alpha: float) -> None:
    x = np.array(v)
    k = len(v)
    assert aggregate(x, "mean") == pytest.approx(sum(v) / k, rel=1e-12, abs=1e-12)
    assert aggregate(x, "worst") == max(v)
    m = max(1, math.ceil((1 - alpha) * k - 1e-9))
    expect = sum(sorted(v)[k - m :]) / m
    assert cvar(x, alpha) == pytest.approx(expect, rel=1e-12, abs=1e-12)
    assert aggregate(x, "cvar", alpha=alpha) == cvar(x, alpha)


@settings(max_examples=100, deadline=None)
@given(values, st.integers(min_value=1, max_value=40))
def test_cvar_is_the_rockafellar_uryasev_minimum(v: list[float], m: int) -> None:
    """With (1 - alpha) K = m an integer, CVaR = min_t t + sum((v - t)+) / m (R&U 2000)."""
    k = len(v)
    m = min(m, k)
    alpha = 1 - m / k
    x = np.array(v)
    ru = min(t + np.maximum(x - t, 0).sum() / m for t in x)
    assert cvar(x, alpha) == pytest.approx(ru, rel=1e-9, abs=1e-9)


def test_a_diverged_draw_makes_the_aggregates_infinite() -> None:
    x = np.array([1.0, 2.0, 3.0, 4.0])
    div = np.array([False, False, False, True])
    assert aggregate(x, "mean", failed=div) == math.inf
    assert aggregate(x, "worst", failed=div) == math.inf
    assert aggregate(x, "cvar", alpha=0.5, failed=div) == math.inf
    assert aggregate(np.array([1.0, np.nan]), "mean") == math.inf
    # along the last axis of a (candidates, draws) table
    np.testing.assert_array_equal(
        aggregate(np.array([[1.0, 3.0], [2.0, 2.0]]), "worst"), [3.0, 2.0]
    )


# ---------------------------------------------------------------- the analysis
UNSTABLE = {
    "draws": 8,
    "seed": 1,
    "parameters": {"J_l": {"log_uniform": [0.3, 3.0]}, "K_s": {"log_uniform": [0.3, 3.0]}},
}


@pytest.fixture(scope="module")
def mixed() -> tuple:
    """retuned-s1-leso on a 2-s horizon, 8 wide draws: some diverge, some do not."""
    cfg = parse_config(_config("retuned-s1-leso", UNSTABLE, 2.0), "mixed")
    return cfg, run_robustness(cfg)


def test_statistics_equal_a_direct_computation_draw_by_draw(mixed: tuple) -> None:
    cfg, res = mixed
    itae, isu, div, t_div = [], [], [], []
    for scen in res.draws.scenarios(cfg.scenario):
        r = simulate_batch(
            cfg.plant, cfg.controller, scen, dt=cfg.dt, method=cfg.method,
            divergence_threshold=cfg.divergence_threshold,
        )  # fmt: skip
        div.append(bool(r.failed[0]))
        t_div.append(float(r.stopped_at[0]))
        itae.append(math.inf if div[-1] else float(r.metric("itae")[0]))
        isu.append(math.inf if div[-1] else float(r.metric("isu")[0]))
    assert 0 < sum(div) < len(div)  # the case tests both kinds of draw
    np.testing.assert_array_equal(res.failed, div)
    np.testing.assert_array_equal(res.itae, itae)
    np.testing.assert_array_equal(res.isu, isu)
    info = res.to_dict()
    assert info["stable_fraction"] == 1 - sum(div) / len(div)
    assert [d["draw"] for d in info["failed"]] == [i for i, x in enumerate(div) if x]
    assert [d["t"] for d in info["failed"]] == [t for t, x in zip(t_div, div, strict=True) if x]
    srt = sorted(itae)
    for key, q in (("q05", 0.05), ("q50", 0.5), ("q95", 0.95)):
        # the empirical quantile: the ceil(qK)-th smallest value (inverted CDF)
        v = srt[math.ceil(q * len(srt)) - 1]
        assert info["itae"][key] == (None if math.isinf(v) else v)
    assert info["itae"]["max"] is None  # a diverged draw is the maximum
    # the worst draw is the earliest divergence, with its parameters
    first = min((t, i) for i, (t, x) in enumerate(zip(t_div, div, strict=True)) if x)[1]
    assert info["worst"]["draw"] == first
    nominal = cfg.plant.params["J_l"]
    assert info["worst"]["parameters"]["J_l"] == pytest.approx(
        nominal * res.draws.factors["J_l"][first]
    )


def test_the_nominal_member_is_the_config_run(mixed: tuple) -> None:
    cfg, res = mixed
    r = cfg.simulate(store=False)
    assert res.nominal["itae"] == r.metrics["itae"]
    assert res.nominal["failed"] is False


def test_the_json_has_no_nan_or_infinity(mixed: tuple) -> None:
    _, res = mixed
    text = json.dumps(res.to_dict(), allow_nan=False)  # raises on NaN / inf
    assert "NaN" not in text and "Infinity" not in text


def test_the_envelope_table_is_bounded_and_matches_the_trajectories(mixed: tuple) -> None:
    cfg, res = mixed
    assert res.error.shape == (8, len(res.t)) and len(res.t) <= 401
    i = int(np.flatnonzero(~res.failed)[0])
    scen = res.draws.scenarios(cfg.scenario)[i]
    full = simulate(
        cfg.plant, cfg.controller, scen, dt=cfg.dt, store=True, decimation=1,
        divergence_threshold=cfg.divergence_threshold,
    )  # fmt: skip
    e = full.signals["y"] - full.signals["r"]
    step = round(res.t[1] / cfg.dt)
    np.testing.assert_allclose(res.error[i], e[::step], rtol=1e-5, atol=1e-6)


def test_chunked_runs_equal_one_call(mixed: tuple, monkeypatch: pytest.MonkeyPatch) -> None:
    """Splitting the members over several engine calls changes no number."""
    import aiofl.analysis.robustness_draws as rb

    cfg, res = mixed
    monkeypatch.setattr(rb, "CALL_TRAJECTORY_BYTES", 1)  # one member per call
    runs = simulate_draws(cfg, res.draws)
    assert runs.engine_calls == 9
    np.testing.assert_array_equal(runs.failed[1:], res.failed)
    np.testing.assert_array_equal(np.where(runs.failed[1:], np.inf, runs.metrics[1:, 0]), res.itae)


def test_a_plant_change_after_t0_is_refused() -> None:
    data = _config("retuned-s1-leso", {"parameters": {"J_l": {"uniform": 0.2}}})
    data["scenario"].update(plant_scale={"J_l": 1.4}, parameter_change_time=0.5)
    cfg = parse_config(data, "late change")
    with pytest.raises(ValueError, match="parameter_change_time"):
        run_robustness(cfg)


def test_draws_compose_with_the_scenarios_own_scale() -> None:
    data = _config("retuned-s1-leso", {"parameters": {"J_l": {"uniform": 0.2}}})
    data["scenario"]["plant_scale"] = {"J_l": 1.4, "K_s": 0.9}
    cfg = parse_config(data, "s2-like")
    d = sample_draws(cfg.uncertainty, draws=3)
    for k, s in enumerate(d.scenarios(cfg.scenario)):
        assert s.plant_scale["J_l"] == pytest.approx(1.4 * d.factors["J_l"][k])
        assert s.plant_scale["K_s"] == 0.9 and s.parameter_change_time == 0.0


# ----------------------------------------------------------------- config errors
@pytest.mark.parametrize(
    ("table", "needle"),
    [
        ({"parameters": {"J_x": {"uniform": 0.2}}}, "allowed: K_s"),
        ({"parameters": {"J_l": {"uniform": 1.5}}}, "uncertainty.parameters.J_l.uniform"),
        ({"parameters": {"J_l": {"uniform": 0.1, "normal": 0.1}}}, "exactly one"),
        ({"parameters": {"J_l": {"log_uniform": [2.0, 1.0]}}}, "0 < a < b"),
        ({"parameters": {"J_l": {"normal": 0.9}}}, "less than or equal to 0.5"),
        ({"draws": 200_000, "parameters": {"J_l": {"uniform": 0.1}}}, "100000"),
        ({"ts": [1e-3, 2e-3]}, "[controller.discrete]"),
        ({"noise_variance": [1e-4, 1e-6]}, "a <= b"),
        ({}, "nothing is uncertain"),
        ({"parameters": {"J_l": {"uniform": 0.1}}, "seeds": 3}, "unknown key"),
    ],
)
def test_bad_uncertainty_tables_are_refused(table: dict, needle: str) -> None:
    with pytest.raises(ConfigError, match=None) as err:
        parse_config(_config("retuned-s1-leso", table), "bad")
    assert needle in str(err.value)


def test_cli_exit_2_on_a_bad_table_and_nothing_written(tmp_path: Path) -> None:
    text = preset_text("retuned-s1-leso") + "\n[uncertainty]\n[uncertainty.parameters]\n"
    bad = tmp_path / "bad.toml"
    bad.write_text(text + "J_x = { uniform = 0.2 }\n")
    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["robustness", str(bad), "--out", str(out)])
    assert result.exit_code == 2
    assert "J_x" in result.output and "allowed" in result.output
    assert not out.exists()
    no_table = CliRunner().invoke(app, ["robustness", "retuned-s1-leso", "--out", str(out)])
    assert no_table.exit_code == 2 and "[uncertainty]" in no_table.output
    assert not out.exists()


def test_cli_writes_json_and_figure_deterministically(tmp_path: Path) -> None:
    data = tomllib.loads(preset_text("retuned-s1-inleso"))
    cfg_file = tmp_path / "run.toml"
    import tomlkit

    data["scenario"]["t_final"] = 0.5
    data["tune"].pop("t_final", None)  # a [tune] horizon longer than the scenario is refused
    data["uncertainty"] = {"draws": 4, "seed": 2, "parameters": {"J_l": {"uniform": 0.2}}}
    cfg_file.write_text(tomlkit.dumps(data))
    outs = []
    for name in ("a", "b"):
        out = tmp_path / name
        result = CliRunner().invoke(
            app, ["robustness", str(cfg_file), "--out", str(out), "--draws", "6"]
        )
        assert result.exit_code == 0, result.output
        assert (out / "robustness.png").stat().st_size > 0
        outs.append(json.loads((out / "robustness.json").read_text()))
    assert outs[0] == outs[1] and outs[0]["draws"] == 6 and outs[0]["seed"] == 2


def test_dask_chunks_equal_the_local_run(mixed: tuple) -> None:
    """Chunks on a (threaded, in-process) Dask cluster give exactly the local numbers."""
    from distributed import Client, LocalCluster

    cfg, res = mixed
    with (
        LocalCluster(
            n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
        ) as cluster,
        Client(cluster) as client,
    ):
        remote = run_robustness(cfg, client=client)
    assert remote.engine_calls == 2
    np.testing.assert_array_equal(remote.itae, res.itae)
    np.testing.assert_array_equal(remote.error, res.error)
    assert remote.to_dict() == res.to_dict()


def test_drawn_sample_times_reach_the_sampled_engine() -> None:
    """A draw's ts and noise variance equal a run of the config sampled at that ts."""
    data = _config(
        "retuned-s1-leso",
        {"draws": 4, "seed": 3, "ts": [5e-4, 2e-3], "noise_variance": [0.0, 1e-6]},
        0.5,
    )
    data["controller"]["discrete"] = {"ts": 1e-3}
    cfg = parse_config(data, "sampled")
    res = run_robustness(cfg)
    assert len(set(res.draws.ts)) > 1  # several sample times in one batch
    for k, scen in enumerate(res.draws.scenarios(cfg.scenario)):
        assert scen.noise_variance == res.draws.noise_variance[k]
        one = cfg.with_sample_time(float(res.draws.ts[k]))
        r = simulate(
            one.plant, one.controller, scen, dt=one.dt, sampling=one.sampling,
            divergence_threshold=one.divergence_threshold,
        )  # fmt: skip
        assert res.itae[k] == r.metrics["itae"]
