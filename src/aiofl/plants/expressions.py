r"""The restricted expression parser for symbolic plants given as strings.

A plant file (:meth:`aiofl.plants.symbolic.SymbolicPlant.from_dict`) writes the vector
fields :math:`f(x)`, :math:`g(x)`, :math:`b_d(x)` and the output :math:`h(x)` of

.. math:: \dot x = f(x) + g(x)u + b_d(x)\tau_d,\qquad y = h(x)

as expression strings.  :func:`parse_expression` turns one into a sympy expression by
walking its Python syntax tree and accepting only numbers, the plant's state and parameter
names, the constants of :data:`CONSTANTS` (``pi``), arithmetic (``+ - * / **``, unary
minus) and a fixed list of functions (:data:`FUNCTIONS`); nothing is ``eval``-ed.  Plant
files may come from anyone, so every bound on what an expression may contain lives here.

**Bounds, checked before sympy sees anything.**  sympy evaluates exact arithmetic eagerly
(``10**10**10`` is a ten-billion-digit integer), so a short string can hang or exhaust
memory; Python's parser and a recursive tree walk overflow the stack on 2,000 nested signs.
Every expression is therefore checked, in this order, and refused with a
:class:`SymbolicPlantError` naming the field (``f[2]``) and the limit:

=================================  ===========  =============================================
bound                              limit        why
=================================  ===========  =============================================
characters                         4,000        the parser's stack; ~40x the longest
                                                shipped expression
unary signs in a row               32           ``--…-x`` nests one level per sign
syntax-tree nodes                  1,000        the work of every later step is linear in it
nesting depth                      32           levels of calls, powers, signs and
                                                parentheses (a chain ``a+b+c`` is one
                                                level); the walk recurses this deep
constant exponent :math:`|n|`      64           ``(x+1)**200`` and towers; an exponent that
                                                depends on x is allowed
expanded size                      2,000 terms  the monomials of the fully expanded form
                                                (e.g. :math:`(x_1+x_2+1)^{30}` has 496):
                                                simplification and Jacobians expand
constants                          finite, real every constant subexpression is evaluated in
                                                float64 as the walk goes: ``1/0``,
                                                ``log(0)``, ``1e400``, ``exp(1000)``,
                                                ``sqrt(-1)`` are refused by name
=================================  ===========  =============================================

and after sympy has built the expression it must not contain ``zoo``, ``nan``, ``oo`` or
``I`` (``1/(x1 - x1)``, ``atan2(0, 0)``) nor a number outside the float64 range.  A plant
may have at most :data:`MAX_STATES` states and :data:`MAX_PARAMS` parameters
(:mod:`aiofl.plants.symbolic`); the symbolic analysis bounds the size of the Lie
derivatives it builds (:mod:`aiofl.plants.normal_form`).  None of this is a time limit:
each bound is on the input's size, so a refusal takes milliseconds.

:class:`SymbolicPlantError`, the error of every symbolic-plant module, is defined here so
this module imports nothing else of aiofl.
"""

from __future__ import annotations

import ast
import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import sympy as sp

from aiofl import limits

__all__ = [
    "CONSTANTS",
    "FUNCTIONS",
    "MAX_EXPANDED_TERMS",
    "MAX_EXPONENT",
    "MAX_EXPRESSION_CHARS",
    "MAX_EXPRESSION_DEPTH",
    "MAX_EXPRESSION_NODES",
    "MAX_PARAMS",
    "MAX_STATES",
    "SymbolicPlantError",
    "check_finite",
    "expanded_terms",
    "function_depth",
    "parse_expression",
    "vanishes_numerically",
]


class SymbolicPlantError(ValueError):
    """A symbolic plant that cannot be used; the message names the field at fault."""


