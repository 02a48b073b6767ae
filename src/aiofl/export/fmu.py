r"""An FMI 2.0 co-simulation FMU of a sampled AIOFL controller (``aiofl export --format fmu``).

:func:`export_fmu` packs the C export (:func:`aiofl.export.export_c`, the engine's discrete
controller) into ``<modelIdentifier>.fmu``:

- ``modelDescription.xml``, written with :mod:`xml.etree.ElementTree` (user text, the
  config's name and description, is escaped by the XML library, never formatted into it,
  and a character XML 1.0 cannot hold is written as a visible escape);
- ``sources/``: the controller's C files, the hand-written co-simulation wrapper
  ``fmi2_wrapper.c`` (shipped in ``aiofl/export/templates``), the FMI 2.0 standard headers
  (2-clause BSD, from FMPy) and ``fmu_adapter.h``, generated here: it maps the controller's
  API and its tunable parameters onto the names the wrapper uses;
- ``binaries/linux64/<modelIdentifier>.so``, built at export with the system C compiler
  (``$CC``, default ``cc``); no compiler: :class:`ExportError`.

Variables: inputs ``y`` and ``r`` (and ``r_1`` .. ``r_rho``, the reference's derivatives,
when the controller takes them: ``td = "exact"``); output ``u``; the calculated parameters
``Ts`` and the design values discretised into the coefficients (``eso.omega0``,
``td.omega``); tunable parameters (settable any time, effective from the next sample) the
design values the step uses directly: ``law.b0`` (the ESO's input column Γ scaled with it),
``law.u_min``/``law.u_max`` when finite, the SEF's gains (``sef.omega_c`` of a linear SEF,
``sef.k*``, ``sef.alpha*``, ... of a nonlinear one), the INLESO's ``eso.k_alpha`` ..., ``td.R``
and ``td.rho``; the integer parameter ``start`` (0 bumpless, 1 zero, 2 output).
The default experiment's step size is Ts; the wrapper's comment says how it samples (only at
communication points that are multiples of Ts; a step passing a sample instant is an error).

The adapter maps the exported API onto the wrapper's names: each FMU instance holds its own
copy of ``NAME_params`` (from ``NAME_default_params``), which the tunable parameters write
into, and calls ``NAME_start(&s, &p, y0, start)`` and ``NAME_step(&s, &p, r, y)``.
"""

from __future__ import annotations

import hashlib
import io
import math
import os
import platform
import re
import shutil
import subprocess
import tempfile
import uuid
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from aiofl.controller import Controller, controller_batch
from aiofl.engine import discrete_rows as DS
from aiofl.engine.discrete_rows import Sampling, sampling_rows
from aiofl.export import c_code
from aiofl.export.c_text import c_prefix
from aiofl.export.errors import ExportError
from aiofl.plants.base import Plant, derivative_unit
from aiofl.text import xml_text

if TYPE_CHECKING:
    from aiofl.config.run_config import RunConfig

__all__ = ["FmuParameter", "export_fmu", "export_fmu_for_config", "find_compiler", "fmu_parameters"]

WRAPPER = "fmi2_wrapper.c"
ADAPTER = "fmu_adapter.h"
FMI_HEADERS = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")
CFLAGS = ("-std=c99", "-O2", "-shared", "-fPIC", "-fvisibility=hidden", "-Wall", "-Wextra")
START_MODES = {"bumpless": 0, "zero": 1, "output": 2}  # the FMU's start parameter


