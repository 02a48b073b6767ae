r"""Symbolic plants: Lie derivatives, relative degree, normal form and zero dynamics.

This is the machinery of the paper's Section III, for any SISO plant

.. math:: \dot x = f(x) + g(x)u + b_d(x)\tau_d,\qquad y = h(x)

written in sympy (in Python, or as strings in a TOML file, see
:meth:`SymbolicPlant.from_dict`).  :func:`analyze` computes

* the Lie derivatives :math:`L_f^k h = \frac{\partial L_f^{k-1}h}{\partial x} f` and
  :math:`L_g L_f^k h` (text before eq. 2);
* the relative degree ρ, the least k+1 with :math:`L_g L_f^{k} h \not\equiv 0` (eq. 2), and
  the region where :math:`\beta(x) = L_g L_f^{\rho-1} h \ne 0`;
* :math:`\alpha(x) = L_f^\rho h` and :math:`\beta(x)`, so that
  :math:`y^{(\rho)} = \alpha(x) + \beta(x)u` and the classical IOFL law
  :math:`u = (-\alpha(x) + v)/\beta(x)` gives :math:`y^{(\rho)} = v`;
* the normal-form coordinates :math:`\xi = (h, L_f h, \dots, L_f^{\rho-1}h)` of eq. (3);
* where ρ < n, internal coordinates η = φ(x) with :math:`\frac{\partial\phi}{\partial x}g = 0`
  (eq. 3), the zero dynamics :math:`\dot\eta = f_0(\eta, 0)` and a numerical check of
  their stability at an equilibrium (linearised eigenvalues; minimum phase or not).

A :class:`SymbolicPlant` compiles to the same fast :class:`aiofl.plants.base.Plant` the engine
runs (:meth:`SymbolicPlant.to_plant`): sympy generates plain Python source for
``f, g, h, bd`` and ``normal_form(x, p) -> (ξ_1..ξ_ρ, α, β)`` returning tuples of floats,
which numba compiles into the closed-loop kernel like any hand-written plant.

Expressions given as strings are parsed by walking their Python syntax tree and accepting
only numbers, the plant's state and parameter names, ``pi``, arithmetic (``+ - * / **``)
and a fixed list of functions (:data:`FUNCTIONS`); nothing is ``eval``-ed.

This module imports sympy; nothing in the engine imports it.
"""

from __future__ import annotations

import ast
import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import sympy as sp
from numpy.typing import NDArray
from sympy.core.function import AppliedUndef

__all__ = [
    "FUNCTIONS",
    "Analysis",
    "RelativeDegreeError",
    "SymbolicPlant",
    "SymbolicPlantError",
    "ZeroDynamics",
    "ZeroDynamicsError",
    "analyze",
    "format_analysis_latex",
    "format_analysis_text",
    "generate_module_source",
    "lie_derivative",
    "load_symbolic_plant",
    "parse_expression",
]


class SymbolicPlantError(ValueError):
    """A symbolic plant that cannot be used; the message names the field at fault."""


class RelativeDegreeError(SymbolicPlantError):
    """The relative degree is undefined (the input never reaches the output)."""


class ZeroDynamicsError(SymbolicPlantError):
    """Internal coordinates η (eq. 3) could not be constructed automatically."""


# ----------------------------------------------------------------------- parsing
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

_CONSTANTS = {"pi": sp.pi}
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
            if node.id in _CONSTANTS:
                return _CONSTANTS[node.id]
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


# ------------------------------------------------------------------ Lie algebra
def lie_derivative(scalar: Any, field_: Any, states: Sequence[sp.Symbol]) -> Any:
    r"""Lie derivative :math:`L_F\lambda(x) = \frac{\partial\lambda}{\partial x}F(x)` (Section III).

    Parameters
    ----------
    scalar
        The scalar function λ(x) (a sympy expression).
    field_
        The vector field F(x), a sequence of n sympy expressions.
    states
        The state symbols :math:`x_1..x_n`.
    """
    if len(field_) != len(states):
        raise SymbolicPlantError(
            f"lie_derivative: field has {len(field_)} entries but there are {len(states)} states"
        )
    return sp.Add(*(sp.diff(scalar, xi) * fi for xi, fi in zip(states, field_, strict=True)))


def _drop_delta(expr: Any) -> Any:
    """Replace DiracDelta terms (derivatives of sign/abs) by 0: they vanish almost everywhere."""
    if expr.has(sp.DiracDelta):
        expr = expr.replace(lambda e: isinstance(e, sp.DiracDelta), lambda e: sp.S.Zero)
    return expr


