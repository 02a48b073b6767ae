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

The plant is read through :class:`SymbolicModel` (its states, parameters, vector fields and
a numeric evaluator), so this module does not import :mod:`aiofl.plants.symbolic`, which
calls it (:meth:`~aiofl.plants.symbolic.SymbolicPlant.analyze`).  The engine plant
compiles ξ, α and β for the IOFL law (:mod:`aiofl.plants.codegen`); the text, LaTeX and JSON
forms of an :class:`Analysis` are :mod:`aiofl.analysis.plant_structure`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Protocol

import numpy as np
import sympy as sp
from numpy.typing import NDArray

from aiofl.plants.expressions import SymbolicPlantError

__all__ = [
    "Analysis",
    "RelativeDegreeError",
    "SymbolicModel",
    "ZeroDynamics",
    "ZeroDynamicsError",
    "analyze",
    "drop_delta",
    "lie_derivative",
]


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


def drop_delta(expr: Any) -> Any:
    """Replace DiracDelta terms (derivatives of sign/abs) by 0: they vanish almost everywhere."""
    if expr.has(sp.DiracDelta):
        expr = expr.replace(lambda e: isinstance(e, sp.DiracDelta), lambda e: sp.S.Zero)
    return expr


def _tidy(expr: Any) -> Any:
    """A compact form of ``expr`` (sympy ``simplify`` unless the expression is large)."""
    expr = drop_delta(sp.sympify(expr))
    if sp.count_ops(expr) > 600:
        return sp.expand(expr)
    return sp.simplify(expr)


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


def _is_zero(expr: Any, plant: SymbolicModel) -> bool:
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


def _equilibrium_guess(plant: SymbolicModel) -> tuple[float, ...]:
    return plant.equilibrium if plant.equilibrium is not None else (0.0,) * plant.n


def _zero_dynamics(plant: SymbolicModel, xi: tuple[Any, ...], rho: int) -> ZeroDynamics:
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
