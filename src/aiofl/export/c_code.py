r"""C99 of a sampled AIOFL controller: a hand-written template plus a generated header.

:func:`export_c` writes the discrete controller the engine simulates
(:mod:`aiofl.engine.kernel.sampled`) as freestanding C99 (no dynamic memory, no globals but the
``const`` parameter instance, only ``<math.h>``), in double or single precision:

* ``NAME_controller.c``: the hand-written source of the structure family, the package file
  ``aiofl/export/templates/controller.c``, with ``#if`` for the options (ESO linear /
  improved / model-assisted, TD exact / han / improved / linear, SEF linear / nonlinear /
  improved, delay);
* ``NAME_controller.h``: generated option and constant macros (``NAME_UP_RHO``, ``_TS``,
  ``_U_MIN``, ``_U_MAX``, ``_LAYOUT``, ...), then the hand-written API of
  ``templates/controller.h``: ``NAME_real``, ``NAME_signal``, ``NAME_params``,
  ``NAME_state``, ``NAME_start/init/reset/step``;
* ``NAME_params.c``: ``const NAME_params NAME_default_params``, every number of the design;
* ``NAME_model.h`` (model-assisted controllers only): the nominal model
  (:mod:`aiofl.export.c_model`).

The prefix (default ``aiofl``) is applied by replacing the template's ``aiofl_`` and
``AIOFL_`` (:func:`apply_prefix`).  Python computes only numbers: the coefficients of the
discrete update are the engine's own, the member row of
:func:`aiofl.engine.discrete_rows.sampling_rows` (ESO :math:`\Phi - I, \Gamma, K, L`; prefilter
:math:`\Phi - I`), and the per-design constants come from the component functions the
engine uses.  ``params_only=True`` writes another instance of the same struct
(:func:`params_files`), checked at compile time against the controller's
``NAME_UP_LAYOUT``, a hash of everything that fixes the struct and the code (prefix,
precision, ρ, Ts, the options, the nominal model's code).

Text from outside aiofl (``title``, ``notes``, the controller's ``structure`` label) reaches
the files only through :func:`aiofl.export.c_text.comment_text`, inside comments; every
comment line passes :func:`aiofl.export.c_text.check_comment_line` and each file
:func:`aiofl.export.c_text.check_inert` before it is returned.
"""

from __future__ import annotations

import hashlib
import math
import re
import textwrap
from collections.abc import Sequence
from importlib.resources import files as package_files
from typing import Any

import numpy as np

from aiofl.components.differentiators import improved_td_constants, linear_prefilter_coefficient
from aiofl.components.feedback import fal_inner_slope, linear_sef_gain
from aiofl.controller import Controller
from aiofl.engine import discrete_rows as DS
from aiofl.engine.discrete_rows import Sampling
from aiofl.engine.sample_time import check_ts, discrete_row
from aiofl.export.c_model import ModelCode, nominal_model
from aiofl.export.c_text import c_prefix, check_comment_line, check_inert, comment_text
from aiofl.export.errors import ExportError

__all__ = [
    "HEADER",
    "PARAMS",
    "PRECISIONS",
    "SOURCE",
    "ExportError",
    "apply_prefix",
    "export_c",
    "file_names",
]

HEADER = "aiofl_controller.h"
SOURCE = "aiofl_controller.c"
PARAMS = "aiofl_params.c"
MODEL = "aiofl_model.h"
PRECISIONS = ("double", "float")
MAX_INSTANCE = 24
"""Longest ``--params-name``: ``PREFIX_<it>_H`` stays within C99's 63 characters."""

# names a parameter instance may not take: NAME_<it> would clash with the controller's
_API_NAMES = frozenset(
    "controller params model default_params state real signal init start reset step "  # noqa: SIM905
    "nominal_model sign abspow inleso fal inlsef_term fhan fault finite usable".split()
)
_TD = {"exact": 0, "han": 1, "improved": 2, "linear": 3}
_SEF = {"linear": 0, "nonlinear": 1, "improved": 2}


def template(name: str) -> str:
    """The text of a shipped template (``controller.c``, ``controller.h``)."""
    return (package_files("aiofl.export") / "templates" / name).read_text(encoding="ascii")