@dataclass(frozen=True)
class FmuParameter:
    """One parameter the FMU shows.

    Attributes
    ----------
    name
        The FMI variable name (the config's column name, e.g. ``"law.b0"``, or ``"Ts"``).
    value
        The exported design's value.
    description
        One line for ``modelDescription.xml``.
    tunable
        ``causality="parameter" variability="tunable"`` (settable during the run) if True,
        else ``causality="calculatedParameter"`` (fixed at export: it is discretised into
        the coefficients).
    minimum, nonzero
        The range a tunable value must be in: ``>= minimum`` (None: any), and not 0.
    setter
        C statements writing the value ``v`` (a ``double``) into the instance's parameter
        struct ``*p`` (``aiofl_params``, its fields as the template names them; the prefix is
        applied with the rest of ``fmu_adapter.h``).
    """

    name: str
    value: float
    description: str
    tunable: bool
    minimum: float | None = None
    nonzero: bool = False
    setter: tuple[str, ...] = ()


def _b0_scales_gamma(controller: Controller, sampling: Sampling) -> bool:
    """Whether b0 enters the discrete coefficients only through Γ, proportionally (so the
    FMU can retune it by scaling Γ): compares the rows at b0 and 2 b0."""
    if controller.eso_model != "none":  # the model-assisted law and gain read the model
        return False
    b0 = controller.value("law.b0")
    rows = [
        sampling_rows(
            controller_batch(controller.with_values(**{"law.b0": b})), [sampling], sampling.ts
        )
        for b in (b0, 2.0 * b0)
    ]
    a, b = rows[0][0], rows[1][0]
    n = controller.rho + 1
    gam = slice(DS.D_GAM, DS.D_GAM + n)
    other = np.ones(a.size, dtype=bool)
    other[gam] = False
    return bool(np.array_equal(a[other], b[other])) and bool(
        np.allclose(b[gam], 2.0 * a[gam], rtol=1e-12, atol=0.0)
    )


def fmu_parameters(controller: Controller, sampling: Sampling) -> list[FmuParameter]:
    """The parameters the FMU of ``controller`` sampled by ``sampling`` shows, Ts first.

    Parameters
    ----------
    controller
        An exportable AIOFL controller.
    sampling
        Its sample time and discretisation.

    Returns
    -------
    list of FmuParameter
        The calculated parameters (Ts, the design values discretised into the observer and
        prefilter coefficients), then the tunable ones, with their C setters.
    """
    c, rho, m = controller, controller.rho, controller.n_feedback
    v = c.value
    calc = [FmuParameter("Ts", sampling.ts, "sample time [s] (fixed at export)", False)]
    if c.eso_gains != "kalman":
        calc.append(FmuParameter("eso.omega0", v("eso.omega0"), "observer bandwidth", False))
    if c.td == "linear":
        calc.append(FmuParameter("td.omega", v("td.omega"), "prefilter bandwidth", False))
    if v("eso.delay") != 0.0:
        what = "known measurement delay compensated [s] (fixed at export)"
        calc.append(FmuParameter("eso.delay", v("eso.delay"), what, False))

    def tun(name: str, what: str, *setter: str, minimum: float | None = None, nz: bool = False):
        return FmuParameter(name, v(name), what, True, minimum, nz, tuple(setter))

    out: list[FmuParameter] = []
    pos = {"minimum": 0.0, "nz": True}  # > 0
    if _b0_scales_gamma(c, sampling):
        out.append(
            tun(
                "law.b0",
                "input gain estimate b0 (the observer's input column scales with it)",
                "p->b0 = (aiofl_real)v;",
                *(
                    f"p->eso_gamma[{j}] = (aiofl_real)((double)aiofl_default_params.eso_gamma"
                    f"[{j}] * (v / (double)aiofl_default_params.b0));"
                    for j in range(rho + 1)
                ),
                nz=True,
            )
        )
    else:
        calc.append(FmuParameter("law.b0", v("law.b0"), "input gain estimate b0", False))
    if c.eso_model == "none" and c.eso_init != "zero":  # read at the start
        out.append(tun("eso.u0", "command held at the start", "p->u0 = (aiofl_real)v;"))
    for name, field in (("law.u_max", "u_max"), ("law.u_min", "u_min")):
        if math.isfinite(v(name)):
            out.append(tun(name, "actuator limit", f"p->{field} = (aiofl_real)v;"))
    if c.eso == "improved":
        for name in ("k_alpha", "k_beta", "g_alpha", "g_beta"):
            out.append(tun(f"eso.{name}", "INLESO injection", f"p->{name} = (aiofl_real)v;"))
    if c.td == "han":
        out.append(tun("td.R", "TD speed factor R", "p->td_r = (aiofl_real)v;", minimum=0.0))
    elif c.td == "improved":
        out.append(tun("td.rho", "ITD speed factor", "p->itd_rho = (aiofl_real)v;"))
    if c.sef == "linear":
        out.append(
            tun(
                "sef.omega_c",
                "SEF bandwidth (gains binomial(rho, i-1) omega_c^(rho-i+1))",
                *(f"p->sef_gain[{i}] = (aiofl_real)fmu_binomial_power({i}, v);" for i in range(m)),
                **pos,
            )
        )
    elif c.sef == "nonlinear":
        slope = "p->sef_slope[{i}] = (aiofl_real)pow((double)p->sef_delta[{i}], "
        slope += "(double)p->sef_alpha[{i}] - 1.0);"
        for i in range(m):
            out.append(tun(f"sef.k{i + 1}", "SEF gain", f"p->sef_k[{i}] = (aiofl_real)v;"))
            alpha = f"p->sef_alpha[{i}] = (aiofl_real)v;"
            out.append(
                tun(f"sef.alpha{i + 1}", "fal exponent", alpha, slope.format(i=i), minimum=0)
            )
            delta = f"p->sef_delta[{i}] = (aiofl_real)v;"
            out.append(tun(f"sef.delta{i + 1}", "fal zone", delta, slope.format(i=i), **pos))
    else:  # improved
        for i in range(m):
            for vec, field, what in (
                ("k", "sef_k", "INLSEF gain"),
                ("kb", "sef_kb", "INLSEF error-dependent gain"),
                ("mu", "sef_mu", "INLSEF gain decay"),
                ("alpha", "sef_alpha", "INLSEF exponent"),
            ):
                name = f"sef.{vec}{i + 1}"
                out.append(tun(name, what, f"p->{field}[{i}] = (aiofl_real)v;"))
        out.append(tun("sef.v_limit", "INLSEF limit", "p->sef_v_limit = (aiofl_real)v;", **pos))
    return calc + out


