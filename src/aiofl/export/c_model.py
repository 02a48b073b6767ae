r"""C99 of the nominal model a model-assisted controller carries: :math:`(\hat\alpha, \hat\beta)`.

A controller with the model-assisted ESO (``eso.model = "nominal"``) evaluates the plant's
nominal normal form in its own coordinates at the corrected estimate,

.. math:: (\hat\alpha, \hat\beta) = (\alpha_0, \beta_0)\big(\Phi^{-1}(\hat\xi_{1..\rho})\big),

(:attr:`aiofl.plants.normal_form.Analysis.alpha_beta_of_xi`).  :func:`model_code` writes it
as ``static void aiofl_nominal_model(const aiofl_params *p, const aiofl_real *xi,
aiofl_real *alpha, aiofl_real *beta)`` (the file ``aiofl_model.h`` the controller
template includes under ``#if AIOFL_ESO_MODEL``) from the **same sympy expressions** the
plant's Python function ``alpha_beta_of_xi`` is generated from
(:func:`aiofl.plants.codegen.plant_sources`): the same substitution (:math:`\xi_i` as
``x[i-1]``, parameter k as ``p[k]``), the same common
subexpressions (:func:`sympy.cse`, ``optimizations="basic"``), printed by a
:class:`sympy.printing.c.C99CodePrinter` (single precision: its ``float`` aliases, so
``sinf``, ``sqrtf``, ...), so the C evaluates the operations the engine evaluates, in the
same order.  The nominal parameters the expressions use are the parameter struct's array
``plant_p`` (``PLANT_P`` in the function), so a second parameter instance may retune them.

Only aiofl's own names reach the code: the printer writes a symbol through a fixed map
(``x[i]`` -> ``xi[i]``, ``p[k]`` -> ``PLANT_P[j]``, temporaries -> ``t0, t1, ...``) and
refuses any other, every number is a literal of the export's precision (:math:`\pi`, e
included; ``M_PI`` is not C99), and :func:`_check_code` scans every generated line: only
numbers, operators, brackets and the identifiers of :data:`_MATH_NAMES` and that map.  The
plant's own names (a plant file's parameter names, its title) appear only in comments,
through :func:`aiofl.export.c_text.comment_text`.

Where the expressions come from (:func:`symbolic_model_for`): a built-in plant's
:func:`aiofl.plants.library.symbolic_model`, a plant file's
:meth:`aiofl.plants.symbolic.SymbolicPlant.from_toml`; a plain Python plant has none and is
refused (:class:`~aiofl.export.errors.ExportError`).  Before any code is written the
expressions are checked against the plant's compiled ``alpha_beta_of_xi`` at a few points
(a plant registered under a built-in name with other dynamics is refused).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl.export.c_text import c_identifier, comment_text
from aiofl.export.errors import ExportError
from aiofl.plants.base import Plant

__all__ = [
    "MODEL_FUNCTION",
    "ModelCode",
    "model_code",
    "nominal_model",
    "symbolic_model_for",
]

MODEL_FUNCTION = "aiofl_nominal_model"
_PARAMS = "PLANT_P"

# the <math.h> functions sympy's C99 printer may call, in both precisions
_MATH_NAMES = frozenset(
    f + suffix
    for f in (  # noqa: SIM905
        "sin cos tan asin acos atan atan2 sinh cosh tanh asinh acosh atanh exp exp2 expm1 log "
        "log2 log10 log1p sqrt cbrt pow fabs floor ceil fmin fmax hypot"
    ).split()
    for suffix in ("", "f")
)
_TOKEN = re.compile(
    r"\s*(?:(\d+(?:\.\d*)?(?:e[-+]?\d+)?f?)|([A-Za-z_][A-Za-z0-9_]*)|([-+*/(),<>=!?:&|\[\];]))"
)


@dataclass(frozen=True)
class ModelCode:
    """The C of the nominal model: the nominal parameter values (the params struct's
    ``plant_p``), the function (the file ``aiofl_model.h``), comment lines."""

    values: list[float]
    function: list[str]
    info: list[str]


def symbolic_model_for(plant: Plant, source: str | None = None) -> Any:
    """The symbolic plant whose expressions the C of ``plant``'s nominal model comes from.

    ``source``: the config's plant entry, a built-in name or a symbolic-plant ``.toml``
    file (default: ``plant.name``).  A plain Python plant has no expressions:
    :class:`ExportError`.
    """
    from aiofl.plants.library import SPECS

    ref = plant.name if source is None else str(source)
    try:
        if ref.endswith(".toml"):
            from aiofl.plants.symbolic import SymbolicPlant

            return SymbolicPlant.from_toml(ref)
        if ref in SPECS:
            from aiofl.plants.library import symbolic_model

            return symbolic_model(ref)
    except (OSError, ValueError) as exc:
        raise ExportError(f"the plant's expressions could not be read: {exc}") from None
    raise ExportError(
        f"plant {plant.name!r} has no symbolic expressions (a plain Python plant): the C of a "
        "model-assisted controller's nominal model (controller.eso.model = 'nominal') is "
        "generated from them; allowed: a built-in plant "
        f"({', '.join(SPECS)}) or a symbolic-plant .toml file"
    )


def _printer(precision: str, lit: Callable[[float], str], names: dict[str, str]) -> Any:
    """A C99 printer of ``precision`` writing numbers with ``lit`` and symbols by ``names``."""
    import sympy as sp
    from sympy.codegen.ast import float32, real
    from sympy.printing.c import C99CodePrinter

    zero, one = lit(0.0), lit(1.0)

    class _Printer(C99CodePrinter):  # type: ignore[misc]
        def _print(self, expr: Any, **kw: Any) -> str:
            if isinstance(expr, sp.Basic) and (expr.is_Number or expr.is_NumberSymbol):
                if expr.is_Rational and not expr.is_Integer:
                    return f"({lit(float(expr.p))}/{lit(float(expr.q))})"
                return lit(float(expr))
            return str(super()._print(expr, **kw))

        def _print_Float(self, expr: Any) -> str:
            return self._print(expr)

        _print_Integer = _print_Rational = _print_Float

        def _print_Symbol(self, expr: Any) -> str:
            if expr.name not in names:  # only aiofl's own names reach the code
                raise ExportError(f"the nominal model has an unknown symbol {expr.name!r}")
            return names[expr.name]

        def _print_sign(self, expr: Any) -> str:  # real-valued, no int arithmetic
            x = self._print(expr.args[0])
            return f"({x} > {zero} ? {one} : ({x} < {zero} ? -{one} : {zero}))"

    settings: dict[str, Any] = {"strict": True}
    if precision == "float":
        settings["type_aliases"] = {real: float32}
    return _Printer(settings)


def _check_code(line: str, allowed: frozenset[str]) -> str:
    """``line`` (a printed expression) if it holds only numbers, operators and the
    ``allowed`` identifiers, else RuntimeError (a bug in aiofl)."""
    pos = 0
    while pos < len(line.rstrip()):
        m = _TOKEN.match(line, pos)
        if m is None or (m.group(2) is not None and m.group(2) not in allowed):
            bad = line[pos : pos + 20] if m is None else m.group(2)
            raise RuntimeError(
                f"internal error: the generated nominal model holds {bad!r}; please report "
                "this as a bug"
            )
        pos = m.end()
    return line


def _agrees(plant: Plant, fn: Callable[..., Any], xs: Sequence[np.ndarray], p: np.ndarray) -> bool:
    """Whether the expressions (``fn``) give the plant's ``alpha_beta_of_xi`` at ``xs``."""
    seen = 0
    for x in xs:
        with np.errstate(all="ignore"):
            want = np.asarray(plant.alpha_beta_of_xi(x, p), dtype=np.float64)  # type: ignore[misc]
            try:
                got = np.asarray(fn(*x), dtype=np.float64)
            except (ValueError, ZeroDivisionError, OverflowError):
                got = np.full(2, np.nan)
        if not np.all(np.isfinite(want)):
            continue
        seen += 1
        if not np.allclose(got, want, rtol=1e-9, atol=1e-12 * np.max(np.abs(want))):
            return False
    return seen > 0


