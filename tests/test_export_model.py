"""The C export of a model-assisted controller (``eso.model = "nominal"``).

The nominal :math:`(\\hat\\alpha, \\hat\\beta)(\\xi)` is C generated from the plant's sympy
expressions (:mod:`aiofl.export.c_model`); compiled (``-std=c99 -Wall -Wextra -Werror``,
float code also under ``-Wconversion -Wdouble-promotion``) and driven in closed loop, its
commands equal those of the engine's discrete controller stepped from Python with the
plant (:class:`aiofl.discrete_controller.DiscreteController`, whose observer gain is placed for
the model as the sampled engine's is).  A model-assisted controller is never exported
without its model; a plain Python plant (no expressions) is refused, through the CLI with
exit status 2; a model-free controller's export ignores the plant.
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest
from typer.testing import CliRunner

from aiofl.cli.app import app
from aiofl.config import load_config
from aiofl.controller import Controller, controller_batch
from aiofl.engine.discrete_rows import D_L, Sampling, sampling_rows
from aiofl.engine.observer_gains import model_jacobians
from aiofl.export import HEADER, PARAMS, SOURCE, ExportError, export_c
from aiofl.export.c_code import MODEL
from aiofl.plants import get_plant, registry
from aiofl.plants.base import Plant
from aiofl.scenario import Reference
from test_export import needs_cc, versus_engine

SAMPLING = Sampling(1e-3)
REF = Reference(amplitude=math.pi / 4, omega=2.0)


@pytest.fixture(scope="module")
def slfjm() -> Plant:
    return get_plant("slfjm")


def assisted(plant: Plant) -> Controller:
    """The issue's design: LADRC structure with exact reference derivatives, the nominal
    model in the ESO, ω0 = 60, ω_c = 25, b0 = the plant's nominal β (≈ 26833.33)."""
    beta = float(plant.normal_form(np.zeros(plant.n_states), plant.param_vector())[-1])
    vals = {"eso.omega0": 60.0, "sef.omega_c": 25.0, "law.b0": beta}
    base = Controller.from_structure("LADRC", rho=plant.relative_degree, values=vals)
    return dataclasses.replace(base, td="exact", eso_model="nominal").with_binomial_alphas()