# ---------------------------------------------------------------------- the C adapter


def _written_fields(params: Sequence[FmuParameter]) -> list[str]:
    """The fields of the parameter struct (``sef_gain[0]``, ``b0``, ...) the setters of
    ``params`` write, each once, in order."""
    found: dict[str, None] = {}
    for p in params:
        for line in p.setter:
            for m in re.finditer(r"p->(\w+(?:\[\d+\])*)\s*=(?!=)", line):
                found[m[1]] = None
    return list(found)


def _adapter(
    controller: Controller,
    params: Sequence[FmuParameter],
    n_in: int,
    guid: str,
    header: str,
) -> str:
    """``fmu_adapter.h``: the controller's API (``aiofl_start``, ``aiofl_step`` with a
    ``const aiofl_params *``; prefixed by the caller) under the wrapper's names."""
    lit = lambda x: c_code._literal(x, "double")  # noqa: E731
    calc = [p for p in params if not p.tunable]
    tun = [p for p in params if p.tunable]
    n = max(len(tun), 1)  # no zero-length arrays
    lines = [
        f"/* {ADAPTER}: generated by aiofl export --format fmu */",
        "#ifndef FMU_ADAPTER_H",
        "#define FMU_ADAPTER_H",
        "#include <math.h>",
        "",
        f'#include "{header}"',
        "",
        f'#define FMU_GUID "{guid}"',
        "#define FMU_TS AIOFL_TS",
        "#define FMU_RHO AIOFL_RHO",
        f"#define FMU_N_IN {n_in}",
        f"#define FMU_N_CALC {len(calc)}",
        f"#define FMU_N_TUN {len(tun)}",
        f"#define FMU_START_DEFAULT {START_MODES[controller.eso_init]}",
        "",
        "typedef aiofl_state fmu_ctl_state;",
        "typedef aiofl_params fmu_ctl_params;",
        "",
        f"static const double fmu_calc_values[{len(calc)}] = {{"
        + ", ".join(lit(p.value) for p in calc)
        + "};",
        f"static const double fmu_tun_defaults[{n}] = {{"
        + (", ".join(lit(p.value) for p in tun) or "0.0")
        + "};",
        f"static const double fmu_tun_min[{n}] = {{"
        + (", ".join("-HUGE_VAL" if p.minimum is None else lit(p.minimum) for p in tun) or "0.0")
        + "};",
        f"static const int fmu_tun_nonzero[{n}] = {{"
        + (", ".join(str(int(p.nonzero)) for p in tun) or "0")
        + "};",
        "",
        "static void fmu_ctl_defaults(fmu_ctl_params *p) { *p = aiofl_default_params; }",
        "",
        "static void fmu_ctl_start(fmu_ctl_state *s, const fmu_ctl_params *p, double y0, int mode)",
        "{",
        "    aiofl_start(s, p, (aiofl_signal)y0, mode);",
        "}",
        "",
        "/* r: r, r_1, ..., r_rho (FMU_N_IN - 1 values; only r with a differentiator) */",
        "static double fmu_ctl_step(fmu_ctl_state *s, const fmu_ctl_params *p, const double *r,"
        " double y)",
        "{",
        "    aiofl_signal rr[AIOFL_RHO + 1];",
        "    int i;",
        "    for (i = 0; i <= AIOFL_RHO; ++i)",
        "        rr[i] = (aiofl_signal)(i < FMU_N_IN - 1 ? r[i] : 0.0);",
        "    return (double)aiofl_step(s, p, rr, (aiofl_signal)y);",
        "}",
        "",
        "/* 1 after a fault (the controller holds u until the next start) */",
        "static int fmu_ctl_fault(const fmu_ctl_state *s) { return aiofl_fault(s); }",
        "",
        "/* 1 if every coefficient a tunable parameter writes is finite in aiofl_real */",
        "static int fmu_ctl_params_finite(const fmu_ctl_params *p)",
        "{",
        "    int ok = 1;",
        *(f"    ok = ok && fabs((double)p->{f}) < HUGE_VAL;" for f in _written_fields(tun)),
        "    (void)p;",
        "    return ok;",
        "}",
        "",
    ]
    if controller.sef == "linear":  # aiofl.components.fastmath.binomial_power, in C
        lines += [
            "static double fmu_binomial_power(int j, double omega)",
            "{",
            "    double binom = 1.0;",
            "    int i;",
            "    for (i = 1; i <= j; ++i) binom = binom * (double)(AIOFL_RHO - i + 1) / (double)i;",
            "    return binom * pow(omega, (double)(AIOFL_RHO - j));",
            "}",
            "",
        ]
    lines += ["/* a tunable parameter into the instance's copy of the parameters */"]
    lines += ["static void fmu_ctl_set(fmu_ctl_params *p, int i, double v)", "{"]
    lines += ["    switch (i) {"]
    for k, p in enumerate(tun):
        lines += [
            f"    case {k}: /* {p.name} */",
            *(f"        {s}" for s in p.setter),
            "        break;",
        ]
    lines += [
        "    default:",
        "        (void)p;",
        "        (void)v;",
        "    }",
        "}",
        "",
        "#endif",
        "",
    ]
    return "\n".join(lines)