def _tidy(expr: Any) -> Any:
    """A compact form of ``expr`` (sympy ``simplify`` unless the expression is large)."""
    expr = _drop_delta(sp.sympify(expr))
    if sp.count_ops(expr) > 600:
        return sp.expand(expr)
    return sp.simplify(expr)


# -------------------------------------------------------------------- the plant
@dataclass(frozen=True, eq=False)
class SymbolicPlant:
    r"""A SISO plant :math:`\dot x = f(x) + g(x)u + b_d(x)\tau_d`, :math:`y = h(x)` in sympy.

    Parameters
    ----------
    name
        Identifier (the engine plant built by :meth:`to_plant` gets this name).
    states
        State symbols :math:`x_1..x_n` (real).
    params
        Ordered ``(symbol, nominal value)`` pairs; the order is that of the parameter vector
        ``p`` of the compiled plant.
    f, g, bd
        Column vectors of n expressions (``bd`` may be None: no disturbance input).
    h
        Output expression; must depend on the state.
    eta
        Optional internal coordinates φ(x) (n − ρ expressions with
        :math:`\partial\phi/\partial x\, g = 0`, eq. 3); found automatically when g has a
        constant direction.
    equilibrium
        Optional point :math:`x_e` for the zero-dynamics stability check; otherwise x = 0 is
        tried, then a numerical root of :math:`\xi(x) = 0,\ \dot\eta(x) = 0`.
    state_labels, description
        Documentation (one label per state, e.g. ``"hub angle θ [rad]"``).
    """

    name: str
    states: tuple[Any, ...]
    params: tuple[tuple[Any, float], ...]
    f: Any
    g: Any
    h: Any
    bd: Any = None
    eta: tuple[Any, ...] | None = None
    equilibrium: tuple[float, ...] | None = None
    state_labels: tuple[str, ...] = ()
    description: str = ""
    _cache: dict[str, Any] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        name = self.name
        states = tuple(self.states)
        if not states:
            raise SymbolicPlantError(f"plant {name!r}: states must list at least one state")
        if len(set(states)) != len(states):
            raise SymbolicPlantError(f"plant {name!r}: states must be distinct")
        params = tuple((s, float(v)) for s, v in self.params)
        for s, v in params:
            if not math.isfinite(v):
                raise SymbolicPlantError(f"plant {name!r}: params.{s} = {v}; allowed: finite")
        psyms = {s for s, _ in params}
        if len(psyms) != len(params):
            raise SymbolicPlantError(f"plant {name!r}: parameter names must be distinct")
        clash = psyms & set(states)
        if clash:
            raise SymbolicPlantError(
                f"plant {name!r}: {', '.join(map(str, clash))} is both a state and a parameter"
            )
        n = len(states)
        object.__setattr__(self, "states", states)
        object.__setattr__(self, "params", params)
        allowed = set(states) | psyms
        vecs: dict[str, Any] = {}
        for fname in ("f", "g", "bd"):
            val = getattr(self, fname)
            if val is None:
                if fname != "bd":
                    raise SymbolicPlantError(f"plant {name!r}: {fname} is required")
                continue
            entries = list(val)
            if len(entries) != n:
                raise SymbolicPlantError(
                    f"plant {name!r}: {fname} has {len(entries)} entries; the plant has n = {n} "
                    f"states ({', '.join(map(str, states))}), so {fname} needs {n}"
                )
            vecs[fname] = sp.ImmutableMatrix([sp.sympify(e) for e in entries])
        h = sp.sympify(self.h)
        if isinstance(h, sp.MatrixBase) or isinstance(self.h, (list, tuple)):
            raise SymbolicPlantError(f"plant {name!r}: h must be one scalar expression (SISO)")
        for fname, expr in (*vecs.items(), ("h", h)):
            free = expr.free_symbols - allowed
            if free:
                raise SymbolicPlantError(
                    f"plant {name!r}: {fname} uses unknown symbol(s) "
                    f"{', '.join(sorted(map(str, free)))}; allowed: states and params"
                )
            if expr.atoms(AppliedUndef):
                raise SymbolicPlantError(f"plant {name!r}: {fname} uses an undefined function")
        if not (h.free_symbols & set(states)):
            raise SymbolicPlantError(
                f"plant {name!r}: h = {h} is not a function of the state x "
                f"({', '.join(map(str, states))}); the output must depend on x"
            )
        if all(e == 0 for e in vecs["g"]):
            raise RelativeDegreeError(
                f"plant {name!r}: g(x) ≡ 0, the input u does not enter the plant; the relative "
                "degree is undefined"
            )
        object.__setattr__(self, "f", vecs["f"])
        object.__setattr__(self, "g", vecs["g"])
        object.__setattr__(self, "bd", vecs.get("bd"))
        object.__setattr__(self, "h", h)
        if self.eta is not None:
            eta = tuple(sp.sympify(e) for e in self.eta)
            for i, e in enumerate(eta, 1):
                if e.free_symbols - allowed:
                    raise SymbolicPlantError(f"plant {name!r}: eta[{i}] uses unknown symbols")
            object.__setattr__(self, "eta", eta)
        if self.equilibrium is not None:
            eq = tuple(float(v) for v in self.equilibrium)
            if len(eq) != n:
                raise SymbolicPlantError(
                    f"plant {name!r}: equilibrium has {len(eq)} entries; the plant has {n} states"
                )
            object.__setattr__(self, "equilibrium", eq)
        labels = tuple(self.state_labels) or tuple(str(s) for s in states)
        if len(labels) != n:
            raise SymbolicPlantError(f"plant {name!r}: state_labels needs {n} entries")
        object.__setattr__(self, "state_labels", labels)

    # ------------------------------------------------------------- constructors
    @classmethod
    def from_strings(
        cls,
        name: str,
        states: Sequence[str] | Mapping[str, str],
        params: Mapping[str, float],
        f: Sequence[str],
        g: Sequence[str],
        h: str,
        bd: Sequence[str] | None = None,
        eta: Sequence[str] | None = None,
        equilibrium: Sequence[float] | None = None,
        description: str = "",
    ) -> SymbolicPlant:
        """Build a plant from expression strings (see :func:`parse_expression`).

        ``states`` is a list of names or a mapping name -> label; ``params`` maps names to
        nominal values.
        """
        if isinstance(states, str) or not isinstance(states, (Sequence, Mapping)):
            raise SymbolicPlantError(f"plant {name!r}: states must be a list of names")
        labels = list(states.values()) if isinstance(states, Mapping) else []
        names = list(states)
        if not isinstance(params, Mapping):
            raise SymbolicPlantError(f"plant {name!r}: params must be a table name = value")
        symbols: dict[str, sp.Symbol] = {}
        for nm in [*names, *params]:
            if not isinstance(nm, str) or not nm.isidentifier() or nm.startswith("_"):
                raise SymbolicPlantError(
                    f"plant {name!r}: {nm!r} is not a valid name (a Python identifier not "
                    "starting with _)"
                )
            if nm in FUNCTIONS or nm in _CONSTANTS:
                raise SymbolicPlantError(
                    f"plant {name!r}: {nm!r} is reserved (a function or constant name)"
                )
            if nm in symbols:
                raise SymbolicPlantError(f"plant {name!r}: name {nm!r} is used twice")
            symbols[nm] = sp.Symbol(nm, real=True)
        for pn, pv in params.items():
            if isinstance(pv, bool) or not isinstance(pv, (int, float)):
                raise SymbolicPlantError(
                    f"plant {name!r}: params.{pn} = {pv!r}; allowed: a finite number"
                )

        def vec(key: str, val: Any) -> list[Any]:
            if isinstance(val, str) or not isinstance(val, Sequence):
                raise SymbolicPlantError(
                    f"plant {name!r}: {key} must be a list of {len(names)} expression strings"
                )
            return [parse_expression(s, symbols, f"{key}[{i}]") for i, s in enumerate(val, 1)]

        return cls(
            name=name,
            states=tuple(symbols[s] for s in names),
            params=tuple((symbols[p], float(v)) for p, v in params.items()),
            f=vec("f", f),
            g=vec("g", g),
            h=parse_expression(h, symbols, "h") if not isinstance(h, (list, tuple)) else h,
            bd=None if bd is None else vec("bd", bd),
            eta=None if eta is None else tuple(vec("eta", eta)),
            equilibrium=None if equilibrium is None else tuple(equilibrium),
            state_labels=tuple(str(v) for v in labels),
            description=description,
        )

    _KEYS = frozenset(
        {"name", "description", "states", "params", "f", "g", "h", "bd", "eta", "equilibrium"}
    )

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "<dict>") -> SymbolicPlant:
        """Build a plant from a dict with the keys of the TOML format.

        .. code-block:: toml

            name = "pendulum"
            description = "damped pendulum"
            states = ["theta", "omega"]          # or a [states] table: theta = "angle [rad]"
            f = ["omega", "-g/l*sin(theta) - c/(m*l**2)*omega"]
            g = ["0", "1/(m*l**2)"]
            h = "theta"
            bd = ["0", "1/(m*l**2)"]             # optional disturbance input
            # eta = ["..."]                      # optional internal coordinates (eq. 3)
            # equilibrium = [0.0, 0.0]           # optional point for the zero dynamics
            [params]
            m = 1.0
            l = 0.5
            c = 0.1
            g = 9.81

        (Top-level keys must come before the ``[params]`` table in TOML.)
        """
        unknown = sorted(set(data) - cls._KEYS)
        if unknown:
            raise SymbolicPlantError(
                f"{source}: unknown key(s) {', '.join(unknown)}; allowed: "
                f"{', '.join(sorted(cls._KEYS))}"
            )
        missing = [k for k in ("states", "params", "f", "g", "h") if k not in data]
        if missing:
            raise SymbolicPlantError(f"{source}: missing key(s) {', '.join(missing)}")
        name = str(data.get("name", Path(source).stem if source != "<dict>" else "symbolic"))
        return cls.from_strings(
            name=name,
            states=data["states"],
            params=data["params"],
            f=data["f"],
            g=data["g"],
            h=data["h"],
            bd=data.get("bd"),
            eta=data.get("eta"),
            equilibrium=data.get("equilibrium"),
            description=str(data.get("description", "")),
        )

    @classmethod
    def from_toml(cls, path: str | Path) -> SymbolicPlant:
        """Read a plant from a TOML file (format of :meth:`from_dict`)."""
        return cls.from_dict(_read_toml(path), str(path))

    # ----------------------------------------------------------------- helpers
    @property
    def n(self) -> int:
        """Number of states n."""
        return len(self.states)

    @property
    def param_symbols(self) -> tuple[Any, ...]:
        """Parameter symbols, in the order of the vector ``p``."""
        return tuple(s for s, _ in self.params)

    @property
    def nominal(self) -> dict[Any, float]:
        """Nominal parameter values by symbol."""
        return dict(self.params)

    def numeric(self, exprs: Sequence[Any]) -> Any:
        """A numpy function ``x -> array`` of ``exprs`` at the nominal parameters."""
        sub = [_drop_delta(sp.sympify(e)).subs(self.nominal) for e in exprs]
        fn = sp.lambdify([self.states], sub, modules="numpy")

        def call(x: Any) -> NDArray[np.float64]:
            return np.array(fn(np.asarray(x, dtype=np.float64)), dtype=np.float64)

        return call

    def analyze(self) -> Analysis:
        """The Section-III analysis of this plant (cached), see :func:`analyze`."""
        if "analysis" not in self._cache:
            self._cache["analysis"] = analyze(self)
        return self._cache["analysis"]

    # ----------------------------------------------------------- code generation
    def function_sources(self, prefix: str = "") -> dict[str, str]:
        """Python source of ``f, g, h, bd, normal_form`` (``def <prefix><name>(x, p)``).

        Each returns a tuple of floats (``h`` one float); integer constants are written as
        floats so numba sees homogeneous tuples (:meth:`aiofl.plants.base.Plant.check`).
        ``normal_form`` returns :math:`(\\xi_1..\\xi_\\rho, \\alpha, \\beta)` with common
        subexpressions shared.
        """
        if "sources" not in self._cache:
            a = self.analyze()
            out = {
                "f": _function_source("f", list(self.f), self, tuple_=True),
                "g": _function_source("g", list(self.g), self, tuple_=True),
                "h": _function_source("h", [self.h], self, tuple_=False),
                "normal_form": _function_source(
                    "normal_form", [*a.xi, a.alpha, a.beta], self, tuple_=True, cse=True
                ),
            }
            if self.bd is not None:
                out["bd"] = _function_source("bd", list(self.bd), self, tuple_=True)
            self._cache["sources"] = out
        srcs: dict[str, str] = self._cache["sources"]
        return {k: v.replace("def _fn_", f"def {prefix}", 1) for k, v in srcs.items()}

    def compile_functions(self) -> dict[str, Any]:
        """The generated functions, executed into a namespace with only ``math``."""
        if "functions" not in self._cache:
            ns: dict[str, Any] = {"math": math}
            srcs = self.function_sources()
            for src in srcs.values():  # source generated from parsed sympy expressions only
                exec(compile(src, f"<aiofl.plants.symbolic {self.name}>", "exec"), ns)
            self._cache["functions"] = {k: ns[k] for k in srcs}
        return dict(self._cache["functions"])

    def to_plant(self, name: str | None = None) -> Any:
        """Compile to an engine :class:`aiofl.plants.base.Plant` (with ``normal_form`` for IOFL).

        The generated functions are plain Python over ``math``, so the engine's numba kernel
        compiles them exactly as it compiles hand-written plants.
        """
        from aiofl.plants.base import Plant

        fns = self.compile_functions()
        return Plant(
            name=name or self.name,
            n_states=self.n,
            f=fns["f"],
            g=fns["g"],
            h=fns["h"],
            bd=fns.get("bd"),
            params={str(s): v for s, v in self.params},
            relative_degree=self.analyze().rho,
            normal_form=fns["normal_form"],
            state_names=tuple(str(s) for s in self.states),
            description=self.description,
        )


