r"""C99 code of a sampled AIOFL controller: ``aiofl_controller.h`` and ``aiofl_controller.c``.

:func:`export_c` writes the discrete controller the engine simulates
(:mod:`aiofl.engine.sampled`) as freestanding C99: no dynamic memory, no globals other than
``static const`` parameters, only ``<math.h>``, in double or single precision.  The
coefficients of the discrete update are the engine's own, taken from the member row of
:func:`aiofl.engine.discrete.sampling_rows` (ESO Φ - I, Γ, K, L; prefilter Φ - I, Γ: the
delta form of :mod:`aiofl.components.discrete`), and the static parts call the same
formulas (fal, INLSEF, INLESO injection, linear SEF, law (14), saturation) with the
per-design constants computed by the component functions the engine uses (fal's inner
slope, linear gains, ITD constants, prefilter coefficients).  The API::

    typedef double aiofl_real;                 /* float with --precision float */
    typedef struct { ... } aiofl_state;
    void       aiofl_init(aiofl_state *s, aiofl_real y0);
    aiofl_real aiofl_step(aiofl_state *s, const aiofl_real *r, aiofl_real y);

``r`` points to ρ+1 values r, ṙ, ..., r^(ρ) at the sample instant (a controller with a
differentiator reads ``r[0]`` only); the header defines ``AIOFL_RHO`` and ``AIOFL_TS``.
``aiofl_init`` starts the ESO as the engine does (``eso.init``): at 0 (``"zero"``, the
default; ``y0`` is then not used) or at :math:`\hat\xi = (y_0, 0, ..., 0)` with y0 the
first measurement (``"output"``).  The command is clamped to ``[U_MIN, U_MAX]``
(``law.u_min``, ``law.u_max``; each only when finite).
In single precision every constant carries an ``f`` suffix and the float functions of
``<math.h>`` are called (``expf``, ``sqrtf``, ...), so the code compiles without a double
operation under ``-Wconversion -Wdouble-promotion``.

The classical IOFL law evaluates the plant model and is refused (:class:`ExportError`).  A
model-assisted controller (``eso.model = "nominal"``) carries the nominal model, as C
generated from the plant's symbolic expressions (:mod:`aiofl.export.c_model`).

Text from outside aiofl (``title``, ``notes``, the controller's ``structure`` label) reaches
the files only through :func:`aiofl.export.c_text.comment_text`, inside comments; every
comment line passes :func:`aiofl.export.c_text.check_comment_line` and each file
:func:`aiofl.export.c_text.check_inert` before it is returned: a config cannot put code
into the C (see :mod:`aiofl.export.c_text`).
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from aiofl.components.differentiators import improved_td_constants, linear_prefilter_coefficient
from aiofl.components.feedback import fal_inner_slope, linear_sef_gain
from aiofl.controller import Controller, controller_batch
from aiofl.engine import discrete as DS
from aiofl.engine.discrete import Sampling, sampling_rows
from aiofl.export.c_model import INPUT_MODEL, LAW_MODEL, STEP_MODEL, nominal_model
from aiofl.export.c_text import c_identifier, check_comment_line, check_inert, comment_text
from aiofl.export.errors import ExportError
from aiofl.plants.base import Plant

__all__ = ["HEADER", "PRECISIONS", "SOURCE", "ExportError", "export_c"]

HEADER = "aiofl_controller.h"
SOURCE = "aiofl_controller.c"
PRECISIONS = ("double", "float")


_MATH = {
    "double": {"fabs": "fabs", "sqrt": "sqrt", "exp": "exp", "log": "log", "tanh": "tanh"},
    "float": {"fabs": "fabsf", "sqrt": "sqrtf", "exp": "expf", "log": "logf", "tanh": "tanhf"},
}


def _literal(x: float, precision: str) -> str:
    """A C literal of ``x`` that round-trips in ``precision``."""
    x = float(x)
    if not math.isfinite(x):
        raise ExportError(f"a non-finite constant ({x}) cannot be written to C")
    s = repr(x) if precision == "double" else f"{float(np.float32(x)):.9g}"
    if not any(c in s for c in ".e"):
        s += ".0"
    return s + ("f" if precision == "float" else "")


@dataclass
class _Writer:
    precision: str

    def lit(self, x: float) -> str:
        return _literal(x, self.precision)

    def fn(self, name: str) -> str:
        return _MATH[self.precision][name]

    def const(self, name: str, value: float, note: str = "") -> str:
        tail = f"  /* {check_comment_line(note)} */" if note else ""
        return f"static const aiofl_real {c_identifier(name)} = {self.lit(value)};{tail}"

    def array(self, name: str, values: Sequence[float], note: str = "") -> str:
        tail = f"  /* {check_comment_line(note)} */" if note else ""
        body = ", ".join(self.lit(v) for v in values)
        return f"static const aiofl_real {c_identifier(name)}[{len(values)}] = {{{body}}};{tail}"

    def matrix(self, name: str, rows: np.ndarray, note: str = "") -> str:
        tail = f"  /* {check_comment_line(note)} */" if note else ""
        n, m = rows.shape
        inner = ",\n    ".join("{" + ", ".join(self.lit(v) for v in row) + "}" for row in rows)
        decl = f"static const aiofl_real {c_identifier(name)}[{n}][{m}]"
        return f"{decl} = {{\n    {inner}\n}};{tail}"


def _used_parameters(c: Controller) -> list[str]:
    """The parameter columns the discrete controller reads, in a readable order."""
    names = ["law.b0", "law.u_max", "eso.omega0"]
    names += [f"eso.alpha{i}" for i in range(1, c.rho + 2)]
    if c.eso_gains == "kalman":  # ω0, α above are their equivalent bandwidth form
        names += ["eso.q", "eso.r"]
    if c.eso == "improved":
        names += ["eso.k_alpha", "eso.k_beta", "eso.g_alpha", "eso.g_beta"]
    names += {
        "exact": [],
        "han": ["td.R"],
        "improved": ["td.a", "td.b", "td.c", "td.rho"],
        "linear": ["td.omega"],
    }[c.td]
    m = c.n_feedback
    if c.sef == "nonlinear":
        for vec in ("k", "alpha", "delta"):
            names += [f"sef.{vec}{i}" for i in range(1, m + 1)]
    elif c.sef == "improved":
        for vec in ("k", "kb", "mu", "alpha"):
            names += [f"sef.{vec}{i}" for i in range(1, m + 1)]
        names.append("sef.v_limit")
    else:
        names.append("sef.omega_c")
    return names


def _comment(lines: Sequence[str]) -> str:
    body = "\n".join(f" * {check_comment_line(ln)}".rstrip() for ln in lines)
    return f"/*\n{body}\n */"


def _wrap(inert: str, width: int = 88) -> list[str]:
    """Text already made inert by :func:`comment_text` as comment lines, wrapped at spaces
    (no line if it is empty)."""
    return textwrap.wrap(inert, width)


def _check(controller: Controller, sampling: Sampling | None, precision: str) -> Sampling:
    if precision not in PRECISIONS:
        raise ExportError(f"--precision = {precision!r}; allowed: {', '.join(PRECISIONS)}")
    if controller.law != "aiofl":
        raise ExportError(
            f"controller.law_kind = {controller.law!r} cannot be exported: the classical "
            "IOFL law evaluates the plant model alpha(x), beta(x) from the full state, which a "
            "controller reading only y does not have; allowed: the AIOFL law (LESO, INLESO, "
            "LADRC structures)"
        )
    if sampling is None:
        raise ExportError(
            "no sample time: give --ts or a [controller.discrete] table with ts in the config"
        )
    try:
        sampling.check(controller)
    except ValueError as exc:
        raise ExportError(str(exc)) from None
    return sampling


def export_c(
    controller: Controller,
    sampling: Sampling | None,
    *,
    precision: str = "double",
    title: str = "aiofl controller",
    notes: Sequence[str] = (),
    plant: Plant | None = None,
    plant_source: str | None = None,
    x0: Sequence[float] = (),
) -> dict[str, str]:
    """The C99 files of the sampled controller, ``{file name: text}``.

    Parameters
    ----------
    controller
        An AIOFL controller (any ESO, TD and SEF kind).
    sampling
        Sample time and discretisation (:class:`aiofl.engine.discrete.Sampling`); the
        converters' quanta are not part of the code.
    precision
        ``"double"`` or ``"float"`` (the type ``aiofl_real``).
    title, notes
        The design's name and extra lines for the comment block (e.g. the config's path
        and description).  They are untrusted text: each is made inert for a C comment by
        :func:`aiofl.export.c_text.comment_text` (kept: ASCII letters, digits and
        ``space _ . , : ; = + - / ( )``; other characters replaced by ``_``, whitespace by
        a space, at most 200 characters each) and wrapped; they never reach the code.
    plant, plant_source, x0
        A model-assisted controller's (``eso.model = "nominal"``) plant, whose nominal
        model the code evaluates (:mod:`aiofl.export.c_model`); the config's plant entry
        its expressions are read from (a built-in name or a plant ``.toml`` file; default
        the plant's name); the initial state the observer gain is placed at (default the
        origin), as the engine places it.  Not used otherwise.

    Raises
    ------
    ExportError
        For the IOFL law, a missing sample time, an invalid discretisation or a
        model-assisted controller without the plant's symbolic model.
    RuntimeError
        If a comment line or a generated file fails the inert-text check
        (:mod:`aiofl.export.c_text`): a bug in aiofl, never the input's fault.
    """
    s = _check(controller, sampling, precision)
    from importlib.metadata import version

    __version__ = version("aiofl")

    w = _Writer(precision)
    c = controller
    rho, m, n = c.rho, c.n_feedback, c.rho + 1
    model, jac = None, None
    if c.eso_model != "none":  # the nominal model's C, and the gain placed for it
        model, jac = nominal_model(c, plant, plant_source, x0, precision, w.lit)
    row = sampling_rows(controller_batch(c), [s], s.ts, jac)[0]
    phi = np.array([row[DS.D_PHI + i * DS.STRIDE : DS.D_PHI + i * DS.STRIDE + n] for i in range(n)])
    gam, kv, lv = (row[o : o + n] for o in (DS.D_GAM, DS.D_K, DS.D_L))
    b0, u_max = c.value("law.b0"), c.value("law.u_max")
    ntd = {"exact": 0, "han": 2, "improved": 2, "linear": rho}[c.td]
    real = precision

    # the only user text in the files, each piece through comment_text (c_text)
    name = comment_text(title) or "unnamed design"
    label = comment_text(c.structure, limit=40) or "custom"
    made_by = comment_text(f"aiofl {__version__}", limit=60)
    info = [
        *_wrap(f"{name}: {label} controller, sampled, generated by {made_by}."),
        "",
        f"ESO {c.eso}, differentiator {c.td}, state error feedback {c.sef}, law "
        + ("model-assisted, u = (b0 v - alpha - xhat_(rho+1))/beta;" if model else "aiofl (14);"),
        f"rho = {rho}, n_feedback = {m}, arithmetic: {precision}.",
        "",
        "Parameters (aiofl column names, as in the TOML config):",
        *(f"  {name} = {c.value(name)!r}" for name in _used_parameters(c)),
        *(["", *model.info] if model else []),
        "",
        "Discretisation:",
        *(f"  {ln}" for ln in s.describe(c)),
        "",
        f"Use: aiofl_init(&s, y0) once with the first measurement y0 (eso.init = {c.eso_init}:",
        (
            "the ESO starts at xhat = (y0, 0, ..., 0)); then at every sample"
            if c.eso_init == "output"
            else "the ESO starts at 0, y0 is not used); then at every sample"
        ),
        "t_k = k*AIOFL_TS: u = aiofl_step(&s, r, y) with y the measurement at t_k and r[0..rho]",
        "= r, r', ..., r^(rho) at t_k"
        + (" (only r[0] is read: the controller has a differentiator)." if ntd else "."),
        (
            "With the one-sample computation delay, apply u at t_(k+1): the observer assumes"
            if s.delay
            else "Apply u at once and hold it until the next sample (zero-order hold)."
        ),
        *(["the previous sample's u over [t_k, t_(k+1))."] if s.delay else []),
        "Quantisation of y and u (y_quantum, u_quantum) belongs to the converters and is not",
        "in this code.",
        *(line for note in notes for line in _wrap(comment_text(note))),
    ]

    # ------------------------------------------------------------------ the header
    fields = []
    if ntd:
        what = {
            "linear": "prefilter r_1..r_rho",
            "improved": "ITD r_1, r_2",
            "han": "TD r_1 - r_prev, r_2",
        }[c.td]
        fields.append(f"    aiofl_real td[{ntd}];  /* {what}, advanced to the next sample */")
    if c.td == "han":
        fields.append("    aiofl_real r_prev;  /* the previous reference */")
    fields.append(
        "    aiofl_real p[AIOFL_RHO + 1];  /* ESO prediction for the next sample; p[0] is "
        "p_1 - y_prev */"
    )
    fields.append("    aiofl_real y_prev;  /* the previous measurement */")
    fields.append("    aiofl_real xhat[AIOFL_RHO + 1];  /* ESO estimate at the last sample */")
    if s.delay:
        fields.append("    aiofl_real u_prev;  /* the command applied over the current interval */")
    header = "\n".join(
        [
            _comment([f"{HEADER}", "", *info]),
            "#ifndef AIOFL_CONTROLLER_H",
            "#define AIOFL_CONTROLLER_H",
            "",
            f"#define AIOFL_RHO {rho}",
            f"#define AIOFL_TS {_literal(s.ts, 'double')}  /* sample time [s] */",
            "",
            f"typedef {real} aiofl_real;",
            "",
            "typedef struct {",
            *fields,
            "} aiofl_state;",
            "",
            "void aiofl_init(aiofl_state *s, aiofl_real y0);",
            "aiofl_real aiofl_step(aiofl_state *s, const aiofl_real *r, aiofl_real y);",
            "",
            "#endif /* AIOFL_CONTROLLER_H */",
            "",
        ]
    )

    # ----------------------------------------------------------------- parameters
    params = [
        *([w.const("TS", s.ts, "sample time [s]")] if c.td in ("han", "improved") else []),
        w.const("B0", b0, "law.b0"),
        w.matrix("ESO_DPHI", phi, "ESO prediction: p+ = xhat + (DPHI xhat + GAMMA u + K phi)"),
        w.array("ESO_GAMMA", gam),
        w.array("ESO_K", kv),
        w.array("ESO_L", lv, "ESO correction: xhat = p + L phi"),
    ]
    u_min = c.value("law.u_min")  # -u_max unless an asymmetric range was given
    if math.isfinite(u_max):
        params.append(w.const("U_MAX", u_max, "law.u_max"))
    if math.isfinite(u_min):
        params.append(w.const("U_MIN", u_min, "law.u_min"))
    if c.eso == "improved":
        params += [
            w.const("K_ALPHA", c.value("eso.k_alpha")),
            w.const("K_BETA", c.value("eso.k_beta")),
            w.const("G_ALPHA", c.value("eso.g_alpha")),
            w.const("G_BETA", c.value("eso.g_beta")),
        ]
    if c.td == "han":
        params.append(w.const("TD_R", c.value("td.R")))
        if s.td == "fhan":
            params.append(w.const("TD_H0", row[DS.D_H0], "fhan's filter factor h0 [s]"))
    elif c.td == "improved":
        bc, gain = improved_td_constants(c.value("td.a"), c.value("td.b"), c.value("td.c"))
        params += [
            w.const("ITD_RHO", c.value("td.rho")),
            w.const("ITD_B_OVER_C", bc, "b/c"),
            w.const("ITD_GAIN", gain, "(1 - a)/c"),
        ]
    elif c.td == "linear":
        pfc = [linear_prefilter_coefficient(rho, i + 1, c.value("td.omega")) for i in range(rho)]
        pf_phi = np.array(
            [
                row[DS.D_PF_PHI + i * DS.PF_STRIDE : DS.D_PF_PHI + i * DS.PF_STRIDE + rho]
                for i in range(rho)
            ]
        )
        params += [
            w.array("PF_C", pfc, "coefficients of (s + omega)^rho"),
            w.matrix("PF_DPHI", pf_phi, "prefilter ZOH: td+ = td + (PF_DPHI td + PF_GAMMA r)"),
            w.array("PF_GAMMA", row[DS.D_PF_GAM : DS.D_PF_GAM + rho]),
        ]
    vec = lambda name: [c.value(f"sef.{name}{i}") for i in range(1, m + 1)]  # noqa: E731
    if c.sef == "nonlinear":
        params += [
            w.array("SEF_K", vec("k")),
            w.array("SEF_ALPHA", vec("alpha")),
            w.array("SEF_DELTA", vec("delta")),
            w.array(
                "SEF_SLOPE",
                [fal_inner_slope(a, d) for a, d in zip(vec("alpha"), vec("delta"), strict=True)],
                "delta^(alpha - 1)",
            ),
        ]
    elif c.sef == "improved":
        params += [
            w.array("SEF_K", vec("k")),
            w.array("SEF_KB", vec("kb")),
            w.array("SEF_MU", vec("mu")),
            w.array("SEF_ALPHA", vec("alpha")),
            w.const("SEF_V_LIMIT", c.value("sef.v_limit")),
        ]
    else:
        gains = [linear_sef_gain(rho, i + 1, c.value("sef.omega_c")) for i in range(m)]
        params.append(w.array("SEF_GAIN", gains, "binomial(rho, i-1) omega_c^(rho-i+1)"))

    source = "\n".join(
        [
            _comment([f"{SOURCE}", "", *info]),
            "#include <math.h>",
            "",
            f'#include "{HEADER}"',
            "",
            *params,
            *(model.params if model else []),
            "",
            *(model.function if model else []),
            *_helpers(c, w, s.td),
            *_init(c, w, ntd, s.delay),
            *_step(c, w, s, m, model is not None),
        ]
    )
    return {HEADER: check_inert(header, HEADER), SOURCE: check_inert(source, SOURCE)}


def _helpers(c: Controller, w: _Writer, s_td: str) -> list[str]:
    """The static helper functions this controller needs (no unused ones: -Werror)."""
    zero, one = w.lit(0.0), w.lit(1.0)
    fabs, exp, log = w.fn("fabs"), w.fn("exp"), w.fn("log")
    out: list[str] = []
    need_sign = c.td == "han" or c.sef in ("nonlinear", "improved") or c.eso == "improved"
    need_pow = c.sef == "improved" or c.eso == "improved"
    if need_sign:
        out += [
            "static aiofl_real aiofl_sign(aiofl_real x)",
            "{",
            f"    return x > {zero} ? {one} : (x < {zero} ? -{one} : {zero});",
            "}",
            "",
        ]
    if need_pow:
        out += [
            "/* |e|^a as exp(a log|e|); 0^a = 0 for a > 0 */",
            "static aiofl_real aiofl_abspow(aiofl_real x, aiofl_real a)",
            "{",
            f"    if (a == {one}) return x;",
            f"    if (a == {zero}) return {one};",
            f"    return {exp}(a * {log}(x));",
            "}",
            "",
        ]
    if c.sef == "nonlinear":
        out += [
            "/* Han's fal, eq. (17) (continuous form), given its inner slope delta^(alpha-1) */",
            "static aiofl_real aiofl_fal(aiofl_real e, aiofl_real alpha, aiofl_real delta,",
            "                            aiofl_real slope)",
            "{",
            f"    aiofl_real ae = {fabs}(e);",
            "    if (ae <= delta) return e * slope;",
            f"    if (alpha == {one}) return e;",
            f"    return {exp}(alpha * {log}(ae)) * aiofl_sign(e);",
            "}",
            "",
        ]
    if c.sef == "improved":
        out += [
            "/* one term of the INLSEF, eq. (20) */",
            "static aiofl_real aiofl_inlsef_term(aiofl_real e, aiofl_real k1, aiofl_real k2,",
            "                                    aiofl_real mu, aiofl_real alpha)",
            "{",
            "    aiofl_real gain = k1;",
            f"    if (k2 != {zero}) gain += k2 / ({one} + {exp}(mu * e * e));",
            f"    return gain * aiofl_abspow({fabs}(e), alpha) * aiofl_sign(e);",
            "}",
            "",
        ]
    if c.eso == "improved":
        out += [
            "/* the INLESO's error injection g(e), eq. (19) */",
            "static aiofl_real aiofl_inleso(aiofl_real e)",
            "{",
            f"    aiofl_real ae = {fabs}(e);",
            "    aiofl_real g = K_ALPHA * aiofl_abspow(ae, G_ALPHA) * aiofl_sign(e);",
            f"    if (K_BETA != {zero}) g += K_BETA * aiofl_abspow(ae, G_BETA) * e;",
            "    return g;",
            "}",
            "",
        ]
    if c.td == "han" and s_td == "fhan":
        out += [
            "/* Han's time-optimal synthesis function fhan (Han 2009) */",
            "static aiofl_real aiofl_fhan(aiofl_real x1, aiofl_real x2, aiofl_real r,",
            "                             aiofl_real h)",
            "{",
            "    aiofl_real d = r * h;",
            "    aiofl_real d0 = h * d;",
            "    aiofl_real y = x1 + h * x2;",
            f"    aiofl_real ay = {fabs}(y);",
            "    aiofl_real a;",
            "    if (ay > d0)",
            f"        a = x2 + {w.lit(0.5)} * ({w.fn('sqrt')}(d * d + {w.lit(8.0)} * r * ay) - d)"
            " * aiofl_sign(y);",
            "    else",
            "        a = x2 + y / h;",
            f"    if ({fabs}(a) > d) return -r * aiofl_sign(a);",
            "    return -r * a / d;",
            "}",
            "",
        ]
    return out


def _init(c: Controller, w: _Writer, ntd: int, delay: int) -> list[str]:
    r"""``aiofl_init``: the differentiator at rest at 0 and the ESO as ``eso.init`` says,
    like the engine's :func:`aiofl.engine.sampled._tpl_ctrl_init`: prediction
    :math:`p_0 = 0` (``"zero"``, the default; ``y0`` unused) or :math:`(y_0, 0, ..., 0)`
    (``"output"``)."""
    zero = w.lit(0.0)
    out = ["void aiofl_init(aiofl_state *s, aiofl_real y0)", "{", "    int i;"]
    if ntd:
        out.append(f"    for (i = 0; i < {ntd}; ++i) s->td[i] = {zero};")
    if c.td == "han":
        out.append(f"    s->r_prev = {zero};")
    out += [
        "    for (i = 0; i <= AIOFL_RHO; ++i) {",
        f"        s->p[i] = {zero};",
        f"        s->xhat[i] = {zero};",
        "    }",
    ]
    if c.eso_init == "output":  # p_0 = (y0, 0, ..., 0): the first innovation is 0
        out += ["    s->y_prev = y0;  /* p_1 = y0 (eso.init = output) */", "    s->xhat[0] = y0;"]
    else:  # p_0 = 0 (p[0] holds p_1 - y_prev)
        out += [f"    s->y_prev = {zero};  /* p_1 = 0 (eso.init = zero) */", "    (void)y0;"]
    if delay:
        out.append(f"    s->u_prev = {zero};")
    return [*out, "}", ""]


def _step(c: Controller, w: _Writer, s: Sampling, m: int, model: bool) -> list[str]:
    rho = c.rho
    exact = c.td == "exact"
    fabs, tanh = w.fn("fabs"), w.fn("tanh")
    body: list[str] = [
        "aiofl_real aiofl_step(aiofl_state *s, const aiofl_real *r, aiofl_real y)",
        "{",
        "    int i, j;",
        "    aiofl_real e, phi, dx1, v, u, um, acc;",
        *(["    aiofl_real a_hat, b_hat;"] if model else []),
    ]
    if c.td == "linear":
        body.append("    aiofl_real rff, next[AIOFL_RHO];")
    elif exact and c.sef == "linear":
        body.append("    aiofl_real rff;")
    if c.td == "han":
        body.append("    aiofl_real prof[2], x1, r2;")
    elif c.td == "improved":
        body.append("    aiofl_real r1, r2;")
    body += [
        "",
        "    /* ESO correction: xhat = p + L phi(e), e = y - p_1 formed from small numbers:",
        "       p[0] holds p_1 - y_prev, and dx1 = xhat_1 - y */",
        "    e = (y - s->y_prev) - s->p[0];",
        "    phi = aiofl_inleso(e);" if c.eso == "improved" else "    phi = e;",
        "    dx1 = ESO_L[0] * phi - e;",
        "    s->xhat[0] = y + dx1;",
        "    for (i = 1; i <= AIOFL_RHO; ++i) s->xhat[i] = s->p[i] + ESO_L[i] * phi;",
        "",
    ]
    body += STEP_MODEL if model else []
    if c.td == "linear":
        body += [
            "    /* feed-forward r1^(rho) of the prefilter at t_k */",
            "    rff = PF_C[0] * (r[0] - s->td[0]);",
            "    for (i = 1; i < AIOFL_RHO; ++i) rff -= PF_C[i] * s->td[i];",
        ]
    elif exact and c.sef == "linear":
        body.append(f"    rff = r[{rho}];")
    elif c.td == "han":
        body += [
            "    /* the TD's profile at t_k (td[0] holds r_1 - r_prev) */",
            "    prof[0] = s->r_prev + s->td[0];",
            "    prof[1] = s->td[1];",
        ]
    body.append("    /* state error feedback, e_i = r_i - xhat_i */")
    if c.sef == "nonlinear":
        body += [
            f"    v = {w.lit(0.0)};",
            f"    for (i = 0; i < {m}; ++i)",
            f"        v += SEF_K[i] * aiofl_fal({ref_vec(c)} - s->xhat[i], SEF_ALPHA[i],"
            " SEF_DELTA[i], SEF_SLOPE[i]);",
        ]
    elif c.sef == "improved":
        body += [
            f"    acc = {w.lit(0.0)};",
            f"    for (i = 0; i < {m}; ++i)",
            f"        acc += aiofl_inlsef_term({ref_vec(c)} - s->xhat[i], SEF_K[i], SEF_KB[i],"
            " SEF_MU[i], SEF_ALPHA[i]);",
            f"    v = SEF_V_LIMIT * {tanh}(acc / SEF_V_LIMIT);",
        ]
    else:
        body += [
            f"    acc = {w.lit(0.0)};",
            f"    for (i = 0; i < {m}; ++i) acc += SEF_GAIN[i] * ({ref_vec(c)} - s->xhat[i]);",
            "    v = (acc + rff) / B0;",
        ]
    body += LAW_MODEL if model else ["    /* law (14) */", "    u = v - s->xhat[AIOFL_RHO] / B0;"]
    if math.isfinite(c.value("law.u_max")):  # actuator range [u_min, u_max]
        body += ["    if (u > U_MAX) u = U_MAX;"]
    if math.isfinite(c.value("law.u_min")):
        body += ["    if (u < U_MIN) u = U_MIN;"]
    body += [
        "",
        "    /* ESO prediction, delta form: p+ = xhat + (DPHI xhat + GAMMA u + K phi),",
        "       DPHI = PHI - I upper triangular */",
        "    um = s->u_prev;" if s.delay else "    um = u;",
        *(INPUT_MODEL if model else []),
        "    for (i = 0; i <= AIOFL_RHO; ++i) {",
        "        acc = ESO_GAMMA[i] * um + ESO_K[i] * phi;",
        "        for (j = i; j <= AIOFL_RHO; ++j) acc += ESO_DPHI[i][j] * s->xhat[j];",
        "        s->p[i] = (i == 0 ? dx1 : s->xhat[i]) + acc;",
        "    }",
        "    s->y_prev = y;",
        "",
    ]
    if c.td == "han":
        body += [
            (
                "    /* Han's discrete TD: r1+ = r1 + Ts r2, r2+ = r2 + Ts fhan(r1 - r, r2, R, h0)"
                " */"
                if s.td == "fhan"
                else "    /* forward Euler on Han's TD, eq. (18) */"
            ),
            "    x1 = s->td[0] - (r[0] - s->r_prev);  /* r_1 - r */",
            "    r2 = s->td[1];",
            "    s->td[0] = x1 + TS * r2;  /* r_1(k+1) - r_k */",
            (
                "    s->td[1] = r2 + TS * aiofl_fhan(x1, r2, TD_R, TD_H0);"
                if s.td == "fhan"
                else f"    s->td[1] = r2 + TS * (-TD_R * aiofl_sign(x1 + r2 * {fabs}(r2) / "
                f"({w.lit(2.0)} * TD_R)));"
            ),
            "    s->r_prev = r[0];",
        ]
    elif c.td == "improved":
        body += [
            "    /* forward Euler on the ITD, eq. (21) */",
            "    r1 = s->td[0];",
            "    r2 = s->td[1];",
            "    s->td[0] = r1 + TS * r2;",
            f"    s->td[1] = r2 + TS * (-ITD_RHO * ITD_RHO * {tanh}(ITD_B_OVER_C * r1 - ITD_GAIN"
            " * r[0]) - ITD_RHO * r2);",
        ]
    elif c.td == "linear":
        body += [
            "    /* prefilter, exact ZOH in delta form: td+ = td + (PF_DPHI td + PF_GAMMA r) */",
            "    for (i = 0; i < AIOFL_RHO; ++i) {",
            "        acc = PF_GAMMA[i] * r[0];",
            "        for (j = 0; j < AIOFL_RHO; ++j) acc += PF_DPHI[i][j] * s->td[j];",
            "        next[i] = s->td[i] + acc;",
            "    }",
            "    for (i = 0; i < AIOFL_RHO; ++i) s->td[i] = next[i];",
        ]
    if s.delay:
        body.append("    s->u_prev = u;")
    body += ["    return u;", "}", ""]
    return body


def ref_vec(c: Controller) -> str:
    """The i-th reference of the errors: ``r[i]`` (exact derivatives), Han's TD profile or
    the differentiator's state."""
    return {"exact": "r[i]", "han": "prof[i]"}.get(c.td, "s->td[i]")