MAX_EXPRESSION_CHARS = 4000
"""Most characters in one expression string."""
MAX_EXPRESSION_NODES = 1000
"""Most syntax-tree nodes (numbers, names, operations, calls) in one expression."""
MAX_EXPRESSION_DEPTH = 32
"""Deepest nesting of calls, powers, unary signs and parenthesised operands."""
MAX_EXPONENT = 64
"""Largest magnitude of a constant exponent, :math:`|n| \\le 64`."""
MAX_EXPANDED_TERMS = 2000
"""Most terms of an expression's fully expanded form (an estimate from its tree)."""
MAX_STATES = limits.MAX_STATES
"""Most states of a symbolic plant (:data:`aiofl.limits.MAX_STATES`).  The analysis takes
up to n Lie derivatives over n states and n x n Jacobians, and numba compiles n-tuples;
SISO plants of this kind have a handful of states (the shipped ones 1 to 4), and 32 is 4x
the largest controller order (``RHO_MAX = 8``)."""
MAX_PARAMS = 64
"""Most parameters of a symbolic plant (the shipped ones have at most 9)."""

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

_CONSTANT_VALUES: Mapping[str, float] = {"pi": math.pi}


def _sign(v: float) -> float:
    return 0.0 if v == 0.0 else math.copysign(1.0, v)


# float64 versions of FUNCTIONS, to evaluate constant subexpressions as the walk goes
_FLOAT_FUNCTIONS: Mapping[str, Callable[..., float]] = {
    "sin": math.sin,
    "cos": math.cos,
    "tan": math.tan,
    "asin": math.asin,
    "acos": math.acos,
    "atan": math.atan,
    "atan2": math.atan2,
    "sinh": math.sinh,
    "cosh": math.cosh,
    "tanh": math.tanh,
    "exp": math.exp,
    "log": math.log,
    "sqrt": math.sqrt,
    "abs": abs,
    "sign": _sign,
    "min": min,
    "max": max,
}

_ADDITIVE = (ast.Add, ast.Sub)
_MULTIPLICATIVE = (ast.Mult, ast.Div)
_BINOPS: Mapping[type, Callable[[Any, Any], Any]] = {
    ast.Add: lambda a, b: a + b,
    ast.Sub: lambda a, b: a - b,
    ast.Mult: lambda a, b: a * b,
    ast.Div: lambda a, b: a / b,
    ast.Pow: lambda a, b: a**b,
}
_SYMBOLS: Mapping[type, str] = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/"}
_SIGN_RUN = re.compile(rf"[-+~](?:\s*[-+~]){{{MAX_EXPRESSION_DEPTH},}}")
_TERMS_CAP = 10**12  # expanded-size estimates saturate here (they are only compared)
_NONFINITE = (sp.zoo, sp.nan, sp.oo, -sp.oo)


def _short(text: str, width: int = 60) -> str:
    """``text`` quoted, cut to ``width`` characters (messages stay one line)."""
    return repr(text if len(text) <= width else text[:width] + "…")


@dataclass(frozen=True)
class _Term:
    """A built subexpression: the sympy object, its float value when it is a constant,
    and the estimated number of terms of its expanded form."""

    expr: Any
    value: float | None
    terms: int


def _same_chain(node: ast.AST, ops: tuple[type, ...]) -> bool:
    return isinstance(node, ast.BinOp) and isinstance(node.op, ops)


def _chain_class(node: ast.AST) -> tuple[type, ...] | None:
    if isinstance(node, ast.BinOp):
        if isinstance(node.op, _ADDITIVE):
            return _ADDITIVE
        if isinstance(node.op, _MULTIPLICATIVE):
            return _MULTIPLICATIVE
    return None