def _function_source(
    fname: str, exprs: list[Any], plant: SymbolicPlant, *, tuple_: bool, cse: bool = False
) -> str:
    from sympy.printing.pycode import PythonCodePrinter

    printer = PythonCodePrinter({"fully_qualified_modules": True})
    mapping = {s: sp.Symbol(f"x[{i}]", real=True) for i, s in enumerate(plant.states)}
    mapping.update({s: sp.Symbol(f"p[{i}]", real=True) for i, s in enumerate(plant.param_symbols)})
    exprs = [_drop_delta(sp.sympify(e)).xreplace(mapping) for e in exprs]
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


def generate_module_source(plants: Sequence[tuple[str, SymbolicPlant]], header: str = "") -> str:
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


# ---------------------------------------------------------------------- analysis
@dataclass(frozen=True)
class ZeroDynamics:
    r"""Internal coordinates and zero dynamics (Section III, after eq. 3).

    Attributes
    ----------
    eta
        φ(x), n − ρ expressions with :math:`\partial\phi/\partial x\,g = 0`.
    eta_symbols
        Symbols :math:`\eta_1..\eta_{n-\rho}`.
    eta_dot
        :math:`\dot\eta = \frac{\partial\phi}{\partial x}f(x)` (u cancels), in x.
    f0
        The zero dynamics :math:`\dot\eta = f_0(\eta, 0)` in η, or None when the
        coordinate change could not be inverted symbolically (then ``eta_dot`` on the
        manifold ξ(x) = 0 describes them).
    equilibrium
        The point :math:`x_e` (ξ(x_e) = 0, η̇(x_e) = 0) where they are linearised.
    jacobian, eigenvalues
        :math:`\partial f_0/\partial\eta` at :math:`x_e` (nominal parameters), its eigenvalues.
    verdict
        ``"minimum phase"`` (all eigenvalues in the open left half plane: locally
        exponentially stable zero dynamics), ``"non-minimum phase"`` (one in the right half
        plane) or ``"marginal (linearisation inconclusive)"``.
    method
        How η was chosen.
    """

    eta: tuple[Any, ...]
    eta_symbols: tuple[Any, ...]
    eta_dot: tuple[Any, ...]
    f0: tuple[Any, ...] | None
    equilibrium: tuple[float, ...]
    jacobian: NDArray[np.float64]
    eigenvalues: NDArray[np.complex128]
    verdict: str
    method: str


