"""What the controller a user runs refuses, and what it does with a sample it cannot use:
``aiofl.DiscreteController``, the exported C and the FMU (issue 34, item 7).

One policy (:mod:`aiofl.engine.sample_time`): a sample time that is not a number in
[1e-9, 1] s or that the design cannot be discretised at, and non-finite coefficients, are
refused at construction naming the argument; ``y`` / ``r`` of the wrong type or shape
raise; a measurement or reference that is not finite or beyond ±1e30 (or an update that
overflows) is a fault: nothing changes, the last command is held, the fault flag stays up
until the next start.  The C is checked against Python with the C-vs-engine harness, the
FMU through FMPy.
"""

from __future__ import annotations

import ctypes
import math

import numpy as np
import pytest

import aiofl
from aiofl.config import load_config
from aiofl.engine.discrete_rows import Sampling
from aiofl.export import ExportError, export_c
from aiofl.export.c_check import CC, CController, build

needs_cc = pytest.mark.skipif(CC is None, reason="no C compiler 'cc' on PATH")
DC = aiofl.DiscreteController
PRESET = "frontier-s1-ladrc"  # LADRC, rho = 4, exact derivatives, no model


@pytest.fixture(scope="module")
def ctrl() -> aiofl.DiscreteController:
    return DC.from_config(PRESET, ts=1e-3)


# ------------------------------------------------------------------ construction
@pytest.mark.parametrize("ts", [5e-324, 1e-300, 0.0, -1e-3, 2.0, math.nan, math.inf])
def test_a_sample_time_out_of_range_is_refused_naming_ts(ts):
    """Before: 5e-324 / 1e-300 gave LinAlgError (assisted-s1-ladrc) or u = 0 for ever
    (paper-s1-inleso)."""
    for preset in ("assisted-s1-ladrc", "paper-s1-inleso"):
        with pytest.raises(ValueError, match=r"ts = .*allowed: a number of seconds, 1e-09 <= ts"):
            DC.from_config(preset, ts=ts)


def test_a_bool_or_a_string_is_not_a_sample_time():
    """Before: ts = True ran as 1.0."""
    for bad in (True, "1e-3"):
        with pytest.raises(TypeError, match="ts = "):
            DC.from_config("paper-s1-inleso", ts=bad)
    with pytest.raises(ValueError, match=r"controller\.discrete\.ts = True"):
        Sampling(True)  # type: ignore[arg-type]


def test_a_sample_time_too_large_for_the_design_names_its_range():
    """Before: "System not reachable; pole placement invalid" (assisted-s1-ladrc, ts = 1)."""
    with pytest.raises(ValueError, match="allowed for this design: about") as info:
        DC.from_config("assisted-s1-ladrc", ts=1.0)
    message = str(info.value)
    assert message.startswith("ts = 1 s: this design cannot be discretised")
    hi = float(message.rsplit("<= ts <= ", 1)[1].split()[0])
    assert 0.1 <= hi < 1.0
    DC.from_config("assisted-s1-ladrc", ts=hi)  # the upper end runs


def test_coefficients_that_are_not_finite_are_refused():
    cfg = load_config(PRESET)
    huge = cfg.controller.with_values(**{"sef.omega_c": 1e308})
    with pytest.raises(ValueError, match=r"sef\.omega_c"):
        DC(huge, Sampling(1e-3))
    with pytest.raises(ExportError, match=r"sef_gain .* not finite numbers in double"):
        export_c(huge, Sampling(1e-3))
    big = cfg.controller.with_values(**{"sef.omega_c": 1e12})  # omega_c^4 = 1e48 > FLT_MAX
    export_c(big, Sampling(1e-3))
    with pytest.raises(ExportError, match=r"not finite numbers in float .*sef\.omega_c"):
        export_c(big, Sampling(1e-3), precision="float")


def test_the_export_refuses_what_the_controller_refuses():
    cfg = load_config("assisted-s1-ladrc")
    model = {"plant": cfg.plant, "plant_source": str(cfg.raw.get("plant", cfg.plant.name))}
    for ts in (5e-324, 1e-300):
        with pytest.raises(ExportError, match=r"controller\.discrete\.ts = .*allowed"):
            export_c(cfg.controller, Sampling(ts), **model)
    with pytest.raises(ExportError, match="allowed for this design: about"):
        export_c(cfg.controller, Sampling(1.0), x0=cfg.scenario.x0, **model)


# ------------------------------------------------------------------ y and r
@pytest.mark.parametrize("y", ["1", None, np.array([1.0, 2.0]), 1j, True, [0.0]])
def test_a_measurement_that_is_not_one_real_number_raises_naming_y(ctrl, y):
    """Before: numba TypingError (str, None, array, complex); True ran as 1.0."""
    ctrl.reset(0.0)
    with pytest.raises(TypeError, match=r"^y = .*allowed: one real number"):
        ctrl.step(1.0, y)
    assert not ctrl.fault


def test_numpy_scalars_are_measurements(ctrl):
    ctrl.reset(0.0)
    a = ctrl.step(1.0, np.float64(0.01))
    ctrl.reset(0.0)
    assert ctrl.step(1.0, np.array(0.01)) == a == (ctrl.reset(0.0) or ctrl.step(1.0, 0.01))