# ---------------------------------------------------------------------- the FMU


def _inputs(controller: Controller) -> list[tuple[str, str]]:
    """The Real inputs, ``(name, description)``, in value-reference order."""
    out = [("y", "measured plant output"), ("r", "reference")]
    if controller.td == "exact":
        out += [
            (f"r_{i}", f"reference derivative d^{i}r/dt^{i}") for i in range(1, 1 + controller.rho)
        ]
    return out


def _units(controller: Controller, plant: Plant | None) -> dict[str, str]:
    """The unit of each Real variable that has one, by variable name: y and r in the
    plant's output unit, r_i in its derivatives', u and the actuator limits in its input
    unit, Ts in s (an undeclared unit, ``""`` or ``"-"``, is left out)."""
    out = {"Ts": "s", "eso.delay": "s"}
    if plant is not None:
        y, u = plant.output_unit, plant.input_unit
        out |= {"y": y, "r": y, "u": u, "law.u_max": u, "law.u_min": u, "eso.u0": u}
        out |= {f"r_{i}": derivative_unit(y, i) for i in range(1, 1 + controller.rho)}
    return {k: v for k, v in out.items() if v and v != "-"}


def _model_description(
    *,
    model_identifier: str,
    title: str,
    description: str,
    guid: str,
    inputs: Sequence[tuple[str, str]],
    params: Sequence[FmuParameter],
    sources: Sequence[str],
    ts: float,
    stop_time: float | None,
    start: int,
    units: dict[str, str] | None = None,
) -> bytes:
    """``modelDescription.xml`` (FMI 2.0 co-simulation), every attribute set through
    :mod:`xml.etree.ElementTree`, which escapes it, and what XML 1.0 cannot hold written as
    an escape (:func:`aiofl.text.xml_text`); ``start``: the default of the start-mode
    parameter (:data:`START_MODES`); ``units``: a Real variable's unit by name
    (:func:`_units`), each declared in ``UnitDefinitions``."""
    present = {"u", *(name for name, _ in inputs), *(p.name for p in params)}
    units = {k: v for k, v in (units or {}).items() if k in present}
    from importlib.metadata import version

    fmt = lambda x: repr(float(x))  # noqa: E731
    root = ET.Element(
        "fmiModelDescription",
        {
            "fmiVersion": "2.0",
            "modelName": title,
            "guid": guid,
            "description": description,
            "generationTool": f"aiofl {version('aiofl')}",
            "variableNamingConvention": "structured",
            "numberOfEventIndicators": "0",
        },
    )
    cs = ET.SubElement(
        root,
        "CoSimulation",
        {
            "modelIdentifier": model_identifier,
            "canHandleVariableCommunicationStepSize": "true",
            "canInterpolateInputs": "false",
            "canBeInstantiatedOnlyOncePerProcess": "false",
            "canNotUseMemoryManagementFunctions": "false",
            "canGetAndSetFMUstate": "false",
            "canSerializeFMUstate": "false",
            "providesDirectionalDerivative": "false",
        },
    )
    files = ET.SubElement(cs, "SourceFiles")
    for name in sources:
        ET.SubElement(files, "File", {"name": name})
    if units:  # FMI 2.0: after CoSimulation, before DefaultExperiment
        defs = ET.SubElement(root, "UnitDefinitions")
        for unit in sorted(set(units.values())):
            ET.SubElement(defs, "Unit", {"name": unit})
    exp = {"startTime": "0.0", "stepSize": fmt(ts)}
    if stop_time is not None:
        exp["stopTime"] = fmt(stop_time)
    ET.SubElement(root, "DefaultExperiment", exp)
    mv = ET.SubElement(root, "ModelVariables")

    def var(name: str, vr: int, attrs: dict[str, str], desc: str, kind: str, t: dict[str, str]):
        sv = ET.SubElement(mv, "ScalarVariable", {"name": name, "valueReference": str(vr), **attrs})
        sv.set("description", desc)
        ET.SubElement(sv, kind, {**t, **({"unit": units[name]} if name in units else {})})

    index = 0  # 1-based index of a ScalarVariable in ModelVariables
    for vr, (name, desc) in enumerate(inputs):
        var(name, vr, {"causality": "input", "variability": "continuous"}, desc, "Real",
            {"start": "0.0"})  # fmt: skip
        index += 1
    input_indices = " ".join(str(i) for i in range(1, index + 1))
    attrs = {"causality": "output", "variability": "discrete", "initial": "calculated"}
    var("u", len(inputs), attrs, "control command (held between samples)", "Real", {})
    u_index = index = index + 1
    calc_indices = []
    calc = [p for p in params if not p.tunable]
    tun = [p for p in params if p.tunable]
    for k, p in enumerate([*calc, *tun]):
        vr = len(inputs) + 1 + k
        index += 1
        if p.tunable:
            a = {"causality": "parameter", "variability": "tunable", "initial": "exact"}
            t = {"start": fmt(p.value)}
            if p.minimum is not None:
                t["min"] = fmt(p.minimum)
        else:
            a = {
                "causality": "calculatedParameter",
                "variability": "fixed",
                "initial": "calculated",
            }
            t = {}
            calc_indices.append(index)
        var(p.name, vr, a, p.description, "Real", t)
    a = {"causality": "parameter", "variability": "fixed", "initial": "exact"}
    t = {"start": str(start), "min": "0", "max": "2"}
    var("start", 0, a, "start mode: 0 bumpless, 1 zero, 2 output", "Integer", t)
    ms = ET.SubElement(root, "ModelStructure")
    outputs = ET.SubElement(ms, "Outputs")
    ET.SubElement(outputs, "Unknown", {"index": str(u_index), "dependencies": input_indices})
    init = ET.SubElement(ms, "InitialUnknowns")
    for i in [u_index, *calc_indices]:
        ET.SubElement(init, "Unknown", {"index": str(i)})
    # ElementTree escapes & < > " but writes what XML 1.0 cannot hold (a control
    # character, U+FFFE) as it is, into a file no parser loads: such characters are
    # written as visible escapes (aiofl.text.xml_text), in every attribute
    for element in root.iter():
        for key, value in element.attrib.items():
            element.set(key, xml_text(value))
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True) + b"\n"