@dataclass(frozen=True)
class Analysis:
    r"""Result of :func:`analyze` (Section III).

    Attributes
    ----------
    plant
        The analysed plant.
    lf_h
        :math:`L_f^k h`, k = 0..ρ (the last one is α).
    lg_lf_h
        :math:`L_g L_f^k h`, k = 0..ρ−1 (zero except the last one, β; eq. 2).
    rho
        Relative degree.
    xi, alpha, beta
        Normal-form coordinates :math:`\xi_i = L_f^{i-1}h`, :math:`\alpha = L_f^\rho h`,
        :math:`\beta = L_gL_f^{\rho-1}h`.
    beta_constant
        β does not depend on x (ρ is then defined everywhere, if β ≠ 0).
    beta_nominal
        β at the nominal parameters when it is constant.
    beta_zero_set, beta_undefined_set
        Factors c(x) of β's numerator / denominator: ρ is not defined where c(x) = 0.
    zero_dynamics
        :class:`ZeroDynamics` when ρ < n and they could be computed, else None.
    zero_dynamics_note
        Why there are none (ρ = n) or why they could not be computed.
    """

    plant: SymbolicPlant
    lf_h: tuple[Any, ...]
    lg_lf_h: tuple[Any, ...]
    rho: int
    beta_constant: bool
    beta_nominal: float | None
    beta_zero_set: tuple[Any, ...]
    beta_undefined_set: tuple[Any, ...]
    zero_dynamics: ZeroDynamics | None
    zero_dynamics_note: str

    @property
    def xi(self) -> tuple[Any, ...]:
        """Normal-form coordinates :math:`(h, L_f h, \\dots, L_f^{\\rho-1} h)`, eq. (3)."""
        return self.lf_h[: self.rho]

    @property
    def alpha(self) -> Any:
        """:math:`\\alpha(x) = L_f^\\rho h`."""
        return self.lf_h[self.rho]

    @property
    def beta(self) -> Any:
        """:math:`\\beta(x) = L_g L_f^{\\rho-1} h`."""
        return self.lg_lf_h[self.rho - 1]

    @cached_property
    def region(self) -> str:
        """Where :math:`\\beta(x) \\ne 0`, i.e. where the relative degree is ρ, in words."""
        if self.beta_constant:
            val = self.beta_nominal
            if val == 0.0:
                return "nowhere at the nominal parameters (β is 0 there)"
            return f"everywhere (β is a nonzero constant, {val:.6g} at the nominal parameters)"
        parts = []
        if self.beta_zero_set:
            parts.append(
                "β = 0 where " + " or ".join(f"{sp.sstr(c)} = 0" for c in self.beta_zero_set)
            )
        if self.beta_undefined_set:
            parts.append(
                "β undefined where "
                + " or ".join(f"{sp.sstr(c)} = 0" for c in self.beta_undefined_set)
            )
        where = "; ".join(parts) if parts else "β depends on x"
        return f"{{x : β(x) ≠ 0}} ({where})"


