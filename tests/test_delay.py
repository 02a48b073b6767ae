"""Transport delays: the sampled engine holds an input and an output delay exactly (against
an independent event-by-event scipy path), refuses what it cannot hold naming the field,
and the sampled loop's delay margin (against a closed form and the engine)."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

from aiofl.config import ConfigError, parse_config
from aiofl.controller import Controller
from aiofl.discrete_controller import DiscreteController
from aiofl.engine.discrete_rows import Sampling, sample_steps
from aiofl.engine.reference_sampled import reference_sampled_simulate
from aiofl.engine.simulation import simulate
from aiofl.plants import get_plant
from aiofl.plants.base import Plant
from aiofl.scenario import Scenario
from test_sampling_criteria import PLANT

BETA_SLFJM = 1.61 * 0.00767 * 70.0 / (0.0059 * 0.0021 * 2.6)


def ladrc(**values: float) -> Controller:
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


@pytest.mark.parametrize(
    ("tin", "tout", "samp"),
    [
        (2e-3, 0.0, Sampling(1e-3)),
        (1.3e-3, 0.7e-3, Sampling(1e-3)),
        (0.5e-3, 2e-3, Sampling(1e-3, delay=1)),
    ],
)
def test_delays_in_the_engine_equal_the_event_by_event_reference(slfjm, tin, tout, samp):
    """The engine's applied command and ADC reading at every sample equal the independent
    scipy path's (the plant between events by DOP853, the delays as event times)."""
    scen = Scenario(t_final=0.4, input_delay=tin, output_delay=tout)
    dt = 1e-4
    n_per = sample_steps(samp.ts, dt)
    res = simulate(slfjm, ladrc(), scen, sampling=samp, dt=dt, decimation=n_per)
    ref = reference_sampled_simulate(slfjm, ladrc(), scen, samp)
    n = ref.t.size
    np.testing.assert_allclose(res.t[:n], ref.t, atol=1e-12)
    scale_u = np.max(np.abs(ref.u))
    scale_y = np.max(np.abs(ref.y_meas))
    assert scale_u > 0 and scale_y > 0
    np.testing.assert_allclose(res["u"][:n], ref.u, rtol=0, atol=1e-6 * scale_u)
    np.testing.assert_allclose(res["y_meas"][:n], ref.y_meas, rtol=0, atol=1e-7 * scale_y)
    # and the delays are there: the command is 0 until τ_in, y_meas lags y by τ_out
    m_in = round(tin / samp.ts + 1e-9) if tin % samp.ts < 1e-12 else int(tin // samp.ts) + 1
    assert np.all(res["u"][:m_in] == 0.0)


def test_an_input_delay_shifts_the_commands_of_the_replayed_controller(slfjm):
    """Replaying the engine's measurements through the discrete controller gives its
    commands; the plant saw them k samples later (to rounding: the replay is compiled
    with the components' fast-math flags)."""
    samp = Sampling(1e-3)
    scen = Scenario(t_final=0.3, input_delay=3e-3)
    res = simulate(slfjm, ladrc(), scen, sampling=samp, dt=1e-4, decimation=10)
    dc = DiscreteController(ladrc(), samp)
    dc.init(res["y_meas"][0])
    u = np.array([dc.step(r, y) for r, y in zip(res["r"][:-1], res["y_meas"][:-1], strict=True)])
    scale = np.max(np.abs(u))
    expect = np.r_[np.zeros(3), u[:-3]]
    np.testing.assert_allclose(res["u"][:-1], expect, rtol=0, atol=1e-12 * scale)


def test_a_sensor_delay_reads_the_stored_output(slfjm):
    samp = Sampling(1e-3)
    res = simulate(
        slfjm, ladrc(), Scenario(t_final=0.2, output_delay=2e-3), sampling=samp, decimation=10
    )
    ym, y = res["y_meas"][:-1], res["y"][:-1]
    np.testing.assert_array_equal(ym[2:], y[:-2])
    np.testing.assert_array_equal(ym[:2], y[0])


def test_no_delay_is_bitwise_the_old_loop_in_a_mixed_group(slfjm):
    samp = Sampling(1e-3)
    from aiofl.engine.simulation import simulate_batch

    scens = [Scenario(t_final=0.2), Scenario(t_final=0.2, input_delay=1e-3)]
    res = simulate_batch(slfjm, [ladrc()] * 2, scens, sampling=samp)
    alone = simulate_batch(slfjm, [ladrc()], scens[0], sampling=samp)
    np.testing.assert_array_equal(res.metrics[0], alone.metrics[0])
    assert not np.array_equal(res.metrics[1], alone.metrics[0])


def test_delays_that_cannot_be_held_are_refused_naming_the_field(slfjm):
    with pytest.raises(ValueError, match=r"scenario\.input_delay = 0\.00015 s is not an integer"):
        simulate(slfjm, ladrc(), Scenario(t_final=0.1, input_delay=1.5e-4))
    with pytest.raises(ValueError, match=r"scenario\.output_delay = 0\.00015 s is not an integer"):
        simulate(
            slfjm,
            ladrc(),
            Scenario(t_final=0.1, output_delay=1.5e-4),
            sampling=Sampling(1e-3),
        )
    with pytest.raises(ValueError, match=r"at most 65536 steps"):
        simulate(
            slfjm,
            ladrc(),
            Scenario(t_final=0.1, input_delay=0.9),
            sampling=Sampling(1e-3),
            dt=1e-5,
        )
    for bad in (-1e-3, 2.0, float("nan")):
        with pytest.raises(ValueError, match=r"scenario\.output_delay = .*allowed:"):
            Scenario(output_delay=bad)


def test_delays_in_toml():
    text = """
plant = "slfjm"
[scenario]
t_final = 1.0
input_delay = 0.002
output_delay = 0.001
[controller]
structure = "LADRC"
[controller.eso]
omega0 = 50.0
[controller.td]
omega = 20.0
[controller.sef]
omega_c = 10.0
[controller.law]
b0 = 26833.0
[controller.discrete]
ts = 1e-3
[simulation]
dt = 1e-4
"""
    cfg = parse_config(tomllib.loads(text))
    assert cfg.scenario.input_delay == 0.002 and cfg.scenario.output_delay == 0.001
    # a continuous controller holds them too (issue 36; method of steps, tests/test_rig.py)
    continuous = text.replace("[controller.discrete]\nts = 1e-3\n", "")
    cfg = parse_config(tomllib.loads(continuous))
    assert cfg.sampling is None and cfg.scenario.input_delay == 0.002
    with pytest.raises(ConfigError, match="input_delay"):
        parse_config(tomllib.loads(text.replace("input_delay = 0.002", "input_delay = -1.0")))
    with pytest.raises(ConfigError, match="output_delay"):
        parse_config(tomllib.loads(text.replace("output_delay = 0.001", "output_delay = 5.0")))
    with pytest.raises(ConfigError, match=r"scenario\.output_delay = 0\.00015 s is not an integer"):
        parse_config(tomllib.loads(text.replace("output_delay = 0.001", "output_delay = 1.5e-4")))


# ----------------------------------------------------------------- the delay margin
# the first-order plant file of the sampling-criteria tests (one plant: one kernel compiled)
FIRST_ORDER_PLANT = PLANT

FIRST_ORDER_RUN = """
name = "first-order-ladrc"
plant = "first.toml"
[scenario]
t_final = 1.0
[controller]
structure = "LADRC"
td_kind = "exact"
rho = 1
[controller.eso]
omega0 = 90.0
[controller.sef]
omega_c = 10.0
[controller.law]
b0 = 3.0
[controller.discrete]
ts = 1e-3
eso = "euler"
[simulation]
dt = 1e-4
"""


def first_order_radius(ts: float, delay: float, beta: float = 3.0) -> float:
    r"""ẏ = βu with the forward-Euler ESO (gains 2ω0, ω0²), u = (ω_c(r − ẑ1) − ẑ2)/β, r = 0,
    and a transport delay τ = kTs + θ: the plant sees :math:`v_{i-k}` for :math:`T_s - θ`
    and :math:`v_{i-k-1}` for θ of each interval, so
    :math:`y^+ = y + β(T_s - θ)v_{i-k} + βθ v_{i-k-1}`; state (y, ẑ1, ẑ2, v_{i-1}, ...,
    v_{i-k-1}) written out, the roots of its characteristic polynomial by numpy."""
    w0, wc = 90.0, 10.0
    k = int(np.floor(delay / ts + 1e-12))
    theta = delay - k * ts
    n = 3 + k + 1
    m = np.zeros((n, n))
    u_row = np.zeros(n)
    u_row[1], u_row[2] = -wc / beta, -1.0 / beta  # u_i from ẑ1, ẑ2
    m[0, 0] = 1.0
    # the plant: v_{i-k} (u_i itself when k = 0) for Ts - θ, v_{i-k-1} for θ
    if k == 0:
        m[0] += beta * (ts - theta) * u_row
    else:
        m[0, 3 + k - 1] += beta * (ts - theta)
    m[0, 3 + k] += beta * theta
    # the observer (it knows its own command, undelayed): b0 u = β u
    m[1, 0], m[1, 1], m[1, 2] = 2 * ts * w0, 1.0 - 2 * ts * w0, ts
    m[1] += ts * beta * u_row
    m[2, 0], m[2, 1], m[2, 2] = ts * w0**2, -ts * w0**2, 1.0
    m[3] = u_row  # v_{i-1}^+ = u_i
    for j in range(1, k + 1):
        m[3 + j, 3 + j - 1] = 1.0
    return float(np.max(np.abs(np.roots(np.poly(m)))))


def test_the_sampled_delay_margin_of_a_first_order_loop_is_the_closed_forms(tmp_path):
    """The linearised sampled loop with a delay has the closed form's spectral radius at
    whole and fractional delays, and its margin is the closed form's (bisected here)."""
    from aiofl.analysis.sampled_loop import SampledLoop
    from aiofl.config import load_config

    (tmp_path / "first.toml").write_text(FIRST_ORDER_PLANT)
    (tmp_path / "run.toml").write_text(FIRST_ORDER_RUN)
    loop = SampledLoop(load_config(str(tmp_path / "run.toml")))
    ts = 1e-3
    for d in (0.0, 1e-3, 2.5e-3, 4e-3, 7.3e-3, 12e-3):
        m = loop.matrix(ts, d)
        got = float(np.max(np.abs(np.linalg.eigvals(m))))
        assert got == pytest.approx(first_order_radius(ts, d), rel=1e-7), d
    # the closed form's margin: whole samples first, then bisection within the sample
    k = 0
    while first_order_radius(ts, (k + 1) * ts) < 1.0:
        k += 1
    lo, hi = k * ts, (k + 1) * ts
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if first_order_radius(ts, mid) < 1.0 else (lo, mid)
    margin = loop.delay_margin(ts)
    assert 2 * ts < margin < 100 * ts
    assert margin == pytest.approx(lo, rel=2e-4)
    # the continuous loop's margin is approached as Ts → 0
    cont = loop.continuous_delay_margin()
    assert loop.delay_margin(1e-4) == pytest.approx(cont, rel=1e-2)


def test_frontier_sampled_delay_margin_at_1ms_against_the_engine():
    """frontier-s1-ladrc at Ts = 1 ms: the independent analysis puts the margin at 2.2 ms
    (a C harness: stable at 2.1, diverging from 2.3 ms); the continuous margin is 1.95 ms.
    The engine with the input delay agrees."""
    from aiofl.analysis.sampled_loop import SampledLoop
    from aiofl.config import load_config

    cfg = load_config("frontier-s1-ladrc")
    loop = SampledLoop(cfg)
    margin = loop.delay_margin(1e-3)
    assert 2.0e-3 < margin < 2.4e-3
    assert loop.continuous_delay_margin() == pytest.approx(1.95e-3, abs=0.01e-3)
    scens = [Scenario(t_final=2.0, input_delay=d) for d in (2.1e-3, 2.3e-3)]
    from aiofl.engine.simulation import simulate_batch

    res = simulate_batch(cfg.plant, [cfg.controller] * 2, scens, sampling=Sampling(1e-3), dt=1e-4)
    # past the margin the loop oscillates with a growing amplitude: within 2 s the output
    # swings by radians (inside the default envelope of ten times max |r|) and u by MV
    assert not res.failed[0] and res.response["e_peak"][0] < 0.1
    assert res.failed[1] or res.response["e_peak"][1] > 100 * res.response["e_peak"][0]


def test_analyze_sampling_reports_both_delay_margins(tmp_path):
    import json

    from typer.testing import CliRunner

    from aiofl.analysis.sampled_loop import SampledLoop
    from aiofl.cli.app import app
    from aiofl.config import load_config

    (tmp_path / "first.toml").write_text(FIRST_ORDER_PLANT)
    run = tmp_path / "run.toml"
    run.write_text(FIRST_ORDER_RUN.replace("t_final = 1.0", "t_final = 0.5"))
    loop = SampledLoop(load_config(str(run)))
    runner = CliRunner()
    res = runner.invoke(app, ["analyze", str(run), "--sampling", "--json"])
    assert res.exit_code == 0, res.output
    info = json.loads(res.stdout)
    assert info["delay_ts"] == 1e-3  # the config's [controller.discrete] ts
    assert info["delay_margin_sampled_s"] == pytest.approx(loop.delay_margin(1e-3), rel=1e-9)
    assert info["delay_margin_continuous_s"] == pytest.approx(loop.continuous_delay_margin())
    text = runner.invoke(app, ["analyze", str(run), "--sampling"]).stdout
    assert "delay margin at Ts = 0.001 s: sampled" in text and "continuous" in text


def test_the_report_note_gives_both_delay_margins():
    from aiofl.reporting.sampling_note import sampling_paragraph

    lim = {
        "tolerance": 0.1,
        "dt": 1e-4,
        "ts_upper": 0.05,
        "ts_max": 2e-3,
        "ts_stable": 3e-3,
        "ts_max_bracket": [2e-3, 2.1e-3],
        "ts_stable_bracket": [3e-3, 3.1e-3],
        "continuous_diverged": False,
        "itae_continuous": 0.01,
        "delay_ts": 1e-3,
        "delay_margin_sampled_s": 2.2e-3,
        "delay_margin_continuous_s": 1.95e-3,
    }
    text = " ".join(sampling_paragraph([("LADRC", "a", "frontier", 1)], {"a": lim}))
    assert "sampled at Ts = 1 ms" in text
    assert "LADRC of scenario 1 2.2 ms (continuous 1.95 ms)" in text
