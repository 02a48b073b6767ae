"""The loop as an engineer reads it: disk margins against closed forms and python-control,
the rig's lag and measurement delay in the sampled loop, LADRC's 2-DOF form against the
engine's simulated loop, and the noise-to-u RMS against a simulated noisy loop."""

from __future__ import annotations

import math
from types import SimpleNamespace

import control
import numpy as np
import pytest

from aiofl.analysis.loop_view import disk_margin, format_loop_view_text, loop_view, rig_loop
from aiofl.analysis.sampled_loop import SampledLoop, zoh
from aiofl.analysis.two_dof import format_two_dof_text, ladrc_two_dof, two_dof_closed_loop
from aiofl.controller import Controller
from aiofl.discrete_controller import DiscreteController
from aiofl.engine.discrete_rows import Sampling
from aiofl.plants.symbolic import SymbolicPlant
from aiofl.scenario import Reference, Scenario
from chain_plant import chain3

GAIN = 2.0  # the chain's input gain: y''' = GAIN u
TS = 1e-3


def ladrc(td: str = "linear", b0: float = 1.6) -> Controller:
    """ρ = 3 LADRC with a wrong b0 (so C and F are not the textbook cancellation)."""
    c = Controller(eso="linear", td=td, sef="linear", law="aiofl", rho=3, n_feedback=3)
    return c.with_values(
        **{
            "law.b0": b0,
            "eso.omega0": 40.0,
            "sef.omega_c": 8.0,
            "td.omega": 15.0,
            "law.u_max": 1e6,
        }
    ).with_binomial_alphas()


