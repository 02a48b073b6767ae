"""The FMU refuses what it cannot run and holds u on a fault, as the controller inside it
(issue 34, item 7; the policy: :mod:`aiofl.engine.sample_time`), through FMPy."""

from __future__ import annotations

import math

import pytest

fmpy = pytest.importorskip("fmpy")
from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.fmi2 import fmi2True  # noqa: E402

from test_export_fmu import HAVE_CC, TS, Fmu  # noqa: E402

pytestmark = pytest.mark.skipif(not HAVE_CC, reason="no C compiler 'cc' on the PATH")
OK, WARNING = 0, 1


@pytest.fixture(scope="module")
def fmu(tmp_path_factory) -> Fmu:
    return Fmu("dcmotor-arm-ladrc", "ladrcf", tmp_path_factory.mktemp("fmu"))


@pytest.mark.parametrize("start", [math.nan, math.inf, 1e300])
def test_setup_experiment_refuses_a_start_time_it_cannot_sample_from(fmu, start):
    """Before: startTime = nan was accepted."""
    s = fmu.slave()
    s.fmi2Reset(s.component)
    with pytest.raises(FMICallException):
        s.setupExperiment(startTime=start)
    with pytest.raises(FMICallException):
        s.setupExperiment(startTime=0.0, stopTime=-1.0)
    s.setupExperiment(startTime=0.5)  # still usable
    s.freeInstance()


def test_a_tunable_value_that_makes_a_coefficient_infinite_is_refused(fmu):
    """Before: sef.omega_c = 1e308 was accepted (gains omega_c^3 = inf, u NaN)."""
    s = fmu.slave()
    vr = fmu.vr["sef.omega_c"]
    with pytest.raises(FMICallException):
        s.setReal([vr], [1e308])
    assert s.getReal([vr])[0] == fmu.cfg.controller.value("sef.omega_c")  # unchanged
    s.setReal([vr], [2.0 * fmu.cfg.controller.value("sef.omega_c")])
    s.freeInstance()


def _do_step(s, t: float) -> int:
    return s.fmi2DoStep(s.component, t, TS, fmi2True)


def test_an_unusable_measurement_holds_u_with_a_warning_until_reset(fmu):
    """Before: a NaN y made u NaN for the rest of the run, status fmi2OK."""
    vin = [fmu.vr[n] for n in fmu.inputs]
    vu = fmu.vr["u"]
    r = [0.5] + [0.0] * (len(vin) - 2)
    s = fmu.slave()
    s.enterInitializationMode()
    s.setReal(vin, [0.0, *r])
    s.exitInitializationMode()
    us, statuses = [], []
    for k, y in enumerate([0.0, 0.001, math.nan, 0.002, 0.003]):
        s.setReal(vin, [y, *r])
        us.append(s.getReal([vu])[0])
        statuses.append(_do_step(s, k * TS))
    assert statuses == [OK, OK, WARNING, WARNING, WARNING]
    assert us[2] == us[3] == us[4] == us[1] and math.isfinite(us[1])
    s.fmi2Reset(s.component)  # clears the fault
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.setReal(vin, [0.0, *r])
    s.exitInitializationMode()
    s.setReal(vin, [0.0, *r])
    assert math.isfinite(s.getReal([vu])[0])
    assert _do_step(s, 0.0) == OK
    s.freeInstance()
