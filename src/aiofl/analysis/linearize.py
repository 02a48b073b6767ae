r"""Linearisation of the whole closed loop (plant + TD + ESO + SEF + law) and its stability.

The closed loop of :mod:`aiofl.engine.simulation` is an ODE
:math:`\dot z = F(z; r, \tau_d, n)`.  This module writes the same equations in Python
(:class:`ClosedLoop`, checked against the engine in the tests), finds the operating point
:math:`z^*` with the reference held at a constant :math:`r^*` and the disturbance at its final
value, and linearises by central finite differences,

.. math:: A = \frac{\partial F}{\partial z}(z^*),\qquad
          \dot{\delta z} = A\,\delta z + B\,(\delta r, \delta\tau_d, \delta n),\quad
          (\delta y, \delta u) = C\,\delta z + D\,(\delta r, \delta\tau_d, \delta n).

The verdict is *stable* if every eigenvalue of A has a negative real part, *unstable* if
one has a positive real part, *marginal* otherwise (within a relative tolerance).

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
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl.components.differentiators import han_td_rhs, improved_td_rhs, linear_prefilter_rhs
from aiofl.components.feedback import fal, inlsef_limit, inlsef_term, linear_sef_gains
from aiofl.components.observers import eso_error_matrix, eso_gains, inleso_injection
from aiofl.controller import Controller
from aiofl.plants.base import Plant
from aiofl.scenario import Reference, Scenario

__all__ = [
    "DEFAULT_AMPLITUDE",
    "ClosedLoop",
    "Linearization",
    "closed_loop_verdict",
    "eso_statespace",
    "format_linearization_text",
    "linear_eso_statespace",
    "linearize_closed_loop",
]

DEFAULT_AMPLITUDE = 1e-3
"""Default error amplitude ε for the secant gains of the non-smooth nonlinearities."""

SWEEP_AMPLITUDES = (1e-4, 1e-3, 1e-2, 1e-1)
"""Amplitudes for ``verdicts_by_amplitude`` when the verdict may depend on ε."""


def reference_operating_value(ref: Reference) -> float:
    """The constant :math:`r^*` the loop is linearised at (sine offset, step final value)."""
    if ref.kind == "sine":
        return float(ref.offset)
    if ref.kind == "step":
        return float(ref.offset + ref.amplitude)
    return float(ref.samples[-1])


# --------------------------------------------------------------------- closed loop
class ClosedLoop:
    r"""Python right-hand side :math:`F(z; r, \tau_d, n)` of one closed loop.

    The same equations as the engine's kernel (:mod:`aiofl.engine.simulation`): TD (18)/(21)/linear,
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