def _measure(tree: ast.AST, where: str, text: str) -> None:
    """Count nodes and nesting depth iteratively (no recursion) and refuse over the limits.

    The left operand of ``a + b`` (``a * b``) that is itself a sum (product) stays on the
    same level, so a long written-out sum is one level deep; every other child is one level
    deeper.  This is the depth :func:`parse_expression`'s walk recurses to.
    """
    nodes = 0
    stack: list[tuple[ast.AST, int]] = [(tree, 0)]
    while stack:
        node, depth = stack.pop()
        if isinstance(node, ast.expr):
            nodes += 1
            if nodes > MAX_EXPRESSION_NODES:
                raise SymbolicPlantError(
                    f"{where}: more than {MAX_EXPRESSION_NODES} syntax nodes in {_short(text)}; "
                    f"allowed: at most {MAX_EXPRESSION_NODES} (numbers, names, operations, "
                    "calls) per expression"
                )
        if depth > MAX_EXPRESSION_DEPTH:
            raise SymbolicPlantError(
                f"{where}: nesting deeper than {MAX_EXPRESSION_DEPTH} levels in {_short(text)}; "
                f"allowed: at most {MAX_EXPRESSION_DEPTH} levels of calls, powers, signs and "
                "parentheses"
            )
        chain = _chain_class(node)
        for child in ast.iter_child_nodes(node):
            if not isinstance(child, ast.expr):
                continue
            flat = (
                chain is not None
                and isinstance(node, ast.BinOp)
                and child is node.left
                and _same_chain(child, chain)
            )
            stack.append((child, depth if flat else depth + 1))


def _float_op(op: type, a: float, b: float) -> float:
    """``a op b`` in float64; raises ZeroDivisionError/OverflowError/ValueError."""
    if op is ast.Add:
        out = a + b
    elif op is ast.Sub:
        out = a - b
    elif op is ast.Mult:
        out = a * b
    elif op is ast.Div:
        out = a / b
    else:
        out = a**b  # a negative base with a fractional exponent gives a complex number
    if isinstance(out, complex):
        raise ValueError("a complex value (negative base with a fractional exponent)")
    if not math.isfinite(out):
        raise OverflowError("a value outside the float64 range")
    return float(out)


def _multinomial_terms(base_terms: int, n: int) -> int:
    """Monomials of :math:`(t_1 + \\dots + t_k)^n`: :math:`\\binom{n+k-1}{k-1}`, capped."""
    if base_terms <= 1 or n == 0:
        return 1
    if base_terms > _TERMS_CAP:
        return _TERMS_CAP
    return min(math.comb(n + base_terms - 1, base_terms - 1), _TERMS_CAP)


def parse_expression(text: str, symbols: Mapping[str, sp.Symbol], where: str = "expression") -> Any:
    """Parse ``text`` into a sympy expression over ``symbols``, safely and within bounds.

    Only numbers, names in ``symbols``, ``pi``, ``+ - * / **``, unary signs and the
    functions of :data:`FUNCTIONS` are accepted; the syntax tree is converted node by node
    (no ``eval``).  Before sympy builds anything the text's length, the runs of unary
    signs, the tree's node count and depth are bounded (see the module notes); while it is
    built, constant exponents are bounded by :data:`MAX_EXPONENT`, the expanded size by
    :data:`MAX_EXPANDED_TERMS`, and every constant subexpression is evaluated in float64
    and must be finite and real.  ``where`` names the field in error messages.

    Parameters
    ----------
    text
        The expression (a number is taken as its ``repr``).
    symbols
        The allowed names, name -> sympy symbol.
    where
        The field, for messages.

    Returns
    -------
    sympy.Expr

    Raises
    ------
    SymbolicPlantError
        On a syntax error, an unknown name or function, an unsupported construct, an
        expression over a bound, a division by zero or a non-finite or complex constant.
    """
    if not isinstance(text, str):
        if isinstance(text, (int, float)) and not isinstance(text, bool):
            text = repr(text)
        else:
            raise SymbolicPlantError(f"{where}: expected a string expression, got {text!r:.60}")
    if len(text) > MAX_EXPRESSION_CHARS:
        raise SymbolicPlantError(
            f"{where}: expression of {len(text)} characters; allowed: at most "
            f"{MAX_EXPRESSION_CHARS}"
        )
    run = _SIGN_RUN.search(text)
    if run:
        signs = sum(ch in "+-~" for ch in run.group())
        raise SymbolicPlantError(
            f"{where}: {signs} unary signs in a row in {_short(text)}; allowed: nesting at "
            f"most {MAX_EXPRESSION_DEPTH} levels deep"
        )
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        raise SymbolicPlantError(f"{where}: cannot parse {_short(text)}: {exc.msg}") from None
    except (RecursionError, MemoryError):  # the parser's own stack, before our depth check
        raise SymbolicPlantError(
            f"{where}: {_short(text)} is nested too deeply to parse; allowed: at most "
            f"{MAX_EXPRESSION_DEPTH} levels"
        ) from None
    _measure(tree, where, text)
    expr = _Builder(symbols, where, text).build(tree.body).expr
    return check_finite(sp.sympify(expr), where, text)


