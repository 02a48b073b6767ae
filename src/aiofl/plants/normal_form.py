r"""Lie derivatives, relative degree, normal form and zero dynamics (Section III).

For a SISO plant

.. math:: \dot x = f(x) + g(x)u + b_d(x)\tau_d,\qquad y = h(x)

(a :class:`aiofl.plants.symbolic.SymbolicPlant`), :func:`analyze` computes

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

**Bounded work.**  Each Lie derivative can be several times larger than the one before
(a chain of ``sin`` links grows 16, 70, 386, 2410, 17925 operations), and sympy's
``simplify`` takes seconds at a hundred operations and minutes at a few hundred.  So an
expression is simplified only while it is small (at most :data:`SIMPLIFY_OPS` operations,
:data:`SIMPLIFY_TERMS` expanded terms and :data:`SIMPLIFY_NESTING` nested function calls,
which covers every shipped plant) and is kept
as it is otherwise (never expanded); whether a larger one vanishes identically is decided
numerically, at seeded random points in 40-digit arithmetic
(:func:`~aiofl.plants.expressions.vanishes_numerically`); and an expression over
:data:`MAX_ANALYSIS_OPS` operations stops the analysis with a
:class:`~aiofl.plants.expressions.SymbolicPlantError` naming it (its normal form would be
too large to compile).  A constant β that is not finite at the nominal parameters, and a
zero-dynamics linearisation that is not, are refused by name.

The plant is read through :class:`SymbolicModel` (its states, parameters, vector fields and
a numeric evaluator), so this module does not import :mod:`aiofl.plants.symbolic`, which
calls it (:meth:`~aiofl.plants.symbolic.SymbolicPlant.analyze`).  The engine plant
compiles ξ, α and β for the IOFL law (:mod:`aiofl.plants.codegen`); the text, LaTeX and JSON
forms of an :class:`Analysis` are :mod:`aiofl.analysis.plant_structure`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Any, Protocol

import numpy as np
import sympy as sp
from numpy.typing import NDArray

from aiofl.plants.coordinates import invert_coordinates
from aiofl.plants.expressions import (
    SymbolicPlantError,
    expanded_terms,
    function_depth,
    vanishes_numerically,
)

__all__ = [
    "MAX_ANALYSIS_OPS",
    "SIMPLIFY_NESTING",
    "SIMPLIFY_OPS",
    "SIMPLIFY_TERMS",
    "Analysis",
    "RelativeDegreeError",
    "SymbolicModel",
    "ZeroDynamics",
    "ZeroDynamicsError",
    "analyze",
    "drop_delta",
    "lie_derivative",
]


SIMPLIFY_OPS = 100
"""Largest expression (``sympy.count_ops``) that is simplified; slfjm's α, the largest
shipped, has 78 and takes ~1.5 s."""
SIMPLIFY_TERMS = 64
"""Largest expanded size (:func:`aiofl.plants.expressions.expanded_terms`) that is
simplified: simplification expands polynomials (``(x1 + 1)**64``, 65 terms, takes ~0.7 s)."""
SIMPLIFY_NESTING = 8
"""Deepest nesting of function calls that is simplified: simplification is exponential in
it (``sin(sin(...(x)))`` 9 deep takes 0.07 s, 12 deep 0.65 s, 15 deep 6 s)."""
MAX_ANALYSIS_OPS = 5000
"""Largest Lie derivative (operations) the analysis builds; beyond it the plant is refused."""
_INVERT_MAX_N = 8
"""Largest n for which the coordinate change is inverted symbolically (LU of an n x n
matrix of parameters grows quickly); beyond it f0 is left to ``eta_dot``."""


class RelativeDegreeError(SymbolicPlantError):
    """The relative degree is undefined (the input never reaches the output)."""


class ZeroDynamicsError(SymbolicPlantError):
    """Internal coordinates η (eq. 3) could not be constructed automatically."""


class SymbolicModel(Protocol):
    """What :func:`analyze` and code generation read of a plant.

    :class:`aiofl.plants.symbolic.SymbolicPlant` is one; see it for the meaning of each
    attribute.
    """

    @property
    def name(self) -> str: ...
    @property
    def description(self) -> str: ...
    @property
    def states(self) -> tuple[Any, ...]: ...
    @property
    def state_labels(self) -> tuple[str, ...]: ...
    @property
    def params(self) -> tuple[tuple[Any, float], ...]: ...
    @property
    def param_symbols(self) -> tuple[Any, ...]: ...
    @property
    def nominal(self) -> dict[Any, float]: ...
    @property
    def n(self) -> int: ...
    @property
    def f(self) -> Any: ...
    @property
    def g(self) -> Any: ...
    @property
    def h(self) -> Any: ...
    @property
    def bd(self) -> Any: ...
    @property
    def eta(self) -> tuple[Any, ...] | None: ...
    @property
    def equilibrium(self) -> tuple[float, ...] | None: ...
    def numeric(self, exprs: Sequence[Any]) -> Any: ...


def lie_derivative(scalar: Any, field_: Any, states: Sequence[sp.Symbol]) -> Any:
    r"""Lie derivative :math:`L_F\lambda(x) = \frac{\partial\lambda}{\partial x}F(x)` (Section III).

    Parameters
    ----------
    scalar, field_, states
        λ(x) (a sympy expression), F(x) (n sympy expressions), the symbols :math:`x_1..x_n`.

    Returns
    -------
    sympy.Expr
    """
    if len(field_) != len(states):
        raise SymbolicPlantError(
            f"lie_derivative: field has {len(field_)} entries but there are {len(states)} states"
        )
    return sp.Add(*(sp.diff(scalar, xi) * fi for xi, fi in zip(states, field_, strict=True)))


def drop_delta(expr: Any) -> Any:
    """Replace DiracDelta terms (derivatives of sign/abs) by 0: they vanish almost everywhere."""
    if expr.has(sp.DiracDelta):
        expr = expr.replace(lambda e: isinstance(e, sp.DiracDelta), lambda e: sp.S.Zero)
    return expr


def _small(expr: Any, ops: int | None = None) -> bool:
    """Whether ``expr`` is small enough to simplify (see the module notes)."""
    return bool(
        (sp.count_ops(expr) if ops is None else ops) <= SIMPLIFY_OPS
        and expanded_terms(expr, cap=10**6) <= SIMPLIFY_TERMS
        and function_depth(expr) <= SIMPLIFY_NESTING
    )


def _tidy(expr: Any, what: str = "an expression") -> Any:
    """A compact form of ``expr``: sympy ``simplify`` while it is small, else as it is.

    Raises :class:`SymbolicPlantError` naming ``what`` when ``expr`` has more than
    :data:`MAX_ANALYSIS_OPS` operations.
    """
    expr = drop_delta(sp.sympify(expr))
    ops = sp.count_ops(expr)
    if ops > MAX_ANALYSIS_OPS:
        raise SymbolicPlantError(
            f"{what} has {ops} operations; allowed: at most {MAX_ANALYSIS_OPS} (the Lie "
            "derivatives of this plant grow too large to analyse and compile)"
        )
    return sp.simplify(expr) if _small(expr, ops) else expr


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
        β at the nominal parameters: the constant, or its value at :attr:`beta_point`.
    beta_point, beta_point_label
        Where a state-dependent β is evaluated (:meth:`at_point`): the declared
        ``equilibrium``, or a run config's x0 (as ``aiofl robustness`` takes it).
    beta_zero_set, beta_undefined_set
        Factors c(x) of β's numerator / denominator: ρ is not defined where c(x) = 0.
    zero_dynamics
        :class:`ZeroDynamics` when ρ < n and they could be computed, else None.
    zero_dynamics_note
        Why there are none (ρ = n) or why they could not be computed.
    """

    plant: SymbolicModel
    lf_h: tuple[Any, ...]
    lg_lf_h: tuple[Any, ...]
    rho: int
    beta_constant: bool
    beta_nominal: float | None
    beta_zero_set: tuple[Any, ...]
    beta_undefined_set: tuple[Any, ...]
    zero_dynamics: ZeroDynamics | None
    zero_dynamics_note: str
    beta_point: tuple[float, ...] | None = None
    beta_point_label: str = ""

    def at_point(self, x: Sequence[float], label: str) -> Analysis:
        """This analysis with a state-dependent β evaluated at ``x`` (named ``label``)."""
        if self.beta_constant:
            return self
        point = tuple(float(v) for v in x)
        at = dict(zip(self.plant.states, point, strict=True))
        val = self.beta.subs({**self.plant.nominal, **at})
        nominal = float(val) if val.is_number and val.is_finite and val.is_real else None
        return replace(self, beta_nominal=nominal, beta_point=point, beta_point_label=label)

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
    def xi_symbols(self) -> tuple[Any, ...]:
        """Symbols :math:`\\xi_1..\\xi_\\rho` for expressions in the normal-form coordinates."""
        return tuple(sp.Symbol(f"xi_{i}", real=True) for i in range(1, self.rho + 1))

    @cached_property
    def inverse(self) -> tuple[tuple[Any, ...] | None, str]:
        r"""The coordinate change back, :math:`x = \Phi^{-1}(\xi)`, where ρ = n.

        Returns ``(x_of_xi, note)``: the n state expressions in :attr:`xi_symbols` (None
        when there is none, with the reason in ``note``).  Found by elimination
        (:func:`invert_coordinates`); a model-assisted observer
        (:mod:`aiofl.components.observers`, ``eso.model = "nominal"``) evaluates the
        nominal :math:`\alpha, \beta` at :math:`\hat x = \Phi^{-1}(\hat\xi)`.
        """
        if self.rho != self.plant.n:
            return None, (
                f"ρ = {self.rho} < n = {self.plant.n}: the observer's estimate of "
                f"(y, ..., y^(ρ-1)) does not determine the state (internal dynamics)"
            )
        return invert_coordinates(self.xi, self.plant.states, self.xi_symbols, _tidy)

    @cached_property
    def alpha_beta_of_xi(self) -> tuple[Any, Any] | None:
        r""":math:`(\alpha(\Phi^{-1}(\xi)), \beta(\Phi^{-1}(\xi)))`: the normal form
        :math:`y^{(\rho)} = \alpha + \beta u` in its own coordinates (None without
        :attr:`inverse`)."""
        x_of_xi, _ = self.inverse
        if x_of_xi is None:
            return None
        sub = dict(zip(self.plant.states, x_of_xi, strict=True))
        return _tidy(self.alpha.subs(sub)), _tidy(self.beta.subs(sub))

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