def apply_prefix(text: str, prefix: str) -> str:
    """``text`` with every ``aiofl_`` / ``AIOFL_`` identifier start replaced by ``prefix_`` /
    ``PREFIX_`` (upper case)."""
    if prefix == "aiofl":
        return text
    text = re.sub(r"\baiofl_", prefix + "_", text)
    return re.sub(r"\bAIOFL_", prefix.upper() + "_", text)


def file_names(prefix: str = "aiofl") -> dict[str, str]:
    """The files of an export with ``prefix``: header, source, params, model."""
    return {k: apply_prefix(v, prefix) for k, v in (("h", HEADER), ("c", SOURCE), ("p", PARAMS))}


def _literal(x: float, precision: str) -> str:
    """A C literal of ``x`` that round-trips in ``precision`` (±HUGE_VAL[F] for ±inf)."""
    x = float(x)
    if math.isinf(x):
        return ("-" if x < 0 else "") + ("HUGE_VALF" if precision == "float" else "HUGE_VAL")
    if not math.isfinite(x):
        raise ExportError(f"a non-finite constant ({x}) cannot be written to C")
    s = repr(x) if precision == "double" else f"{float(np.float32(x)):.9g}"
    if not any(c in s for c in ".e"):
        s += ".0"
    return s + ("f" if precision == "float" else "")


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
        check_ts(sampling.ts, "controller.discrete.ts")
        sampling.check(controller)
    except (TypeError, ValueError) as exc:
        raise ExportError(str(exc)) from None
    return sampling


# the parameter each field of aiofl_params comes from (for a non-finite field's message)
_FIELD_SOURCE = {
    "b0": "law.b0",
    "u0": "eso.u0",
    "eso": "eso.omega0 / eso.alpha* at this Ts",
    "k_": "eso.k_alpha / eso.k_beta",
    "g_": "eso.g_alpha / eso.g_beta",
    "td": "td.R / Ts",
    "itd": "td.a, td.b, td.c, td.rho",
    "pf": "td.omega",
    "sef_gain": "sef.omega_c",
    "sef_slope": "sef.delta* / sef.alpha*",
    "sef": "the sef.* parameters",
    "plant_p": "the plant's nominal parameters",
}


def _check_finite(fields: list[tuple[str, Any]], precision: str) -> None:
    """Refuse a parameter struct whose coefficients are not finite in ``precision`` (the
    actuator limits excepted: +-HUGE_VAL is an open range)."""
    big = float(np.finfo(np.float32).max) if precision == "float" else math.inf
    for name, value in fields:
        if name in ("u_min", "u_max"):
            continue
        vals = np.asarray(value, dtype=np.float64)
        if not np.all(np.abs(vals) < big):  # NaN fails too
            source = next(v for k, v in _FIELD_SOURCE.items() if name.startswith(k))
            raise ExportError(
                f"the controller's coefficients {name} = {np.array2string(vals, threshold=8)} "
                f"are not finite numbers in {precision} (from {source}); allowed: parameters "
                "whose coefficients are finite (a smaller value)"
            )


def _used_parameters(c: Controller) -> list[str]:
    """The parameter columns the discrete controller reads, in a readable order."""
    names = ["law.b0", "law.u_max", "law.u_min", "eso.omega0"]
    names += [f"eso.alpha{i}" for i in range(1, c.rho + 2)]
    names += ["eso.u0"] if c.value("eso.u0") != 0.0 else []
    names += ["eso.delay"] if c.value("eso.delay") != 0.0 else []
    if c.eso_gains == "kalman":
        names += ["eso.q", "eso.r"]
    if c.eso == "improved":
        names += ["eso.k_alpha", "eso.k_beta", "eso.g_alpha", "eso.g_beta"]
    names += {"exact": [], "han": ["td.R"], "improved": ["td.a", "td.b", "td.c", "td.rho"]}.get(
        c.td, ["td.omega"]
    )
    vecs = {"nonlinear": ("k", "alpha", "delta"), "improved": ("k", "kb", "mu", "alpha")}
    for vec in vecs.get(c.sef, ()):
        names += [f"sef.{vec}{i}" for i in range(1, c.n_feedback + 1)]
    names += {"improved": ["sef.v_limit"], "linear": ["sef.omega_c"]}.get(c.sef, [])
    return names


