r"""Plant structure — relative degree, region, normal form, zero dynamics — as text, LaTeX, JSON.

The structure is the Section-III :class:`~aiofl.plants.normal_form.Analysis` of a symbolic
plant (:func:`aiofl.plants.normal_form.analyze`): the Lie derivatives :math:`L_f^k h`,
:math:`L_gL_f^k h`, the relative degree ρ (eq. 2) and where :math:`\beta(x) \ne 0`,
:math:`\alpha(x)`, :math:`\beta(x)` with :math:`y^{(\rho)} = \alpha(x) + \beta(x)u`, the
normal-form coordinates ξ and internal coordinates η (eq. 3), and the zero dynamics with
their linearised eigenvalues.  :func:`format_analysis_text` is what ``aiofl analyze PLANT``
prints, :func:`format_analysis_latex` its ``--latex`` and :func:`analysis_to_dict` its
``--json`` output.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import sympy as sp
from numpy.typing import NDArray

from aiofl.plants.normal_form import Analysis

__all__ = ["analysis_to_dict", "format_analysis_latex", "format_analysis_text"]


def _fmt_eig(eig: NDArray[np.complex128]) -> str:
    return ", ".join(
        f"{z.real:.6g}" if abs(z.imag) < 1e-12 else f"{z.real:.6g}{z.imag:+.6g}j" for z in eig
    )


def format_analysis_text(a: Analysis) -> str:
    """Plain-text report of an :class:`Analysis` (what ``aiofl analyze PLANT`` prints)."""
    p = a.plant
    out = [f"Plant {p.name}" + (f": {p.description}" if p.description else "")]
    out.append(
        "  states: "
        + ", ".join(
            f"{s}" + (f" ({lab})" if lab != str(s) else "")
            for s, lab in zip(p.states, p.state_labels, strict=True)
        )
    )
    out.append("  parameters: " + ", ".join(f"{s} = {v:g}" for s, v in p.params))
    out.append("  f(x) = [" + ", ".join(sp.sstr(e) for e in p.f) + "]")
    out.append("  g(x) = [" + ", ".join(sp.sstr(e) for e in p.g) + "]")
    out.append(f"  h(x) = {sp.sstr(p.h)}")
    out.append("")
    out.append("Lie derivatives (Section III, eq. 2)")
    for k in range(a.rho):
        name_g = "L_g h" if k == 0 else ("L_g L_f h" if k == 1 else f"L_g L_f^{k} h")
        name_f = "h" if k == 0 else ("L_f h" if k == 1 else f"L_f^{k} h")
        out.append(f"  {name_f} = {sp.sstr(a.lf_h[k])}")
        out.append(f"  {name_g} = {sp.sstr(a.lg_lf_h[k])}")
    out.append("")
    out.append(f"relative degree  ρ = {a.rho}   (n = {p.n})")
    out.append(f"  defined: {a.region}")
    out.append(f"  β(x) = L_g L_f^{a.rho - 1} h = {sp.sstr(a.beta)}")
    if a.beta_point is not None:
        at = "[" + ", ".join(f"{v:g}" for v in a.beta_point) + "]"
        value = f"{a.beta_nominal:.6g}" if a.beta_nominal is not None else "not finite"
        out.append(f"  β at {a.beta_point_label} = {at}: {value}")
    out.append(f"  α(x) = L_f^{a.rho} h = {sp.sstr(a.alpha)}")
    out.append(f"  y^({a.rho}) = α(x) + β(x)·u;  IOFL: u = (−α(x) + v)/β(x) gives y^({a.rho}) = v")
    out.append("")
    out.append("normal-form coordinates ξ = (h, L_f h, …, L_f^(ρ−1) h)  (eq. 3)")
    for i, e in enumerate(a.xi, 1):
        out.append(f"  ξ{i} = {sp.sstr(e)}")
    out.append("")
    out.append("zero dynamics")
    zd = a.zero_dynamics
    if zd is None:
        out.append(f"  {a.zero_dynamics_note}")
    else:
        out.append(f"  η = φ(x) with ∂φ/∂x·g = 0 ({zd.method}):")
        for s, e in zip(zd.eta_symbols, zd.eta, strict=True):
            out.append(f"    {s} = {sp.sstr(e)}")
        if zd.f0 is not None:
            out.append("  η̇ = f0(η, 0):")
            for s, e in zip(zd.eta_symbols, zd.f0, strict=True):
                out.append(f"    d{s}/dt = {sp.sstr(e)}")
        else:
            out.append("  η̇ = ∂φ/∂x·f(x) on the manifold ξ(x) = 0:")
            for s, e in zip(zd.eta_symbols, zd.eta_dot, strict=True):
                out.append(f"    d{s}/dt = {sp.sstr(e)}")
        out.append(f"  equilibrium x_e = {[round(v, 12) for v in zd.equilibrium]}")
        out.append(f"  eigenvalues of ∂f0/∂η at x_e: {_fmt_eig(zd.eigenvalues)}")
        out.append(f"  verdict: {zd.verdict} (local, from the linearisation at x_e)")
    return "\n".join(out)


def format_analysis_latex(a: Analysis) -> str:
    """LaTeX (an ``align*`` block and a sentence) of an :class:`Analysis`."""
    p = a.plant
    lx = sp.latex

    def lie_name(k: int, with_g: bool) -> str:
        base = "h" if k == 0 else ("L_f h" if k == 1 else f"L_f^{{{k}}} h")
        return f"L_g {base}" if with_g else base

    rows = [
        r"\dot x &= f(x) + g(x)u,\quad f(x) = " + lx(sp.Matrix(p.f)),
        r"g(x) &= " + lx(sp.Matrix(p.g)) + r",\quad h(x) = " + lx(p.h),
    ]
    for k in range(a.rho):
        rows.append(f"{lie_name(k, False)} &= {lx(a.lf_h[k])}")
        rows.append(f"{lie_name(k, True)} &= {lx(a.lg_lf_h[k])}")
    rows.append(rf"\rho &= {a.rho}\quad (n = {p.n})")
    rows.append(rf"\beta(x) = L_g L_f^{{{a.rho - 1}}} h &= {lx(a.beta)}")
    rows.append(rf"\alpha(x) = L_f^{{{a.rho}}} h &= {lx(a.alpha)}")
    rows.append(r"\xi &= " + lx(sp.Matrix(a.xi)))
    zd = a.zero_dynamics
    if zd is not None:
        rows.append(r"\eta &= " + lx(sp.Matrix(zd.eta)))
        body = zd.f0 if zd.f0 is not None else zd.eta_dot
        rows.append(
            r"\dot\eta &= " + lx(sp.Matrix(body)) + ("" if zd.f0 is not None else r"\ (\xi = 0)")
        )
    out = [f"% aiofl analyze {p.name}", r"\begin{align*}", " \\\\\n".join(rows), r"\end{align*}"]
    region = a.region.replace("≠", r"$\neq$").replace("β", r"$\beta$").replace("ρ", r"$\rho$")
    out.append(f"Relative degree defined: {region}.")
    if zd is not None:
        eig = _fmt_eig(zd.eigenvalues)
        out.append(f"Zero dynamics linearised at $x_e$: eigenvalues {eig}; {zd.verdict}.")
    else:
        out.append(f"Zero dynamics: {a.zero_dynamics_note}.")
    return "\n".join(out)


def analysis_to_dict(a: Analysis) -> dict[str, Any]:
    """JSON-ready dict of an :class:`~aiofl.plants.normal_form.Analysis` (``--json``)."""
    zd = a.zero_dynamics
    lie = {}
    for k in range(a.rho + 1):
        lie[f"L_f^{k} h"] = sp.sstr(a.lf_h[k])
        if k < a.rho:
            lie[f"L_g L_f^{k} h"] = sp.sstr(a.lg_lf_h[k])
    return {
        "plant": a.plant.name,
        "n": a.plant.n,
        "rho": a.rho,
        "lie_derivatives": lie,
        "alpha": sp.sstr(a.alpha),
        "beta": sp.sstr(a.beta),
        "beta_constant": a.beta_constant,
        "beta_nominal": a.beta_nominal,
        "beta_point": None if a.beta_point is None else list(a.beta_point),
        "beta_point_label": a.beta_point_label or None,
        "region": a.region,
        "xi": [sp.sstr(e) for e in a.xi],
        "zero_dynamics": None
        if zd is None
        else {
            "eta": [sp.sstr(e) for e in zd.eta],
            "f0": None if zd.f0 is None else [sp.sstr(e) for e in zd.f0],
            "eta_dot": [sp.sstr(e) for e in zd.eta_dot],
            "equilibrium": list(zd.equilibrium),
            "eigenvalues": [[float(z.real), float(z.imag)] for z in zd.eigenvalues],
            "verdict": zd.verdict,
        },
        "zero_dynamics_note": a.zero_dynamics_note,
    }