def check_finite(expr: Any, where: str, text: str | None = None) -> Any:
    """Refuse an expression that contains ``zoo``, ``nan``, ``±oo``, ``I`` or a number
    outside the float64 range (the generated code must never contain ``inf`` or ``nan``).

    Returns ``expr`` unchanged.  ``where`` (and ``text``, the source) name the field.

    Parameters
    ----------
    expr
        A sympy expression.
    where
        The field, for messages.
    text
        The expression's source, for messages (None: printed from ``expr``).

    Returns
    -------
    sympy.Expr
        ``expr``.

    Raises
    ------
    SymbolicPlantError
        For a non-finite, complex or out-of-range value.
    """
    shown = _short(text) if text is not None else _short(sp.sstr(expr))
    if expr.has(*_NONFINITE):
        raise SymbolicPlantError(
            f"{where}: {shown} is not finite (a division by zero or an infinite value: "
            f"sympy gives {_short(sp.sstr(expr), 50)}); allowed: finite expressions"
        )
    if expr.has(sp.I):
        raise SymbolicPlantError(
            f"{where}: {shown} has a complex value ({_short(sp.sstr(expr), 50)}); allowed: "
            "real expressions"
        )
    for atom in expr.atoms(sp.Number):
        try:
            ok = math.isfinite(float(atom))
        except (OverflowError, TypeError, ValueError):
            ok = False
        if not ok:
            raise SymbolicPlantError(
                f"{where}: the number {_short(sp.sstr(atom), 30)} in {shown} is outside the "
                "float64 range; allowed: |value| <= 1.8e308"
            )
    return expr


def expanded_terms(expr: Any, cap: int = _TERMS_CAP) -> int:
    r"""Estimated number of terms of ``sp.expand(expr)``, computed from the tree (capped).

    An atom or a function call counts 1 (its arguments are estimated on their own), a sum
    the sum of its terms', a product the product of its factors', and a power with an
    integer exponent n of a k-term base :math:`\binom{|n|+k-1}{k-1}` (the monomials of
    degree n in k terms).  The estimate bounds the work of expanding, cancelling or
    simplifying the expression.  Iterative; the largest estimate over all subexpressions
    is returned.
    """
    out: dict[int, int] = {}
    worst = 1
    stack: list[tuple[Any, bool]] = [(expr, False)]
    while stack:
        node, done = stack.pop()
        if not done:
            stack.append((node, True))
            stack.extend((a, False) for a in node.args if id(a) not in out)
            continue
        if node.is_Add:
            t = min(sum(out.get(id(a), 1) for a in node.args), cap)
        elif node.is_Mul:
            t = 1
            for a in node.args:
                t = min(t * out.get(id(a), 1), cap)
        elif node.is_Pow and node.exp.is_Integer:
            t = _multinomial_terms(out.get(id(node.base), 1), min(abs(int(node.exp)), 10**6))
            t = min(t, cap)
        else:
            t = 1
        out[id(node)] = t
        worst = max(worst, t)
        if worst >= cap:
            return cap
    return worst


def function_depth(expr: Any) -> int:
    """Deepest nesting of function applications in ``expr`` (``sin(exp(x))`` is 2);
    iterative."""
    worst = 0
    stack: list[tuple[Any, int]] = [(expr, 0)]
    while stack:
        node, depth = stack.pop()
        if isinstance(node, sp.Function):
            depth += 1
            worst = max(worst, depth)
        stack.extend((a, depth) for a in node.args)
    return worst