def _params_values(
    c: Controller, s: Sampling, row: np.ndarray, model: ModelCode | None
) -> list[tuple[str, Any]]:
    """The fields of ``aiofl_params`` in order: (name, float | vector | matrix)."""
    rho, m, n = c.rho, c.n_feedback, c.rho + 1
    phi = [row[DS.D_PHI + i * DS.STRIDE : DS.D_PHI + i * DS.STRIDE + n] for i in range(n)]
    out: list[tuple[str, Any]] = [
        ("b0", c.value("law.b0")),
        ("u_min", c.value("law.u_min")),
        ("u_max", c.value("law.u_max")),
        ("u0", c.value("eso.u0")),
        ("eso_dphi", phi),
        ("eso_gamma", row[DS.D_GAM : DS.D_GAM + n]),
        ("eso_k", row[DS.D_K : DS.D_K + n]),
        ("eso_l", row[DS.D_L : DS.D_L + n]),
    ]
    if c.eso == "improved":
        out += [(k, c.value(f"eso.{k}")) for k in ("k_alpha", "k_beta", "g_alpha", "g_beta")]
    if c.td == "han":
        out += [("td_r", c.value("td.R")), ("td_h0", row[DS.D_H0] if s.td == "fhan" else 0.0)]
    elif c.td == "improved":
        bc, gain = improved_td_constants(c.value("td.a"), c.value("td.b"), c.value("td.c"))
        out += [("itd_rho", c.value("td.rho")), ("itd_b_over_c", bc), ("itd_gain", gain)]
    elif c.td == "linear":
        w = c.value("td.omega")
        pf = DS.D_PF_PHI
        out.append(("pf_c", [linear_prefilter_coefficient(rho, i + 1, w) for i in range(rho)]))
        out.append(
            (
                "pf_dphi",
                [row[pf + i * DS.PF_STRIDE : pf + i * DS.PF_STRIDE + rho] for i in range(rho)],
            )
        )
    vec = lambda name: [c.value(f"sef.{name}{i}") for i in range(1, m + 1)]  # noqa: E731
    if c.sef == "nonlinear":
        out += [(f"sef_{k}", vec(k)) for k in ("k", "alpha", "delta")]
        slopes = [fal_inner_slope(a, d) for a, d in zip(vec("alpha"), vec("delta"), strict=True)]
        out.append(("sef_slope", slopes))
    elif c.sef == "improved":
        out += [(f"sef_{k}", vec(k)) for k in ("k", "kb", "mu", "alpha")]
        out.append(("sef_v_limit", c.value("sef.v_limit")))
    else:
        w = c.value("sef.omega_c")
        out.append(("sef_gain", [linear_sef_gain(rho, i + 1, w) for i in range(m)]))
    if model is not None:
        out.append(("plant_p", model.values or [0.0]))
    return out


def _initializer(value: Any, precision: str, indent: str = "    ") -> str:
    if np.ndim(value) == 0:
        return _literal(float(value), precision)
    if np.ndim(value) == 1:
        return "{" + ", ".join(_literal(float(v), precision) for v in value) + "}"
    inner = f",\n{indent}    ".join(_initializer(v, precision) for v in value)
    return f"{{\n{indent}    {inner}}}"


def _comment(lines: Sequence[str]) -> str:
    body = "\n".join(f" * {check_comment_line(ln)}".rstrip() for ln in lines)
    return f"/*\n{body}\n */"


