"""The C export: compiled with the system C compiler, loaded with ctypes, driven in closed
loop with a plant simulation, its commands equal the engine's discrete controller's
(double: 1e-12 of the largest command on well-conditioned designs; float: 2e-5) for LESO,
INLESO and LADRC designs at ρ = 1..4 and in every start mode; the API (prefix, parameter
struct, bumpless start, parameter instances) works from C."""

from __future__ import annotations

import dataclasses
import math
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from aiofl.cli.app import app
from aiofl.config import load_config
from aiofl.controller import Controller
from aiofl.discrete_controller import DiscreteController
from aiofl.engine.discrete_rows import Sampling
from aiofl.export import HEADER, PARAMS, SOURCE, ExportError, export_c
from aiofl.export.c_check import CC, STRICT_FLOAT, WARN, CController, build, loop
from aiofl.plants import get_plant
from aiofl.plants.base import Plant
from aiofl.scenario import Reference

needs_cc = pytest.mark.skipif(CC is None, reason="no C compiler 'cc' on PATH")

BETA_SLFJM = 1.61 * 0.00767 * 70.0 / (0.0059 * 0.0021 * 2.6)
# relative degree -> (plant, its true input gain, a reference it can follow)
PLANTS = {
    1: ("tank", 0.04, Reference(amplitude=0.25, omega=0.5, offset=1.0)),
    2: ("pendulum", 4.0, Reference(amplitude=0.5, omega=1.0)),
    3: ("dcmotor_arm", 500.0, Reference(amplitude=0.5, omega=1.0)),
    4: ("slfjm", BETA_SLFJM, Reference(amplitude=math.pi / 4, omega=2.0)),
}
TOL = {"double": 1e-12, "float": 2e-5}


def design(structure: str, rho: int) -> Controller:
    """A working design of each structure for the plant of relative degree ρ: Han's TD / the
    ITD at ρ ≤ 2, exact derivatives at ρ = 3, 4 (n_feedback = ρ), and the shipped re-tuned
    LESO at ρ = 4."""
    _, b, _ = PLANTS[rho]
    if rho == 4 and structure == "LESO":
        return load_config("retuned-s1-leso").controller
    w0 = {1: 40.0, 2: 60.0, 3: 80.0, 4: 50.0}[rho]
    wc = {1: 5.0, 2: 7.5, 3: 10.0, 4: 12.5}[rho]
    extra = {"law.u_max": 10.0} if rho == 1 else {}  # the tank's pump saturates
    if structure == "LADRC":
        vals = {"law.b0": b, "eso.omega0": w0, "sef.omega_c": wc, "td.omega": 2 * wc, **extra}
        return Controller.from_structure(
            "LADRC", rho=rho, n_feedback=rho, values=vals
        ).with_binomial_alphas()
    gains = [math.comb(rho, i) * wc ** (rho - i) / b for i in range(rho)]
    vals = {"law.b0": b, "eso.omega0": w0, **extra}
    if structure == "LESO":
        td = "han" if rho <= 2 else "exact"
        vals["td.R"] = 50.0
        for i in range(rho):
            vals |= {f"sef.k{i + 1}": gains[i], f"sef.delta{i + 1}": 0.05}
            vals[f"sef.alpha{i + 1}"] = (0.8, 0.9, 1.0)[min(i, 2)]
        kinds = {"eso": "linear", "sef": "nonlinear"}
    else:
        td = "improved" if rho <= 2 else "exact"
        vals |= {"eso.k_alpha": 1.0, "eso.k_beta": 0.5, "eso.g_alpha": 0.9, "eso.g_beta": 0.3}
        vals |= {"td.a": 0.0, "td.b": 1.0, "td.c": 0.05, "td.rho": 20.0}
        vals["sef.v_limit"] = 5000.0 / b
        for i in range(rho):
            vals |= {f"sef.k{i + 1}": gains[i], f"sef.kb{i + 1}": 0.2 * gains[i]}
            vals |= {f"sef.mu{i + 1}": 1.0, f"sef.alpha{i + 1}": 1.0}
        kinds = {"eso": "improved", "sef": "improved"}
    ctrl = Controller(
        **kinds, td=td, law="aiofl", rho=rho, n_feedback=rho, values=vals, structure=structure
    )
    return ctrl.with_binomial_alphas()