def _is_zero(expr: Any, plant: SymbolicPlant) -> bool:
    """Whether ``expr`` vanishes identically in x at the nominal parameters."""
    e = _tidy(expr)
    if e == 0:
        return True
    e_nom = sp.simplify(e.subs(plant.nominal))
    if e_nom == 0:
        return True
    if e_nom.free_symbols:
        return bool(e_nom.equals(0))
    return False


def analyze(plant: SymbolicPlant) -> Analysis:
    r"""Lie derivatives, relative degree, α, β, ξ and zero dynamics (Section III).

    The relative degree is the least ρ with :math:`L_gL_f^{\rho-1}h \not\equiv 0` (eq. 2),
    tested identically in x at the nominal parameters.  If :math:`L_gL_f^k h \equiv 0` for
    k = 0..n−1 the input never reaches the output (it then never does) and
    :class:`RelativeDegreeError` is raised.

    Raises
    ------
    RelativeDegreeError
        When ρ is undefined everywhere.
    """
    states, f, g = plant.states, list(plant.f), list(plant.g)
    lf = [plant.h]
    lg: list[Any] = []
    rho = 0
    for k in range(plant.n):
        lgk = _tidy(lie_derivative(lf[k], g, states))
        if _is_zero(lgk, plant):
            lg.append(sp.S.Zero)
            lf.append(_tidy(lie_derivative(lf[k], f, states)))
            continue
        lg.append(lgk)
        rho = k + 1
        break
    if rho == 0:
        raise RelativeDegreeError(
            f"plant {plant.name!r}: L_g L_f^k h ≡ 0 for k = 0..{plant.n - 1}: the input never "
            "appears in any derivative of the output, so the relative degree is undefined "
            "everywhere (eq. 2 has no solution); check g and h"
        )
    if len(lf) == rho:
        lf.append(_tidy(lie_derivative(lf[rho - 1], f, states)))
    beta = lg[rho - 1]
    sset = set(states)
    beta_constant = not (beta.free_symbols & sset)
    beta_nominal = float(beta.subs(plant.nominal)) if beta_constant else None
    zeros: tuple[Any, ...] = ()
    undefined: tuple[Any, ...] = ()
    if not beta_constant:
        num, den = sp.fraction(sp.together(beta))
        zeros = tuple(fc for fc, _ in sp.factor_list(num)[1] if fc.free_symbols & sset)
        undefined = tuple(fc for fc, _ in sp.factor_list(den)[1] if fc.free_symbols & sset)
    zd: ZeroDynamics | None = None
    if rho == plant.n:
        note = "none: ρ = n, there are no internal dynamics"
    else:
        try:
            zd = _zero_dynamics(plant, tuple(lf[:rho]), rho)
            note = f"{zd.verdict} (eigenvalues of the linearised zero dynamics at x_e)"
        except ZeroDynamicsError as exc:
            note = str(exc)
    return Analysis(
        plant=plant,
        lf_h=tuple(lf),
        lg_lf_h=tuple(lg),
        rho=rho,
        beta_constant=beta_constant,
        beta_nominal=beta_nominal,
        beta_zero_set=zeros,
        beta_undefined_set=undefined,
        zero_dynamics=zd,
        zero_dynamics_note=note,
    )