class _Design:
    """Everything the files of one export are written from (numbers and comment text)."""

    def __init__(self, controller: Controller, sampling: Sampling | None, **kw: Any) -> None:
        from importlib.metadata import version

        precision = kw["precision"]
        self.s = s = _check(controller, sampling, precision)
        self.c = c = controller
        self.precision = precision
        self.model: ModelCode | None = None
        jac = None
        if c.eso_model != "none":
            lit = lambda x: _literal(x, precision)  # noqa: E731
            self.model, jac = nominal_model(
                c, kw["plant"], kw["plant_source"], kw["x0"], precision, lit
            )
        try:
            # a Ts the design cannot be discretised at is named, with the range it can
            self.row = discrete_row(c, s, jac, "controller.discrete.ts")
        except ValueError as exc:
            raise ExportError(str(exc)) from None
        self.ntd = {"exact": 0, "han": 2, "improved": 2, "linear": c.rho}[c.td]
        self.fields = _params_values(c, s, self.row, self.model)
        _check_finite(self.fields, precision)
        name = comment_text(kw["title"]) or "unnamed design"
        label = comment_text(c.structure, limit=40) or "custom"
        made_by = comment_text(f"aiofl {version('aiofl')}", limit=60)
        self.headline = textwrap.wrap(f"{name}: {label} controller, sampled, by {made_by}.", 88)
        self.notes = [ln for note in kw["notes"] for ln in textwrap.wrap(comment_text(note), 88)]
        opts = {
            "REAL_IS_FLOAT": int(precision == "float"),
            "RHO": c.rho,
            "NFB": c.n_feedback,
            "NTD": max(self.ntd, 1),
            "ESO_IMPROVED": int(c.eso == "improved"),
            "ESO_MODEL": int(self.model is not None),
            "N_PLANT_P": len(self.model.values or [0.0]) if self.model else 0,
            "TD": _TD[c.td],
            "TD_FHAN": int(c.td == "han" and s.td == "fhan"),
            "SEF": _SEF[c.sef],
            "DELAY": int(bool(s.delay)),
            "KDELAY": int(self.row[DS.D_KDELAY]),  # eso.delay, in samples
        }
        self.options = opts
        sig = repr(
            (sorted(opts.items()), repr(s.ts), s.eso, s.td, self.model and self.model.function)
        )
        self.layout = "0x" + hashlib.sha256(sig.encode()).hexdigest()[:8] + "UL"

    def info(self) -> list[str]:
        c, s = self.c, self.s
        return [
            *self.headline,
            "",
            f"ESO {c.eso}{' model-assisted' if self.model else ''}, differentiator {c.td}, "
            f"state error feedback {c.sef}; rho = {c.rho}, n_feedback = {c.n_feedback}, "
            f"arithmetic: {self.precision}.",
            "",
            "Parameters (aiofl column names, as in the TOML config):",
            *(f"  {name} = {c.value(name)!r}" for name in _used_parameters(c)),
            *(["", *self.model.info] if self.model else []),
            "",
            "Discretisation:",
            *(f"  {ln}" for ln in s.describe(c)),
            *(["", *self.notes] if self.notes else []),
        ]

    def params_c(self, var: str, header: str, what: str) -> str:
        body = ",\n".join(f"    .{k} = {_initializer(v, self.precision)}" for k, v in self.fields)
        return "\n".join(
            [
                _comment([what, "", *self.info()]),
                "#include <math.h>",
                "",
                f'#include "{header}"',
                "",
                f"#if !defined(AIOFL_LAYOUT) || AIOFL_LAYOUT != {self.layout}",
                "#error these parameters are for another controller (prefix, precision, rho, Ts,"
                " options)",
                "#endif",
                "",
                f"const aiofl_params {var} = {{",
                body,
                "};",
                "",
            ]
        )

    def header(self) -> str:
        c, s = self.c, self.s
        u_min, u_max = (_literal(c.value(k), "double") for k in ("law.u_min", "law.u_max"))
        use = [
            "Use: aiofl_init(&s, &aiofl_default_params, y0) once with the first measurement y0",
            "(bumpless: the ESO at (y0, 0, ..., 0, -b0 u0), the differentiator at rest at y0,",
            "so the first u is u0 = p->u0, eso.u0; or aiofl_start(&s, &p, y0, AIOFL_START_ZERO",
            "/ _OUTPUT); aiofl_start_at takes over a command u0 now holding the plant); then",
            "at every sample",
            "t_k = k*AIOFL_TS: u = aiofl_step(&s, &p, r, y) with y the measurement at t_k and",
            "r[0..rho] = r, r', ..., r^(rho) at t_k"
            + (" (only r[0] is read: the controller has a differentiator)." if self.ntd else "."),
            (
                "With the one-sample computation delay, apply u at t_(k+1)."
                if s.delay
                else "Apply u at once and hold it until the next sample (zero-order hold)."
            ),
            "aiofl_reset(&s, &p, y) restarts bumplessly mid-run.  Switch parameter instances",
            "(aiofl export --params-only) only at a sample boundary.",
            "A y or r that is not finite or beyond +-AIOFL_SIGNAL_MAX (1e30), or an update that",
            "overflows, is a fault: u is held at its last value and aiofl_fault(&s) is 1 until",
            "the next start (aiofl_init / aiofl_start / aiofl_reset).",
        ]
        macros = [f"#define AIOFL_{k} {v}" for k, v in self.options.items()]
        return "\n".join(
            [
                _comment([HEADER, "", *self.info(), "", *use]),
                "#ifndef AIOFL_CONTROLLER_H",
                "#define AIOFL_CONTROLLER_H",
                "",
                "#include <math.h>",
                "",
                "/* the design's structure (generated) */",
                *macros,
                f"#define AIOFL_TS {_literal(s.ts, 'double')} /* sample time [s] */",
                f"#define AIOFL_U_MIN ({u_min}) /* law.u_min of the default parameters */",
                f"#define AIOFL_U_MAX ({u_max}) /* law.u_max */",
                f"#define AIOFL_LAYOUT {self.layout} /* prefix, precision, rho, Ts, options */",
                "",
                template("controller.h").rstrip("\n"),
                "",
                "#endif /* AIOFL_CONTROLLER_H */",
                "",
            ]
        )


