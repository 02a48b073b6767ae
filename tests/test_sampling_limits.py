"""Sampling limits (aiofl.analysis.sampling_limits, ``aiofl analyze --sampling``): against the
exact eigenvalues of a linear sampled loop, against direct runs, and the command line."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm
from typer.testing import CliRunner

from aiofl.analysis.sampling_limits import sampling_figure, sampling_limits, sampling_limits_many
from aiofl.cli.app import app
from aiofl.config import RunConfig, parse_config
from aiofl.engine.discrete_rows import Sampling

W0, WC, B = 100.0, 10.0, 4.0  # observer and feedback bandwidths, the plant's input gain


def double_integrator(eso: str) -> RunConfig:
    """The pendulum with g = 0 and no friction is the chain ÿ = 4u: an LADRC (exact
    reference derivatives, b0 = b) on it is linear, so its sampled loop is too."""
    return parse_config(
        {
            "name": f"double-integrator-{eso}",
            "plant": "pendulum",
            "scenario": {
                "t_final": 5.0,
                "plant_overrides": {"g": 0.0, "c": 0.0},
                "reference": {"amplitude": 0.5, "omega": 2.0},
            },
            "controller": {
                "structure": "LADRC",
                "td_kind": "exact",
                "rho": 2,
                "n_feedback": 2,
                "eso": {"omega0": W0},
                "sef": {"omega_c": WC},
                "law": {"b0": B},
                "discrete": {"ts": 1e-4, "eso": eso},
            },
            "simulation": {"dt": 1e-4},
        }
    )


def euler_loop_radius(ts: float) -> float:
    """Spectral radius of the sampled loop at the samples, written out independently: the
    plant's exact ZOH, the forward-Euler ESO with gains 3ω0, 3ω0², ω0³, the law
    u = (-ωc² ξ̂1 - 2ωc ξ̂2 - ξ̂3)/b (r = 0).  State [x1, x2, ξ̂1, ξ̂2, ξ̂3]."""
    aug = np.zeros((3, 3))
    aug[0, 1] = ts
    aug[1, 2] = B * ts
    e = expm(aug)
    php, gp = e[:2, :2], e[:2, 2]
    beta = np.array([3 * W0, 3 * W0**2, W0**3])
    k = np.array([WC**2, 2 * WC])
    u = np.r_[0.0, 0.0, -k, -1.0] / B  # u as a row on the state
    innov = np.r_[1.0, 0.0, -1.0, 0.0, 0.0]  # y - ξ̂1
    m = np.zeros((5, 5))
    m[:2, :2] = php
    m[:2] += np.outer(gp, u)
    eso = np.eye(3) + ts * np.eye(3, k=1)
    m[2:, 2:] = eso
    m[2:] += np.outer(ts * B * np.r_[0.0, 1.0, 0.0], u) + np.outer(ts * beta, innov)
    return float(np.max(np.abs(np.linalg.eigvals(m))))


def test_ts_stable_agrees_with_the_exact_eigenvalues_of_the_sampled_loop():
    """The critical Ts of the linear sampled loop (spectral radius 1, by bisection on the
    exact matrix) is ts_stable to the search's resolution (one dt): the linearised loop's
    spectral radius is a stability criterion, so a slowly growing oscillation that stays
    bounded over the horizon no longer counts as stable."""
    lo, hi = 1e-4, 0.05
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if euler_loop_radius(mid) < 1.0 else (lo, mid)
    lim = sampling_limits(double_integrator("euler"))
    assert lim.ts_stable is not None and lim.ts_stable_bracket[1] is not None
    assert lo - 1e-4 <= lim.ts_stable <= lo < lim.ts_stable_bracket[1] <= lo + 1e-4
    assert 0.005 < lo < 0.02  # ω0·Ts ≈ 0.93: below the observer-alone bound of 2


def test_limits_are_those_of_direct_runs_and_zoh_outlasts_euler():
    euler, zoh = sampling_limits_many([double_integrator("euler"), double_integrator("zoh")])
    assert zoh.ts_stable > euler.ts_stable
    cfg = double_integrator("euler")
    for ts in (euler.ts_stable, euler.ts_max):
        res = replace(cfg, sampling=Sampling(ts, eso="euler")).simulate(store=False)
        assert not res.failed, ts
    # the first unstable Ts: the linearisation says so (its growth is too slow to diverge
    # within the horizon); every run's spectral radius is the independent formula's
    assert euler_loop_radius(euler.ts_stable_bracket[1]) >= 1.0 > euler_loop_radius(euler.ts_stable)
    for p in euler.points:
        assert p.radius == pytest.approx(euler_loop_radius(p.ts), rel=1e-7, abs=1e-9)
        assert p.omega0_ts == pytest.approx(W0 * p.ts)
    itae = replace(cfg, sampling=Sampling(euler.ts_max, eso="euler")).simulate(store=False)
    assert itae.metrics["itae"] <= 1.1 * euler.itae_continuous
    fail = replace(cfg, sampling=Sampling(euler.ts_max_bracket[1], eso="euler"))
    res = fail.simulate(store=False)
    assert res.failed or res.metrics["itae"] > 1.1 * euler.itae_continuous
    # the ladder and the refinements are all in the points, in order
    ts = [p[0] for p in euler.points]
    assert ts == sorted(ts) and euler.ts_max in ts and euler.ts_stable in ts
    assert sampling_figure(euler).axes[0].get_xscale() == "log"


def test_a_continuous_loop_that_diverges_has_no_limits():
    lim = sampling_limits(
        parse_config(
            {
                "plant": "slfjm",
                "scenario": {"t_final": 1.0},
                "controller": {
                    "structure": "LADRC",
                    "n_feedback": 4,
                    "eso": {"omega0": 10.0},
                    "td": {"omega": 10.0},
                    "sef": {"omega_c": 1.0},
                    "law": {"b0": 1.0},  # a b0 far from the plant's 2.68e4: diverges
                },
                "simulation": {"dt": 1e-4},
            }
        )
    )
    assert lim.continuous_diverged
    assert lim.ts_max is None and lim.ts_stable is None


def test_analyze_sampling_cli(tmp_path: Path):
    cfg = tmp_path / "dbl.toml"
    cfg.write_text(
        "\n".join(
            [
                'plant = "pendulum"',
                "[scenario]",
                "t_final = 5.0",
                "plant_overrides = { g = 0.0, c = 0.0 }",
                "[scenario.reference]",
                "amplitude = 0.5",
                "omega = 2.0",
                "[controller]",
                'structure = "LADRC"',
                'td_kind = "exact"',
                "rho = 2",
                "n_feedback = 2",
                "[controller.eso]",
                f"omega0 = {W0}",
                "[controller.sef]",
                f"omega_c = {WC}",
                "[controller.law]",
                f"b0 = {B}",
                "[controller.discrete]",
                "ts = 1e-4",
                'eso = "euler"',
                "[simulation]",
                "dt = 1e-4",
            ]
        )
    )
    runner = CliRunner()
    out = tmp_path / "out"
    res = runner.invoke(app, ["analyze", str(cfg), "--sampling", "--json", "--out", str(out)])
    assert res.exit_code == 0, res.output
    info = json.loads(res.stdout)
    assert {"ts_max", "ts_stable", "itae_continuous", "points"} <= set(info)
    assert info == json.loads((out / "sampling.json").read_text())
    assert (out / "sampling.png").read_bytes()[:4] == b"\x89PNG"
    assert info["ts_stable"] == sampling_limits(double_integrator("euler")).ts_stable
    text = runner.invoke(app, ["analyze", str(cfg), "--sampling"])
    assert text.exit_code == 0 and "ts_max" in text.stdout and "ts_stable" in text.stdout
    for args in (["--sampling", "--tolerance", "0"], ["--sampling", "--closed-loop"]):
        bad = runner.invoke(app, ["analyze", str(cfg), *args, "--out", str(tmp_path / "b")])
        assert bad.exit_code == 2, bad.output
        assert not (tmp_path / "b").exists()


@pytest.mark.parametrize("n_grid", [6, 14])
def test_the_ladder_does_not_change_the_limits_beyond_its_resolution(n_grid):
    """A coarser first ladder refines to the same limits (the brackets close to one dt)."""
    lim = sampling_limits(double_integrator("euler"), n_grid=n_grid, rtol=0.0)
    assert lim.ts_stable_bracket[1] - lim.ts_stable == pytest.approx(1e-4)
    assert lim.ts_stable == pytest.approx(
        0.0092, abs=1e-9
    )  # the exact critical Ts is in [0.0092, 0.0093)