def find_compiler() -> str:
    """The C compiler the FMU's binary is built with: ``$CC`` or ``cc`` on the PATH.

    Raises
    ------
    ExportError
        If there is none.
    """
    name = os.environ.get("CC") or "cc"
    path = shutil.which(name)
    if path is None:
        raise ExportError(
            f"--format fmu: no C compiler ({name!r} not found on the PATH): the FMU's "
            "binary is built at export; install one (e.g. gcc) or set CC, or export the C "
            "sources with --format c"
        )
    return path


def export_fmu(
    controller: Controller,
    sampling: Sampling | None,
    *,
    precision: str = "double",
    model_identifier: str = "aiofl",
    title: str = "aiofl controller",
    description: str = "",
    notes: Sequence[str] = (),
    stop_time: float | None = None,
    plant: Plant | None = None,
    plant_source: str | None = None,
    x0: Sequence[float] = (),
) -> tuple[str, bytes]:
    """The FMU of the sampled controller: ``(file name, zip archive bytes)``.

    Parameters
    ----------
    controller, sampling, precision, notes, plant, plant_source, x0
        As :func:`aiofl.export.export_c` (the C inside the FMU is that export's).
    model_identifier
        The FMU's model identifier: its file name (``<id>.fmu``) and binary (``<id>.so``);
        a C identifier.
    title, description
        ``modelName`` and ``description`` of ``modelDescription.xml`` (any text: the XML
        library escapes it).
    stop_time
        The default experiment's stop time (e.g. the config's scenario ``t_final``), or None.

    Returns
    -------
    tuple of (str, bytes)
        ``"<model_identifier>.fmu"`` and the archive.

    Raises
    ------
    ExportError
        What :func:`aiofl.export.export_c` refuses; a model identifier that is not a C
        identifier; no C compiler (:func:`find_compiler`); a platform other than Linux
        x86-64; a compiler that fails on the sources (its message included).
    """
    try:
        c_prefix(model_identifier)
    except ValueError as exc:
        raise ExportError(f"--prefix: {exc}") from None
    if platform.system() != "Linux" or platform.machine() not in ("x86_64", "AMD64"):
        raise ExportError(
            "--format fmu builds a linux64 binary: run the export on Linux x86-64 "
            f"(this is {platform.system()} {platform.machine()})"
        )
    cc = find_compiler()
    files = c_code.export_c(
        controller,
        sampling,
        precision=precision,
        prefix=model_identifier,
        title=title,
        notes=notes,
        plant=plant,
        plant_source=plant_source,
        x0=x0,
    )
    assert sampling is not None  # export_c refuses a missing sample time
    params = fmu_parameters(controller, sampling)
    inputs = _inputs(controller)
    templates = resources.files("aiofl.export") / "templates"
    wrapper = (templates / WRAPPER).read_text(encoding="utf-8")
    headers = {h: (templates / "fmi2" / h).read_text(encoding="utf-8") for h in FMI_HEADERS}
    digest = hashlib.sha256()
    for text in [*files.values(), wrapper, *headers.values()]:
        digest.update(text.encode())
    digest.update(repr((model_identifier, [(p.name, p.value) for p in params])).encode())
    guid = "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, "aiofl:" + digest.hexdigest())) + "}"
    header = c_code.file_names(model_identifier)["h"]
    adapter = c_code.apply_prefix(
        _adapter(controller, params, len(inputs), guid, c_code.HEADER), model_identifier
    )
    sources = {**files, **headers, ADAPTER: adapter, WRAPPER: wrapper}
    assert header in files
    compiled = [*sorted(f for f in files if f.endswith(".c")), WRAPPER]
    xml = _model_description(
        model_identifier=model_identifier,
        title=title,
        description=description,
        guid=guid,
        inputs=inputs,
        params=params,
        sources=compiled,
        ts=sampling.ts,
        stop_time=stop_time,
        start=START_MODES[controller.eso_init],
        units=_units(controller, plant),
    )
    with tempfile.TemporaryDirectory(prefix="aiofl-fmu-") as tmp:
        src = Path(tmp) / "sources"
        src.mkdir()
        for name, text in sources.items():
            (src / name).write_text(text, encoding="utf-8")
        so = Path(tmp) / f"{model_identifier}.so"
        cmd = [cc, *CFLAGS, "-I", str(src), "-o", str(so), *(str(src / f) for f in compiled)]
        proc = subprocess.run([*cmd, "-lm"], capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            raise ExportError(
                f"--format fmu: the C compiler {cc} failed on the FMU's sources:\n"
                + proc.stderr.strip()[-2000:]
            )
        binary = so.read_bytes()
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:

        def add(name: str, data: bytes) -> None:
            info = zipfile.ZipInfo(name, date_time=(2020, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            z.writestr(info, data)

        add("modelDescription.xml", xml)
        for name in sorted(sources):
            add(f"sources/{name}", sources[name].encode())
        add(f"binaries/linux64/{model_identifier}.so", binary)
    return f"{model_identifier}.fmu", buf.getvalue()


def export_fmu_for_config(
    cfg: RunConfig, sampling: Sampling | None, *, precision: str, config: str, prefix: str = "aiofl"
) -> tuple[str, bytes]:
    """:func:`export_fmu` of a loaded config's controller (``aiofl export --format fmu``):
    its name, description and scenario length go into ``modelDescription.xml``, its plant
    and initial state to a model-assisted observer; ``config`` (the path or preset name
    given) into the C files' comment block."""
    return export_fmu(
        cfg.controller,
        sampling,
        precision=precision,
        model_identifier=prefix,
        title=cfg.name,
        description=cfg.description or f"aiofl controller of {cfg.name}",
        notes=[f"Config: {config}", *([cfg.description] if cfg.description else [])],
        stop_time=cfg.scenario.t_final,
        plant=cfg.plant,
        plant_source=cfg.plant_source,
        x0=cfg.scenario.x0,
    )
