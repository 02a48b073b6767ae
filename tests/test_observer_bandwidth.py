"""The observer bandwidth ceiling (aiofl.analysis.observer_bandwidth): each cap's closed
form, the noise loop equal to the engine's own discrete controller on the ZOH chain, the
noise cap's ω0 giving the stated command noise in a simulated sampled loop, the tune bound
clipped to it, and ``aiofl analyze --ceiling``."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from aiofl.analysis import observer_bandwidth as ob
from aiofl.cli.app import app
from aiofl.components.discrete import eso_zoh
from aiofl.controller import Controller
from aiofl.discrete_controller import DiscreteController
from aiofl.engine.discrete_rows import Sampling

DATA = Path(__file__).parent / "data"


def _ladrc(rho: int, b0: float, w0: float, ts: float, ratio: float = 4.0) -> DiscreteController:
    ctl = Controller(
        eso="linear",
        td="linear",
        sef="linear",
        law="aiofl",
        rho=rho,
        values={"eso.omega0": w0, "sef.omega_c": w0 / ratio, "law.b0": b0, "td.omega": 1.0},
        structure="LADRC",
    )
    dc = DiscreteController(ctl, Sampling(ts=ts, eso="zoh"))
    dc.init(0.0)
    return dc


def _run_chain(dc, rho, b0, ts, n_of_k, quantum=0.0):
    """The engine's controller on the exact ZOH chain y^(rho) = b0 u, r = 0; the
    measurement is x1 + n_k (quantised when quantum > 0); returns the commands."""
    phi, gam = eso_zoh(rho, b0, ts)
    pr, gr = phi[:rho, :rho], gam[:rho]
    x = np.zeros(rho)
    out = np.empty(len(n_of_k))
    for k, n in enumerate(n_of_k):
        y = x[0] + n
        if quantum:
            y = quantum * np.round(y / quantum)
        u = dc.step(0.0, y)
        out[k] = u
        x = pr @ x + gr * u
    return out


# ------------------------------------------------------------------ closed forms
def test_sampling_and_delay_caps_closed_form():
    assert ob.sampling_cap(1e-3).omega0 == pytest.approx(300.0, rel=1e-15)
    assert ob.sampling_cap(2.5e-4).omega0 == pytest.approx(1200.0, rel=1e-15)
    assert math.isinf(ob.sampling_cap(None).omega0)
    assert ob.delay_cap(2e-3).omega0 == pytest.approx(150.0, rel=1e-15)
    assert "told" in ob.delay_cap(1e-3, told=True).rule
    assert math.isinf(ob.delay_cap(0.0).omega0)
    with pytest.raises(ValueError, match="delay"):
        ob.delay_cap(-1.0)
    c = ob.omega0_ceiling(rho=2, b0=1.0, ts=1e-3, delay=5e-3)
    assert c.binding.name == "delay" and c.omega0 == pytest.approx(60.0)
    assert c.to_dict()["binding"] == "delay"


@pytest.mark.parametrize("w0", [30.0, 300.0])
def test_noise_gain_rho1_closed_form(w0):
    """rho = 1: the current observer with both poles at e^(-w0 T) has
    L = (1 - b^2, (1 - b)^2 / T) (Miklosovic et al. 2006), so |F L| =
    (wc (1 - b^2) + (1 - b)^2 / T) / b0."""
    ts, b0, ratio = 1e-3, 7.0, 4.0
    b = math.exp(-w0 * ts)
    want = ((w0 / ratio) * (1 - b * b) + (1 - b) ** 2 / ts) / b0
    assert ob.noise_gain(1, b0, w0, ts, ratio=ratio) == pytest.approx(want, rel=1e-10)


@pytest.mark.parametrize(("rho", "w0"), [(1, 120.0), (2, 200.0), (3, 150.0)])
def test_noise_loop_is_the_engines_loop(rho, w0):
    """The assembled loop's impulse response equals the engine's DiscreteController on
    the ZOH chain (to rounding), and its H2 norm (Lyapunov) the root sum of squares of it."""
    b0, ts = 3.0, 1e-3
    a, b, c, d = ob.noise_loop(rho, b0, w0, ts)
    n = 4000
    impulse = np.zeros(n)
    impulse[0] = 1.0
    engine = _run_chain(_ladrc(rho, b0, w0, ts), rho, b0, ts, impulse[:60])
    z, mine = np.zeros(a.shape[0]), []
    for k in range(n):
        mine.append(c @ z + d * impulse[k])
        z = a @ z + b * impulse[k]
    mine = np.array(mine)
    np.testing.assert_allclose(engine, mine[:60], rtol=0, atol=1e-9 * abs(d))
    assert abs(mine[-1]) < 1e-12 * abs(d)  # decayed: the sum below is the whole norm
    h2 = ob.noise_rms_gain(rho, b0, w0, ts)
    assert h2 == pytest.approx(math.sqrt(np.sum(mine**2)), rel=1e-8)


def test_noise_grows_with_omega0_and_the_cap_meets_the_budget():
    rho, b0, ts, var, scale = 2, 5.0, 1e-3, 1e-6, 2.0
    ws = np.geomspace(5.0, 900.0, 12)
    g = [ob.noise_rms_gain(rho, b0, w, ts) for w in ws]
    assert np.all(np.diff(g) > 0)
    cap = ob.noise_cap(rho, b0, ts, noise_variance=var, u_scale=scale)
    std = math.sqrt(var) * ob.noise_rms_gain(rho, b0, cap.omega0, ts)
    assert std == pytest.approx(ob.NOISE_FRACTION * scale, rel=1e-9)
    # a noise-free sensor does not cap; an enormous noise caps at the search's floor
    assert math.isinf(ob.noise_cap(rho, b0, ts, noise_variance=0.0, u_scale=1.0).omega0)
    # Brent's bracket: the whole range meets the budget, or none of it does
    assert ob.largest_omega0(lambda w: w, 10.0, 1.0, 5.0) == (5.0, "not binding")
    assert ob.largest_omega0(lambda w: w, 0.5, 1.0, 5.0) == (1.0, "exceeded")
    w, how = ob.largest_omega0(lambda w: w**3, 8.0, 1.0, 5.0)
    assert how == "solved" and w == pytest.approx(2.0, rel=1e-10)


# --------------------------------------------------------- simulated sampled loop
@pytest.mark.parametrize(("rho", "quantised"), [(1, False), (2, False), (2, True)])
def test_noise_cap_gives_the_stated_command_noise(rho, quantised):
    """A sensor whose noise the cap should meet at omega0 = 200 rad/s (R_d =
    (NOISE_FRACTION x scale / ||T_nu(200)||_2)^2) gets the cap 200; there, the engine's
    controller on the ZOH chain with that white Gaussian noise -- or a quantiser of step q
    dithered by a Gaussian sigma = q, R_d = sigma^2 + q^2/12 -- sends a command whose std
    is NOISE_FRACTION x the scale, within the estimate's sampling error (20000 samples:
    3 %; measured 1 % over three seeds)."""
    b0, ts, scale = 4.0, 1e-3, 1.5
    r_d = (ob.NOISE_FRACTION * scale / ob.noise_rms_gain(rho, b0, 200.0, ts)) ** 2
    quantum = math.sqrt(r_d / (1.0 + 1.0 / 12.0)) if quantised else 0.0
    sigma = quantum if quantised else math.sqrt(r_d)
    cap = ob.noise_cap(rho, b0, ts, noise_variance=sigma**2 + quantum**2 / 12.0, u_scale=scale)
    assert cap.omega0 == pytest.approx(200.0, rel=1e-9)
    rng = np.random.default_rng(36 + rho)
    n = sigma * rng.standard_normal(21000)
    u = _run_chain(_ladrc(rho, b0, cap.omega0, ts), rho, b0, ts, n, quantum)
    measured = float(np.std(u[1000:]))
    assert measured == pytest.approx(ob.NOISE_FRACTION * scale, rel=0.03)


# ----------------------------------------------------------------- configs, CLI
@pytest.fixture(scope="module")
def config_path(tmp_path_factory) -> Path:
    """The maglev LADRC sampled at 1 ms with a 12-bit encoder's quantum and a noise, with
    a [tune] table tuning eso.omega0."""
    d = tmp_path_factory.mktemp("ceiling")
    shutil.copy(DATA / "maglev.toml", d / "maglev.toml")
    text = (DATA / "maglev-ladrc.toml").read_text()
    discrete = "[controller.discrete]\nts = 1e-3\ny_quantum = 2e-5\n\n[controller.eso]"
    text = text.replace("[controller.eso]", discrete)
    noise = "t_final = 1.0\nnoise_variance = 1e-10\nnoise_hold = 1e-3"
    text = text.replace("t_final = 1.0", noise)
    text += (
        "\n[tune]\npopulation = 4\ngenerations = 1\n[tune.parameters]\n"
        '"eso.omega0" = { lo = 20.0, hi = 2000.0, log = true }\n'
    )
    path = d / "cfg.toml"
    path.write_text(text)
    return path


def test_config_ceiling_reads_the_config(config_path):
    from aiofl.config import load_config

    cfg = load_config(str(config_path))
    c = ob.config_ceiling(cfg)
    names = [cap.name for cap in c.caps]
    assert names == ["sampling", "delay", "noise"]
    assert c.caps[0].omega0 == pytest.approx(300.0)
    var = 1e-10 + (2e-5) ** 2 / 12.0
    noise = c.caps[2]
    assert math.isfinite(noise.omega0)
    _lo, hi = cfg.controller.u_range()
    assert not math.isfinite(hi)  # unbounded: the scale is the holding input's
    assert "|u*|" in noise.rule
    # the cap's omega0 meets the budget at the design's ratio 400/80 = 5, n_feedback = 3
    scale = float(noise.rule.split("|u*| = ")[1].split(",")[0])
    std = math.sqrt(var) * ob.noise_rms_gain(3, -2800.0, noise.omega0, 1e-3, ratio=5.0)
    assert std == pytest.approx(ob.NOISE_FRACTION * scale, rel=1e-3)
    assert c.binding is min((x for x in c.caps), key=lambda x: x.omega0)


def test_analyze_prints_the_ceiling(config_path):
    runner = CliRunner()
    res = runner.invoke(app, ["analyze", str(config_path), "--ceiling"])
    assert res.exit_code == 0, res.output
    assert "observer bandwidth ceiling" in res.output
    assert "sampling  300 rad/s" in res.output and "binding:" in res.output
    assert "ABOVE the ceiling" in res.output or "within the ceiling" in res.output
    res = runner.invoke(app, ["analyze", str(config_path), "--ceiling", "--json"])
    data = json.loads(res.output)
    assert [c["name"] for c in data["caps"]] == ["sampling", "delay", "noise"]
    assert data["binding"] in ("sampling", "noise")
    res = runner.invoke(app, ["analyze", str(config_path), "--ceiling", "--u-scale", "0"])
    assert res.exit_code == 2 and "--u-scale" in res.output


def test_tune_clips_the_omega0_bound(config_path):
    from aiofl.config import load_config
    from aiofl.tuning.search import prepare

    cfg = load_config(str(config_path))
    prep = prepare(cfg, None, omega0_ceiling=True)
    want = ob.config_ceiling(cfg, hold_omega_c=True).omega0
    assert prep.settings.parameters["eso.omega0"].hi == pytest.approx(want, rel=1e-12)
    assert prep.space.hi[0] == pytest.approx(want, rel=1e-12)
    assert any("clipped from 2000" in n for n in prep.notes)
    plain = prepare(cfg, None)
    assert plain.settings.parameters["eso.omega0"].hi == 2000.0 and not plain.notes
    runner = CliRunner()
    res = runner.invoke(app, ["tune", str(config_path), "--check", "--omega0-ceiling"])
    assert res.exit_code == 0, res.output
    assert "omega0 ceiling" in res.output and "clipped" in res.output
    # a ceiling below the bound's lo: refused, naming the setting
    text = config_path.read_text().replace("lo = 20.0", "lo = 1000.0")
    bad = config_path.with_name("bad.toml")
    bad.write_text(text)
    res = runner.invoke(app, ["tune", str(bad), "--check", "--omega0-ceiling"])
    assert res.exit_code == 2 and "omega0_ceiling" in res.output


def test_config_delay_cap_counts_the_loop_delay(config_path):
    """tau = the scenario's input + output delay, plus Ts with a one-sample computation
    delay: 1 ms + 0.5 ms + 1 ms -> omega0 <= 0.3 / 2.5 ms = 120 rad/s."""
    from aiofl.config import load_config

    text = config_path.read_text()
    text = text.replace("noise_hold = 1e-3", "noise_hold = 1e-3\ninput_delay = 1e-3")
    text = text.replace("noise_hold = 1e-3", "noise_hold = 1e-3\noutput_delay = 5e-4", 1)
    text = text.replace("ts = 1e-3\n", "ts = 1e-3\ndelay = 1\n", 1)
    path = config_path.with_name("delayed.toml")
    path.write_text(text)
    delay = ob.config_ceiling(load_config(str(path))).caps[1]
    assert delay.name == "delay" and delay.omega0 == pytest.approx(0.3 / 2.5e-3, rel=1e-12)
