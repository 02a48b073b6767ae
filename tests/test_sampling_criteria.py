"""``aiofl analyze --sampling``'s definition of stable: the linearised sampled loop
(aiofl.analysis.sampled_loop), a bounded run and no extra time at the saturation; against
a closed-form critical sample time, and a loop that is not stable in continuous time."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from aiofl.analysis.sampled_loop import SampledLoop
from aiofl.analysis.sampling_limits import sampling_limits
from aiofl.cli.app import app
from aiofl.config import load_config

BETA, W0, WC = 3.0, 90.0, 10.0

PLANT = """
name = "first_order_sampling"
description = "y' = k u"
states = ["y"]
f = ["0"]
g = ["k"]
h = "y"
[params]
k = 3.0
"""

RUN = """
name = "first-order-ladrc"
plant = "first.toml"
[scenario]
t_final = {t_final}
[scenario.reference]
kind = "sine"
amplitude = 0.5
omega = 2.0
[controller]
structure = "LADRC"
td_kind = "exact"
rho = 1
allow_b0_sign_mismatch = {allow}
[controller.eso]
omega0 = {w0}
[controller.sef]
omega_c = {wc}
[controller.law]
b0 = {b0}
u_max = {u_max}
[controller.discrete]
ts = 1e-4
eso = "euler"
[simulation]
dt = 1e-4
"""


def first_order(tmp_path: Path, b0: float = BETA, u_max: str = "inf", t_final: float = 1.0) -> Path:
    (tmp_path / "first.toml").write_text(PLANT)
    run = tmp_path / "run.toml"
    run.write_text(
        RUN.format(w0=W0, wc=WC, b0=b0, u_max=u_max, allow=str(b0 < 0).lower(), t_final=t_final)
    )
    return run


def euler_radius(ts: float) -> float:
    """ẏ = βu, the forward-Euler ESO (gains 2ω0, ω0²) and u = (ω_c(r − ẑ1) − ẑ2)/b0 with
    b0 = β, r = 0, state (y, ẑ1, ẑ2) at the samples: the matrix written out, its
    characteristic polynomial's roots by numpy."""
    a = ts
    m = np.array(
        [
            [1.0, -a * WC, -a],
            [2 * a * W0, 1.0 - a * WC - 2 * a * W0, 0.0],
            [a * W0**2, -a * W0**2, 1.0],
        ]
    )
    return float(np.max(np.abs(np.roots(np.poly(m)))))


def test_the_critical_ts_of_a_first_order_loop_is_found(tmp_path: Path) -> None:
    """In the errors the matrix is block triangular: the observer's double eigenvalue
    1 − ω0Ts and the tracking eigenvalue 1 − ω_cTs, so the loop is stable iff
    Ts < 2/max(ω0, ω_c) = 2/90 s; ts_stable is that to one dt, and the spectral radius of
    every run is the closed form's."""
    crit = 2.0 / max(W0, WC)
    assert euler_radius(0.999 * crit) < 1.0 < euler_radius(1.001 * crit)
    lim = sampling_limits(load_config(str(first_order(tmp_path))), ts_upper=0.04)
    assert lim.ts_stable is not None
    assert crit - 1e-4 <= lim.ts_stable < crit < lim.ts_stable_bracket[1] <= crit + 1e-4
    assert "linearisation" in lim.first_failure
    for p in lim.points:
        assert p.radius == pytest.approx(euler_radius(p.ts), rel=1e-6)
        assert p.omega0_ts == pytest.approx(W0 * p.ts)
    info = lim.to_dict()
    assert "spectral radius < 1" in info["criteria"] and "bounded" in info["criteria"]
    assert info["points"][0]["fails"] == []


def test_the_linearisation_is_the_continuous_one_at_small_ts(tmp_path: Path) -> None:
    """log(radius)/Ts → the continuous loop's largest real part as Ts → 0."""
    loop = SampledLoop(load_config(str(first_order(tmp_path))))
    assert loop.available and loop.continuous_stable
    slowest = float(np.max(loop.continuous_eigenvalues.real))
    assert np.log(loop.spectral_radius(1e-5)) / 1e-5 == pytest.approx(slowest, rel=2e-3)


def test_a_loop_held_by_the_saturation_is_not_stable(tmp_path: Path) -> None:
    """With |u| ≤ 0.5 (the continuous loop never reaches it) and a 4 s horizon, the sampled
    loop just above the critical Ts grows until the saturation holds it: bounded runs that
    only criterion 3 rejects.  Without the linearisation (criterion 1) they set ts_stable;
    with it the first failure is the linearisation's, at 2/ω0."""
    cfg = load_config(str(first_order(tmp_path, u_max="0.5", t_final=4.0)))
    lim = sampling_limits(cfg, ts_upper=0.04, linearise=False)
    assert lim.saturated_continuous == 0.0
    held = [p for p in lim.points if not p.failed and p.saturated > 0.05]
    assert held and all(p.ts > 2.0 / W0 for p in held)
    assert lim.first_failure == ["saturation"] and lim.ts_stable_bracket[1] in [p.ts for p in held]
    assert lim.ts_stable is not None and lim.ts_stable > 2.0 / W0  # no criterion 1 here
    full = sampling_limits(cfg, ts_upper=0.04)
    assert full.ts_stable < 2.0 / W0 < full.ts_stable_bracket[1]


def test_a_loop_unstable_in_continuous_time_prints_no_ts_stable(tmp_path: Path) -> None:
    run = first_order(tmp_path, b0=-BETA)  # the wrong sign of the input gain
    runner = CliRunner()
    text = runner.invoke(app, ["analyze", str(run), "--sampling"])
    assert text.exit_code == 0, text.output
    assert "ts_stable =" not in text.stdout and "no ts_stable" in text.stdout
    assert "definitions:" in text.stdout
    info = json.loads(runner.invoke(app, ["analyze", str(run), "--sampling", "--json"]).stdout)
    assert info["continuous_diverged"] and info["ts_stable"] is None and info["ts_max"] is None
    assert "criteria" in info


def test_the_one_sample_delay_is_in_the_linearisation(tmp_path: Path) -> None:
    """With ``delay = 1`` the plant gets the previous command (a state u_{k-1}) and so does
    the ESO's prediction: state (y, ẑ1, ẑ2, u_{k-1}), the matrix written out."""
    from dataclasses import replace

    from aiofl.engine.discrete_rows import Sampling

    cfg = load_config(str(first_order(tmp_path)))
    loop = SampledLoop(replace(cfg, sampling=Sampling(1e-4, delay=1, eso="euler")))

    def radius(a: float) -> float:
        m = np.array(
            [
                [1.0, 0.0, 0.0, a * BETA],
                [2 * a * W0, 1 - 2 * a * W0, a, a * BETA],
                [a * W0**2, -(a * W0**2), 1.0, 0.0],
                [0.0, -WC / BETA, -1 / BETA, 0.0],
            ]
        )
        return float(np.max(np.abs(np.linalg.eigvals(m))))

    for ts in (0.005, 0.01, 0.0224, 0.03):
        assert loop.spectral_radius(ts) == pytest.approx(radius(ts), rel=1e-6)