# ------------------------------------------------------------------ linearisation
@dataclass(frozen=True)
class Linearization:
    """The closed loop linearised at its operating point.

    Attributes
    ----------
    a, b, c, d
        State-space matrices; inputs ``(r, d, n)`` (reference, disturbance, measurement
        noise), outputs ``(y, u)``.
    state_names
        Names of the states (see :class:`ClosedLoop`).
    z_op, r_op, d_op
        Operating point.
    eigenvalues
        Eigenvalues of ``a``, sorted by decreasing real part.
    amplitude
        Error amplitude ε of the secant gains.
    notes
        How each non-smooth element was handled, and other remarks.
    """

    a: NDArray[np.float64]
    b: NDArray[np.float64]
    c: NDArray[np.float64]
    d: NDArray[np.float64]
    state_names: tuple[str, ...]
    z_op: NDArray[np.float64]
    r_op: float
    d_op: float
    eigenvalues: NDArray[np.complex128]
    amplitude: float
    notes: tuple[str, ...]

    input_names = ("r", "d", "n")
    output_names = ("y", "u")

    @property
    def max_real(self) -> float:
        """Largest real part of the eigenvalues."""
        return float(self.eigenvalues.real.max())

    def verdict(self, rtol: float = 1e-6) -> str:
        """``"stable"``, ``"unstable"`` or ``"marginal"`` (|max Re| ≤ rtol·max|λ|)."""
        return _verdict(self.eigenvalues, rtol)

    @property
    def slowest(self) -> complex:
        """The eigenvalue with the largest real part (slowest / least damped mode)."""
        return complex(self.eigenvalues[0])

    @property
    def fastest(self) -> complex:
        """The eigenvalue with the most negative real part."""
        return complex(self.eigenvalues[-1])

    def statespace(self) -> Any:
        """The linearised loop as a ``control.StateSpace`` (python-control)."""
        import control

        return control.ss(
            self.a,
            self.b,
            self.c,
            self.d,
            states=list(self.state_names),
            inputs=list(self.input_names),
            outputs=list(self.output_names),
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (``verdict``, ``eigenvalues`` as [[re, im], ...], ...)."""
        return {
            "verdict": self.verdict(),
            "eigenvalues": [[float(z.real), float(z.imag)] for z in self.eigenvalues],
            "max_real": self.max_real,
            "slowest": [self.slowest.real, self.slowest.imag],
            "fastest": [self.fastest.real, self.fastest.imag],
            "states": list(self.state_names),
            "operating_point": {
                "r": self.r_op,
                "d": self.d_op,
                "z": [float(v) for v in self.z_op],
            },
            "amplitude": self.amplitude,
            "notes": list(self.notes),
        }


def _verdict(eig: NDArray[np.complex128], rtol: float = 1e-6) -> str:
    scale = max(1.0, float(np.max(np.abs(eig))))
    mx = float(eig.real.max())
    if mx < -rtol * scale:
        return "stable"
    if mx > rtol * scale:
        return "unstable"
    return "marginal"


def linearize_closed_loop(
    config: Any = None,
    *,
    plant: Plant | None = None,
    controller: Controller | None = None,
    scenario: Scenario | None = None,
    amplitude: float = DEFAULT_AMPLITUDE,
    r_op: float | None = None,
) -> Linearization:
    r"""Linearise the closed loop of a run config (or plant, controller, scenario).

    Parameters
    ----------
    config
        A :class:`aiofl.config.RunConfig`, a preset name or a config path (or None with
        ``plant``, ``controller``, ``scenario``).
    amplitude
        Error amplitude ε for the secant gains of fal / g(e) / INLSEF (module docstring).
    r_op
        Reference value to hold (default: see :func:`reference_operating_value`).

    Returns
    -------
    Linearization
    """
    if config is not None:
        if isinstance(config, str) or hasattr(config, "__fspath__"):
            from aiofl.config import load_config

            config = load_config(config)
        plant, controller, scenario = config.plant, config.controller, config.scenario
    if plant is None or controller is None or scenario is None:
        raise ValueError("give a run config, or plant, controller and scenario")
    loop = ClosedLoop(plant, controller, scenario, mode="linearise", amplitude=amplitude)
    if r_op is not None:
        loop.r_op = float(r_op)
    z = loop.operating_point()
    a = loop.jacobian(z)
    # input and output matrices by central differences
    rho = controller.rho
    h = 1e-6

    def evaluate(zz: NDArray[np.float64], dr: float = 0.0, dd: float = 0.0, dn: float = 0.0) -> Any:
        rd = np.zeros(rho + 1)
        rd[0] = loop.r_op + dr
        return loop.rhs(zz, rd=rd, d=loop.d_op + dd, noise=dn)

    b_cols, d_cols = [], []
    for kw in ({"dr": h}, {"dd": h}, {"dn": h}):
        neg = {k: -v for k, v in kw.items()}
        fp, yp, up = evaluate(z, **kw)
        fm, ym, um = evaluate(z, **neg)
        b_cols.append((fp - fm) / (2 * h))
        d_cols.append([(yp - ym) / (2 * h), (up - um) / (2 * h)])
    c_rows = np.zeros((2, loop.n_z))
    for j in range(loop.n_z):
        hj = 1e-6 * max(1.0, abs(z[j]))
        zp, zm = z.copy(), z.copy()
        zp[j] += hj
        zm[j] -= hj
        _, yp, up = evaluate(zp)
        _, ym, um = evaluate(zm)
        c_rows[:, j] = [(yp - ym) / (2 * hj), (up - um) / (2 * hj)]
    eig = np.linalg.eigvals(a)
    eig = eig[np.lexsort((eig.imag, -eig.real))]
    notes = list(loop.nonsmooth)
    if controller.law == "iofl":
        notes.append("IOFL law: the ESO is integrated but not used; its poles do not interact")
    if scenario.noise_variance > 0:
        notes.append("measurement noise set to 0 at the operating point (it is an input n)")
    return Linearization(
        a=a,
        b=np.column_stack(b_cols),
        c=c_rows,
        d=np.array(d_cols).T,
        state_names=loop.state_names,
        z_op=z,
        r_op=loop.r_op,
        d_op=loop.d_op,
        eigenvalues=eig,
        amplitude=float(amplitude),
        notes=tuple(notes),
    )


def _depends_on_amplitude(controller: Controller) -> bool:
    c = controller
    if c.law != "aiofl":
        return False
    if c.eso == "improved" and c.value("eso.g_alpha") != 1.0:
        return True
    if c.sef == "improved":
        return True
    if c.sef == "nonlinear":
        return any(
            c.value(f"sef.alpha{i}") != 1.0 for i in range(1, c.n_feedback + 1)
        )  # fal is linear only for ε ≤ δ
    return False


def closed_loop_verdict(
    run_config: Any, amplitude: float = DEFAULT_AMPLITUDE, linearization: Any = None
) -> dict[str, Any]:
    """Stability verdict of a run config's linearised closed loop.

    ``run_config`` is a :class:`~aiofl.config.RunConfig` or a config path / preset name;
    ``linearization`` reuses a :func:`linearize_closed_loop` result at ``amplitude``
    (the default operating point) instead of computing it again.

    Returns
    -------
    dict
        ``{"verdict": "stable"|"unstable"|"marginal", "eigenvalues": [[re, im], ...],
        "max_real", "slowest", "fastest", "states", "operating_point", "amplitude",
        "notes"}`` and, when the secant gains depend on ε, ``"verdicts_by_amplitude"``
        (ε -> verdict over :data:`SWEEP_AMPLITUDES`).
    """
    cfg = run_config
    if isinstance(cfg, str) or hasattr(cfg, "__fspath__"):
        from aiofl.config import load_config

        cfg = load_config(cfg)
    lin = linearization or linearize_closed_loop(cfg, amplitude=amplitude)
    out = lin.to_dict()
    if _depends_on_amplitude(cfg.controller):
        sweep = {}
        for eps in SWEEP_AMPLITUDES:
            try:
                sweep[f"{eps:g}"] = linearize_closed_loop(cfg, amplitude=eps).verdict()
            except ValueError as exc:
                sweep[f"{eps:g}"] = f"no operating point: {exc}"
        out["verdicts_by_amplitude"] = sweep
    return out


# ----------------------------------------------------------- python-control interop
def linear_eso_statespace(rho: int, omega0: float, alphas: Sequence[float], b0: float) -> Any:
    r"""The linear ESO (5)/(16) as a ``control.StateSpace`` with inputs (u, y).

    .. math:: \dot{\hat\xi} = (A - LC)\hat\xi + b_0 e_\rho u + L y,\qquad
              L = (\beta_1..\beta_{\rho+1}),\ \beta_i = \alpha_i\omega_0^i

    Outputs are the ρ+1 estimates; the eigenvalues of A − LC are the roots of
    :math:`s^{\rho+1} + \beta_1 s^\rho + \dots + \beta_{\rho+1}`.
    """
    import control

    if len(alphas) != rho + 1:
        raise ValueError(f"alphas has {len(alphas)} entries; rho + 1 = {rho + 1} needed")
    betas = eso_gains(omega0, alphas)
    a = eso_error_matrix(betas)
    b = np.zeros((rho + 1, 2))
    b[rho - 1, 0] = b0
    b[:, 1] = betas
    names = [f"xi_hat{i}" for i in range(1, rho + 2)]
    return control.ss(
        a,
        b,
        np.eye(rho + 1),
        np.zeros((rho + 1, 2)),
        inputs=["u", "y"],
        outputs=names,
        states=names,
    )


def eso_statespace(controller: Controller) -> Any:
    """The (linear) ESO of a controller as a ``control.StateSpace`` (inputs u, y)."""
    if controller.eso != "linear":
        raise ValueError("eso_statespace: only the linear ESO is a linear system (eso = 'linear')")
    c = controller
    alphas = [c.value(f"eso.alpha{i}") for i in range(1, c.rho + 2)]
    return linear_eso_statespace(c.rho, c.value("eso.omega0"), alphas, c.value("law.b0"))


# ---------------------------------------------------------------------- formatting
def _fmt(z: complex) -> str:
    if abs(z.imag) < 1e-9 * max(1.0, abs(z.real)):
        return f"{z.real:.6g}"
    return f"{z.real:.6g} {'+' if z.imag >= 0 else '−'} {abs(z.imag):.6g}j"


def format_linearization_text(
    lin: Linearization, name: str = "", extra: dict[str, Any] | None = None
) -> str:
    """Plain-text report of a :class:`Linearization` (``aiofl analyze CONFIG --closed-loop``)."""
    out = [f"Closed-loop linearisation{f' of {name}' if name else ''}"]
    out.append(
        f"  operating point: r = {lin.r_op:g}, τ_d = {lin.d_op:g}; states: "
        + ", ".join(lin.state_names)
    )
    out.append(f"  z* = [{', '.join(f'{v:.6g}' for v in lin.z_op)}]")
    out.append(f"  eigenvalues ({len(lin.eigenvalues)}):")
    for z in lin.eigenvalues:
        if z.real < 0:
            tau = f"   decays, τ = {1 / abs(z.real):.4g} s"
        elif z.real > 0:
            tau = f"   GROWS, τ = {1 / z.real:.4g} s"
        else:
            tau = ""
        out.append(f"    {_fmt(z)}{tau}")
    out.append(f"  slowest mode: {_fmt(lin.slowest)}   fastest mode: {_fmt(lin.fastest)}")
    out.append(f"  verdict: {lin.verdict().upper()} (max Re = {lin.max_real:.6g})")
    for note in lin.notes:
        out.append(f"  note: {note}")
    if extra and "verdicts_by_amplitude" in extra:
        sweep = ", ".join(f"ε={k}: {v}" for k, v in extra["verdicts_by_amplitude"].items())
        out.append(f"  verdict by error amplitude: {sweep}")
    return "\n".join(out)