def vanishes_numerically(expr: Any, states: Sequence[Any], n_points: int = 3) -> bool:
    r"""Whether ``expr`` (free of parameters) vanishes identically in x, decided numerically.

    ``expr`` is evaluated in 40-digit arithmetic (mpmath) at ``n_points`` seeded random
    points :math:`x \in [0.3, 0.9]^n`; it is taken as zero when at every point where it is
    real :math:`|e(x)| \le 10^{-25}(1 + \sum_i |t_i(x)|)`, :math:`t_i` its additive terms
    (so cancellation error is allowed for), and there is at least one such point.  A
    nonzero analytic function vanishes at random points with probability zero.

    Parameters
    ----------
    expr
        A sympy expression free of parameters.
    states
        The state symbols it may depend on.
    n_points
        The random points tried (default 3).

    Returns
    -------
    bool
    """
    import mpmath

    terms = list(sp.Add.make_args(expr))
    fn = sp.lambdify(list(states), [expr, *terms], modules="mpmath")
    rng = np.random.default_rng(0)
    usable = 0
    with mpmath.workdps(40):
        for _ in range(n_points):
            point = [mpmath.mpf(float(v)) for v in rng.uniform(0.3, 0.9, len(states))]
            try:
                vals = fn(*point)
            except (ZeroDivisionError, ValueError, TypeError, OverflowError):
                continue
            if any(isinstance(v, mpmath.mpc) and v.imag != 0 for v in vals):
                continue
            vals = [mpmath.mpf(mpmath.re(v)) for v in vals]
            if not all(mpmath.isfinite(v) for v in vals):
                continue
            usable += 1
            scale = 1 + sum(abs(v) for v in vals[1:])
            if abs(vals[0]) > mpmath.mpf("1e-25") * scale:
                return False
    return usable > 0


