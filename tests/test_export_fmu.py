"""The FMU export (``aiofl export --format fmu``): FMPy, the test oracle, validates it with no
problem; fed the measurements and references of the engine's discrete controller driven in
closed loop by a plant simulation, it returns the engine's command sequence (1e-12 relative
in double) for a LADRC (ρ = 3, exact reference derivatives as inputs) and an LESO (ρ = 4,
Han's TD); a b0 set through FMI gives the engine's commands with that b0; the step-size rule;
bad input exits with status 2 and leaves nothing."""

from __future__ import annotations

import math
import subprocess
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from aiofl.cli.app import app
from aiofl.config import load_config
from aiofl.controller import Controller
from aiofl.discrete_controller import DiscreteController
from aiofl.engine.discrete_rows import Sampling
from aiofl.export.fmu import export_fmu_for_config, find_compiler

fmpy = pytest.importorskip("fmpy")
from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402
from fmpy.validation import validate_fmu  # noqa: E402

try:
    find_compiler()
    HAVE_CC = True
except ValueError:
    HAVE_CC = False
pytestmark = pytest.mark.skipif(not HAVE_CC, reason="no C compiler 'cc' on the PATH")

TS = 1e-3
T_FINAL = 0.6
START = {"bumpless": 0, "zero": 1, "output": 2}
# config -> the FMU's model identifier: a LADRC (rho = 3, exact derivatives: inputs y, r,
# r_1..r_3) and an LESO (rho = 4, Han's TD: inputs y, r)
DESIGNS = {"dcmotor-arm-ladrc": "ladrc", "retuned-s1-leso": "leso"}