def _is_zero(expr: Any, plant: SymbolicModel, what: str = "an expression") -> bool:
    """Whether ``expr`` vanishes identically in x at the nominal parameters (symbolically
    while it is small, else numerically)."""
    e = _tidy(expr, what)
    if e == 0:
        return True
    e_nom = e.subs(plant.nominal)
    if not _small(e_nom):
        return e_nom == 0 or (
            not e_nom.has(sp.zoo, sp.nan, sp.oo, -sp.oo)
            and vanishes_numerically(e_nom, [s for s in plant.states if s in e_nom.free_symbols])
        )
    e_nom = sp.simplify(e_nom)
    if e_nom == 0:
        return True
    if e_nom.free_symbols:
        return bool(e_nom.equals(0))
    return False


def analyze(plant: SymbolicModel) -> Analysis:
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
    where = f"plant {plant.name!r}:"
    for k in range(plant.n):
        lgk = _tidy(lie_derivative(lf[k], g, states), f"{where} L_g L_f^{k} h")
        if _is_zero(lgk, plant, f"{where} L_g L_f^{k} h"):
            lg.append(sp.S.Zero)
            lf.append(_tidy(lie_derivative(lf[k], f, states), f"{where} L_f^{k + 1} h"))
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
        lf.append(_tidy(lie_derivative(lf[rho - 1], f, states), f"{where} L_f^{rho} h"))
    beta = lg[rho - 1]
    sset = set(states)
    beta_constant = not (beta.free_symbols & sset)
    beta_nominal = _beta_nominal(plant, beta) if beta_constant else None
    zeros: tuple[Any, ...] = ()
    undefined: tuple[Any, ...] = ()
    if not beta_constant and _small(beta):
        num, den = sp.fraction(sp.together(beta))
        zeros, undefined = _state_factors(num, sset), _state_factors(den, sset)
    zd: ZeroDynamics | None = None
    if rho == plant.n:
        note = "none: ρ = n, there are no internal dynamics"
    else:
        try:
            zd = _zero_dynamics(plant, tuple(lf[:rho]), rho, beta)
            note = f"{zd.verdict} (eigenvalues of the linearised zero dynamics at x_e)"
        except ZeroDynamicsError as exc:
            note = str(exc)
    out = Analysis(
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
    if plant.equilibrium is not None:  # a state-dependent β at the declared operating point
        out = out.at_point(plant.equilibrium, "x_e, the plant's equilibrium")
    return out


def _state_factors(expr: Any, sset: set[Any]) -> tuple[Any, ...]:
    """The factors of ``expr`` that depend on the state (``expr`` itself when sympy cannot
    factor it, e.g. ``x**x``, where ``factor_list`` raises)."""
    try:
        factors = [fc for fc, _ in sp.factor_list(expr)[1]]
    except (TypeError, ValueError, sp.PolynomialError):
        factors = [expr]
    return tuple(fc for fc in factors if fc.free_symbols & sset)


def _beta_nominal(plant: SymbolicModel, beta: Any) -> float:
    """A constant β at the nominal parameters; refused when it is not a finite real number
    (e.g. ``1/b`` with ``b = 0``)."""
    val = beta.subs(plant.nominal)
    try:
        out = float(val)
    except (TypeError, ValueError, OverflowError):
        out = math.nan
    if not math.isfinite(out):
        raise SymbolicPlantError(
            f"plant {plant.name!r}: β = L_g L_f^(ρ-1) h = {sp.sstr(beta)[:80]} is {sp.sstr(val)} "
            "at the nominal parameters, not a finite number (a division by zero or an "
            "overflow in params?); allowed: a finite β"
        )
    return out


def _internal_coordinates(plant: SymbolicModel, xi: tuple[Any, ...], rho: int) -> tuple[Any, str]:
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
            what = f"plant {plant.name!r}: ∂φ/∂x·g of eta[{i}]"
            if not _is_zero(lgphi, plant, what):
                shown = sp.sstr(_tidy(lgphi, what))
                raise ZeroDynamicsError(
                    f"plant {plant.name!r}: eta[{i}] = {sp.sstr(e)[:60]} has ∂φ/∂x·g = "
                    f"{shown[:80]} ≠ 0; eq. (3) needs it to vanish"
                )
        return eta, "given in the model"
    # g(x) = γ(x)·c with a constant direction c: φ = w·x for w in the left null space of c
    k = next(i for i, gi in enumerate(g) if not _is_zero(gi, plant))
    direction = sp.Matrix([_tidy(gi / g[k], f"plant {plant.name!r}: g/g_{k + 1}") for gi in g])
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
    point = dict(zip(states, x0, strict=True))
    at_x0 = sp.Matrix(xi).jacobian(states).subs(plant.nominal).subs(point)
    dxi = _real_array(at_x0, plant, "the Jacobian of ξ at a generic point").reshape(rho, plant.n)
    rows = list(dxi)
    chosen: list[Any] = []
    for w in basis:
        wv = _real_array(w.subs(plant.nominal), plant, "a left null vector of g").ravel()
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


def _real_array(values: Any, plant: SymbolicModel, what: str) -> NDArray[np.float64]:
    """``values`` (sympy numbers) as a float array; ZeroDynamicsError if one is not a finite
    real number (e.g. ``sqrt(x1 - 1)`` at a point with x1 < 1, or a parameter of 0)."""
    try:
        arr = np.array(values, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        arr = np.array([np.nan])
    if not np.all(np.isfinite(arr)):
        raise ZeroDynamicsError(
            f"plant {plant.name!r}: {what} is not finite and real at the nominal parameters; "
            "give eta = [...] and equilibrium = [...] in the model"
        )
    return arr


def _equilibrium_guess(plant: SymbolicModel) -> tuple[float, ...]:
    return plant.equilibrium if plant.equilibrium is not None else (0.0,) * plant.n


def _beta_vanishes_at(plant: SymbolicModel, beta: Any, x_e: NDArray[np.float64]) -> float | None:
    """β(x_e) if it is 0 or undefined there (relative to its size at a generic point), else None."""
    fn = plant.numeric([beta])
    x_gen = np.random.default_rng(0).uniform(0.3, 0.9, plant.n)
    with np.errstate(all="ignore"):
        b_e = float(np.asarray(fn(x_e), dtype=np.float64).ravel()[0])
        b_gen = float(np.asarray(fn(x_gen), dtype=np.float64).ravel()[0])
    size = abs(b_gen) if np.isfinite(b_gen) else 1.0
    if not np.isfinite(b_e) or abs(b_e) <= 1e-12 * max(size, 1e-300):
        return b_e
    return None


def _zero_dynamics(
    plant: SymbolicModel, xi: tuple[Any, ...], rho: int, beta: Any = None
) -> ZeroDynamics:
    from scipy.optimize import root

    states, n, m = plant.states, plant.n, plant.n - rho
    eta, method = _internal_coordinates(plant, xi, rho)
    eta_dot = tuple(
        _tidy(lie_derivative(e, list(plant.f), states), f"plant {plant.name!r}: η̇_{i}")
        for i, e in enumerate(eta, 1)
    )
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
    b_e = None if beta is None else _beta_vanishes_at(plant, beta, x_e)
    if b_e is not None:
        raise ZeroDynamicsError(
            f"plant {plant.name!r}: β(x_e) = {b_e:g} at the zero-dynamics equilibrium x_e = "
            f"{x_e.tolist()}: ρ is not defined at x_e; no verdict"
        )
    tmap = sp.Matrix([*eta, *xi])
    jt = plant.numeric(list(tmap.jacobian(states)))(x_e).reshape(n, n)
    if not np.all(np.isfinite(jt)):
        raise ZeroDynamicsError(
            f"plant {plant.name!r}: the Jacobian of (η, ξ) is not finite at x_e = "
            f"{x_e.tolist()} (nominal parameters); no zero-dynamics verdict"
        )
    if np.linalg.matrix_rank(jt, tol=1e-10) < n:
        raise ZeroDynamicsError(
            f"plant {plant.name!r}: (η, ξ) is not a coordinate change at x_e = {x_e.tolist()} "
            "(singular Jacobian); give other eta = [...]"
        )
    jq = plant.numeric(list(sp.Matrix(eta_dot).jacobian(states)))(x_e).reshape(m, n)
    jac = jq @ np.linalg.inv(jt)[:, :m]
    if not np.all(np.isfinite(jac)):
        raise ZeroDynamicsError(
            f"plant {plant.name!r}: the linearised zero dynamics ∂f0/∂η are not finite at "
            f"x_e = {x_e.tolist()} (nominal parameters); no zero-dynamics verdict"
        )
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
    """f0(η, 0) when z = T(x) is linear in x (solve T(x) = (η, 0) for x); else None (also
    for n > 8 or when an η̇ is too large to simplify: symbolic LU grows quickly)."""
    if len(states) > _INVERT_MAX_N or not all(_small(e) for e in eta_dot):
        return None
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
