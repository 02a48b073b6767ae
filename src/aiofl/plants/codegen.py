r"""Code generation: a symbolic plant as plain Python functions the engine compiles.

sympy prints :math:`f(x)`, :math:`g(x)`, :math:`h(x)`, :math:`b_d(x)` of

.. math:: \dot x = f(x) + g(x)u + b_d(x)\tau_d,\qquad y = h(x)

and ``normal_form(x, p) -> (ξ_1..ξ_ρ, α, β)`` (the normal-form coordinates of eq. 3 and
:math:`y^{(\rho)} = \alpha(x) + \beta(x)u`, from :mod:`aiofl.plants.normal_form`) as
Python source over ``math`` only, each function ``(x, p)`` returning a tuple of floats
(``h`` one float).  numba compiles them into the closed-loop kernel like hand-written plant
functions (:meth:`aiofl.plants.symbolic.SymbolicPlant.to_plant`), and
:func:`generate_module_source` writes them ahead of time for the shipped plants
(:mod:`aiofl.plants.library_generated`).

Generated code never holds ``inf``, ``nan``, ``zoo`` or a complex number: an expression
with one (``1/(x1 - x1)``, a Lie derivative whose constant overflows float64, a constant
such as ``exp(1000)``) refuses the plant with a
:class:`~aiofl.plants.expressions.SymbolicPlantError` naming the function and entry, and
the printed source is checked once more for those words before it is compiled.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from typing import Any, Protocol

import sympy as sp

from aiofl.plants.expressions import SymbolicPlantError, check_finite
from aiofl.plants.normal_form import Analysis, SymbolicModel, drop_delta

__all__ = ["compile_sources", "generate_module_source", "plant_sources"]


class _HasSources(Protocol):
    """A plant that prints its generated functions (a ``SymbolicPlant``)."""

    def function_sources(self, prefix: str = "") -> dict[str, str]: ...


def plant_sources(plant: SymbolicModel, analysis: Analysis) -> dict[str, str]:
    r"""Python source of ``f, g, h, bd, normal_form``, each ``def _fn_<name>(x, p)``.

    Each returns a tuple of floats (``h`` one float); integer constants are written as
    floats so numba sees homogeneous tuples (:meth:`aiofl.plants.base.Plant.check`).
    ``normal_form`` returns :math:`(\xi_1..\xi_\rho, \alpha, \beta)` of ``analysis`` with
    common subexpressions shared.  ``bd`` is present when the plant has one.
    """
    a = analysis
    nf_names = [f"ξ_{i}" for i in range(1, a.rho + 1)] + ["α", "β"]
    out = {
        "f": _function_source("f", list(plant.f), plant, tuple_=True),
        "g": _function_source("g", list(plant.g), plant, tuple_=True),
        "h": _function_source("h", [plant.h], plant, tuple_=False),
        "normal_form": _function_source(
            "normal_form", [*a.xi, a.alpha, a.beta], plant, tuple_=True, cse=True, names=nf_names
        ),
    }
    if plant.bd is not None:
        out["bd"] = _function_source("bd", list(plant.bd), plant, tuple_=True)
    in_xi = a.alpha_beta_of_xi
    if in_xi is not None:
        # functions of ξ (ρ = n): ξ_i is written as the i-th state's symbol, so the
        # function reads it as x[i-1] like every generated function
        x_of_xi, _ = a.inverse
        back = dict(zip(a.xi_symbols, plant.states, strict=True))
        out["alpha_beta_of_xi"] = _function_source(
            "alpha_beta_of_xi",
            [e.xreplace(back) for e in in_xi],
            plant,
            tuple_=True,
            cse=True,
            names=["α(Φ⁻¹(ξ))", "β(Φ⁻¹(ξ))"],
        )
        out["state_of_xi"] = _function_source(
            "state_of_xi",
            [e.xreplace(back) for e in x_of_xi],
            plant,
            tuple_=True,
            cse=True,
        )
    return out


#: the generated functions, in the order a module holds them
GENERATED_FUNCTIONS = ("f", "g", "h", "bd", "normal_form", "alpha_beta_of_xi", "state_of_xi")


def compile_sources(sources: dict[str, str], name: str) -> dict[str, Any]:
    """Execute generated ``sources`` (name -> source) into a namespace with only ``math``.

    Returns the functions by the same names; ``name`` (the plant's) labels their code objects.
    """
    ns: dict[str, Any] = {"math": math}
    for src in sources.values():  # source generated from parsed sympy expressions only
        exec(compile(src, f"<aiofl.plants.symbolic {name}>", "exec"), ns)
    return {k: ns[k] for k in sources}


def _function_source(
    fname: str,
    exprs: list[Any],
    plant: SymbolicModel,
    *,
    tuple_: bool,
    cse: bool = False,
    names: list[str] | None = None,
) -> str:
    from sympy.printing.pycode import PythonCodePrinter

    printer = PythonCodePrinter({"fully_qualified_modules": True})
    mapping = {s: sp.Symbol(f"x[{i}]", real=True) for i, s in enumerate(plant.states)}
    mapping.update({s: sp.Symbol(f"p[{i}]", real=True) for i, s in enumerate(plant.param_symbols)})
    exprs = [drop_delta(sp.sympify(e)) for e in exprs]
    for i, e in enumerate(exprs):
        label = names[i] if names else (f"{fname}[{i + 1}]" if tuple_ else fname)
        _check_constants(e, f"plant {plant.name!r}: generated {fname}, {label}")
    exprs = [e.xreplace(mapping) for e in exprs]
    lines = [f"def _fn_{fname}(x, p):"]
    if cse:
        reps, exprs = sp.cse(exprs, symbols=sp.numbered_symbols("_c"), optimizations="basic")
        for sym, val in reps:
            lines.append(f"    {sym} = {_code(val, printer)}")

    items = [_code(e, printer) for e in exprs]
    if tuple_:
        body = ", ".join(items) + ("," if len(items) == 1 else "")
        lines.append(f"    return ({body})")
    else:
        lines.append(f"    return {items[0]}")
    src = "\n".join(lines) + "\n"
    bad = _NONFINITE_CODE.search(src)
    if bad:  # the checks above should make this unreachable
        raise SymbolicPlantError(
            f"plant {plant.name!r}: the generated {fname} would contain {bad.group()!r}; "
            "allowed: finite real expressions"
        )
    return src


_NONFINITE_CODE = re.compile(r"\b(?:inf|nan|zoo|oo|NaN|Infinity)\b|\b\d+(?:\.\d*)?j\b")


def _check_constants(expr: Any, where: str) -> None:
    """Refuse ``expr`` if it holds ``zoo``/``nan``/``oo``/``I``, a number outside float64,
    or a constant subexpression that is not a finite real float (``exp(1000)``)."""
    check_finite(expr, where)
    stack = [expr]
    while stack:  # the largest constant subexpressions, each evaluated once
        sub = stack.pop()
        if sub.is_Atom:
            continue
        if sub.free_symbols:
            stack.extend(sub.args)
            continue
        try:
            val = complex(sub.evalf(17))
        except (TypeError, ValueError, OverflowError):
            val = complex(math.nan)
        if val.imag != 0 or not math.isfinite(val.real):
            raise SymbolicPlantError(
                f"{where}: the constant {sp.sstr(sub)[:60]} is not a finite real float64 "
                f"({val}); allowed: finite real expressions"
            )


def _code(expr: Any, printer: Any) -> str:
    """Python source of one expression; bare numbers become float literals."""
    expr = sp.sympify(expr)
    if expr.is_Number or (not expr.free_symbols and expr.is_real is not False):
        try:
            val = float(expr)
        except (TypeError, OverflowError):
            pass
        else:
            if not math.isfinite(val):
                raise SymbolicPlantError(f"generated code: {sp.sstr(expr)[:60]} is not finite")
            return repr(val)
    return str(printer.doprint(expr))


def generate_module_source(plants: Sequence[tuple[str, _HasSources]], header: str = "") -> str:
    """Source of a module holding the generated functions of several plants.

    Functions are named ``<prefix>_f``, ``<prefix>_g``, ``<prefix>_h``, ``<prefix>_bd`` and
    ``<prefix>_normal_form``.
    """
    parts = [f'"""{header}"""\n' if header else "", "import math\n"]
    for prefix, plant in plants:
        srcs = plant.function_sources(prefix=f"{prefix}_")
        for key in GENERATED_FUNCTIONS:
            if key in srcs:
                parts.append("\n\n" + srcs[key])
    return "".join(parts)