class _Builder:
    """The walk of :func:`parse_expression` over a measured tree (depth <= the limit)."""

    def __init__(self, symbols: Mapping[str, sp.Symbol], where: str, text: str) -> None:
        self.symbols = symbols
        self.where = where
        self.text = text

    def fail(self, what: str) -> SymbolicPlantError:
        return SymbolicPlantError(f"{self.where}: {what} in {_short(self.text)}")

    def constant(self, fn: Callable[[], float], what: str) -> float:
        """Evaluate a constant subexpression in float64; refuse it if not finite and real."""
        try:
            val = fn()
        except ZeroDivisionError:
            raise self.fail(f"division by zero: {what}") from None
        except OverflowError:
            raise self.fail(
                f"{what} overflows (outside the float64 range, |value| <= 1.8e308)"
            ) from None
        except ValueError as exc:
            raise self.fail(f"{what} is not a finite real number ({exc})") from None
        if isinstance(val, complex) or not math.isfinite(val):
            raise self.fail(f"{what} is not a finite real number")
        return float(val)

    def checked_terms(self, terms: int) -> int:
        if terms > MAX_EXPANDED_TERMS:
            raise self.fail(
                f"the expanded form would have about {terms:.3g} terms; allowed: at most "
                f"{MAX_EXPANDED_TERMS} (write the expression with fewer or smaller powers)"
            )
        return terms

    def build(self, node: ast.AST) -> _Term:
        if isinstance(node, ast.Constant):
            return self.literal(node.value)
        if isinstance(node, ast.Name):
            return self.name(node.id)
        if isinstance(node, ast.BinOp):
            return self.binop(node)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            sub = self.build(node.operand)
            if isinstance(node.op, ast.UAdd):
                return sub
            val = None if sub.value is None else -sub.value
            return _Term(-sub.expr, val, sub.terms)
        if isinstance(node, ast.Call):
            return self.call(node)
        raise self.fail(
            f"unsupported syntax {type(node).__name__} (allowed: numbers, names, "
            "+ - * / **, function calls)"
        )

    def literal(self, val: Any) -> _Term:
        if isinstance(val, bool) or not isinstance(val, (int, float)):
            raise self.fail("only numbers are allowed as literals")
        fval = self.constant(lambda: float(val), f"the literal {str(val)[:30]}")
        return _Term(sp.Integer(val) if isinstance(val, int) else sp.Float(val), fval, 1)

    def name(self, ident: str) -> _Term:
        if ident in self.symbols:
            return _Term(self.symbols[ident], None, 1)
        if ident in CONSTANTS:
            return _Term(CONSTANTS[ident], _CONSTANT_VALUES[ident], 1)
        hint = " (a function; call it)" if ident in FUNCTIONS else ""
        allowed = ", ".join(sorted(self.symbols))
        raise self.fail(f"unknown name {ident!r}{hint}; allowed names: {allowed}, pi")

    def binop(self, node: ast.BinOp) -> _Term:
        if type(node.op) not in _BINOPS:
            extra = " (use ** for powers)" if isinstance(node.op, ast.BitXor) else ""
            raise self.fail(f"operator {type(node.op).__name__} not allowed{extra}")
        if isinstance(node.op, ast.Pow):
            return self.power(node)
        # a left-leaning chain a + b - c (or a * b / c) is walked in a loop, so a long
        # written-out sum costs no recursion; it is combined pairwise, left to right,
        # exactly as the recursive walk would
        chain = _chain_class(node)
        assert chain is not None
        rights: list[tuple[type, ast.expr]] = []
        left: ast.expr = node
        while _same_chain(left, chain):
            assert isinstance(left, ast.BinOp)
            rights.append((type(left.op), left.right))
            left = left.left
        acc = self.build(left)
        for op, right in reversed(rights):
            rhs = self.build(right)
            if op is ast.Div and rhs.value == 0.0:
                raise self.fail("division by zero")
            val = None
            if acc.value is not None and rhs.value is not None:
                a, b = acc.value, rhs.value
                what = f"{a:.6g} {_SYMBOLS[op]} {b:.6g}"
                val = self.constant(lambda a=a, b=b, op=op: _float_op(op, a, b), what)
            terms = acc.terms + rhs.terms if chain is _ADDITIVE else acc.terms * rhs.terms
            acc = _Term(_BINOPS[op](acc.expr, rhs.expr), val, self.checked_terms(terms))
        return acc

    def power(self, node: ast.BinOp) -> _Term:
        base = self.build(node.left)
        exp = self.build(node.right)
        if exp.value is not None and abs(exp.value) > MAX_EXPONENT:
            raise self.fail(
                f"the exponent {exp.value:.6g} is outside the allowed range |n| <= {MAX_EXPONENT}"
            )
        val = None
        if base.value is not None and exp.value is not None:
            a, b = base.value, exp.value
            if a == 0.0 and b < 0.0:
                raise self.fail("division by zero (0 to a negative power)")
            val = self.constant(lambda: _float_op(ast.Pow, a, b), f"({a:.6g})**({b:.6g})")
        terms = 1
        if exp.value is not None and float(exp.value).is_integer():
            terms = _multinomial_terms(base.terms, int(abs(exp.value)))
        return _Term(base.expr**exp.expr, val, self.checked_terms(terms))

    def call(self, node: ast.Call) -> _Term:
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
            name = node.func.id if isinstance(node.func, ast.Name) else ast.unparse(node.func)
            raise self.fail(
                f"unknown function {name[:40]!r}; allowed: {', '.join(sorted(FUNCTIONS))}"
            )
        fname = node.func.id
        fn, arity = FUNCTIONS[fname]
        if node.keywords or len(node.args) != arity:
            raise self.fail(f"{fname}() takes {arity} positional argument(s)")
        args = [self.build(a) for a in node.args]
        val = None
        if all(a.value is not None for a in args):
            vals = [float(a.value) for a in args]  # type: ignore[arg-type]
            what = f"{fname}({', '.join(f'{v:.6g}' for v in vals)})"
            val = self.constant(lambda: _FLOAT_FUNCTIONS[fname](*vals), what)
        return _Term(fn(*(a.expr for a in args)), val, 1)
