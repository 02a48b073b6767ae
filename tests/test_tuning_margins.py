"""Stability margins as tuning quantities (aiofl.tuning.margins, aiofl.tuning.objective): a
first-order loop whose loop transfer function is known in closed form, the grammar, the
NSGA-II evaluation and the warnings on a chosen design."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

from aiofl.config import load_config
from aiofl.tuning.margins import candidate_margins, design_warnings
from aiofl.tuning.objective import objective_matrix, parse_constraint, parse_quantity
from test_sampling_criteria import PLANT

BETA, W0 = 3.0, 40.0


RUN = """
name = "first-order-margins"
plant = "first.toml"
[scenario]
t_final = 1.0
[scenario.reference]
kind = "step"
amplitude = 0.5
[controller]
structure = "LADRC"
td_kind = "exact"
rho = 1
[controller.eso]
omega0 = 40.0
[controller.sef]
omega_c = 5.0
[controller.law]
b0 = 3.0
[simulation]
dt = 1e-4
"""

TUNE = """
[tune]
algorithm = "nsga2"
objectives = ["itae", "pm"]
constraints = ["ms <= 1.6"]
t_final = 0.3
population = 6
generations = 2
seed = 3
[tune.parameters]
'sef.omega_c' = { lo = 1.0, hi = 60.0, log = true }
"""


def config(tmp_path: Path, tune: bool = False) -> Path:
    (tmp_path / "first.toml").write_text(PLANT)
    run = tmp_path / "run.toml"
    run.write_text(RUN + (TUNE if tune else ""))
    return run


def closed_form_pm(kp: float) -> float:
    """The LADRC (ρ = 1, b0 = β, ESO gains 2ω0, ω0²) on ẏ = βu, broken at the plant input:
    the controller from y to u is C(s) = ((2ω0kp + ω0²)s + kpω0²) / (b0 s(s + 2ω0 + kp)),
    so L(s) = ((2ω0kp + ω0²)s + kpω0²) / (s²(s + 2ω0 + kp)); PM = 180° + ∠L(jω_gc) at
    |L(jω_gc)| = 1 (one crossover: |L| falls monotonically)."""

    def L(w: float) -> complex:
        s = 1j * w
        return ((2 * W0 * kp + W0**2) * s + kp * W0**2) / (s**2 * (s + 2 * W0 + kp))

    wgc = brentq(lambda w: abs(L(w)) - 1.0, 1e-3, 1e4, xtol=1e-14)
    return 180.0 + math.degrees(np.angle(L(wgc)))


def test_the_phase_margin_is_the_closed_form_one(tmp_path: Path) -> None:
    cfg = load_config(str(config(tmp_path)))
    kps = np.array([[2.0], [5.0], [20.0]])
    m = candidate_margins(cfg, ["sef.omega_c"], kps)
    expected = [closed_form_pm(k) for k in kps[:, 0]]
    assert m["pm"] == pytest.approx(expected, rel=1e-6)
    assert np.all(np.isinf(m["gm"]))  # the phase never reaches −180°: no phase crossover
    assert np.all(m["ms"] > 1.0) and np.all(m["dm"] > 0)
    skipped = candidate_margins(cfg, ["sef.omega_c"], kps, skip=np.array([True, False, True]))
    assert skipped["pm"][0] == -math.inf and skipped["ms"][2] == math.inf


def test_margin_quantities_in_objectives_and_constraints(tmp_path: Path) -> None:
    assert parse_quantity("pm").sign == -1.0 and parse_quantity("ms").sign == 1.0
    assert parse_constraint("dm >= 0.002").quantity.metric == "dm"
    assert parse_quantity("gm:nominal").aggregate == "nominal"
    with pytest.raises(ValueError, match="no aggregate"):
        parse_quantity("pm:cvar")
    pm = np.array([60.0, 30.0, math.inf])
    margins = {"pm": pm, "ms": np.array([1.2, 2.5, 1.0]), "gm": pm, "dm": pm}
    metrics, div = np.ones((3, 5)), np.zeros(3, dtype=bool)
    objs = (parse_quantity("itae"), parse_quantity("pm"))
    cons = (parse_constraint("pm >= 45"), parse_constraint("ms <= 2"))
    F, G, raw = objective_matrix(objs, cons, metrics, div, "nominal", 0.9, 1e6, margins)
    assert F[:, 1].tolist() == [-60.0, -30.0, -1e6]  # maximised: its negative, inf clipped
    assert ((G <= 0).all(axis=1)).tolist() == [True, False, True]  # inf PM meets pm >= 45
    assert raw[:, 0].tolist() == pm.tolist()


def test_nsga2_with_a_margin_objective_and_constraint(tmp_path: Path) -> None:
    """Every front design meets ``ms <= 1.6`` (recomputed), the front shows PM itself."""
    from aiofl.tuning.results import write_outputs
    from aiofl.tuning.search import tune

    run = config(tmp_path, tune=True)
    res = tune(str(run), progress=False)
    front = res.front
    assert front is not None and front.objectives == ("itae", "pm")
    cfg = load_config(str(run))
    m = candidate_margins(cfg, ["sef.omega_c"], front.values)
    assert np.all(m["ms"] <= 1.6)
    assert front.F[:, 1] == pytest.approx(m["pm"], rel=1e-9)  # the margin, not its negative
    summary = write_outputs(res, tmp_path / "out")
    saved = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert saved["warnings"] == summary["warnings"]
    assert saved["chosen_margins"]["pm"] == pytest.approx(
        closed_form_pm(res.best_values["sef.omega_c"]), rel=1e-6
    )


def test_warnings_on_a_chosen_design(tmp_path: Path) -> None:
    from aiofl.tuning.space import ParameterBounds

    cfg = load_config(str(config(tmp_path)))
    bounds = {"sef.omega_c": ParameterBounds(lo=1.0, hi=5.04, log=True)}
    warn, margins = design_warnings(cfg, bounds, {"sef.omega_c": 5.0})
    assert any("upper search bound" in w and "log scale" in w for w in warn)
    assert margins is not None and margins["pm"] == pytest.approx(closed_form_pm(5.0))
    inner = {"sef.omega_c": ParameterBounds(lo=1.0, hi=50.0)}
    warn, _ = design_warnings(cfg, inner, {"sef.omega_c": 5.0})
    assert not any("search bound" in w for w in warn)
    # b0 = β/20: twenty times the loop gain the design assumes
    low_pm = replace(cfg, controller=cfg.controller.with_values(**{"law.b0": 0.15}))
    warn, m = design_warnings(low_pm, inner, {"sef.omega_c": 5.0})
    assert m is not None and m["pm"] < 30.0 and any("phase margin" in w for w in warn)
    assert (m["ms"] > 2.5) == any("sensitivity peak" in w for w in warn)
