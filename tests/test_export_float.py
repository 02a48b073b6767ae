"""Float that holds: on every shipped S1/S2 design at Ts = 1 ms, the float C in closed loop
with the plant (scale, load step) gives an ITAE within 5 % and an ISU within 2 % of the
double engine's discrete controller fed the same, unrounded measurement.

Before the offset coordinates (see ``templates/controller.c``) frontier-s1-ladrc's float C
gave ISU 123.6 against 15.4; now both agree to ~1e-4.  Designs whose sampled loop diverges
at 1 ms (no ITAE to compare) are skipped, and export warns about them or refuses them.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from aiofl.config import list_presets, load_config
from aiofl.discrete_controller import DiscreteController
from aiofl.engine.discrete_rows import Sampling
from aiofl.export import export_c
from aiofl.export.c_check import (
    CC,
    FLOAT_ISU_TOL,
    FLOAT_ITAE_TOL,
    CController,
    build,
    itae_isu,
    loop,
)

SHIPPED = sorted(
    name
    for name in list_presets()
    if name.split("-")[0] in ("paper", "retuned", "frontier", "assisted")
    and ("-s1-" in name or "-s2-" in name)
)
TS = 1e-3
T_MAX = 12.0  # past S2's load step at 10 s


def _run(name: str, tmp: Path) -> dict[str, tuple[float, float] | None]:
    cfg = load_config(name)
    c, sc = cfg.controller, cfg.scenario
    samp = dataclasses.replace(cfg.sampling, ts=TS) if cfg.sampling else Sampling(TS)
    model = cfg.plant if c.eso_model != "none" else None
    t_final = min(sc.t_final, T_MAX)
    kw = {
        "x0": sc.x0,
        "scale": dict(sc.plant_scale),
        "disturbance": (sc.disturbance_amplitude, sc.disturbance_time),
        "delay": samp.delay,
        "n_sub": 5,
    }
    eng = DiscreteController(c, samp, plant=model, x0=sc.x0)
    files = export_c(
        c,
        samp,
        precision="float",
        plant=cfg.plant,
        x0=sc.x0,
        plant_source=str(cfg.raw.get("plant", cfg.plant.name)),
    )
    cc = CController(build(tmp / name, files), "float")
    out: dict[str, tuple[float, float] | None] = {}
    for key, ctl in (("engine", eng), ("float", cc)):
        started: list[bool] = []

        def step(r: list[float], y: float, ctl=ctl, started=started, key=key) -> float:
            if not started:
                ctl.start(y, c.eso_init) if key == "float" else ctl.init(y)
                started.append(True)
            return ctl.step(r, y)

        t, y, u = loop(step, cfg.plant, sc.reference, c.rho, TS, t_final, **kw)
        out[key] = itae_isu(t, y, u, sc.reference, TS) if len(t) == round(t_final / TS) else None
    return out


@pytest.fixture(scope="module")
def table(tmp_path_factory) -> dict[str, dict[str, tuple[float, float] | None]]:
    tmp = tmp_path_factory.mktemp("float")
    return {name: _run(name, tmp) for name in SHIPPED}


@pytest.mark.skipif(CC is None, reason="no C compiler on PATH")
def test_float_holds_on_every_shipped_s1_s2_design(table):
    assert len(SHIPPED) >= 16
    held = []
    for name, res in table.items():
        if res["engine"] is None:  # the sampled loop diverges at 1 ms: nothing to compare
            continue
        assert res["float"] is not None, name
        (i_e, s_e), (i_f, s_f) = res["engine"], res["float"]
        assert abs(i_f / i_e - 1.0) <= FLOAT_ITAE_TOL, (name, i_f, i_e)
        assert abs(s_f / s_e - 1.0) <= FLOAT_ISU_TOL, (name, s_f, s_e)
        held.append(name)
    assert "frontier-s1-ladrc" in held and "frontier-s1-leso" in held and len(held) >= 12
    # the ones skipped diverge sampled at 1 ms (the INLESOs' Euler ITD)
    skipped = sorted(set(SHIPPED) - set(held))
    assert all("inleso" in n for n in skipped), skipped


@pytest.mark.skipif(CC is None, reason="no C compiler on PATH")
def test_frontier_s1_ladrc_float_isu_is_the_double_one(table):
    """The issue's case: ISU 123.6 (float) against 15.4 (double) before; now equal to
    1e-3 relative."""
    (_, s_e), (_, s_f) = table["frontier-s1-ladrc"]["engine"], table["frontier-s1-ladrc"]["float"]
    assert 9.0 < s_e < 11.0 and abs(s_f / s_e - 1.0) < 1e-3  # ISU over 12 s
    assert np.isfinite(s_f)


@pytest.mark.skipif(CC is None, reason="no C compiler on PATH")
def test_without_the_offset_coordinates_float_does_not_hold(table, tmp_path):
    """The same float code with y and r as floats (-DAIOFL_SIGNAL_IS_FLOAT: y rounded to 24
    bits before the observer) on frontier-s1-ladrc: the ISU is several times the double
    one, the issue's failure; the double signals are what makes float hold."""
    cfg = load_config("frontier-s1-ladrc")
    c, sc = cfg.controller, cfg.scenario
    files = export_c(c, Sampling(TS), precision="float")
    cc = CController(build(tmp_path, files, ["-DAIOFL_SIGNAL_IS_FLOAT"]), "float", signal="float")
    started: list[bool] = []

    def step(r: list[float], y: float) -> float:
        if not started:
            cc.start(y, c.eso_init)
            started.append(True)
        return cc.step(r, y)

    t_final = min(sc.t_final, T_MAX)
    t, y, u = loop(step, cfg.plant, sc.reference, c.rho, TS, t_final, n_sub=5)
    _, s_q = itae_isu(t, y, u, sc.reference, TS)
    _, s_e = table["frontier-s1-ladrc"]["engine"]
    assert s_q > 2.0 * s_e, (s_q, s_e)
