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
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Protocol

import sympy as sp

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
    out = {
        "f": _function_source("f", list(plant.f), plant, tuple_=True),
        "g": _function_source("g", list(plant.g), plant, tuple_=True),
        "h": _function_source("h", [plant.h], plant, tuple_=False),
        "normal_form": _function_source(
            "normal_form", [*a.xi, a.alpha, a.beta], plant, tuple_=True, cse=True
        ),
    }
    if plant.bd is not None:
        out["bd"] = _function_source("bd", list(plant.bd), plant, tuple_=True)
    return out


def compile_sources(sources: dict[str, str], name: str) -> dict[str, Any]:
    """Execute generated ``sources`` (name -> source) into a namespace with only ``math``.

    Returns the functions by the same names; ``name`` (the plant's) labels their code objects.
    """
    ns: dict[str, Any] = {"math": math}
    for src in sources.values():  # source generated from parsed sympy expressions only
        exec(compile(src, f"<aiofl.plants.symbolic {name}>", "exec"), ns)
    return {k: ns[k] for k in sources}


def _function_source(
    fname: str, exprs: list[Any], plant: SymbolicModel, *, tuple_: bool, cse: bool = False
) -> str:
    from sympy.printing.pycode import PythonCodePrinter

    printer = PythonCodePrinter({"fully_qualified_modules": True})
    mapping = {s: sp.Symbol(f"x[{i}]", real=True) for i, s in enumerate(plant.states)}
    mapping.update({s: sp.Symbol(f"p[{i}]", real=True) for i, s in enumerate(plant.param_symbols)})
    exprs = [drop_delta(sp.sympify(e)).xreplace(mapping) for e in exprs]
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
    return "\n".join(lines) + "\n"


def _code(expr: Any, printer: Any) -> str:
    """Python source of one expression; bare numbers become float literals."""
    expr = sp.sympify(expr)
    if expr.is_Number or (not expr.free_symbols and expr.is_real is not False):
        try:
            return repr(float(expr))
        except TypeError:
            pass
    return str(printer.doprint(expr))


def generate_module_source(plants: Sequence[tuple[str, _HasSources]], header: str = "") -> str:
    """Source of a module holding the generated functions of several plants.

    Functions are named ``<prefix>_f``, ``<prefix>_g``, ``<prefix>_h``, ``<prefix>_bd`` and
    ``<prefix>_normal_form``.
    """
    parts = [f'"""{header}"""\n' if header else "", "import math\n"]
    for prefix, plant in plants:
        srcs = plant.function_sources(prefix=f"{prefix}_")
        for key in ("f", "g", "h", "bd", "normal_form"):
            if key in srcs:
                parts.append("\n\n" + srcs[key])
    return "".join(parts)
