"""A start at the operating point: ``[controller.eso] u0`` (a number, or "trim").

The extended state starts at :math:`\\hat\\xi_{\\rho+1}(0) = -b_0 u_0`, the total
disturbance of a plant held by :math:`u_0`, so the first command is :math:`u_0` and a plant
resting at its operating point stays there (industry's bumpless transfer).  The same start
in the continuous engine, the slow reference path, the sampled engine, the
DiscreteController, the exported C (``aiofl_start`` reads ``p->u0``; ``aiofl_start_at``
takes a command to carry over) and the FMU's parameters.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from aiofl.cli.configs import load_run_config
from aiofl.config import ConfigError
from aiofl.config.objects import controller_table
from aiofl.controller import Controller
from aiofl.discrete_controller import DiscreteController
from aiofl.engine.discrete_rows import Sampling
from aiofl.engine.reference import reference_simulate
from aiofl.engine.simulation import simulate
from aiofl.export import export_c
from aiofl.export.c_check import CC, CController, build, loop
from aiofl.export.fmu import fmu_parameters
from aiofl.plants import get_plant
from aiofl.plants.operating_point import trim
from aiofl.scenario import Reference, Scenario

DATA = Path(__file__).parent / "data"
PEND = get_plant("pendulum")
Y0 = 0.3  # the pendulum held at 0.3 rad (u_e = m g l sin(0.3) / ... from trim)
needs_cc = pytest.mark.skipif(CC is None, reason="no C compiler 'cc' on PATH")


def _u_hold() -> float:
    return trim(PEND, Y0).u


def _ladrc(u0: float, init: str = "bumpless") -> Controller:
    vals = {"law.b0": 4.0, "eso.omega0": 60.0, "sef.omega_c": 7.5, "td.omega": 15.0}
    ctrl = Controller.from_structure("LADRC", rho=2, n_feedback=2, values=vals, eso_init=init)
    return ctrl.with_binomial_alphas().with_values(**{"eso.u0": u0})


def _held_scenario(t_final: float = 1.0) -> Scenario:
    return Scenario(t_final=t_final, reference=Reference(amplitude=0.0, offset=Y0), x0=(Y0, 0.0))


@pytest.fixture(scope="module")
def maglev_runs() -> dict[str, dict[bool, object]]:
    """The maglev held at 1 cm, its 1-mm step at 0.2 s: started at u = 0
    (``maglev-ladrc.toml``) and at u_e (``maglev-ladrc-trim.toml``: ``u0 = "trim"``)."""
    runs: dict[str, dict[bool, object]] = {}
    for name, file in (("zero", "maglev-ladrc.toml"), ("trim", "maglev-ladrc-trim.toml")):
        cfg = load_run_config(DATA / file)
        runs[name] = {False: cfg.simulate(), True: cfg.with_sample_time(1e-4).simulate()}
    return runs


@pytest.mark.parametrize("sampled", [False, True], ids=["continuous", "sampled"])
def test_the_maglev_started_at_its_holding_input_does_not_sag(maglev_runs, sampled):
    """u0 = "trim": u(0) = u_e = 0.7004 (the trim), the ball stays within 1e-8 m of 1 cm
    until the step; started at u = 0 it drops 0.58-0.6 mm before the observer catches up."""
    held, dropped = maglev_runs["trim"][sampled], maglev_runs["zero"][sampled]
    cfg = load_run_config(DATA / "maglev-ladrc.toml")
    u_e = trim(cfg.plant, 0.01, x_guess=cfg.scenario.x0).u
    before = held.t < 0.2  # type: ignore[attr-defined]
    assert held["u"][0] == pytest.approx(u_e, rel=1e-12)  # type: ignore[index]
    assert np.max(np.abs(held["y"][before] - 0.01)) < 1e-8  # type: ignore[index]
    sag = 0.01 - np.min(dropped["y"][dropped.t < 0.2])  # type: ignore[index, attr-defined]
    assert sag > 4e-4 and dropped["u"][0] == 0.0  # type: ignore[index]
    assert held.status == "ok" and dropped.status == "ok"  # type: ignore[attr-defined]


def test_u0_trim_resolves_to_the_holding_input_and_round_trips(tmp_path):
    text = (
        (DATA / "maglev-ladrc.toml")
        .read_text()
        .replace('init = "bumpless"', 'init = "bumpless"\nu0 = "trim"')
    )
    path = tmp_path / "trim.toml"
    path.write_text(text.replace('plant = "maglev.toml"', f'plant = "{DATA / "maglev.toml"}"'))
    cfg = load_run_config(path)
    u_e = trim(cfg.plant, 0.01, x_guess=cfg.scenario.x0).u
    assert cfg.controller.value("eso.u0") == pytest.approx(u_e, rel=1e-12)
    assert controller_table(cfg.controller)["eso"]["u0"] == cfg.controller.value("eso.u0")
    assert "u0" not in controller_table(_ladrc(0.0))["eso"]  # only when set
    # a zero start cannot hold a command: refused, naming the key
    path.write_text(path.read_text().replace('init = "bumpless"', 'init = "zero"'))
    with pytest.raises(ConfigError, match=r"controller\.eso\.u0"):
        load_run_config(path)


def test_u0_is_refused_where_it_cannot_act():
    with pytest.raises(ValueError, match=r"eso\.u0 = 1\.0.*eso\.init = 'output' or 'bumpless'"):
        _ladrc(1.0, init="zero")
    with pytest.raises(ValueError, match=r"eso\.u0"):
        dataclasses.replace(_ladrc(1.0), eso_model="nominal")
    with pytest.raises(ValueError, match=r"controller\.eso\.u0"):
        _ladrc(math.inf)


def test_engine_and_reference_path_start_at_u0_alike():
    """The compiled continuous loop and scipy's solve_ivp path agree with eso.u0 = u_e, and
    both keep the held pendulum at rest: ξ̂_3(0) = -b0 u_e makes u(0) = u_e."""
    u_e = _u_hold()
    ctrl = _ladrc(u_e)
    sc = _held_scenario(0.5)
    eng = simulate(PEND, ctrl, sc, dt=1e-4, decimation=50)
    ref = reference_simulate(PEND, ctrl, sc, t_eval=eng.t, rtol=1e-10)
    np.testing.assert_allclose(eng["y"], ref.y, atol=1e-9)
    np.testing.assert_allclose(eng["u"], ref.u, atol=1e-7 * abs(u_e))
    assert ref.u[0] == pytest.approx(u_e, rel=1e-12)
    assert ref.xi[0, -1] == pytest.approx(-4.0 * u_e, rel=1e-12)
    # the plant's own gain is not b0 = 4, but at rest the start is exact: y barely moves
    assert np.max(np.abs(eng["y"] - Y0)) < 1e-3
    zero = simulate(PEND, _ladrc(0.0), sc, dt=1e-4, decimation=50)
    assert np.max(np.abs(zero["y"] - Y0)) > 10 * np.max(np.abs(eng["y"] - Y0))


def test_discrete_controller_starts_and_resets_at_u0():
    u_e = _u_hold()
    dc = DiscreteController(_ladrc(u_e), Sampling(1e-3))
    dc.init(Y0)
    assert dc.step([Y0], Y0) == pytest.approx(u_e, rel=1e-12)
    for _ in range(50):
        dc.step([0.5], 0.1)
    dc.reset(Y0, u0=-2.5)  # hand over another command
    assert dc.step([Y0], Y0) == pytest.approx(-2.5, rel=1e-12)
    dc.reset(Y0)  # None: the design's eso.u0
    assert dc.step([Y0], Y0) == pytest.approx(u_e, rel=1e-12)


@needs_cc
@pytest.mark.parametrize("delay", [False, True], ids=["no-delay", "one-sample-delay"])
def test_c_starts_at_u0_like_the_engine(tmp_path, delay):
    """The exported C's aiofl_start reads p->u0 and equals the engine's discrete controller
    to 1e-12 over a closed-loop second from the held pendulum; aiofl_start_at hands over any
    command; the FMU shows eso.u0 as a parameter with the input's unit."""
    import ctypes

    u_e = _u_hold()
    ctrl = _ladrc(u_e)
    sampling = Sampling(1e-3, delay=int(delay))
    cc = CController(build(tmp_path, export_c(ctrl, sampling)), "double")
    eng = DiscreteController(ctrl, sampling)
    u_eng: list[float] = []

    def step(r: list[float], y: float) -> float:
        if not u_eng:
            cc.start(y, "bumpless")
            eng.init(y)
        u_eng.append(eng.step(r, y))
        return cc.step(r, y)

    ref = Reference(amplitude=0.1, omega=2.0, offset=Y0)
    _, _, u_c = loop(step, PEND, ref, 2, 1e-3, 1.0, x0=(Y0, 0.0), n_sub=5)
    np.testing.assert_allclose(u_c, np.array(u_eng), rtol=0, atol=1e-12 * max(1.0, abs(u_e)))
    assert u_c[0] == pytest.approx(u_e, rel=1e-12)
    start_at = cc.lib.aiofl_start_at
    start_at.argtypes = [
        ctypes.c_void_p,
        ctypes.c_void_p,
        ctypes.c_double,
        ctypes.c_double,
        ctypes.c_int,
    ]
    start_at(cc.state, cc.params, Y0, -2.5, 0)
    assert cc.step([Y0, 0.0, 0.0], Y0) == pytest.approx(-2.5, rel=1e-12)
    params = {p.name: p for p in fmu_parameters(ctrl, sampling)}
    assert params["eso.u0"].value == pytest.approx(u_e) and params["eso.u0"].tunable
