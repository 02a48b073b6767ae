r"""The whole closed loop (plant + TD + ESO + SEF + law) as a Python right-hand side.

:class:`ClosedLoop` evaluates :math:`F(z; r, \tau_d, n)`, the ODE the engine integrates
(:mod:`aiofl.engine.kernel.continuous`), from the same component functions the kernel calls, so
each formula is written once; the tests check it against the engine.  In ``"linearise"``
mode it is the loop :mod:`aiofl.analysis.linearize` differentiates.

Defaults and non-smooth elements (how each is handled)
-------------------------------------------------------
* Operating point: :math:`r^*` = the sine's offset, the step's final value, or the last
  sample; :math:`\tau_d` at its final value; the true plant with the scenario's parameter
  changes (the controller keeps the nominal model); measurement noise 0.  At the operating
  point every error fed to a nonlinearity is 0 (ESO innovation, SEF errors).
* fal (17), the INLESO injection g(e) (19) and the INLSEF terms (20) are odd functions of
  an error that vanishes at :math:`z^*`.  Each is replaced by its *equivalent (secant)
  gain* :math:`N(\varepsilon) = \phi(\varepsilon)/\varepsilon` at an error amplitude ε
  (default :data:`DEFAULT_AMPLITUDE`).  For fal with ε ≤ δ this is exactly its slope
  :math:`\delta^{\alpha-1}` at 0.  For :math:`|e|^a\operatorname{sign}(e)` with a < 1 the
  slope at 0 is infinite and the secant :math:`\varepsilon^{a-1}` depends on ε, so the
  verdict is also given over a range of ε (``verdicts_by_amplitude``); for a > 1 it tends
  to the slope 0.  The tanh of eq. (20) and of the ITD (21) is smooth (slope 1 / exact).
* Han's TD (18) is a time-optimal bang-bang system, not linearisable (sign at 0).  Like
  every TD it is driven by r alone (no feedback from the loop), so the loop is a cascade
  and its stability does not depend on the TD; Han's TD is left out of the state and its
  outputs are held at :math:`(r^*, 0)`.  The smooth ITD (21) and linear prefilter are
  linearised with the loop (their poles appear among the eigenvalues).
* Under the IOFL law the ESO is integrated by the engine but not used: its poles appear
  among the eigenvalues without interacting with the loop.

Exact derivatives and the operating point
-----------------------------------------
In ``"linearise"`` mode the right-hand side is complex-safe: the secant gains are numbers
computed once at the real amplitude ε, the saturation chooses its branch by the real part,
the ITD's tanh is :func:`numpy.tanh`, and the plant's functions are evaluated through
:class:`aiofl.analysis.derivatives.PlantDerivatives`.  :meth:`ClosedLoop.linear_model`
then takes every Jacobian by the complex step (exact to rounding, so a repeated pole stays
repeated).  :meth:`ClosedLoop.operating_point` solves :math:`F(z^*) = 0` with
:func:`scipy.optimize.root` on a scaled problem with that exact Jacobian.

The loop can also be *broken at the plant input* (``u_plant``): the plant is driven by an
external input while the controller's own output u (which its ESO also sees) is returned;
:mod:`aiofl.analysis.frequency` takes its gain, phase and delay margins.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.analysis.compiled_loop import CompiledLoop
from aiofl.analysis.derivatives import COMPLEX_STEP, PlantDerivatives
from aiofl.components.differentiators import (
    han_td_rhs,
    improved_td_constants,
    improved_td_rhs,
    linear_prefilter_coefficients,
    linear_prefilter_rhs,
    linear_prefilter_update,
)
from aiofl.components.fastmath import binomial_power
from aiofl.components.feedback import fal, inlsef_limit, inlsef_term
from aiofl.components.model_gains import design_point_jacobian, model_gain
from aiofl.components.observers import eso_gain, inleso_injection
from aiofl.controller import Controller
from aiofl.plants.base import Plant
from aiofl.scenario import Reference, Scenario

__all__ = [
    "DEFAULT_AMPLITUDE",
    "OPERATING_POINT_RTOL",
    "ClosedLoop",
    "reference_operating_value",
]

DEFAULT_AMPLITUDE = 1e-3
"""Default error amplitude ε for the secant gains of the non-smooth nonlinearities."""

OPERATING_POINT_RTOL = 1e-9
r"""An operating point is accepted when every equation's residual is at most this times the
size of its terms, :math:`|F_i(z)| \le 10^{-9} \sum_j |J_{ij}|\,\max(|z_j|, s_j) + 10^{-12}`
(s: the typical magnitudes of the scaled solve)."""


def is_complex(v: Any) -> bool:
    """Whether v (a number, an array or a sequence of numbers) is complex: numpy's
    ``iscomplexobj`` without converting an array or a number."""
    if isinstance(v, complex | np.ndarray | np.generic):
        return isinstance(v, complex) or v.dtype.kind == "c"
    if isinstance(v, list | tuple):
        return any(is_complex(item) for item in v)
    return False


def _dot(k: NDArray[np.float64], v: NDArray[Any]) -> Any:
    """``numpy.dot(k, v)`` of a vector v, or of each column of a batch v (one dot of a
    contiguous copy per column: the summation order, hence the last bit, of one state's)."""
    if v.ndim == 1:
        return np.dot(k, v)
    return np.array([np.dot(k, col) for col in np.ascontiguousarray(v.T)])


def reference_operating_value(ref: Reference) -> float:
    """The constant :math:`r^*` the loop is linearised at (sine offset, step final value)."""
    if ref.kind == "sine":
        return float(ref.offset)
    if ref.kind == "step":
        return float(ref.offset + ref.amplitude)
    return float(ref.samples[-1])


class ClosedLoop:
    r"""Python right-hand side :math:`F(z; r, \tau_d, n)` of one closed loop.

    The same equations as the engine's kernel (:mod:`aiofl.engine.kernel.continuous`): TD
    (18)/(21)/linear, ESO (5)/(16)/(19), SEF (17)/(20)/linear, law (14) or classical IOFL.

    Parameters
    ----------
    plant, controller, scenario
        The loop; the plant runs with the scenario's changed parameters, the IOFL law with
        the nominal ones.
    mode
        ``"linearise"``: non-smooth scalar functions replaced by their secant gains at
        ``amplitude`` and Han's TD left out of the state (see the module docstring);
        ``"exact"``: the engine's functions, Han's TD included (for cross-checks).
    amplitude
        Error amplitude ε of the secant gains.

    Attributes
    ----------
    state_names
        Names of the entries of z: ``x1..`` (plant), ``td.r1..`` (TD, if in the state),
        ``eso.xi_hat1..xi_hat{ρ+1}``.
    """

    def __init__(
        self,
        plant: Plant,
        controller: Controller,
        scenario: Scenario,
        *,
        mode: str = "linearise",
        amplitude: float = DEFAULT_AMPLITUDE,
    ) -> None:
        if mode not in ("linearise", "exact"):
            raise ValueError(f"mode = {mode!r}; allowed: linearise, exact")
        if not amplitude > 0:
            raise ValueError(f"amplitude = {amplitude}; allowed: > 0")
        c = controller
        self.plant, self.controller, self.scenario = plant, c, scenario
        self.mode, self.amplitude = mode, float(amplitude)
        self.rho, self.m = c.rho, c.n_feedback
        if c.eso_model == "nominal":
            c.check_plant(plant, scenario.x0 or None)  # it has (α, β)(Φ⁻¹(ξ)), ρ = n
        if c.law == "iofl" and plant.normal_form is None:
            raise ValueError(f"the IOFL law needs plant {plant.name!r}'s normal form; it has none")
        if c.law == "iofl" and plant.relative_degree not in (None, c.rho):
            raise ValueError(
                f"controller.rho = {c.rho} but plant {plant.name!r} has relative degree "
                f"{plant.relative_degree}; the IOFL normal form needs them equal"
            )
        self.p_true = plant.param_vector(scenario.plant_overrides, scenario.plant_scale)
        self.p_nom = plant.param_vector()
        self.b0 = c.value("law.b0")
        self.u_max = c.value("law.u_max")
        u_min = c.value("law.u_min") if "law.u_min" in L.FLOAT_COLUMNS else math.nan
        self.u_min = -self.u_max if math.isnan(u_min) else u_min
        self.derivatives = PlantDerivatives(plant)
        alphas = [c.value(f"eso.alpha{i}") for i in range(1, c.rho + 2)]
        # the components' formulas run in Python (compiling them cost 1-4 s per process)
        w0 = c.value("eso.omega0")
        self.betas = np.array([eso_gain.py_func(a, w0, i + 1) for i, a in enumerate(alphas)])
        if c.eso_model == "nominal" and c.eso_gains == "bandwidth":
            # the engine's gains: placed for the nominal model at Φ(x0) (model_gains)
            x0 = np.asarray(scenario.x0 or np.zeros(plant.n_states), dtype=np.float64)
            xi0 = np.asarray(plant.normal_form(x0, self.p_nom), dtype=np.float64)[: c.rho]  # type: ignore[misc]
            jac = design_point_jacobian(plant.alpha_beta_of_xi, xi0, self.p_nom)
            self.betas = model_gain(jac, alphas, c.value("eso.omega0"))
        wc = c.value("sef.omega_c")
        if c.sef == "linear" or c.law == "iofl":
            self.lin_k = np.array([binomial_power.py_func(c.rho, i, wc) for i in range(c.rho)])
        else:
            self.lin_k = np.array([c.value(f"sef.k{i}") for i in range(1, c.rho + 1)])
        n = plant.n_states
        if c.td == "improved" or (c.td == "han" and mode == "exact"):
            n_td = 2
        elif c.td == "linear":
            n_td = c.rho
        else:
            n_td = 0
        self.n, self.n_td = n, n_td
        self.o_td, self.o_eso = n, n + n_td
        self.n_z = n + n_td + c.rho + 1
        self.state_names = (
            tuple(plant.state_names)
            + tuple(f"td.r{i}" for i in range(1, n_td + 1))
            + tuple(f"eso.xi_hat{i}" for i in range(1, c.rho + 2))
        )
        # equivalent gains of the non-smooth functions (linearise mode)
        eps = self.amplitude
        self.nonsmooth: list[str] = []
        if c.eso == "improved":
            ka, kb, ga, gb = (
                c.value(k) for k in ("eso.k_alpha", "eso.k_beta", "eso.g_alpha", "eso.g_beta")
            )
            self.k_inj = inleso_injection(eps, ka, kb, ga, gb) / eps
            self.nonsmooth.append(
                f"INLESO g(e) (19): secant gain {self.k_inj:.6g} at ε = {eps:g} "
                f"(exponent {ga:g}{' < 1: infinite slope at 0' if ga < 1 else ''})"
            )
        if c.law == "aiofl" and c.sef == "nonlinear":
            self.k_sef = np.array(
                [
                    c.value(f"sef.k{i}")
                    * fal(eps, c.value(f"sef.alpha{i}"), c.value(f"sef.delta{i}"))
                    / eps
                    for i in range(1, self.m + 1)
                ]
            )
            self.nonsmooth.append(
                "fal (17): secant gains k_i·fal(ε)/ε = "
                + ", ".join(f"{k:.6g}" for k in self.k_sef)
                + f" (= slope δ^(α−1) at 0 where ε ≤ δ; ε = {eps:g})"
            )
        elif c.law == "aiofl" and c.sef == "improved":
            self.k_sef = np.array(
                [
                    inlsef_term(
                        eps,
                        c.value(f"sef.k{i}"),
                        c.value(f"sef.kb{i}"),
                        c.value(f"sef.mu{i}"),
                        c.value(f"sef.alpha{i}"),
                    )
                    / eps
                    for i in range(1, self.m + 1)
                ]
            )
            self.nonsmooth.append(
                "INLSEF terms (20): secant gains "
                + ", ".join(f"{k:.6g}" for k in self.k_sef)
                + f" at ε = {eps:g}; tanh slope 1 at 0"
            )
        if c.td == "han":
            self.nonsmooth.append(
                "Han TD (18): bang-bang (sign), not linearisable; driven by r only (a cascade), "
                "left out of the state with outputs held at (r*, 0)"
                if mode == "linearise"
                else "Han TD (18) integrated exactly"
            )
        if c.td == "improved":
            self.itd_constants = improved_td_constants(
                c.value("td.a"), c.value("td.b"), c.value("td.c")
            )
            self.itd_rho = c.value("td.rho")
        if c.td == "linear":
            self.prefilter = linear_prefilter_coefficients(c.rho, c.value("td.omega"))
        self.r_op = reference_operating_value(scenario.reference)
        self.d_op = float(scenario.disturbance_amplitude)
        self.n_ref = c.rho + 1 if c.td == "exact" else 1
        # inputs of linear_model: r, with the exact TD its derivatives r^(1)..r^(ρ)
        # (r_d1..), the disturbance d and the measurement noise n
        self.input_names = ("r", *(f"r_d{k}" for k in range(1, self.n_ref)), "d", "n")

    # ---------------------------------------------------------------- pieces
    def _sef(self, e: NDArray[Any], rff: Any) -> Any:
        c, m = self.controller, self.m
        if c.sef == "linear":
            return (rff + _dot(self.lin_k[:m], e[:m])) / self.b0
        if self.mode == "linearise":
            return _dot(self.k_sef, e[:m])
        if c.sef == "nonlinear":
            return sum(
                c.value(f"sef.k{i + 1}")
                * fal(e[i], c.value(f"sef.alpha{i + 1}"), c.value(f"sef.delta{i + 1}"))
                for i in range(m)
            )
        s = sum(
            inlsef_term(
                e[i],
                c.value(f"sef.k{i + 1}"),
                c.value(f"sef.kb{i + 1}"),
                c.value(f"sef.mu{i + 1}"),
                c.value(f"sef.alpha{i + 1}"),
            )
            for i in range(m)
        )
        dl = c.value("sef.v_limit")
        return inlsef_limit(s, dl)

    def _injection(self, e: Any) -> Any:
        c = self.controller
        if c.eso == "linear":
            return e
        if self.mode == "linearise":
            return self.k_inj * e
        return inleso_injection(
            e,
            c.value("eso.k_alpha"),
            c.value("eso.k_beta"),
            c.value("eso.g_alpha"),
            c.value("eso.g_beta"),
        )

    def _saturate(self, u: Any) -> Any:
        """The actuator range :math:`[u_{min}, u_{max}]`, branch chosen by the real part
        (slope 1 inside, 0 at a limit; the engine's ``saturate_range``), per column of a
        batch."""
        if isinstance(u, np.ndarray) and u.ndim:
            inside = np.where(u.real < self.u_min, self.u_min, u)
            return np.where(u.real > self.u_max, self.u_max, inside)
        if u.real > self.u_max:
            return self.u_max
        if u.real < self.u_min:
            return self.u_min
        return u

    def _plant(self, name: str, x: NDArray[Any], p: NDArray[np.float64]) -> NDArray[Any]:
        if self.mode == "exact":
            return np.asarray(getattr(self.plant, name)(x, p), dtype=np.float64).reshape(-1)
        return self.derivatives.evaluate(name, x, p)

    def rhs(
        self,
        z: NDArray[Any],
        rd: Sequence[Any] | NDArray[Any] | None = None,
        d: Any = None,
        noise: Any = 0.0,
        u_plant: Any = None,
    ) -> tuple[NDArray[Any], Any, Any]:
        r""":math:`(\dot z, y, u)` at state z, or at each column of a batch of states.

        Parameters
        ----------
        z
            State (layout of :attr:`state_names`); complex in ``"linearise"`` mode for the
            complex step.  In ``"linearise"`` mode z may be a batch of K states, shape
            (n_z, K): every operation acts along the trailing axis and column k of
            :math:`\dot z` (and entry k of y, u) is the right-hand side at column k, the
            plant's functions on a tangent batch (columns :math:`z + ihe_j`) evaluated by
            :meth:`aiofl.analysis.derivatives.PlantDerivatives.evaluate_columns`.
        rd
            :math:`(r, \dot r, \dots, r^{(\rho)})`; default the operating point
            :math:`(r^*, 0, \dots)`.  With a batch: shape (ρ+1,) (shared) or (ρ+1, K).
        d
            Disturbance :math:`\tau_d` (default: its operating value); scalar or shape (K,).
        noise
            Measurement noise added to y for the ESO; scalar or shape (K,).
        u_plant
            If given, the loop is broken at the plant input: the plant is driven by
            ``u_plant`` and the returned u is the controller's output (which its ESO uses).
        """
        c, rho, m, n = self.controller, self.rho, self.m, self.n
        cplx = (
            is_complex(z)
            or (rd is not None and is_complex(rd))
            or is_complex(d)
            or is_complex(noise)
            or is_complex(u_plant)
        )
        if cplx and self.mode == "exact":
            raise ValueError("complex arguments need mode = 'linearise'")
        dtype = np.complex128 if cplx else np.float64
        z = np.asarray(z, dtype=dtype)
        batch = z.shape[1:]  # () for one state, (K,) for K columns
        if batch and self.mode == "exact":
            raise ValueError("a batch of states needs mode = 'linearise'")
        rdv = np.zeros((rho + 1, *batch), dtype=dtype)
        if rd is None:
            rdv[0] = self.r_op
        else:
            k = min(len(rd), rho + 1)
            rda = np.asarray(rd, dtype=dtype)[:k]
            rdv[:k] = rda[:, None] if batch and rda.ndim == 1 else rda
        d = self.d_op if d is None else d
        x = z[:n]
        td = z[self.o_td : self.o_td + self.n_td]
        xi = z[self.o_eso : self.o_eso + rho + 1]
        dz = np.zeros((self.n_z, *batch), dtype=dtype)
        r = rdv[0]
        rff: Any = 0.0
        prof = np.zeros((rho, *batch), dtype=dtype)
        if c.td == "exact":
            prof[:] = rdv[:rho]
            rff = rdv[rho]
        elif c.td == "han":
            if self.n_td:
                dz[self.o_td], dz[self.o_td + 1] = han_td_rhs(td[0], td[1], r, c.value("td.R"))
                prof[:2] = td[:2]
            else:  # the TD's outputs (r1, r2) given as (r, r') (aiofl.analysis.orbit)
                prof[: min(2, rho)] = rdv[: min(2, rho)]
        elif c.td == "improved":
            if self.mode == "exact":
                a, b, cc, rr = (c.value(k) for k in ("td.a", "td.b", "td.c", "td.rho"))
                dz[self.o_td], dz[self.o_td + 1] = improved_td_rhs(td[0], td[1], r, a, b, cc, rr)
            else:  # eq. (21) with numpy's tanh (the engine's fast_tanh is tanh to 2 ulp)
                b_over_c, gain = self.itd_constants
                rr = self.itd_rho
                dz[self.o_td] = td[1]
                dz[self.o_td + 1] = -rr * rr * np.tanh(b_over_c * td[0] - gain * r) - rr * td[1]
            prof[:2] = td[:2]
        else:
            d_td = dz[self.o_td : self.o_td + rho]  # a view: the prefilter writes into dz
            if self.mode == "exact":
                rff = linear_prefilter_rhs(td[:rho], d_td, rho, r, c.value("td.omega"))
            else:  # the same update in Python, so it runs on complex numbers
                rff = linear_prefilter_update.py_func(td, d_td, 0, rho, r, self.prefilter, 0)
            prof[:] = td[:rho]
        p_true = self.p_true
        need_bd = self.plant.bd is not None and bool(np.any(d != 0.0))
        if batch:  # the plant's functions at x in one tangent-batch evaluation
            names = ("h", "f", "g", "bd") if need_bd else ("h", "f", "g")
            hx, *fgb = self.derivatives.evaluate_columns(names, x, p_true)
        else:
            hx = self._plant("h", x, p_true)
        y = hx[0]
        model = c.law == "aiofl" and c.eso_model == "nominal"
        if model:  # the nominal (α, β) at x̂ = Φ⁻¹(ξ̂), model-assisted law
            a_hat, b_hat = self._plant("alpha_beta_of_xi", xi[:rho], self.p_nom)
            e = prof[:m] - xi[:m]
            u = (self.b0 * self._sef(e, rff) - a_hat - xi[rho]) / b_hat
        elif c.law == "aiofl":
            e = prof[:m] - xi[:m]
            u = self._sef(e, rff) - xi[rho] / self.b0
        else:
            nfx = self._plant("normal_form", x, self.p_nom)
            acc = rff + _dot(self.lin_k[:m], prof[:m] - nfx[:m])
            u = (-nfx[rho] + acc) / nfx[rho + 1]
        u = self._saturate(u)
        inj = self._injection(y + noise - xi[0])
        o = self.o_eso
        betas = self.betas[:, None] if batch else self.betas
        dz[o : o + rho] = xi[1 : rho + 1] + betas[:rho] * inj
        dz[o + rho - 1] += a_hat + b_hat * u if model else self.b0 * u
        dz[o + rho] = betas[rho] * inj
        u_in = u if u_plant is None else u_plant
        if not batch:
            fgb = [self._plant(name, x, p_true) for name in ("f", "g", "bd")[: 3 if need_bd else 2]]
        dz[:n] = fgb[0] + fgb[1] * u_in
        if need_bd:
            dz[:n] += fgb[2] * d
        if not cplx and not batch:
            y, u = float(y), float(u)
        return dz, y, u

    # ------------------------------------------------------------ linear models
    def _inputs_split(self, v: NDArray[Any]) -> tuple[NDArray[Any], Any, Any]:
        nr = self.n_ref
        return v[:nr], v[nr], v[nr + 1]

    def operating_inputs(self) -> NDArray[np.float64]:
        """The inputs at the operating point, in the order of :attr:`input_names`."""
        v = np.zeros(len(self.input_names))
        v[0], v[self.n_ref] = self.r_op, self.d_op
        return v

    NL_MODE = 0
    """How the compiled loop evaluates the non-smooth scalars (:class:`CompiledLoop`)."""

    @functools.cached_property
    def compiled(self) -> CompiledLoop:
        """This loop compiled, with its exact Jacobian (:mod:`aiofl.analysis.loop_kernel`)."""
        if self.mode != "linearise":
            raise ValueError("the compiled loop needs mode = 'linearise'")
        return CompiledLoop(self, nl_mode=self.NL_MODE)

    def linear_model(
        self, z: NDArray[np.float64], *, broken: bool = False
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        r"""Exact Jacobians :math:`(A, B, C, D)` at z by the complex step.

        Closed loop (``broken=False``): :math:`\dot{\delta z} = A\,\delta z + B\,\delta v`,
        :math:`(\delta y, \delta u) = C\,\delta z + D\,\delta v` with v the inputs of
        :attr:`input_names`.  Loop broken at the plant input (``broken=True``): input the
        plant's :math:`u_p` (held at the controller's :math:`u^*`), output the controller's
        u; closing :math:`u_p = u` gives back the closed loop's A
        (:math:`A_{cl} = A + BC` when D = 0).

        By the compiled loop's forward mode (:meth:`CompiledLoop.linear_model`), the plant's
        Jacobians by the complex step (:mod:`aiofl.analysis.derivatives`), checked first.
        """
        if self.mode != "linearise":
            raise ValueError("linear_model needs mode = 'linearise'")
        z = np.asarray(z, dtype=np.float64)
        self.verify_derivatives(z)
        return self.compiled.linear_model(z, broken=broken)

    def verify_derivatives(self, z: NDArray[np.float64]) -> None:
        """Check the plant's complex-step derivatives against finite differences at z's
        plant state (:meth:`aiofl.analysis.derivatives.PlantDerivatives.verify`; with the
        true parameters, and the nominal ones the IOFL law's model runs with): a function
        that fails it is differentiated by finite differences from then on (noted)."""
        x = np.asarray(z, dtype=np.float64)[: self.n]
        self.derivatives.verify(x, self.p_true)
        if self.controller.law == "iofl":
            self.derivatives.verify(x, self.p_nom)

    def tangent_batch(self, z: NDArray[np.float64]) -> NDArray[np.complex128]:
        r"""The n_z complex steps of z as the columns of one batch for :meth:`rhs`:
        :math:`Z_{:,j} = z + ihe_j` (h = :data:`aiofl.analysis.derivatives.COMPLEX_STEP`),
        so that :math:`\operatorname{Im}F(Z)/h` is the Jacobian :math:`\partial F/\partial z`."""
        z = np.asarray(z, dtype=np.float64)
        batch = np.empty((z.size, z.size), dtype=np.complex128)
        batch.real = z[:, None]
        batch.imag = COMPLEX_STEP * np.eye(z.size)
        return batch

    def jacobian(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        r""":math:`A = \partial F/\partial z` at z, compiled (for the operating-point search;
        :meth:`linear_model` also checks the plant's derivatives at z first)."""
        return self.compiled.state_jacobian(np.asarray(z, dtype=np.float64))[1][: self.n_z]

    def _value(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """:math:`F(z)` at the operating inputs: compiled in ``"linearise"`` mode."""
        return self.compiled.rhs(z) if self.mode == "linearise" else self.rhs(z)[0]

    # ----------------------------------------------------------- operating point
    def initial_guess(self) -> NDArray[np.float64]:
        """A starting point for the operating-point search (plant at x0, TD settled)."""
        z = np.zeros(self.n_z)
        x0 = np.array(self.scenario.x0 or [0.0] * self.n, dtype=np.float64)
        # move x0 onto the output level h(x) = r* (Gauss-Newton steps along ∇h)
        for _ in range(20):
            hx = float(self._plant("h", x0, self.p_true)[0])
            if not math.isfinite(hx) or abs(hx - self.r_op) < 1e-12 * (1.0 + abs(self.r_op)):
                break
            grad = np.array(
                [
                    self._plant("h", x0 + 1j * COMPLEX_STEP * e, self.p_true)[0].imag / COMPLEX_STEP
                    for e in np.eye(self.n)
                ]
            )
            if not np.all(np.isfinite(grad)) or not np.any(grad):
                break
            x0 = x0 + (self.r_op - hx) * grad / float(grad @ grad)
        z[: self.n] = x0
        c, r = self.controller, self.r_op
        if c.td == "improved":
            z[self.o_td] = (1.0 - c.value("td.a")) * r / c.value("td.b")
        elif self.n_td:
            z[self.o_td] = r
        z[self.o_eso] = float(self._plant("h", x0, self.p_true)[0])
        return z

    def _residual(self, z: NDArray[np.float64], typical: NDArray[np.float64]) -> float:
        """Largest residual relative to the size of its equation's terms (see
        :data:`OPERATING_POINT_RTOL`); inf where F is not finite."""
        f = self._value(z)
        if not np.all(np.isfinite(f)):
            return math.inf
        terms = np.abs(self.jacobian(z)) @ np.maximum(np.abs(z), typical)
        return float(np.max(np.abs(f) / (OPERATING_POINT_RTOL * terms + 1e-12)))

    def _scaled_solve(self, guess: NDArray[np.float64], method: str) -> NDArray[np.float64]:
        """:func:`scipy.optimize.root` on :math:`G(w) = F(s\\odot w)/t` with s the
        typical magnitudes of the states and t those of the equations."""
        from scipy.optimize import root

        f0, j0 = self._value(guess), self.jacobian(guess)
        try:
            newton = guess - np.linalg.lstsq(j0, f0, rcond=None)[0]
        except np.linalg.LinAlgError:
            newton = guess
        s = np.maximum.reduce([np.abs(guess), np.abs(np.nan_to_num(newton)), np.ones_like(guess)])
        t = np.abs(j0) @ s + np.abs(f0)
        t = np.where(t > 0.0, t, 1.0)

        def fun(w: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
            zz = s * w
            return self._value(zz) / t, self.jacobian(zz) * s[None, :] / t[:, None]

        options = {"xtol": 1e-14} if method == "hybr" else {"xtol": 1e-14, "ftol": 1e-14}
        sol = root(fun, guess / s, jac=True, method=method, options=options)
        self._typical = s
        return np.asarray(sol.x, dtype=np.float64) * s

    def _guesses(self, base: NDArray[np.float64]) -> list[NDArray[np.float64]]:
        """The given start, its Newton step, the plain start (x0, rest 0) and two seeded
        perturbations of it (10 % of the typical magnitudes)."""
        out = [base]
        try:
            step = np.linalg.lstsq(self.jacobian(base), self._value(base), rcond=None)[0]
            out.append(base - step)
        except (np.linalg.LinAlgError, ValueError, ArithmeticError):
            pass
        plain = np.zeros(self.n_z)
        plain[: self.n] = np.array(self.scenario.x0 or [0.0] * self.n, dtype=np.float64)
        out.append(plain)
        rng = np.random.default_rng(0)
        scale = np.maximum(np.abs(base), 1.0)
        out += [base + 0.1 * scale * rng.standard_normal(self.n_z) for _ in range(2)]
        return [g for g in out if np.all(np.isfinite(g))]

    def operating_point(self, z0: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """Solve :math:`F(z^*) = 0` with :func:`scipy.optimize.root` on a scaled problem.

        From :meth:`initial_guess` (or ``z0``), its Newton step and a few nearby starts,
        methods ``hybr`` then ``lm``, each with the exact Jacobian; the first point whose
        residual passes :data:`OPERATING_POINT_RTOL` is returned.

        Raises
        ------
        ValueError
            When no start converges (the loop may have no equilibrium at r*).
        """
        base = self.initial_guess() if z0 is None else np.asarray(z0, dtype=np.float64).copy()
        best, best_res, errors = base, math.inf, []
        for guess in self._guesses(base):
            for method in ("hybr", "lm"):
                try:
                    with np.errstate(all="ignore"):
                        z = self._scaled_solve(guess, method)
                        res = self._residual(z, self._typical)
                except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
                    errors.append(f"{type(exc).__name__}: {exc}")
                    continue
                if res <= 1.0:
                    return z
                if res < best_res:
                    best, best_res = z, res
        detail = (
            f"smallest relative residual {best_res * OPERATING_POINT_RTOL:.3g} at z = "
            f"[{', '.join(f'{v:.4g}' for v in best)}]"
            if math.isfinite(best_res)
            else "every start failed" + (f" ({errors[-1]})" if errors else "")
        )
        raise ValueError(
            f"no closed-loop operating point found with r held at {self.r_op:g}: "
            f"scipy.optimize.root (hybr, lm) from {len(self._guesses(base))} starts did not "
            f"converge; {detail}; the loop may have no equilibrium there"
        )