def model_code(
    plant: Plant,
    symbolic: Any,
    precision: str,
    lit: Callable[[float], str],
    xi_star: Sequence[float],
) -> ModelCode:
    r"""The C of ``plant``'s nominal :math:`(\hat\alpha, \hat\beta)(\xi)` from ``symbolic``'s
    expressions at ``plant``'s nominal parameters, in ``precision`` (literals by ``lit``).

    ``xi_star``: a point where the model is defined (the design point, :math:`\Phi(x_0)`),
    one of those where the expressions are checked against ``plant.alpha_beta_of_xi``.

    Parameters
    ----------
    plant
        The plant (its nominal parameters and ``alpha_beta_of_xi``).
    symbolic
        Its symbolic model (:class:`aiofl.plants.symbolic.SymbolicPlant`).
    precision
        ``"double"`` or ``"float"``.
    lit
        A number -> its C literal in ``precision``.
    xi_star
        ξ* (above).

    Returns
    -------
    ModelCode

    Raises
    ------
    ExportError
        No :math:`\Phi^{-1}` (ρ < n), a parameter the plant does not have, expressions
        that are not the plant's, or ones the C printer cannot write.
    """
    import sympy as sp

    from aiofl.plants.normal_form import drop_delta

    analysis = symbolic.analyze()
    in_xi = analysis.alpha_beta_of_xi
    if in_xi is None or plant.alpha_beta_of_xi is None:
        _, note = analysis.inverse
        raise ExportError(f"plant {plant.name!r} has no normal form in xi: {note}")
    rho = analysis.rho
    values = dict(plant.params)
    missing = [str(s) for s in symbolic.param_symbols if str(s) not in values]
    if missing:
        raise ExportError(f"plant {plant.name!r} has no parameter(s) {', '.join(missing)}")
    # the substitution of aiofl.plants.codegen: ξ_i as x[i-1], parameter k as p[k]
    xs = [sp.Symbol(f"x[{i}]", real=True) for i in range(rho)]
    ps = [sp.Symbol(f"p[{k}]", real=True) for k in range(len(symbolic.param_symbols))]
    mapping = dict(zip(analysis.xi_symbols, xs, strict=True))
    mapping.update(zip(symbolic.param_symbols, ps, strict=True))
    exprs = [drop_delta(sp.sympify(e)).xreplace(mapping) for e in in_xi]

    p_plant = plant.param_vector()
    p_sym = np.array([values[str(s)] for s in symbolic.param_symbols], dtype=np.float64)
    rng = np.random.default_rng(0)
    star = np.asarray(xi_star, dtype=np.float64)
    points = [star, *(star + rng.uniform(-0.5, 0.5, rho) for _ in range(4))]
    numeric = sp.lambdify(xs, [e.xreplace(dict(zip(ps, p_sym, strict=True))) for e in exprs])
    if not _agrees(plant, numeric, points, p_plant):
        raise ExportError(
            f"the symbolic model of plant {plant.name!r} does not give the plant's "
            "alpha_beta_of_xi (a plant registered under a built-in name?); the C of the "
            "nominal model is generated from the symbolic one"
        )

    reps, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("_c"), optimizations="basic")
    used = sorted(
        {k for k, s in enumerate(ps) if any(s in e.free_symbols for _, e in reps)}
        | {k for k, s in enumerate(ps) if any(s in e.free_symbols for e in reduced)}
    )
    names = {f"x[{i}]": f"xi[{i}]" for i in range(rho)}
    names |= {f"p[{k}]": f"{_PARAMS}[{j}]" for j, k in enumerate(used)}
    temps = [c_identifier(f"t{j}") for j in range(len(reps))]
    names |= {str(sym): t for (sym, _), t in zip(reps, temps, strict=True)}
    printer = _printer(precision, lit, names)
    allowed = _MATH_NAMES | {"xi", _PARAMS, *temps}

    def code(e: Any) -> str:
        try:
            text = " ".join(str(printer.doprint(e)).split())
        except (TypeError, ValueError, NotImplementedError) as exc:
            raise ExportError(f"the nominal model cannot be written as C: {exc}") from None
        return _check_code(text, allowed)

    body = [f"    const aiofl_real {t} = {code(v)};" for t, (_, v) in zip(temps, reps, strict=True)]
    body += [f"    *alpha = {code(reduced[0])};", f"    *beta = {code(reduced[1])};"]
    pnames = [comment_text(str(symbolic.param_symbols[k]), limit=40) for k in used]
    function = [
        "/* the nominal normal form in its own coordinates, (alpha, beta)(PHI^-1(xi)), from",
        "   the plant's symbolic model (generated, common subexpressions t_j); the nominal",
        "   parameters are the params struct's plant_p */",
        f"static void {MODEL_FUNCTION}(const aiofl_params *p, const aiofl_real *xi,",
        "                              aiofl_real *alpha, aiofl_real *beta)",
        "{",
        *(
            [f"    const aiofl_real *{_PARAMS} = p->plant_p;"]
            if any(_PARAMS in line for line in body)
            else ["    (void)p;"]
        ),
        *([] if any("xi[" in line for line in body) else ["    (void)xi;"]),
        *body,
        "}",
        "",
    ]
    plant_name = comment_text(plant.name, limit=60) or "unnamed"
    info = [
        f"Nominal model (eso.model = nominal) of plant {plant_name}, rho = {rho}: alpha, beta",
        "at xi = the corrected estimate; nominal parameters PLANT_P[j]:",
        *(
            f"  PLANT_P[{j}] = {n} = {float(p_sym[k])!r}"
            for j, (k, n) in enumerate(zip(used, pnames, strict=True))
        ),
    ]
    return ModelCode(values=[float(p_sym[k]) for k in used], function=function, info=info)


