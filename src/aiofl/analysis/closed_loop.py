r"""The whole closed loop (plant + TD + ESO + SEF + law) as a Python right-hand side.

:class:`ClosedLoop` evaluates :math:`F(z; r, \tau_d, n)`, the ODE the engine integrates
(:mod:`aiofl.engine.kernel`), from the same component functions the kernel calls, so
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
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from aiofl.components.differentiators import han_td_rhs, improved_td_rhs, linear_prefilter_rhs
from aiofl.components.feedback import fal, inlsef_limit, inlsef_term, linear_sef_gains
from aiofl.components.observers import eso_gains, inleso_injection
from aiofl.controller import Controller
from aiofl.plants.base import Plant
from aiofl.scenario import Reference, Scenario

__all__ = ["DEFAULT_AMPLITUDE", "ClosedLoop", "reference_operating_value"]

DEFAULT_AMPLITUDE = 1e-3
"""Default error amplitude ε for the secant gains of the non-smooth nonlinearities."""


def reference_operating_value(ref: Reference) -> float:
    """The constant :math:`r^*` the loop is linearised at (sine offset, step final value)."""
    if ref.kind == "sine":
        return float(ref.offset)
    if ref.kind == "step":
        return float(ref.offset + ref.amplitude)
    return float(ref.samples[-1])


class ClosedLoop:
    r"""Python right-hand side :math:`F(z; r, \tau_d, n)` of one closed loop.

    The same equations as the engine's kernel (:mod:`aiofl.engine.kernel`): TD (18)/(21)/linear,
    ESO (5)/(16)/(19), SEF (17)/(20)/linear, law (14) or classical IOFL.

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
        alphas = [c.value(f"eso.alpha{i}") for i in range(1, c.rho + 2)]
        self.betas = eso_gains(c.value("eso.omega0"), alphas)
        wc = c.value("sef.omega_c")
        if c.sef == "linear" or c.law == "iofl":
            self.lin_k = linear_sef_gains(c.rho, wc)
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
        self.r_op = reference_operating_value(scenario.reference)
        self.d_op = float(scenario.disturbance_amplitude)

    # ---------------------------------------------------------------- pieces
    def _sef(self, e: NDArray[np.float64], rff: float) -> float:
        c, m = self.controller, self.m
        if c.sef == "linear":
            return (rff + float(np.dot(self.lin_k[:m], e[:m]))) / self.b0
        if self.mode == "linearise":
            return float(np.dot(self.k_sef, e[:m]))
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

    def _injection(self, e: float) -> float:
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

    def rhs(
        self,
        z: NDArray[np.float64],
        rd: Sequence[float] | None = None,
        d: float | None = None,
        noise: float = 0.0,
    ) -> tuple[NDArray[np.float64], float, float]:
        r""":math:`(\dot z, y, u)` at state z.

        Parameters
        ----------
        z
            State (layout of :attr:`state_names`).
        rd
            :math:`(r, \dot r, \dots, r^{(\rho)})`; default the operating point
            :math:`(r^*, 0, \dots)`.
        d
            Disturbance :math:`\tau_d` (default: its operating value).
        noise
            Measurement noise added to y for the ESO.
        """
        c, rho, m, n = self.controller, self.rho, self.m, self.n
        z = np.asarray(z, dtype=np.float64)
        rdv = np.zeros(rho + 1)
        if rd is None:
            rdv[0] = self.r_op
        else:
            k = min(len(rd), rho + 1)
            rdv[:k] = np.asarray(rd, dtype=np.float64)[:k]
        d = self.d_op if d is None else float(d)
        x = z[:n]
        td = z[self.o_td : self.o_td + self.n_td]
        xi = z[self.o_eso : self.o_eso + rho + 1]
        dz = np.zeros(self.n_z)
        r = rdv[0]
        rff = 0.0
        prof = np.zeros(rho)
        if c.td == "exact":
            prof[:] = rdv[:rho]
            rff = rdv[rho]
        elif c.td == "han":
            if self.n_td:
                dz[self.o_td], dz[self.o_td + 1] = han_td_rhs(td[0], td[1], r, c.value("td.R"))
                prof[:2] = td[:2]
            else:
                prof[0] = r
        elif c.td == "improved":
            a, b, cc, rr = (c.value(k) for k in ("td.a", "td.b", "td.c", "td.rho"))
            dz[self.o_td], dz[self.o_td + 1] = improved_td_rhs(td[0], td[1], r, a, b, cc, rr)
            prof[:2] = td[:2]
        else:
            d_td = dz[self.o_td : self.o_td + rho]  # a view: the prefilter writes into dz
            rff = linear_prefilter_rhs(td[:rho], d_td, rho, r, c.value("td.omega"))
            prof[:] = td[:rho]
        p_true = self.p_true
        y = float(np.asarray(self.plant.h(x, p_true), dtype=np.float64).reshape(()))
        if c.law == "aiofl":
            e = prof[:m] - xi[:m]
            u = self._sef(e, rff) - xi[rho] / self.b0
        else:
            nfx = np.asarray(self.plant.normal_form(x, self.p_nom), dtype=np.float64)  # type: ignore[misc]
            acc = rff + float(np.dot(self.lin_k[:m], prof[:m] - nfx[:m]))
            u = (-nfx[rho] + acc) / nfx[rho + 1]
        u = min(max(u, -self.u_max), self.u_max)
        inj = self._injection(y + noise - xi[0])
        o = self.o_eso
        dz[o : o + rho] = xi[1 : rho + 1] + self.betas[:rho] * inj
        dz[o + rho - 1] += self.b0 * u
        dz[o + rho] = self.betas[rho] * inj
        fx = np.asarray(self.plant.f(x, p_true), dtype=np.float64)
        gx = np.asarray(self.plant.g(x, p_true), dtype=np.float64)
        dz[:n] = fx + gx * u
        if d != 0.0 and self.plant.bd is not None:
            dz[:n] += np.asarray(self.plant.bd(x, p_true), dtype=np.float64) * d
        return dz, y, u

    def initial_guess(self) -> NDArray[np.float64]:
        """A starting point for the operating-point search (plant at x0, TD settled)."""
        z = np.zeros(self.n_z)
        x0 = np.array(self.scenario.x0 or [0.0] * self.n, dtype=np.float64)
        # move x0 onto the output level h(x) = r* (Gauss-Newton steps along ∇h)
        for _ in range(20):
            hx = float(np.asarray(self.plant.h(x0, self.p_true)).reshape(()))
            if abs(hx - self.r_op) < 1e-12 * (1.0 + abs(self.r_op)):
                break
            grad = np.array(
                [
                    (
                        float(np.asarray(self.plant.h(x0 + dx, self.p_true)).reshape(()))
                        - float(np.asarray(self.plant.h(x0 - dx, self.p_true)).reshape(()))
                    )
                    / 2e-6
                    for dx in np.eye(self.n) * 1e-6
                ]
            )
            if not np.any(grad):
                break
            x0 = x0 + (self.r_op - hx) * grad / float(grad @ grad)
        z[: self.n] = x0
        c, r = self.controller, self.r_op
        if c.td == "improved":
            z[self.o_td] = (1.0 - c.value("td.a")) * r / c.value("td.b")
        elif self.n_td:
            z[self.o_td] = r
        z[self.o_eso] = float(np.asarray(self.plant.h(x0, self.p_true)).reshape(()))
        return z

    def jacobian(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """:math:`\\partial F/\\partial z` at z by central differences."""
        cols = []
        for j in range(self.n_z):
            h = 1e-6 * max(1.0, abs(z[j]))
            zp, zm = z.copy(), z.copy()
            zp[j] += h
            zm[j] -= h
            cols.append((self.rhs(zp)[0] - self.rhs(zm)[0]) / (2.0 * h))
        return np.column_stack(cols)

    def operating_point(self, z0: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """Solve :math:`F(z^*) = 0` (Newton with backtracking from :meth:`initial_guess`).

        Raises
        ------
        ValueError
            When no equilibrium is found.
        """
        z = self.initial_guess() if z0 is None else np.asarray(z0, dtype=np.float64).copy()

        def res_norm(zz: NDArray[np.float64]) -> float:
            return float(np.linalg.norm(self.rhs(zz)[0]))

        fz = res_norm(z)
        for _ in range(60):
            if fz < 1e-10 * (1.0 + float(np.linalg.norm(z))):
                return z
            jac = self.jacobian(z)
            try:
                step = np.linalg.lstsq(jac, -self.rhs(z)[0], rcond=None)[0]
            except np.linalg.LinAlgError:
                break
            lam = 1.0
            while lam > 1e-6:
                zn = z + lam * step
                fn = res_norm(zn)
                if np.isfinite(fn) and fn < fz:
                    break
                lam *= 0.5
            else:
                break
            z, fz = zn, fn
        if fz < 1e-7 * (1.0 + float(np.linalg.norm(z))):
            return z
        raise ValueError(
            f"no closed-loop operating point found with r held at {self.r_op:g} "
            f"(residual {fz:.3g}); the loop may have no equilibrium there"
        )