@needs_cc
@pytest.mark.parametrize("precision", ["double", "float"])
def test_model_assisted_c_equals_the_discrete_controller(tmp_path, slfjm, precision):
    """Double: the same operations in the same order (the expressions' common
    subexpressions as in the plant's generated Python), so only libm's last bits and the
    compilers' evaluation differ: 1e-12 of the largest command (seen: 3e-14).  Float:
    24-bit arithmetic (eps 6e-8) against the engine's double on the same float-rounded
    inputs; the rho = 4 observer amplifies a rounding of the measurement by |L_5| ~ 7e5
    and alpha-hat (~1e4 xi) carries float's relative error into u: 1e-5 of the largest
    command (seen: 8e-7; the model-free float tests allow 1e-4)."""
    ctrl = assisted(slfjm)
    files = export_c(ctrl, SAMPLING, precision=precision, plant=slfjm)
    src, model = files[SOURCE], files[MODEL]
    assert "static void aiofl_nominal_model(const aiofl_params *p, const aiofl_real *xi," in model
    assert "aiofl_nominal_model(p, xi, &a_hat, &b_hat);" in src
    assert "u = (p->b0 * v - a_hat - s->xhat[AIOFL_RHO]) / b_hat;" in src
    assert "um = (a_hat + b_hat * um) / p->b0;" in src
    assert "#define AIOFL_ESO_MODEL 1" in files[HEADER]
    assert "Nominal model (eso.model = nominal) of plant slfjm" in files[HEADER]
    for mode in ("zero", "bumpless"):
        u_c, u_e, y = versus_engine(
            tmp_path / mode, files, precision, slfjm, REF, ctrl, SAMPLING, 2.0, mode
        )
        assert np.all(np.isfinite(u_e)) and np.max(np.abs(y)) < 10.0  # a working loop
        late = slice(len(y) // 2, None)
        t = np.arange(len(y)) * SAMPLING.ts
        assert np.max(np.abs(y[late] - REF.amplitude * np.sin(REF.omega * t[late]))) < 0.05
        rel = np.max(np.abs(u_c - u_e)) / np.max(np.abs(u_e))
        assert rel < (1e-12 if precision == "double" else 2e-5), (mode, rel)
    if precision == "float":  # every literal of the model and the params is a float one
        code = re.sub(r"/\*.*?\*/", "", model + files[PARAMS], flags=re.S)
        literals = re.findall(r"(?<![\w.\[])(\d+\.\d*(?:e[-+]?\d+)?f?)(?![\w.])", code)
        assert literals and all(lit.endswith("f") for lit in literals)
        assert "sinf(xi[0])" in model and "cosf(xi[0])" in model


def test_the_observer_gain_is_placed_for_the_model(slfjm):
    """ESO_L is the gain the sampled engine uses: placed for the model's error map at
    Φ(x0) (here the origin), not the chain's current-observer gain."""
    ctrl = assisted(slfjm)
    batch = controller_batch(ctrl)
    jac = model_jacobians(slfjm, batch, [()])
    placed = sampling_rows(batch, [SAMPLING], SAMPLING.ts, jac)[0][D_L : D_L + 5]
    chain = sampling_rows(batch, [SAMPLING], SAMPLING.ts)[0][D_L : D_L + 5]
    assert not np.allclose(placed, chain)
    src = export_c(ctrl, SAMPLING, plant=slfjm)[PARAMS]
    line = re.search(r"\.eso_l = \{([^}]*)\}", src)
    assert line is not None
    np.testing.assert_array_equal([float(v) for v in line.group(1).split(",")], placed)


def test_never_exported_without_the_model(slfjm):
    ctrl = assisted(slfjm)
    with pytest.raises(ExportError, match="pass plant="):
        export_c(ctrl, SAMPLING)
    # a model-free controller's export ignores the plant, and has no model
    free = dataclasses.replace(ctrl, eso_model="none")
    assert export_c(free, SAMPLING) == export_c(free, SAMPLING, plant=slfjm)
    assert MODEL not in export_c(free, SAMPLING)
    assert "#define AIOFL_ESO_MODEL 0" in export_c(free, SAMPLING)[HEADER]


def test_plants_without_the_expressions_are_refused(slfjm):
    ctrl = assisted(slfjm)
    plain = dataclasses.replace(slfjm, name="my_python_plant")
    with pytest.raises(ExportError, match=r"my_python_plant.*no symbolic expressions"):
        export_c(ctrl, SAMPLING, plant=plain)
    # a plant registered under a built-in name with other dynamics: the expressions are not its
    other = dataclasses.replace(
        slfjm,
        alpha_beta_of_xi=lambda xi, p: (-2.0 * float(xi[0]), slfjm.alpha_beta_of_xi(xi, p)[1]),
    )
    with pytest.raises(ExportError, match="does not give the plant's alpha_beta_of_xi"):
        export_c(ctrl, SAMPLING, plant=other)


RUN = """
plant = "{plant}"
[scenario]
t_final = 1.0
[controller]
structure = "LADRC"
td_kind = "exact"
[controller.eso]
omega0 = 60.0
model = "nominal"
[controller.sef]
omega_c = 25.0
[controller.law]
b0 = {b0}
[controller.discrete]
ts = 1e-3
[simulation]
dt = 1e-4
"""


def test_cli_refuses_a_plain_python_plant(tmp_path, monkeypatch, slfjm):
    plain = dataclasses.replace(slfjm, name="plain_slfjm")
    monkeypatch.setitem(registry._REGISTRY, "plain_slfjm", lambda: plain)
    monkeypatch.setitem(registry._CACHE, "plain_slfjm", plain)
    cfg = tmp_path / "plain.toml"
    cfg.write_text(RUN.format(plant="plain_slfjm", b0=26833.33))
    out = tmp_path / "c"
    res = CliRunner().invoke(app, ["export", str(cfg), "--out", str(out)])
    assert res.exit_code == 2, res.output
    assert "no symbolic expressions" in res.output and "plain_slfjm" in res.output
    assert not out.exists()


PENDULUM = """
name = "pendulum_file"
states = ["theta", "theta_dot"]
f = ["theta_dot", "-g/l*sin(theta) - c/(m*l**2)*theta_dot"]
g = ["0", "1/(m*l**2)"]
h = "theta"
[params]
m = 1.0
l = 0.5
c = 0.1
g = 9.81
"""


@needs_cc
def test_cli_exports_a_plant_files_model(tmp_path):
    """A plant file's expressions (SymbolicPlant.from_toml) through ``aiofl export``; the
    gain placed at the scenario's x0, as the engine places it."""
    (tmp_path / "pend.toml").write_text(PENDULUM)
    cfg_path = tmp_path / "run.toml"
    text = RUN.format(plant="pend.toml", b0=4.0).replace('td_kind = "exact"\n', "")
    text = text.replace('structure = "LADRC"', 'structure = "LADRC"\ntd_kind = "exact"')
    text = text.replace("t_final = 1.0", "t_final = 1.0\nx0 = [0.2, 0.0]")
    cfg_path.write_text(text)
    out = tmp_path / "c"
    res = CliRunner().invoke(app, ["export", str(cfg_path), "--out", str(out)])
    assert res.exit_code == 0, res.output
    cfg = load_config(str(cfg_path))
    assert cfg.controller.eso_model == "nominal" and cfg.scenario.x0 == (0.2, 0.0)
    files = {p.name: p.read_text() for p in out.iterdir() if p.suffix in (".c", ".h")}
    assert "PLANT_P[" in files[MODEL] and "sin(xi[0])" in files[MODEL]
    ref = Reference(amplitude=0.5, omega=1.0)
    u_c, u_e, _ = versus_engine(
        tmp_path / "b",
        files,
        "double",
        cfg.plant,
        ref,
        cfg.controller,
        cfg.sampling,
        1.0,
        cfg.controller.eso_init,
        x0=cfg.scenario.x0,
    )
    assert np.max(np.abs(u_c - u_e)) < 1e-12 * np.max(np.abs(u_e))


def test_the_plants_name_reaches_only_comments(slfjm):
    """The plant's name (a plant file's, user text) is made inert in the comment block; the
    model's code holds only aiofl's names (xi, PLANT_P, t_j, <math.h>)."""
    # (a bidirectional control is refused where the name enters: aiofl.text)
    hostile = dataclasses.replace(slfjm, name="x */ #define aiofl_step EVIL /* ")
    files = export_c(assisted(slfjm), SAMPLING, plant=hostile, plant_source="slfjm")
    for text in files.values():
        code = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
        assert "EVIL" not in code and "#define aiofl_step" not in code
    assert "of plant x _/ _define aiofl_step EVIL /_" in files[HEADER]
