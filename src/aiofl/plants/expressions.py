r"""The restricted expression parser for symbolic plants given as strings.

A plant file (:meth:`aiofl.plants.symbolic.SymbolicPlant.from_dict`) writes the vector
fields :math:`f(x)`, :math:`g(x)`, :math:`b_d(x)` and the output :math:`h(x)` of

.. math:: \dot x = f(x) + g(x)u + b_d(x)\tau_d,\qquad y = h(x)

as expression strings.  :func:`parse_expression` turns one into a sympy expression by
walking its Python syntax tree and accepting only numbers, the plant's state and parameter
names, the constants of :data:`CONSTANTS` (``pi``), arithmetic (``+ - * / **``, unary
minus) and a fixed list of functions (:data:`FUNCTIONS`); nothing is ``eval``-ed.  Plant
files may come from anyone, so every bound on what an expression may contain lives here.

:class:`SymbolicPlantError`, the error of every symbolic-plant module, is defined here so
this module imports nothing else of aiofl.
"""

from __future__ import annotations

import ast
from collections.abc import Mapping
from typing import Any

import sympy as sp

__all__ = ["CONSTANTS", "FUNCTIONS", "SymbolicPlantError", "parse_expression"]


class SymbolicPlantError(ValueError):
    """A symbolic plant that cannot be used; the message names the field at fault."""


FUNCTIONS: Mapping[str, tuple[Any, int]] = {
    "sin": (sp.sin, 1),
    "cos": (sp.cos, 1),
    "tan": (sp.tan, 1),
    "asin": (sp.asin, 1),
    "acos": (sp.acos, 1),
    "atan": (sp.atan, 1),
    "atan2": (sp.atan2, 2),
    "sinh": (sp.sinh, 1),
    "cosh": (sp.cosh, 1),
    "tanh": (sp.tanh, 1),
    "exp": (sp.exp, 1),
    "log": (sp.log, 1),
    "sqrt": (sp.sqrt, 1),
    "abs": (sp.Abs, 1),
    "sign": (sp.sign, 1),
    "min": (sp.Min, 2),
    "max": (sp.Max, 2),
}
"""Functions allowed in expression strings: name -> (sympy function, number of arguments)."""

CONSTANTS: Mapping[str, Any] = {"pi": sp.pi}
"""Named constants allowed in expression strings: name -> sympy constant."""

_BINOPS = {
    ast.Add: lambda a, b: a + b,
    ast.Sub: lambda a, b: a - b,
    ast.Mult: lambda a, b: a * b,
    ast.Div: lambda a, b: a / b,
    ast.Pow: lambda a, b: a**b,
}


def parse_expression(text: str, symbols: Mapping[str, sp.Symbol], where: str = "expression") -> Any:
    """Parse ``text`` into a sympy expression over ``symbols``, safely.

    Only numbers, names in ``symbols``, ``pi``, ``+ - * / **``, unary minus and the
    functions of :data:`FUNCTIONS` are accepted; the syntax tree is converted node by node
    (no ``eval``).  ``where`` names the field in error messages.

    Raises
    ------
    SymbolicPlantError
        On a syntax error, an unknown name or function, or an unsupported construct.
    """
    if not isinstance(text, str):
        if isinstance(text, (int, float)) and not isinstance(text, bool):
            text = repr(text)
        else:
            raise SymbolicPlantError(f"{where}: expected a string expression, got {text!r}")
    if len(text) > 20_000:
        raise SymbolicPlantError(f"{where}: expression longer than 20000 characters")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        raise SymbolicPlantError(f"{where}: cannot parse {text!r}: {exc.msg}") from None

    allowed = ", ".join(sorted(symbols))

    def build(node: ast.AST) -> Any:
        if isinstance(node, ast.Expression):
            return build(node.body)
        if isinstance(node, ast.Constant):
            val = node.value
            if isinstance(val, bool) or not isinstance(val, (int, float)):
                raise SymbolicPlantError(
                    f"{where}: only numbers are allowed as literals in {text!r}"
                )
            return sp.Integer(val) if isinstance(val, int) else sp.Float(val)
        if isinstance(node, ast.Name):
            if node.id in symbols:
                return symbols[node.id]
            if node.id in CONSTANTS:
                return CONSTANTS[node.id]
            hint = " (a function; call it)" if node.id in FUNCTIONS else ""
            raise SymbolicPlantError(
                f"{where}: unknown name {node.id!r}{hint} in {text!r}; allowed names: {allowed}, pi"
            )
        if isinstance(node, ast.BinOp):
            op = _BINOPS.get(type(node.op))
            if op is None:
                extra = " (use ** for powers)" if isinstance(node.op, ast.BitXor) else ""
                raise SymbolicPlantError(
                    f"{where}: operator {type(node.op).__name__} not allowed in {text!r}{extra}"
                )
            return op(build(node.left), build(node.right))
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            val = build(node.operand)
            return -val if isinstance(node.op, ast.USub) else val
        if isinstance(node, ast.Call):
            if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
                name = getattr(node.func, "id", ast.unparse(node.func))
                raise SymbolicPlantError(
                    f"{where}: unknown function {name!r} in {text!r}; allowed: "
                    f"{', '.join(sorted(FUNCTIONS))}"
                )
            fn, arity = FUNCTIONS[node.func.id]
            if node.keywords or len(node.args) != arity:
                raise SymbolicPlantError(
                    f"{where}: {node.func.id}() takes {arity} positional argument(s) in {text!r}"
                )
            return fn(*(build(a) for a in node.args))
        raise SymbolicPlantError(
            f"{where}: unsupported syntax {type(node).__name__} in {text!r} (allowed: numbers, "
            "names, + - * / **, function calls)"
        )

    return sp.sympify(build(tree))