def _internal_coordinates(plant: SymbolicPlant, xi: tuple[Any, ...], rho: int) -> tuple[Any, str]:
    """Choose φ(x) with ∂φ/∂x g = 0 (eq. 3)."""
    states, g = plant.states, sp.Matrix(plant.g)
    m = plant.n - rho
    if plant.eta is not None:
        eta = plant.eta
        if len(eta) != m:
            raise ZeroDynamicsError(
                f"plant {plant.name!r}: eta has {len(eta)} entries; n − ρ = {m} are needed"
            )
        for i, e in enumerate(eta, 1):
            lgphi = lie_derivative(e, list(g), states)
            if not _is_zero(lgphi, plant):
                raise ZeroDynamicsError(
                    f"plant {plant.name!r}: eta[{i}] = {e} has ∂φ/∂x·g = {sp.simplify(lgphi)} "
                    "≠ 0; eq. (3) needs it to vanish"
                )
        return eta, "given in the model"
    # g(x) = γ(x)·c with a constant direction c: φ = w·x for w in the left null space of c
    k = next(i for i, gi in enumerate(g) if not _is_zero(gi, plant))
    direction = sp.Matrix([sp.simplify(gi / g[k]) for gi in g])
    if any(d.free_symbols & set(states) for d in direction):
        raise ZeroDynamicsError(
            f"plant {plant.name!r}: cannot construct internal coordinates η automatically: g(x) "
            "has no constant direction (g/g_k depends on x), so linear φ(x) = w·x with "
            "∂φ/∂x·g = 0 do not exist; give eta = [...] in the model (n − ρ functions with "
            "∂φ/∂x·g(x) ≡ 0, eq. 3)"
        )
    basis = direction.T.nullspace()
    # choose by the generic rank (at a pseudo-random point); x_e is checked later
    x0 = tuple(np.random.default_rng(0).uniform(0.3, 0.9, plant.n))
    dxi = np.array(
        sp.Matrix(xi).jacobian(states).subs(plant.nominal).subs(dict(zip(states, x0, strict=True))),
        dtype=np.float64,
    ).reshape(rho, plant.n)
    rows = list(dxi)
    chosen: list[Any] = []
    for w in basis:
        wv = np.array(w.subs(plant.nominal), dtype=np.float64).ravel()
        trial = np.vstack([*rows, wv])
        if np.linalg.matrix_rank(trial, tol=1e-9) == len(rows) + 1:
            rows.append(wv)
            chosen.append(w)
        if len(chosen) == m:
            break
    if len(chosen) < m:
        raise ZeroDynamicsError(
            f"plant {plant.name!r}: cannot complete ξ to a coordinate change with linear η "
            "(the Jacobian of (η, ξ) is singular); give eta = [...] in the model"
        )
    eta = tuple(sp.expand((w.T * sp.Matrix(states))[0]) for w in chosen)
    return eta, "linear, from the left null space of g's constant direction"