def plant_tf() -> control.TransferFunction:
    return control.tf([GAIN], [1.0, 0.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def sym_chain():
    states = ["x1", "x2", "x3"]
    return SymbolicPlant.from_strings(
        "chain3s", states, {"k": GAIN}, ["x2", "x3", "0"], ["0", "0", "k"], "x1"
    ).to_plant()


def config(plant, ctrl, delay: int = 0, y_quantum: float = 0.0) -> SimpleNamespace:
    scen = Scenario(reference=Reference(kind="step", amplitude=0.5), t_final=2.0)
    samp = Sampling(TS, delay=delay, y_quantum=y_quantum)
    return SimpleNamespace(
        plant=plant, controller=ctrl, scenario=scen, sampling=samp, dt=1e-4, name="chain"
    )


# ------------------------------------------------------------------ disk margins
@pytest.mark.parametrize("k", [0.2, 0.5, 0.8])
def test_disk_margin_of_a_gain_and_a_delay_has_its_closed_form(k: float) -> None:
    """L(z) = k/z: (S − T)/2 = (z − k)/(2(z + k)) peaks at z = −1, so α = 2(1 − k)/(1 + k),
    the disk gain margin (1 + α/2)/(1 − α/2) = 1/k (the classical one) and the disk phase
    margin 2·atan(α/2) = 90° − 2·atan(k) (Seiler, Packard & Gahinet 2020, eqs. 6–10)."""
    loop = control.tf([k], [1.0, 0.0], TS)
    w = np.logspace(-1, math.log10(math.pi / TS), 500)
    alpha, dgm, dpm, w_worst = disk_margin(loop, w)
    assert alpha == pytest.approx(2 * (1 - k) / (1 + k), rel=1e-9)
    assert dgm == pytest.approx(-20 * math.log10(k), rel=1e-9)
    assert dpm == pytest.approx(90.0 - 2 * math.degrees(math.atan(k)), rel=1e-9)
    assert w_worst == pytest.approx(math.pi / TS)
    ref = control.disk_margins(loop, w)
    assert (alpha, dgm, dpm) == pytest.approx(tuple(float(v) for v in ref), rel=1e-12)


def test_disk_margin_of_an_all_pass_loop() -> None:
    """L(s) = k(1 − s)/(1 + s): |L| = k, the phase falls to −180° as ω → ∞, so the same
    closed form as k/z holds in the limit: α → 2(1 − k)/(1 + k)."""
    k = 0.5
    loop = control.tf([-k, k], [1.0, 1.0])
    alpha, dgm, _, _ = disk_margin(loop, np.logspace(-2, 7, 2000))
    assert alpha == pytest.approx(2 * (1 - k) / (1 + k), rel=1e-6)
    assert dgm == pytest.approx(-20 * math.log10(k), rel=1e-5)


# ------------------------------------------------------------------ the rig's loop
@pytest.fixture(scope="module")
def sampled(sym_chain):
    return {d: SampledLoop(config(sym_chain, ladrc(), delay=d)) for d in (0, 1)}


@pytest.mark.parametrize("delay", [0, 1])
def test_rig_loop_without_lag_or_delay_is_the_sampled_loop(sampled, delay: int) -> None:
    loop = sampled[delay]
    rig = rig_loop(loop, TS)
    a, b, c = loop.broken_loop(TS)
    assert np.array_equal(rig.a, a) and np.array_equal(rig.b, b) and np.array_equal(rig.c, c)
    assert np.allclose(rig.a_cl, loop.matrix(TS), rtol=0, atol=1e-12)


@pytest.mark.parametrize("d", [1, 3])
def test_measurement_delay_equals_a_transport_delay_of_whole_samples(sampled, d: int) -> None:
    """d samples of measurement delay and a transport delay d·Ts at the plant input give the
    same loop (a delay commutes with the plant): equal closed-loop spectra."""
    loop = sampled[0]
    rig = rig_loop(loop, TS, delay_samples=d)
    mine = np.sort_complex(np.linalg.eigvals(rig.a_cl))
    ref = np.sort_complex(np.linalg.eigvals(loop.matrix(TS, d * TS)))
    # the shift registers differ by eigenvalues at 0 only (Jordan blocks: computed ~1e-5)
    assert np.max(np.abs(mine)) == pytest.approx(np.max(np.abs(ref)), rel=1e-9)
    assert np.allclose(mine[np.abs(mine) > 1e-2], ref[np.abs(ref) > 1e-2], rtol=1e-8)


def test_lag_enters_as_its_zoh_discretisation(sampled) -> None:
    """The lag's state follows a' = (u − a)/τ exactly between samples: with the plant's
    input held at 1 for one sample from rest, the lag's state ends at 1 − e^{−Ts/τ}."""
    tau = 2e-3
    rig = rig_loop(sampled[0], TS, lag=tau)
    n = sampled[0].ap.shape[0]
    x1 = rig.b[: n + 1, 0]  # one sample of a unit held input from rest
    assert x1[n] == pytest.approx(1 - math.exp(-TS / tau), rel=1e-12)
    # a vanishing lag gives back the lag-free loop's margins
    base = loop_view_rows(sampled[0], 0.0)
    tiny = loop_view_rows(sampled[0], 1e-9)
    assert tiny["phase_margin_deg"] == pytest.approx(base["phase_margin_deg"], rel=1e-5)


def loop_view_rows(loop: SampledLoop, lag: float) -> dict:
    from aiofl.analysis.sampled_loop import unit_circle_margins

    rig = rig_loop(loop, TS, lag=lag)
    return unit_circle_margins(rig.a, rig.b, rig.c, TS)


@pytest.mark.parametrize("delay", [0, 1])
def test_sampled_disk_margin_equals_python_controls_on_the_2dof_loop(sampled, delay) -> None:
    """The sampled loop's disk margin (linearised engine update, rig_loop) equals
    python-control's on P(z)·C(z) built from the 2-DOF form and the ZOH plant."""
    rig = rig_loop(sampled[delay], TS)
    form = ladrc_two_dof(ladrc(), Sampling(TS, delay=delay))
    pd = control.c2d(control.ss(plant_tf()), TS, "zoh")
    w = np.logspace(-1, math.log10(math.pi / TS), 1500)
    ref_loop = control.series(form.feedback_ss, pd)
    ours = control.disk_margins(rig.loop_transfer(), w)
    ref = control.disk_margins(ref_loop, w)
    assert tuple(float(v) for v in ours) == pytest.approx(tuple(float(v) for v in ref), rel=1e-7)
    # disk_margin refines python-control's grid minimum: the same or a little smaller
    mine = disk_margin(rig.loop_transfer(), w)
    assert mine[:3] == pytest.approx(disk_margin(ref_loop, w)[:3], rel=1e-7)
    assert ref[0] * (1 - 1e-3) <= mine[0] <= ref[0]
    # and the noise path n -> u is -C/(1 + PC) (rig: the command computed at the sample,
    # C: the one the DAC applies, one sample later with the computation delay)
    tn = control.feedback(-form.feedback_ss, pd, sign=1)
    z = np.exp(1j * np.array([1.0, 30.0, 300.0, 3000.0]) * TS)
    expected = np.ravel(tn(z)) * z**delay
    assert np.allclose(np.ravel(rig.noise_transfer()(z)), expected, rtol=1e-7)


# ------------------------------------------------------------------ the 2-DOF form
@pytest.fixture(scope="module")
def engine_step():
    """The engine's continuous loop on the chain y''' = 2u (a compiled kernel shared with
    tests/test_plant_table.py), a 0.5 step through the linear prefilter."""
    from aiofl.engine.simulation import simulate

    scen = Scenario(reference=Reference(kind="step", amplitude=0.5), t_final=1.5)
    return simulate(chain3(0.0, 0.0, GAIN), ladrc(), scen, dt=1e-4, decimation=5)


def test_continuous_2dof_step_response_equals_the_engines(engine_step) -> None:
    res = engine_step
    form = ladrc_two_dof(ladrc())
    assert form.dt is None and form.reference_inputs == ("r",)
    u_step = 0.5 * np.ones_like(res.t)
    cl = control.forced_response(two_dof_closed_loop(form, plant_tf()), T=res.t, U=u_step)
    assert np.max(np.abs(cl.outputs[0] - res["y"])) < 1e-9
    assert np.max(np.abs(cl.outputs[1] - res["u"])) < 1e-8 * np.max(np.abs(res["u"]))
    # the TransferFunction objects themselves: y/r = P F / (1 + P C)
    tf = control.feedback(plant_tf(), form.feedback) * form.prefilter
    y_tf = control.forced_response(tf, T=res.t, U=u_step).outputs
    assert np.max(np.abs(y_tf - res["y"])) < 1e-5


def discrete_run(ctrl, samp: Sampling, n: int, r, noise=None):
    """The engine's discrete controller (its compiled update) on the exact ZOH model of
    the chain: y_k, u_k (the command the DAC applies over [t_k, t_k+1))."""
    a = np.eye(3, k=1)
    b = np.array([[0.0], [0.0], [GAIN]])
    phi, gam = zoh(a, b, TS)
    dc = DiscreteController(ctrl, samp)
    dc.init(0.0)
    x = np.zeros(3)
    ys, us = np.empty(n), np.empty(n)
    u_prev = 0.0
    for k in range(n):
        ys[k] = x[0]
        u = dc.step(r[k], x[0] + (0.0 if noise is None else noise[k]))
        ua = u_prev if samp.delay else u
        us[k] = ua
        u_prev = u
        x = phi @ x + gam[:, 0] * ua
    return ys, us


@pytest.mark.parametrize("delay", [0, 1])
@pytest.mark.parametrize("td", ["linear", "exact"])
def test_discrete_2dof_step_response_equals_the_engines_controller(delay: int, td: str) -> None:
    """The sampled 2-DOF form (the engine's discrete rows) on the ZOH plant reproduces the
    engine's discrete controller stepping the same plant, to rounding; with the exact TD
    its F has a column per derivative (a sine reference and its derivatives)."""
    ctrl = ladrc(td)
    samp = Sampling(TS, delay=delay)
    n = 1500
    t = np.arange(n) * TS
    if td == "linear":
        r = [0.5] * n
        u_in = 0.5 * np.ones((1, n))
    else:
        w = 3.0
        u_in = np.array([0.4 * w**i * np.sin(w * t + i * math.pi / 2) for i in range(4)])
        r = list(u_in.T)
    ys, us = discrete_run(ctrl, samp, n, r)
    form = ladrc_two_dof(ctrl, samp)
    assert form.dt == TS and len(form.reference_inputs) == (1 if td == "linear" else 4)
    pd = control.c2d(control.ss(plant_tf()), TS, "zoh")
    cl = control.forced_response(two_dof_closed_loop(form, pd), T=t, U=u_in)
    assert np.max(np.abs(cl.outputs[0] - ys)) < 1e-10 * max(1.0, np.max(np.abs(ys)))
    assert np.max(np.abs(cl.outputs[1] - us)) < 1e-9 * np.max(np.abs(us))
    text = "\n".join(format_two_dof_text([form]))
    assert "C(z) = " in text and ("F(z)" in text or "F_r_d3(z)" in text)


def test_2dof_refuses_a_nonlinear_controller() -> None:
    c = Controller(eso="improved", td="han", sef="nonlinear", rho=2, n_feedback=2)
    with pytest.raises(ValueError, match=r"eso = 'improved'.*sef = 'nonlinear'"):
        ladrc_two_dof(c)


# ------------------------------------------------------------------ noise in u
def test_predicted_noise_rms_in_u_equals_the_simulated(sym_chain) -> None:
    """White measurement noise σ = 1e-3 per sample on the sampled loop: the RMS of u
    predicted by the H2 norm of the linearised loop (loop_view) equals the RMS of u in a
    simulated noisy loop (the engine's discrete controller, r = 0) within sampling error."""
    sigma, n, skip = 1e-3, 60000, 3000
    cfg = config(sym_chain, ladrc(), delay=1)
    view = loop_view(cfg, noise_std=sigma)
    row = next(r for r in view["rows"] if r["label"].startswith("sampled"))
    assert row["label"] == "sampled at Ts = 1 ms: ZOH + 1-sample computation delay"
    predicted = row["noise_to_u"]["u_rms"]
    noise = np.random.default_rng(7).normal(0.0, sigma, n)
    _, us = discrete_run(ladrc(), Sampling(TS, delay=1), n, [0.0] * n, noise)
    simulated = float(np.sqrt(np.mean(us[skip:] ** 2)))
    assert simulated == pytest.approx(predicted, rel=0.03)
    # a quantum q is noise of variance q²/12 (the config's own when no σ is given)
    q = 2 * math.pi / 4096
    view_q = loop_view(config(sym_chain, ladrc(), delay=1, y_quantum=q))
    row_q = next(r for r in view_q["rows"] if r["label"].startswith("sampled"))
    assert view_q["noise_std"] == pytest.approx(q / math.sqrt(12))
    assert row_q["noise_to_u"]["u_rms"] == pytest.approx(predicted * q / math.sqrt(12) / sigma)
    assert "moves u by" in "\n".join(format_loop_view_text(view_q, "rad", "V "))


def test_loop_view_rows_are_labelled_with_what_they_include(sym_chain) -> None:
    view = loop_view(config(sym_chain, ladrc()), lag=1e-3, delay_samples=1)
    labels = [r["label"] for r in view["rows"]]
    assert labels == [
        "continuous, ideal",
        "continuous + 1 ms actuator lag",
        "sampled at Ts = 1 ms: ZOH + 0-sample computation delay",
        "sampled at Ts = 1 ms: ZOH + 0-sample computation delay + 1 ms actuator lag",
        "sampled at Ts = 1 ms: ZOH + 0-sample computation delay + 1 sample measurement delay",
        "sampled at Ts = 1 ms: ZOH + 0-sample computation delay + 1 ms actuator lag"
        " + 1 sample measurement delay",
    ]
    rows = view["rows"]
    assert all(r["stable"] for r in rows)
    # what the rig adds costs phase: each added element lowers the disk margin
    assert rows[2]["disk_margin"] > rows[3]["disk_margin"] > rows[5]["disk_margin"]
    assert rows[2]["disk_margin"] > rows[4]["disk_margin"] > rows[5]["disk_margin"]
    assert rows[0]["disk_margin"] > rows[1]["disk_margin"]
    # the disk margin is never more generous than the classical margins
    for r in rows:
        assert r["disk_gain_margin_db"] <= r["gain_margin_db"] + 1e-9
        assert r["disk_phase_margin_deg"] <= r["phase_margin_deg"] + 1e-9
    # a measurement delay of one sample costs about Ts of delay margin
    assert rows[2]["delay_margin_s"] - rows[4]["delay_margin_s"] == pytest.approx(TS, rel=1e-6)


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"lag": -1e-3}, "lag"),
        ({"lag": float("nan")}, "lag"),
        ({"delay_samples": 1.5}, "delay_samples"),
        ({"delay_samples": 10**6}, "delay_samples"),
        ({"noise_std": -1.0}, "noise_std"),
    ],
)
def test_bad_options_are_named(sym_chain, kw, match) -> None:
    with pytest.raises(ValueError, match=match):
        loop_view(config(sym_chain, ladrc()), **kw)