@pytest.mark.parametrize(
    ("r", "error", "match"),
    [
        ([], ValueError, r"r has shape \(0,\); allowed: .*1 to 5"),
        ([1.0] * 6, ValueError, r"r has shape \(6,\)"),
        (np.ones((2, 2)), ValueError, r"r has shape \(2, 2\)"),
        ("x", TypeError, "r = 'x'"),
        (None, TypeError, "r = None"),
        ([1.0, 1j], TypeError, "r = "),
    ],
)
def test_a_reference_of_the_wrong_type_or_length_raises_naming_r(ctrl, r, error, match):
    """Before: r = [] ran as r = 0, a too-long r raised numpy's broadcast error."""
    ctrl.reset(0.0)
    with pytest.raises(error, match=match):
        ctrl.step(r, 0.0)


# ------------------------------------------------------------------ faults
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, 1e308, -1.5e30])
def test_an_unusable_measurement_holds_the_last_command_until_reset(ctrl, bad):
    """Before: NaN, inf or 1e308 made u NaN until reset(), with no flag."""
    ctrl.reset(0.0)
    for k in range(5):
        last = ctrl.step(1.0, 0.001 * k)
    state = ctrl.state
    assert not ctrl.fault
    assert ctrl.step(1.0, bad) == last and ctrl.fault
    np.testing.assert_array_equal(ctrl.state, state)  # the sample changed nothing
    assert ctrl.step(1.0, 0.005) == last and ctrl.fault  # held until a start
    assert ctrl.run(3, 1.0, 0.005) == last
    np.testing.assert_array_equal(ctrl.state, state)
    ctrl.reset(0.005)
    assert not ctrl.fault
    fresh = DC.from_config(PRESET, ts=1e-3)
    fresh.reset(0.005)
    assert ctrl.step(1.0, 0.006) == fresh.step(1.0, 0.006)


def test_an_unusable_reference_is_a_fault_too(ctrl):
    ctrl.reset(0.0)
    first = ctrl.step([1.0, 0.0, 0.0, 0.0, 0.0], 0.0)
    assert ctrl.step([1.0, math.nan], 0.0) == first and ctrl.fault  # a derivative it reads
    ctrl.reset(0.0)
    assert ctrl.step(2e30, 0.0) == 0.0 and ctrl.fault  # before any command: 0 held


def test_a_limit_value_is_usable(ctrl):
    ctrl.reset(0.0)
    u = ctrl.step(1.0, 1e30)
    assert math.isfinite(u) and not ctrl.fault


def test_an_update_that_overflows_is_undone_and_a_fault(ctrl):
    ctrl.reset(0.0)
    last = ctrl.step(1.0, 0.0)
    huge = np.full_like(ctrl.state, 1e307)  # a state the next update overflows from
    ctrl.state = huge
    assert ctrl.step(1.0, 0.0) == last and ctrl.fault
    np.testing.assert_array_equal(ctrl.state, huge)  # undone


def test_a_start_at_an_unusable_measurement_is_a_fault():
    c = DC.from_config(PRESET, ts=1e-3)
    c.reset(math.nan)  # bumpless: starts at y0
    assert c.fault and c.step(1.0, 0.0) == 0.0
    c.reset(0.0)
    assert not c.fault
    zero = DC.from_config("paper-s1-inleso", ts=1e-3)
    assert zero.controller.eso_init == "zero"
    zero.init(math.nan)  # the zero start ignores y0
    assert not zero.fault


# ------------------------------------------------------------------ C against Python
SEQUENCE = [0.0, 0.001, 0.002, math.nan, 0.003, 0.004]  # the fault at k = 3


@needs_cc
@pytest.mark.parametrize("bad", [math.nan, math.inf, 1e31])
@pytest.mark.parametrize("where", ["y", "r"])
def test_the_c_controller_faults_and_holds_as_python(tmp_path, bad, where):
    """The exported C (aiofl_step, aiofl_fault) against aiofl.DiscreteController on the
    same samples, a fault in the middle, then a reset: the same commands and flags."""
    cfg = load_config(PRESET)
    sampling = Sampling(1e-3)
    c = CController(build(tmp_path, export_c(cfg.controller, sampling)), "double")
    fault = c.lib.aiofl_fault
    fault.argtypes = [ctypes.c_void_p]
    fault.restype = ctypes.c_int
    py = DC(cfg.controller, sampling)
    c.reset(0.0)
    py.reset(0.0)
    rows = []
    for k in range(8):
        y, r = 0.001 * k, [1.0, 0.5, 0.0, 0.0, 0.0]
        if k == 3:
            y, r = (bad, r) if where == "y" else (y, [bad, *r[1:]])
        if k == 6:
            c.reset(y)
            py.reset(y)
        rows.append((c.step(r, y), py.step(r, y), fault(c.state), py.fault))
    u_c, u_py, f_c, f_py = (list(col) for col in zip(*rows, strict=True))
    assert f_c == f_py == [0, 0, 0, 1, 1, 1, 0, 0]
    np.testing.assert_allclose(u_c, u_py, rtol=1e-12, atol=0.0)
    assert u_c[3] == u_c[4] == u_c[5] == u_c[2]  # held


@needs_cc
def test_a_c_start_at_an_unusable_measurement_is_a_fault(tmp_path):
    cfg = load_config(PRESET)
    c = CController(build(tmp_path, export_c(cfg.controller, Sampling(1e-3))), "double")
    fault = c.lib.aiofl_fault
    fault.argtypes = [ctypes.c_void_p]
    c.start(math.nan, "bumpless")
    assert fault(c.state) == 1 and c.step([1.0] + [0.0] * 4, 0.0) == 0.0
    c.start(math.nan, "zero")
    assert fault(c.state) == 0