def _equilibrium_guess(plant: SymbolicPlant) -> tuple[float, ...]:
    return plant.equilibrium if plant.equilibrium is not None else (0.0,) * plant.n


def _zero_dynamics(plant: SymbolicPlant, xi: tuple[Any, ...], rho: int) -> ZeroDynamics:
    from scipy.optimize import root

    states, n, m = plant.states, plant.n, plant.n - rho
    eta, method = _internal_coordinates(plant, xi, rho)
    eta_dot = tuple(_tidy(lie_derivative(e, list(plant.f), states)) for e in eta)
    # equilibrium of the zero dynamics: ξ(x) = 0 and η̇(x) = 0
    resid = plant.numeric([*xi, *eta_dot])
    x_e = np.array(_equilibrium_guess(plant), dtype=np.float64)
    if not np.all(np.abs(resid(x_e)) < 1e-9):
        sol = root(resid, x_e, method="hybr")
        if not sol.success or not np.all(np.abs(resid(sol.x)) < 1e-8):
            raise ZeroDynamicsError(
                f"plant {plant.name!r}: no equilibrium of the zero dynamics found near "
                f"x = {x_e.tolist()} (ξ(x) = 0, η̇(x) = 0); give equilibrium = [...] in the model"
            )
        x_e = sol.x
    tmap = sp.Matrix([*eta, *xi])
    jt = plant.numeric(list(tmap.jacobian(states)))(x_e).reshape(n, n)
    if np.linalg.matrix_rank(jt, tol=1e-10) < n:
        raise ZeroDynamicsError(
            f"plant {plant.name!r}: (η, ξ) is not a coordinate change at x_e = {x_e.tolist()} "
            "(singular Jacobian); give other eta = [...]"
        )
    jq = plant.numeric(list(sp.Matrix(eta_dot).jacobian(states)))(x_e).reshape(m, n)
    jac = jq @ np.linalg.inv(jt)[:, :m]
    eig = np.linalg.eigvals(jac)
    scale = max(1.0, float(np.max(np.abs(eig))) if eig.size else 1.0)
    tol = 1e-9 * scale
    if np.all(eig.real < -tol):
        verdict = "minimum phase"
    elif np.any(eig.real > tol):
        verdict = "non-minimum phase"
    else:
        verdict = "marginal (linearisation inconclusive)"
    eta_syms = tuple(sp.Symbol(f"eta{i}", real=True) for i in range(1, m + 1))
    f0 = _invert_linear(tmap, states, eta_syms, rho, eta_dot)
    return ZeroDynamics(
        eta=eta,
        eta_symbols=eta_syms,
        eta_dot=eta_dot,
        f0=f0,
        equilibrium=tuple(float(v) for v in x_e),
        jacobian=jac,
        eigenvalues=eig,
        verdict=verdict,
        method=method,
    )


