"""Transport delays: the sampled engine holds an input and an output delay exactly (against
an independent event-by-event scipy path), refuses what it cannot hold naming the field,
and the sampled loop's delay margin (against a closed form and the engine)."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

from aiofl.config import ConfigError, parse_config
from aiofl.controller import Controller
from aiofl.engine.discrete import Sampling, sample_steps
from aiofl.engine.reference import reference_sampled_simulate
from aiofl.engine.sampled import DiscreteController
from aiofl.engine.simulation import simulate
from aiofl.plants import get_plant
from aiofl.plants.base import Plant
from aiofl.scenario import Scenario

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
    with pytest.raises(ValueError, match=r"scenario\.input_delay = 0\.002 s needs a sampled"):
        simulate(slfjm, ladrc(), Scenario(t_final=0.1, input_delay=2e-3))
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
        with pytest.raises(ValueError, match=r"scenario\.output_delay = .*allowed: 0 <="):
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
[simulation]
dt = 1e-4
"""
    cfg = parse_config(tomllib.loads(text))
    assert cfg.scenario.input_delay == 0.002 and cfg.scenario.output_delay == 0.001
    with pytest.raises(ConfigError, match="input_delay"):
        parse_config(tomllib.loads(text.replace("input_delay = 0.002", "input_delay = -1.0")))
    with pytest.raises(ConfigError, match="output_delay"):
        parse_config(tomllib.loads(text.replace("output_delay = 0.001", "output_delay = 5.0")))