def versus_engine(
    folder: Path,
    files: dict[str, str],
    precision: str,
    plant: Plant,
    ref: Reference,
    ctrl: Controller,
    sampling: Sampling,
    t_final: float,
    mode: str = "zero",
    x0: tuple[float, ...] = (),
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Drive the plant with the C controller started in ``mode``; step the engine's
    discrete controller started the same way (``eso.init = mode``) on the same, unrounded
    measurement and reference.  Returns (u_C, u_engine, y)."""
    extra = STRICT_FLOAT if precision == "float" else []
    cc = CController(build(folder, files, extra), precision)
    model = plant if ctrl.eso_model != "none" else None
    eng = DiscreteController(dataclasses.replace(ctrl, eso_init=mode), sampling, model, x0)
    u_e: list[float] = []

    def step(r: list[float], y: float) -> float:
        if not u_e:
            cc.start(y, mode)
            eng.init(y)
        u_e.append(eng.step(r, y))
        return cc.step(r, y)

    start = (ref.offset,) if plant.name == "tank" else x0  # the tank: not empty
    _, y, u_c = loop(step, plant, ref, ctrl.rho, sampling.ts, t_final, x0=start, n_sub=5)
    return u_c, np.array(u_e), y


CASES = [(s, rho) for rho in (1, 2, 3, 4) for s in ("LESO", "INLESO", "LADRC")]


@needs_cc
@pytest.mark.parametrize("precision", ["double", "float"])
@pytest.mark.parametrize(("structure", "rho"), CASES, ids=[f"{s}-rho{r}" for s, r in CASES])
def test_c_controller_equals_the_engines_in_closed_loop(tmp_path, structure, rho, precision):
    name, _, ref = PLANTS[rho]
    ctrl = design(structure, rho)
    sampling = Sampling(1e-3)
    files = export_c(ctrl, sampling, precision=precision)
    u_c, u_e, y = versus_engine(
        tmp_path, files, precision, get_plant(name), ref, ctrl, sampling, 2.0
    )
    assert np.all(np.isfinite(u_e)) and np.max(np.abs(y)) < 1e3  # a working loop
    rel = np.max(np.abs(u_c - u_e)) / np.max(np.abs(u_e))
    assert rel < TOL[precision], rel


@needs_cc
@pytest.mark.parametrize(
    ("structure", "rho", "sampling"),
    [
        ("LADRC", 4, Sampling(5e-4, delay=1)),
        ("LESO", 2, Sampling(1e-3, eso="euler", td="euler")),
        ("LESO", 4, Sampling(2e-3, h0=4e-3)),
        ("INLESO", 2, Sampling(2e-4, delay=1)),
    ],
    ids=["delay", "euler-eso-euler-td", "fhan-h0", "inleso-delay"],
)
@pytest.mark.parametrize("mode", ["zero", "output", "bumpless"])
def test_c_controller_options_and_starts_equal_the_engines(
    tmp_path, structure, rho, sampling, mode
):
    name, _, ref = PLANTS[rho]
    ctrl = design(structure, rho)
    files = export_c(ctrl, sampling)
    u_c, u_e, _ = versus_engine(
        tmp_path, files, "double", get_plant(name), ref, ctrl, sampling, 1.0, mode
    )
    assert np.max(np.abs(u_c - u_e)) < TOL["double"] * np.max(np.abs(u_e))


@needs_cc
@pytest.mark.parametrize(
    ("preset", "ts", "t_final"),
    [("tank-ladrc", 1e-3, 2.0), ("dcmotor-arm-ladrc", 1e-3, 2.0), ("paper-s1-inleso", 1e-4, 0.5)],
)
def test_shipped_designs_export_and_agree(tmp_path, preset, ts, t_final):
    """Shipped designs through the CLI (with --prefix).  The paper's ITD is linearly
    unstable under Euler at 1 ms, so that design runs at 0.1 ms."""
    out = tmp_path / "c"
    args = ["export", preset, "--ts", str(ts), "--prefix", "ctl", "--out", str(out)]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    cfg = load_config(preset)
    files = {p.name: p.read_text() for p in out.iterdir() if p.suffix in (".c", ".h")}
    cc = CController(build(tmp_path / "b", files), "double", prefix="ctl")
    eng = DiscreteController(cfg.controller, Sampling(ts))
    u_e: list[float] = []

    def step(r: list[float], y: float) -> float:
        if not u_e:
            cc.start(y, cfg.controller.eso_init)
            eng.init(y)
        u_e.append(eng.step(r, y))
        return cc.step(r, y)

    x0 = (cfg.scenario.reference.offset,) if cfg.plant.name == "tank" else ()
    _, _, u_c = loop(
        step, cfg.plant, cfg.scenario.reference, cfg.controller.rho, ts, t_final, x0=x0
    )
    assert np.max(np.abs(u_c - np.array(u_e))) < 1e-12 * np.max(np.abs(u_e))


@needs_cc
@pytest.mark.parametrize(("structure", "rho"), [("LESO", 2), ("INLESO", 2), ("LADRC", 4)])
def test_float_code_has_no_double_arithmetic(tmp_path, structure, rho):
    """-Wconversion -Wdouble-promotion -Werror: no silent double operation in float code
    (the signals' differences are explicit casts); every parameter is a float literal."""
    files = export_c(design(structure, rho), Sampling(1e-3, delay=1), precision="float")
    build(tmp_path, files, STRICT_FLOAT)
    assert "#define AIOFL_REAL_IS_FLOAT 1" in files[HEADER]
    code = re.sub(r"/\*.*?\*/", "", files[PARAMS], flags=re.S).split("aiofl_params", 1)[1]
    literals = re.findall(r"(?<![\w.\[])(\d+\.\d*(?:e[-+]?\d+)?f?)(?![\w.])", code)
    assert literals and all(lit.endswith("f") for lit in literals)


def test_generated_code_follows_the_api_and_rules():
    ctrl = load_config("retuned-s1-inleso").controller
    files = export_c(ctrl, Sampling(1e-3), title="t", prefix="motor")
    assert set(files) == {"motor_controller.h", "motor_controller.c", "motor_params.c"}
    h, c = files["motor_controller.h"], files["motor_controller.c"]
    assert re.search(r"#define MOTOR_RHO 4\b", h) and re.search(r"#define MOTOR_TS 0\.001\b", h)
    assert "#define MOTOR_U_MIN (-HUGE_VAL)" in h and "#define MOTOR_U_MAX (HUGE_VAL)" in h  # open
    for proto in (
        "void motor_init(motor_state *s, const motor_params *p, motor_signal y0);",
        "void motor_reset(motor_state *s, const motor_params *p, motor_signal y0);",
        "void motor_start(motor_state *s, const motor_params *p, motor_signal y0, int mode);",
        "motor_real motor_step(motor_state *s, const motor_params *p, const motor_signal *r, "
        "motor_signal y);",
        "extern const motor_params motor_default_params;",
    ):
        assert proto in h
    assert "aiofl_" not in c and "AIOFL_" not in c  # the prefix replaced every name
    includes = ["<math.h>", '"motor_controller.h"', '"motor_model.h"']  # the last: #if model
    assert re.findall(r"#include\s*(\S+)", c) == includes
    assert not re.search(r"\b(malloc|calloc|realloc|free)\b", c)
    # the source is the shipped template, prefixed
    from aiofl.export.c_code import apply_prefix, template

    assert c == apply_prefix(template("controller.c"), "motor")
    for name in ("law.b0", "eso.omega0", "eso.k_alpha", "td.rho", "sef.mu2", "sef.v_limit"):
        assert f"{name} = {ctrl.value(name)!r}" in h
    assert "forward Euler" in h and "Ts = 0.001 s" in h


# ------------------------------------------------------------- firmware-ready C, from C
MAIN = r"""
#include <stdio.h>
#include "a_controller.h"
#include "b_controller.h"
int main(void)
{
    a_state sa; b_state sb;
    const a_signal ra[A_RHO + 1] = {0.1};
    const b_signal rb[B_RHO + 1] = {0.1};
    a_real ua; b_real ub;
    a_init(&sa, &a_default_params, 0.0);
    b_init(&sb, &b_default_params, 0.0);
    ua = a_step(&sa, &a_default_params, ra, 0.0);
    ub = b_step(&sb, &b_default_params, rb, 0.0);
    printf("%d %d %.17g %.17g\n", A_RHO, B_RHO, (double)ua, (double)ub);
    return 0;
}
"""


@needs_cc
@pytest.mark.parametrize("precision", ["double", "float"])
def test_two_prefixed_exports_link_into_one_program(tmp_path, precision):
    """Two designs of different ρ and structure, prefixes a and b, in one program under
    -std=c99 -Wall -Wextra -Werror (float: -Wconversion -Wdouble-promotion): every
    external symbol carries its prefix (nm), and each gives its own first command."""
    ca, cb = design("LADRC", 2), design("LESO", 4)
    files = export_c(ca, Sampling(1e-3), precision=precision, prefix="a")
    files |= export_c(cb, Sampling(1e-3), precision=precision, prefix="b")
    for n, t in files.items():
        (tmp_path / n).write_text(t)
    (tmp_path / "main.c").write_text(MAIN)
    extra = STRICT_FLOAT if precision == "float" else []
    srcs = sorted(str(p) for p in tmp_path.glob("*.c"))
    exe = tmp_path / "prog"
    proc = subprocess.run(
        [str(CC), *WARN, *extra, "-o", str(exe), *srcs, "-lm"], capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stderr
    out = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.split()
    assert out[:2] == ["2", "4"]
    for src in (s for s in srcs if not s.endswith("main.c")):
        obj = tmp_path / (Path(src).stem + ".o")
        subprocess.run([str(CC), *WARN, *extra, "-c", "-o", str(obj), src], check=True)
        nm = subprocess.run(
            ["nm", "-g", "--defined-only", str(obj)], capture_output=True, text=True
        )
        names = [ln.split()[-1] for ln in nm.stdout.splitlines() if ln.strip()]
        assert names and all(n.startswith(Path(src).stem[0] + "_") for n in names), names
    for prefix, ctrl in (("a", ca), ("b", cb)):  # the first command equals the engine's
        eng = DiscreteController(dataclasses.replace(ctrl, eso_init="bumpless"), Sampling(1e-3))
        eng.init(0.0)
        want = eng.step([0.1] + [0.0] * ctrl.rho, 0.0)
        got = float(out[2 if prefix == "a" else 3])
        assert abs(got - want) <= TOL[precision] * max(1.0, abs(want)), (prefix, got, want)


@needs_cc
def test_switching_parameter_instances_at_a_sample_boundary(tmp_path):
    """--params-only writes a second instance (ω0, ω_c, b0 changed); the controller steps
    with the default for 1 s, then with the second one: the commands equal the engine's
    controller A for 1 s, then controller B carrying on from A's state."""
    name, _, ref = PLANTS[2]
    ca = design("LADRC", 2)
    cb = ca.with_values(**{"eso.omega0": 90.0, "sef.omega_c": 9.0, "law.b0": 5.0})
    s = Sampling(1e-3)
    files = export_c(ca, s) | export_c(cb, s, params_only="fast")
    assert set(files) == {HEADER, SOURCE, PARAMS, "aiofl_fast.c", "aiofl_fast.h"}
    cc = CController(build(tmp_path, files), "double")
    ea, eb = (DiscreteController(dataclasses.replace(c, eso_init="bumpless"), s) for c in (ca, cb))
    u_e: list[float] = []

    def step(r: list[float], y: float) -> float:
        k = len(u_e)
        if k == 0:
            cc.start(y, "bumpless")
            ea.init(y)
        if k == 1000:  # the sample boundary
            cc.use("aiofl_fast")
            eb.state = ea.state
        u_e.append((ea if k < 1000 else eb).step(r, y))
        return cc.step(r, y)

    _, _, u_c = loop(step, get_plant(name), ref, 2, 1e-3, 2.0)
    u_e_arr = np.array(u_e)
    assert np.max(np.abs(u_c - u_e_arr)) < 1e-12 * np.max(np.abs(u_e_arr))
    # B differs from A: the switch changed the commands
    u_a = [ea.step(r, 0.0) for r in ([0.5, 0.0, 0.0],) * 3]
    u_b = [eb.step(r, 0.0) for r in ([0.5, 0.0, 0.0],) * 3]
    assert abs(u_a[-1] - u_b[-1]) > 1e-3


@needs_cc
@pytest.mark.parametrize(
    "other",
    [
        {"prefix": "aiofl", "ts": 2e-3},
        {"prefix": "aiofl", "rho": 1},
        {"prefix": "aiofl", "precision": "float"},
        {"prefix": "aiofl", "delay": 1},
    ],
    ids=["ts", "rho", "precision", "delay"],
)
def test_a_parameter_instance_of_another_layout_does_not_compile(tmp_path, other):
    """The params-only file checks AIOFL_LAYOUT (prefix, precision, ρ, Ts, options) with
    #error; the same design compiles."""
    ctrl = design("LADRC", 2)
    files = export_c(ctrl, Sampling(1e-3))
    same = export_c(ctrl.with_values(**{"eso.omega0": 80.0}), Sampling(1e-3), params_only="b")
    build(tmp_path / "same", files | same)
    c2 = design("LADRC", other.get("rho", 2))
    s2 = Sampling(other.get("ts", 1e-3), delay=other.get("delay", 0))
    bad = export_c(c2, s2, params_only="b", precision=other.get("precision", "double"))
    for n, t in (files | bad).items():
        (tmp_path / n).write_text(t)
    proc = subprocess.run(
        [str(CC), *WARN, "-c", "-o", str(tmp_path / "b.o"), str(tmp_path / "aiofl_b.c")],
        capture_output=True,
        text=True,
    )
    assert proc.returncode != 0 and "these parameters are for another controller" in proc.stderr


@needs_cc
@pytest.mark.parametrize("structure", ["LADRC", "LESO", "INLESO"])
def test_bumpless_start_holds_the_pendulum(tmp_path, structure):
    """The pendulum at rest at y0 = r = 0.3 (holding it needs |u| = 1.45): with the
    bumpless start the first command is no larger (here 0: the extended state starts at 0
    and learns the gravity load), |u| stays below 1.5x the holding input and y within
    0.02 of 0.3 for 1 s; the zero and output starts kick it (|u| up to 9-118, y strays
    0.09-0.34).  NAME_reset mid-run (after a run elsewhere) gives the same first command."""
    plant = get_plant("pendulum")
    p = plant.param_vector()
    x0 = np.array([0.3, 0.0])
    g = np.asarray(plant.compiled[1](x0, p))
    u_hold = abs(float(np.asarray(plant.compiled[0](x0, p))[1] / g[1]))
    ref = Reference(amplitude=0.0, omega=1.0, offset=0.3)
    ctrl = design(structure, 2)
    cc = CController(build(tmp_path, export_c(ctrl, Sampling(1e-3))), "double")
    seen = {}
    for mode in ("bumpless", "zero", "output"):
        us: list[float] = []

        def step(r: list[float], y: float, mode: str = mode, us: list[float] = us) -> float:
            if not us:
                cc.start(y, mode)
            us.append(cc.step(r, y))
            return us[-1]

        _, y, u = loop(step, plant, ref, 2, 1e-3, 1.0, x0=x0)
        seen[mode] = (abs(u[0]), float(np.max(np.abs(u))), float(np.max(np.abs(y - 0.3))))
    u0, umax, dev = seen["bumpless"]
    assert u0 <= u_hold and umax < 1.5 * u_hold and dev < 0.02
    for mode in ("zero", "output"):
        assert seen[mode][1] > 4 * u_hold and seen[mode][2] > 4 * dev, (mode, seen)
    # reset mid-run: after a second of tracking another reference, at rest at 0.3 again
    cc.start(0.0, "zero")
    for k in range(500):
        cc.step([0.5 * math.sin(k * 1e-3), 0.0, 0.0], 0.1)
    cc.reset(0.3)
    assert abs(cc.step([0.3, 0.0, 0.0], 0.3)) <= u_hold + 1e-12


@needs_cc
@pytest.mark.parametrize("structure", ["LESO", "INLESO", "LADRC"])
def test_asymmetric_actuator_range_c_equals_the_engine(tmp_path, structure):
    """law.u_min = -0.5 law.u_max: U_MIN / U_MAX in the header and the params, the C clamps
    like the engine; on the tank both limits are reached and the commands agree."""
    name, _, ref = PLANTS[1]
    ctrl = design(structure, 1).with_values(**{"law.u_max": 10.0, "law.u_min": -5.0})
    files = export_c(ctrl, Sampling(1e-3))
    assert "#define AIOFL_U_MIN (-5.0)" in files[HEADER]
    assert ".u_min = -5.0," in files[PARAMS] and ".u_max = 10.0," in files[PARAMS]
    plant = get_plant(name)
    u_c, u_e, _ = versus_engine(tmp_path, files, "double", plant, ref, ctrl, Sampling(1e-3), 2.0)
    assert np.min(u_e) == np.min(u_c) == -5.0 and np.max(u_e) == np.max(u_c) == 10.0
    assert np.max(np.abs(u_c - u_e)) < TOL["double"] * 10.0


def test_iofl_and_missing_sample_time_are_refused():
    with pytest.raises(ExportError, match="IOFL law evaluates the plant model"):
        export_c(load_config("iofl-s1").controller, Sampling(1e-3))
    with pytest.raises(ExportError, match="no sample time"):
        export_c(load_config("retuned-s1-leso").controller, None)