def nominal_model(
    controller: Any,
    plant: Plant | None,
    source: str | None,
    x0: Sequence[float],
    precision: str,
    lit: Callable[[float], str],
) -> tuple[ModelCode, NDArray[np.float64] | None]:
    r"""The C of a model-assisted ``controller``'s nominal model (:func:`model_code`) and the
    model's Jacobian its observer gain is placed for at :math:`\Phi(x_0)`, as the engine
    places it (:func:`aiofl.engine.observer_gains.model_jacobians`; None for Kalman gains).
    ``source``: the config's plant entry (:func:`symbolic_model_for`).

    Parameters
    ----------
    controller
        The model-assisted controller.
    plant
        Its plant; None is refused (:class:`ExportError`).
    source
        The config's plant entry.
    x0
        The start state (empty: zeros), where :math:`\Phi(x_0)` is taken.
    precision, lit
        As for :func:`model_code`.

    Returns
    -------
    model : ModelCode
    jacobian : ndarray or None
    """
    from aiofl.controller import controller_batch
    from aiofl.engine.observer_gains import model_jacobians

    if plant is None:
        raise ExportError(
            f"controller.eso.model = {controller.eso_model!r}: the code evaluates the plant's "
            "nominal model; pass plant= (aiofl export reads it from the config)"
        )
    try:
        controller.check_plant(plant, x0 or None)
        jac = model_jacobians(plant, controller_batch(controller), [tuple(x0)])
        p = plant.param_vector()
        x_start = np.asarray(x0, dtype=np.float64) if len(x0) else np.zeros(plant.n_states)
        xi_star = np.asarray(plant.normal_form(x_start, p), dtype=np.float64)[: controller.rho]  # type: ignore[misc]
    except ValueError as exc:
        raise ExportError(str(exc)) from None
    symbolic = symbolic_model_for(plant, source)
    return model_code(plant, symbolic, precision, lit, xi_star), jac
