"""The compiled Radau IIA integrator of the orbit analyses against scipy (the reference).

:class:`aiofl.analysis.loop_radau.LoopIntegrator` integrates the compiled closed loop in
numba; scipy's ``solve_ivp`` (BDF) on the same F and J, called from Python, stays the
reference: end states, dense output, Floquet multipliers and Lyapunov exponents agree
within the tolerances stated here, for every kind of input the loop takes (a sine with
its derivatives, Han's TD precomputed, a step, samples, the reference held).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from aiofl.analysis.budget import BudgetExceeded, time_budget
from aiofl.analysis.loop_radau import LoopIntegrator, RadauSolution
from aiofl.analysis.orbit_loop import OrbitLoop
from aiofl.analysis.variational import trajectory
from aiofl.config import load_config
from aiofl.scenario import Reference

SAME_METHOD = 1e-6
"""Compiled and scipy's own Radau IIA (Python) end states agree to this, relative to each
state's largest magnitude along the run, at rtol 1e-8: the same method and step-size
control, the steps differing with the last bits of F and J (measured: 2e-11 on a smooth
loop, 4e-7 with Han's chattering TD outputs as the input)."""
BDF = 1e-4
"""... and with scipy's BDF (the integrator the orbit analyses used before), whose own
error at rtol 1e-8 is larger (measured up to 7e-6, against a run at rtol 1e-11)."""


def _loop(preset: str, reference: Reference | None = None, *, scipy: bool = False) -> OrbitLoop:
    cfg = load_config(preset)
    scenario = cfg.scenario if reference is None else replace(cfg.scenario, reference=reference)
    loop = OrbitLoop(cfg.plant, cfg.controller, scenario, dt=float(cfg.dt))
    loop.compiled_integrator = not scipy
    return loop


CASES = [
    ("flexjoint-hub-ladrc", None, False),  # sine with its derivatives (exact profile)
    ("paper-s1-leso", None, False),  # Han's TD: its outputs precomputed, interpolated
    ("frontier-s1-leso", None, True),  # r held at r*: the limit cycle's simulation
    ("tank-ladrc", Reference(kind="step", amplitude=0.5, offset=1.0, t_step=0.3), False),
    ("tank-ladrc", Reference(kind="samples", samples=(1.0, 1.4, 0.8), sample_dt=0.2), False),
]
T1 = 0.5


def _start(loop: OrbitLoop) -> tuple[np.ndarray, np.ndarray]:
    z0 = loop.operating_point()
    z0 = z0 + 1e-3 * np.maximum(np.abs(z0), 1e-2)  # off the equilibrium
    if loop.controller.td == "han":
        loop.han_signal(0.0, T1)
    return z0, np.maximum(np.abs(z0), 1e-3 * max(float(np.max(np.abs(z0))), 1.0))


@pytest.mark.parametrize(("preset", "reference", "hold"), CASES)
def test_compiled_trajectory_equals_scipy(preset: str, reference: Any, hold: bool) -> None:
    """The compiled run (a :class:`RadauSolution`: the compiled path ran) ends where
    scipy's Radau ends (:data:`SAME_METHOD`) and scipy's BDF (:data:`BDF`), on the same
    loop, inputs and tolerances; its dense output passes through its steps and agrees
    with scipy's between them."""
    from scipy.integrate import solve_ivp

    from aiofl.analysis.variational import _atol

    loop, ref_loop = _loop(preset, reference), _loop(preset, reference, scipy=True)
    z0, scale = _start(loop)
    _start(ref_loop)
    d = loop.d_op if hold else None
    t1 = 0.05 if hold else T1  # held: a fal loop near its equilibrium, slow for scipy
    f, jac = loop.field(hold=hold, d=d)
    fs, js = ref_loop.field(hold=hold, d=d)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        got = trajectory(f, jac, z0, 0.0, t1, scale=scale, rtol=1e-8)
        bdf = trajectory(fs, js, z0, 0.0, t1, scale=scale, rtol=1e-8)
        atol = _atol(scale, 1e-8)
        radau = solve_ivp(fs, (0, t1), z0, "Radau", jac=js, rtol=1e-8, atol=atol, dense_output=True)
    assert isinstance(got, RadauSolution) and not isinstance(bdf, RadauSolution)
    assert got.t[-1] == bdf.t[-1] == radau.t[-1] == t1
    size = np.maximum(np.max(np.abs(radau.y), axis=1), 1e-9)
    assert np.max(np.abs(got.y[:, -1] - radau.y[:, -1]) / size) < SAME_METHOD
    assert np.max(np.abs(got.y[:, -1] - bdf.y[:, -1]) / size) < BDF
    assert np.allclose(got.sol(got.t), got.y, rtol=1e-12, atol=0.0)
    ts = np.linspace(0.02 * t1, 0.98 * t1, 29)
    assert np.max(np.abs(got.sol(ts) - radau.sol(ts)) / size[:, None]) < 10 * SAME_METHOD


@pytest.mark.parametrize("preset", ["retuned-s2-leso", "paper-s3-inleso"])
def test_floquet_multipliers_of_nonsmooth_loops_equal_scipy(preset: str) -> None:
    """Tracking orbits with fal / g(e) that close to about 1 % (the report's settings):
    the largest multiplier compiled (Φ on 8 parts of each Radau step) equals scipy's (BDF,
    one part per its shorter steps) to 1 % (measured 0.3 % and 1e-6), and the verdict's
    word is the same."""
    from aiofl.analysis.orbit import floquet_word, tracking_floquet

    quick = {"passes": 2, "settle": 2, "rtol": 1e-5}
    got = tracking_floquet(_loop(preset), **quick)
    ref = tracking_floquet(_loop(preset, scipy=True), **quick)
    assert got["largest"] == pytest.approx(ref["largest"], rel=1e-2)
    assert floquet_word(got) == floquet_word(ref) == "stable"


def test_lyapunov_exponent_of_a_step_run_equals_scipy() -> None:
    """The largest finite-time Lyapunov exponent of tank-ladrc's run to a step: compiled
    and scipy agree to 1e-3 relative (the exponents are about −5 1/s: the slowest pole)."""
    from aiofl.analysis.orbit import tracking_ftle

    step = Reference(kind="step", amplitude=0.5, offset=1.0, t_step=0.3)
    got = tracking_ftle(_loop("tank-ladrc", step))
    ref = tracking_ftle(_loop("tank-ladrc", step, scipy=True))
    assert got["largest"] == pytest.approx(ref["largest"], rel=1e-3)
    assert got["largest"] < 0


def test_a_spent_budget_stops_the_compiled_integration() -> None:
    """The time budget is checked between the compiled slices: a spent one raises
    BudgetExceeded out of the integration."""
    loop = _loop("flexjoint-hub-ladrc")
    z0 = loop.operating_point()
    f, jac = loop.field()
    assert isinstance(f.integrator, LoopIntegrator) and f.integrator.usable(z0)
    with time_budget(1e-6), pytest.raises(BudgetExceeded):
        time.sleep(1e-3)
        trajectory(f, jac, z0, 0.0, 1.0)


def test_a_plant_without_compiled_jets_is_integrated_by_scipy() -> None:
    """A plant numba cannot compile for complex numbers (math.erf) has no compiled jets:
    its loop is integrated by scipy and still gives the trajectory."""
    from test_linearize import tank_f_erf, tank_plant

    cfg = load_config("tank-ladrc")
    plant = tank_plant("erf-tank", tank_f_erf)
    loop = OrbitLoop(plant, cfg.controller, cfg.scenario, dt=float(cfg.dt))
    z0 = loop.operating_point()
    f, jac = loop.field()
    assert not f.integrator.usable(z0)
    sol = trajectory(f, jac, z0, 0.0, 0.5)
    assert not isinstance(sol, RadauSolution) and np.all(np.isfinite(sol.y))
    assert math.isclose(sol.t[-1], 0.5)