def export_c(
    controller: Controller,
    sampling: Sampling | None,
    *,
    precision: str = "double",
    prefix: str = "aiofl",
    title: str = "aiofl controller",
    notes: Sequence[str] = (),
    plant: Any = None,
    plant_source: str | None = None,
    x0: Sequence[float] = (),
    params_only: str | None = None,
) -> dict[str, str]:
    """The C99 files of the sampled controller, ``{file name: text}``.

    Parameters
    ----------
    controller
        An AIOFL controller (any ESO, TD and SEF kind).
    sampling
        Sample time and discretisation (:class:`aiofl.engine.discrete_rows.Sampling`); the
        converters' quanta are not part of the code.
    precision
        ``"double"`` or ``"float"`` (the type ``NAME_real``).
    prefix
        The start of every external name (:func:`aiofl.export.c_text.c_prefix`).
    title, notes
        The design's name and extra lines for the comment blocks: untrusted text, made
        inert by :func:`aiofl.export.c_text.comment_text`; they never reach the code.
    plant, plant_source, x0
        A model-assisted controller's plant, its config entry and the state its observer
        gain is placed at (:func:`aiofl.export.c_model.nominal_model`).
    params_only
        A C identifier: write only ``NAME_<params_only>.h/.c``, a parameter instance
        ``const NAME_params NAME_<params_only>`` for a controller exported with the same
        prefix, precision, ρ, Ts and options (a compile-time ``#error`` otherwise).

    Returns
    -------
    dict of str to str
        ``{file name: text}``.

    Raises
    ------
    ExportError
        For the IOFL law, a missing sample time, an invalid discretisation or prefix, or a
        model-assisted controller without the plant's symbolic model.
    """
    try:
        prefix = c_prefix(prefix)
    except ValueError as exc:
        raise ExportError(str(exc)) from None
    ident = r"[A-Za-z][A-Za-z0-9]*(?:_[A-Za-z0-9]+)*"
    if params_only is not None and (
        len(params_only) > MAX_INSTANCE or not re.fullmatch(ident, params_only)
    ):
        raise ExportError(
            f"--params-name = {params_only[:80]!r} is not a C identifier; allowed: a letter, "
            f"then letters, digits and single _, at most {MAX_INSTANCE}"
        )
    if params_only is not None and params_only.lower() in _API_NAMES:
        raise ExportError(
            f"--params-name = {params_only!r} is a name of the controller's own files or API; "
            f"allowed: any other identifier (not {', '.join(sorted(_API_NAMES))})"
        )
    d = _Design(
        controller,
        sampling,
        precision=precision,
        title=title,
        notes=notes,
        plant=plant,
        plant_source=plant_source,
        x0=x0,
    )
    if params_only is not None:
        h, c = f"aiofl_{params_only}.h", f"aiofl_{params_only}.c"
        guard = f"AIOFL_{params_only.upper()}_H"
        decl = "\n".join(
            [
                _comment([h, "", "Another parameter instance of the controller in", HEADER]),
                f"#ifndef {guard}",
                f"#define {guard}",
                f'#include "{HEADER}"',
                f"extern const aiofl_params aiofl_{params_only};",
                "#endif",
                "",
            ]
        )
        out = {h: decl, c: d.params_c(f"aiofl_{params_only}", h, c)}
    else:
        out = {
            HEADER: d.header(),
            SOURCE: template("controller.c"),
            PARAMS: d.params_c("aiofl_default_params", HEADER, PARAMS),
        }
        if d.model is not None:
            out[MODEL] = "\n".join([_comment([MODEL, "", *d.model.info]), *d.model.function])
    return {
        apply_prefix(name, prefix): check_inert(apply_prefix(text, prefix), name)
        for name, text in out.items()
    }