class Fmu:
    """One FMU built from a preset, extracted, with its variables' value references."""

    def __init__(self, config: str, ident: str, folder: Path) -> None:
        self.cfg = load_config(config)
        self.sampling = Sampling(TS)
        name, data = export_fmu_for_config(
            self.cfg, self.sampling, precision="double", config=config, prefix=ident
        )
        self.path = folder / name
        self.path.write_bytes(data)
        self.md = fmpy.read_model_description(str(self.path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.unzipped = fmpy.extract(str(self.path), unzipdir=str(folder / ident))
        self.inputs = [v.name for v in self.md.modelVariables if v.causality == "input"]

    def slave(self, *, reals: dict[str, float] | None = None) -> FMU2Slave:
        """An instance started at t = 0 (``start`` as the controller's eso.init), with
        ``reals`` set before initialisation; not yet initialised."""
        s = FMU2Slave(
            guid=self.md.guid,
            unzipDirectory=self.unzipped,
            modelIdentifier=self.md.coSimulation.modelIdentifier,
            instanceName="test",
        )
        s.instantiate()
        s.setupExperiment(startTime=0.0)
        s.setInteger([self.vr["start"]], [START[self.cfg.controller.eso_init]])
        for name, value in (reals or {}).items():
            s.setReal([self.vr[name]], [value])
        return s

    def run(
        self, y: np.ndarray, r: np.ndarray, *, h: float = TS, reals: dict | None = None
    ) -> np.ndarray:
        """The FMU's u_k fed y_k and r_k (FMU2Slave: set the inputs at t_k, read u, doStep)."""
        s = self.slave(reals=reals)
        vin = [self.vr[n] for n in self.inputs]
        vu = self.vr["u"]
        s.enterInitializationMode()
        s.setReal(vin, [y[0], *r[0, : len(vin) - 1]])
        s.exitInitializationMode()
        out, t, sub = [], 0.0, round(TS / h)
        for k in range(len(y)):
            for j in range(sub):
                if j == 0:
                    s.setReal(vin, [y[k], *r[k, : len(vin) - 1]])
                    out.append(s.getReal([vu])[0])
                s.doStep(currentCommunicationPoint=t, communicationStepSize=h)
                t = (k * sub + j + 1) * h
                assert s.getReal([vu])[0] == out[-1]  # held until the next sample
        s.terminate()
        s.freeInstance()
        return np.array(out)


def engine_loop(cfg, controller: Controller, t_final: float = T_FINAL, n_sub: int = 5, y0=None):
    """The engine's discrete controller in closed loop with the config's plant (RK4 at
    Ts/n_sub, u held; from the scenario's x0, or the first state at ``y0``): the samples
    y_k, r_k (r, r', ..., r^(rho) of the sine) and u_k."""
    plant, ref, rho = cfg.plant, cfg.scenario.reference, controller.rho
    model = plant if controller.eso_model != "none" else None
    eng = DiscreteController(controller, Sampling(TS), plant=model, x0=cfg.scenario.x0)
    f, g, h = plant.compiled[:3]
    p = plant.param_vector()
    x = np.zeros(plant.n_states)
    x[: len(cfg.scenario.x0)] = cfg.scenario.x0
    if y0 is not None:
        x[0] = y0
    dt = TS / n_sub

    def rhs(xv, u):
        return np.asarray(f(xv, p)) + np.asarray(g(xv, p)) * u

    ys, rs, us = [], [], []
    for k in range(round(t_final / TS)):
        t = k * TS
        y = float(h(x, p))
        rv = [
            ref.amplitude * ref.omega**i * math.sin(ref.omega * t + ref.phase + i * math.pi / 2)
            for i in range(rho + 1)
        ]
        rv[0] += ref.offset
        if k == 0:
            eng.init(y)
        u = eng.step(rv, y)
        ys.append(y)
        rs.append(rv)
        us.append(u)
        for _ in range(n_sub):
            k1 = rhs(x, u)
            k2 = rhs(x + 0.5 * dt * k1, u)
            k3 = rhs(x + 0.5 * dt * k2, u)
            k4 = rhs(x + dt * k3, u)
            x = x + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return np.array(ys), np.array(rs), np.array(us)


@pytest.fixture(scope="module")
def fmus(tmp_path_factory) -> dict[str, Fmu]:
    folder = tmp_path_factory.mktemp("fmu")
    return {cfg: Fmu(cfg, ident, folder) for cfg, ident in DESIGNS.items()}


@pytest.fixture(scope="module")
def loops(fmus) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    return {name: engine_loop(f.cfg, f.cfg.controller) for name, f in fmus.items()}


def rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


@pytest.mark.parametrize("config", list(DESIGNS))
def test_fmpy_validates_the_fmu(fmus, config):
    f = fmus[config]
    assert validate_fmu(str(f.path)) == []
    assert f.md.fmiVersion == "2.0" and f.md.coSimulation is not None
    assert (
        f.md.defaultExperiment.stepSize == str(TS) or float(f.md.defaultExperiment.stepSize) == TS
    )
    rho = f.cfg.controller.rho
    exact = f.cfg.controller.td == "exact"
    assert f.inputs == ["y", "r", *([f"r_{i}" for i in range(1, rho + 1)] if exact else [])]
    outputs = [v.name for v in f.md.modelVariables if v.causality == "output"]
    assert outputs == ["u"]
    params = {v.name: v for v in f.md.modelVariables if "arameter" in v.causality}
    assert params["Ts"].causality == "calculatedParameter"
    assert params["law.b0"].causality == "parameter" and params["law.b0"].variability == "tunable"
    assert float(params["law.b0"].start) == f.cfg.controller.value("law.b0")
    assert params["start"].type == "Integer"
    with zipfile.ZipFile(f.path) as z:
        names = set(z.namelist())
    ident = DESIGNS[config]
    assert f"binaries/linux64/{ident}.so" in names
    assert {"sources/fmi2_wrapper.c", "sources/fmi2Functions.h", "sources/fmu_adapter.h"} <= names


@pytest.mark.parametrize("config", list(DESIGNS))
def test_fmu_returns_the_engines_commands(fmus, loops, config):
    y, r, u_engine = loops[config]
    assert np.all(np.isfinite(u_engine)) and np.ptp(u_engine) > 0
    u_fmu = fmus[config].run(y, r)
    assert rel(u_fmu, u_engine) <= 1e-12, rel(u_fmu, u_engine)


def test_a_step_of_a_fraction_of_ts_samples_at_the_multiples_of_ts(fmus, loops):
    config = "dcmotor-arm-ladrc"
    y, r, u_engine = (a[:100] for a in loops[config])
    u_fmu = fmus[config].run(y, r, h=TS / 4)
    assert rel(u_fmu, u_engine) <= 1e-12


def test_a_step_passing_a_sample_instant_is_an_error(fmus):
    f = fmus["retuned-s1-leso"]
    for h in (2 * TS, 1.5 * TS):
        s = f.slave()
        s.enterInitializationMode()
        s.exitInitializationMode()
        with pytest.raises(FMICallException):
            s.doStep(currentCommunicationPoint=0.0, communicationStepSize=h)
        s.doStep(currentCommunicationPoint=0.0, communicationStepSize=TS)  # still usable
        s.terminate()
        s.freeInstance()


@pytest.mark.parametrize(
    ("config", "name", "factor"),
    [
        ("dcmotor-arm-ladrc", "law.b0", 1.25),
        ("dcmotor-arm-ladrc", "sef.omega_c", 1.2),
        ("retuned-s1-leso", "sef.delta1", 2.0),
        ("retuned-s1-leso", "td.R", 0.5),
    ],
)
def test_a_parameter_set_through_fmi_gives_the_engines_commands_with_it(fmus, config, name, factor):
    f = fmus[config]
    value = factor * f.cfg.controller.value(name)
    y, r, u_engine = engine_loop(f.cfg, f.cfg.controller.with_values(**{name: value}), 0.3)
    # b0: the FMU scales the observer's input column by b0'/b0, the engine discretises anew
    u_fmu = f.run(y, r, reals={name: value})
    assert rel(u_fmu, u_engine) <= 1e-12, rel(u_fmu, u_engine)
    assert rel(f.run(y, r), u_engine) > 1e-6  # the default is another controller


def test_a_parameter_set_during_the_run_takes_effect_at_the_next_sample(fmus, loops):
    f = fmus["dcmotor-arm-ladrc"]
    y, r, u_before = (a[:300] for a in loops["dcmotor-arm-ladrc"])
    new = {"law.b0": 0.7 * f.cfg.controller.value("law.b0")}
    engines = [
        DiscreteController(c, Sampling(TS))
        for c in (f.cfg.controller, f.cfg.controller.with_values(**new))
    ]
    engines[0].init(y[0])
    u_engine = []
    for k in range(len(y)):
        if k == 150:  # the second design continues from the first one's state
            engines[1].state = engines[0].state
        u_engine.append(engines[k >= 150].step(r[k], y[k]))
    s = f.slave()
    vin, vu = [f.vr[n] for n in f.inputs], f.vr["u"]
    s.enterInitializationMode()
    s.setReal(vin, [y[0], *r[0]])
    s.exitInitializationMode()
    u_fmu = []
    for k in range(len(y)):
        if k == 150:
            s.setReal([f.vr["law.b0"]], [new["law.b0"]])
        s.setReal(vin, [y[k], *r[k]])
        u_fmu.append(s.getReal([vu])[0])
        s.doStep(currentCommunicationPoint=k * TS, communicationStepSize=TS)
    s.terminate()
    s.freeInstance()
    assert rel(np.array(u_fmu), np.array(u_engine)) <= 1e-12
    assert (
        np.array_equal(u_fmu[:150], u_before[:150])
        or rel(np.array(u_fmu[:150]), u_before[:150]) < 1e-12
    )
    assert rel(np.array(u_fmu[150:]), u_before[150:]) > 1e-3


def test_two_instances_keep_their_own_state_and_parameters(fmus, loops):
    f = fmus["dcmotor-arm-ladrc"]
    y, r, _ = (a[:200] for a in loops["dcmotor-arm-ladrc"])
    b0 = {"law.b0": 0.8 * f.cfg.controller.value("law.b0")}
    alone = [f.run(y, r), f.run(y, r, reals=b0)]
    slaves = [f.slave(), f.slave(reals=b0)]
    vin, vu = [f.vr[n] for n in f.inputs], f.vr["u"]
    for s in slaves:
        s.enterInitializationMode()
        s.setReal(vin, [y[0], *r[0]])
        s.exitInitializationMode()
    both = [[], []]
    for k in range(len(y)):  # interleaved, one process
        for s, out in zip(slaves, both, strict=True):
            s.setReal(vin, [y[k], *r[k]])
            s.doStep(currentCommunicationPoint=k * TS, communicationStepSize=TS)
            out.append(s.getReal([vu])[0])
    for s in slaves:
        s.terminate()
        s.freeInstance()
    assert np.array_equal(both[0], alone[0]) and np.array_equal(both[1], alone[1])


def test_simulate_fmu_reads_u_k_after_the_step_from_t_k(fmus, loops):
    """FMPy's simulate_fmu sets the inputs at t_k, steps, then records: u_k at t_(k+1)."""
    config = "retuned-s1-leso"
    f = fmus[config]
    y, r, u_engine = (a[:200] for a in loops[config])
    t = np.arange(len(y)) * TS
    signals = np.zeros(len(y), dtype=[("time", np.float64), ("y", np.float64), ("r", np.float64)])
    signals["time"], signals["y"], signals["r"] = t, y, r[:, 0]
    res = fmpy.simulate_fmu(
        str(f.path),
        stop_time=t[-1] + TS,
        output_interval=TS,
        input=signals,
        output=["u"],
        start_values={"start": START[f.cfg.controller.eso_init]},
    )
    assert rel(res["u"][1 : len(y) + 1], u_engine) <= 1e-12


def test_model_description_escapes_the_configs_text(tmp_path):
    text = "a <b> & \"c\" ]]> 'd'"
    cfg = load_config("dcmotor-arm-ladrc")
    from dataclasses import replace

    cfg = replace(cfg, name=text, description=text)
    name, data = export_fmu_for_config(cfg, Sampling(TS), precision="double", config="x")
    path = tmp_path / name
    path.write_bytes(data)
    with zipfile.ZipFile(path) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    assert root.get("modelName") == text and root.get("description") == text
    assert validate_fmu(str(path)) == []


def test_export_cli_writes_the_fmu(tmp_path):
    out = tmp_path / "out"
    res = CliRunner().invoke(
        app, ["export", "tank-ladrc", "--ts", "0.001", "--format", "fmu", "--out", str(out)]
    )
    assert res.exit_code == 0, res.output
    assert (out / "aiofl.fmu").is_file()
    assert validate_fmu(str(out / "aiofl.fmu")) == []


def test_no_compiler_exits_2_and_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    out = tmp_path / "out"
    res = CliRunner().invoke(
        app, ["export", "tank-ladrc", "--ts", "0.001", "--format", "fmu", "--out", str(out)]
    )
    assert res.exit_code == 2
    assert "C compiler" in res.output
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("args", "what"),
    [
        (["--format", "fmu"], "--out"),
        (["--format", "exe"], "--format"),
        (["--format", "fmu", "--prefix", "2x"], "--prefix"),
        (["--format", "fmu", "--params-only"], "--params-only"),
    ],
    ids=["out-is-a-file", "unknown-format", "bad-prefix", "params-only"],
)
def test_bad_input_exits_2_and_leaves_nothing(tmp_path, args, what):
    out = tmp_path / "out"
    if what == "--out":
        out.write_text("keep")
    res = CliRunner().invoke(
        app, ["export", "tank-ladrc", "--ts", "0.001", *args, "--out", str(out)]
    )
    assert res.exit_code == 2
    assert what in res.output
    if what == "--out":
        assert out.read_text() == "keep"
    assert sorted(p.name for p in tmp_path.iterdir()) == (["out"] if what == "--out" else [])


def test_the_fmus_sources_compile_without_a_warning(fmus, tmp_path):
    """The sources shipped in the FMU, built as a tool rebuilding them would (the files
    modelDescription.xml lists), under -Wall -Wextra -Werror -pedantic."""
    f = fmus["retuned-s1-leso"]
    src = Path(f.unzipped) / "sources"
    listed = f.md.buildConfigurations[0].sourceFileSets[0].sourceFiles
    files = [src / s for s in listed]
    cmd = [find_compiler(), "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2"]
    cmd += ["-shared", "-fPIC", "-I", str(src), "-o", str(tmp_path / "x.so"), *map(str, files)]
    proc = subprocess.run([*cmd, "-lm"], capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr


def test_start_is_an_integer_parameter_fixed_before_initialisation(fmus, loops):
    f = fmus["retuned-s1-leso"]
    start = next(v for v in f.md.modelVariables if v.name == "start")
    assert start.variability == "fixed" and int(start.start) == START[f.cfg.controller.eso_init]
    s = f.slave()
    with pytest.raises(FMICallException):
        s.setInteger([f.vr["start"]], [7])
    s.enterInitializationMode()
    s.exitInitializationMode()
    with pytest.raises(FMICallException):  # fixed: not after initialisation
        s.setInteger([f.vr["start"]], [int(start.start)])
    s.terminate()
    s.freeInstance()


@pytest.mark.parametrize("mode", list(START))
def test_each_start_mode_gives_the_engines_commands_with_that_eso_init(fmus, mode):
    import dataclasses

    f = fmus["retuned-s1-leso"]  # Han's TD: bumpless and output start it differently
    ctrl = dataclasses.replace(f.cfg.controller, eso_init=mode)
    y, r, u_engine = engine_loop(f.cfg, ctrl, 0.3, y0=0.2)  # away from r(0) = 0
    others = [engine_loop(f.cfg, dataclasses.replace(ctrl, eso_init=m), 0.3, y0=0.2)[2]
              for m in START if m != mode]  # fmt: skip
    assert all(rel(u, u_engine) > 1e-3 for u in others)  # three different starts
    s = f.slave()
    s.setInteger([f.vr["start"]], [START[mode]])
    vin, vu = [f.vr[n] for n in f.inputs], f.vr["u"]
    s.enterInitializationMode()
    s.setReal(vin, [y[0], r[0, 0]])
    s.exitInitializationMode()
    u_fmu = []
    for k in range(len(y)):
        s.setReal(vin, [y[k], r[k, 0]])
        u_fmu.append(s.getReal([vu])[0])
        s.doStep(currentCommunicationPoint=k * TS, communicationStepSize=TS)
    s.terminate()
    s.freeInstance()
    assert rel(np.array(u_fmu), u_engine) <= 1e-12