def _invert_linear(
    tmap: Any,
    states: tuple[Any, ...],
    eta_syms: tuple[Any, ...],
    rho: int,
    eta_dot: tuple[Any, ...],
) -> tuple[Any, ...] | None:
    """f0(η, 0) when z = T(x) is linear in x (solve T(x) = (η, 0) for x); else None."""
    jac = tmap.jacobian(states)
    if jac.free_symbols & set(states):
        return None
    rhs = sp.Matrix([*eta_syms, *([0] * rho)])
    try:
        x_of_eta = jac.LUsolve(rhs - tmap.subs(dict.fromkeys(states, 0)))
    except (ValueError, ZeroDivisionError):
        return None
    sub = dict(zip(states, x_of_eta, strict=True))
    return tuple(_tidy(e.subs(sub)) for e in eta_dot)


# ------------------------------------------------------------------- formatting
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


# ---------------------------------------------------------------------- loading
def _read_toml(path: str | Path) -> dict[str, Any]:
    """The TOML table of a plant file; a missing or malformed file is a SymbolicPlantError."""
    p = Path(path)
    if not p.is_file():
        raise SymbolicPlantError(f"plant file {str(p)!r} does not exist")
    try:
        return tomllib.loads(p.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise SymbolicPlantError(f"malformed TOML in {p}: {exc}") from None


def load_symbolic_plant(target: str | Path) -> SymbolicPlant:
    """A symbolic plant by built-in name (``"slfjm"``, ...) or from a TOML file.

    A run config (a TOML with ``plant = "<name>"``) resolves to its plant.
    """
    from aiofl.plants.library import symbolic_model, symbolic_plant_names

    text = str(target)
    if text in symbolic_plant_names():
        return symbolic_model(text)
    path = Path(text)
    if path.suffix == ".toml" or path.exists():
        data = _read_toml(path)
        if "f" not in data and isinstance(data.get("plant"), str):
            return load_symbolic_plant(data["plant"])
        return SymbolicPlant.from_dict(data, str(path))
    from aiofl.plants.builtin import available_plants

    if text in available_plants():
        raise SymbolicPlantError(
            f"plant {text!r} is registered from Python functions and has no symbolic model; "
            "write it as a symbolic-plant TOML file "
            "(see aiofl.plants.symbolic.SymbolicPlant.from_dict)"
        )
    raise SymbolicPlantError(
        f"unknown plant {text!r}: not a built-in symbolic plant "
        f"({', '.join(symbolic_plant_names())}) nor a TOML file"
    )
