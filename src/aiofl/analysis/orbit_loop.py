r"""The closed loop along a trajectory: exact nonlinearities, complex-step safe.

:class:`OrbitLoop` is :class:`aiofl.analysis.closed_loop.ClosedLoop`'s complex-safe
right-hand side (plant through :class:`aiofl.analysis.derivatives.PlantDerivatives`, the
ITD's tanh, the prefilter, the saturation by its real part) with the *exact* non-smooth
functions instead of their secant gains, so that :math:`\partial F/\partial z(t, z)` along a
trajectory is exact (complex step, :meth:`OrbitLoop.jacobian_at`).  On real numbers it is
the engine's right-hand side (tests: equal to ``ClosedLoop(mode="exact")``).

How the non-smooth elements are differentiated
----------------------------------------------
A scalar φ(e) is evaluated on a complex step :math:`e = e_r + ih` as
:math:`\varphi(e_r) + ih\,\varphi'(e_r)`, with the derivative written out:

* fal (17): :math:`\delta^{\alpha-1}` for :math:`|e| \le \delta` (the linear inner
  branch), :math:`\alpha|e|^{\alpha-1}` outside; the one-sided slopes differ at
  :math:`|e| = \delta`, which a tracking orbit crosses at isolated instants (measure zero;
  the integrator sees a jump in the coefficient of the variational equation, not in z).
* INLESO g(e) (19): :math:`k_\alpha\alpha|e|^{\alpha-1} + k_\beta(\beta+1)|e|^\beta`;
  INLSEF terms (20): :math:`(k_1 + k_2\sigma)\alpha|e|^{\alpha-1} + k_2\sigma'|e|^\alpha
  \operatorname{sign} e` with :math:`\sigma = 1/(1+e^{\mu e^2})`, and its limit
  :math:`v_l\tanh(s/v_l)` by the complex tanh.  For α < 1 the slope is infinite at
  e = 0; it is taken at :math:`\max(|e|, 10^{-12})` (:data:`SLOPE_FLOOR`): an integrable
  spike at the isolated zero crossings.
* Han's TD (18) is bang-bang and driven by r alone (a cascade): as in the linearisation it
  is not part of the state.  Its outputs :math:`(r_1, r_2)` are an input, precomputed by
  fixed-step RK4 (:meth:`OrbitLoop.han_signal`) and averaged over 20 steps to remove the
  chattering of the sliding mode at the step size.
* Saturation: slope 1 inside, 0 at a limit (the branch by the real part).

With ``describing`` set (:meth:`OrbitLoop.nonlinearities`), each non-smooth function is
replaced by a given gain :math:`N_i e` (the describing-function loop of
:mod:`aiofl.analysis.orbit`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from aiofl.analysis.closed_loop import ClosedLoop, is_complex
from aiofl.analysis.loop_radau import LoopIntegrator
from aiofl.components.differentiators import han_td_rhs
from aiofl.components.feedback import fal, inlsef_limit, inlsef_term
from aiofl.components.observers import inleso_injection
from aiofl.controller import Controller
from aiofl.plants.base import Plant
from aiofl.scenario import Reference, Scenario

__all__ = ["SLOPE_FLOOR", "Nonlinearity", "OrbitLoop", "reference_derivatives"]

Scalar = Callable[[float], float]

SLOPE_FLOOR = 1e-12
"""|e| below which the slope of :math:`|e|^{a}`, a < 1, is taken at this value."""


def _cs(value: Callable[[float], float], slope: Callable[[float], float], e: Any) -> Any:
    r"""φ(e) on a real number, :math:`\varphi(e_r) + i h \varphi'(e_r)` on a complex step;
    on an array of complex steps (a tangent batch) the same per entry, φ and φ' taken once
    when the entries share their real part."""
    if isinstance(e, np.ndarray):
        er = e.real
        e0 = float(er.flat[0])
        if e.dtype.kind != "c" or not (er == e0).all():
            return np.array([_cs(value, slope, v) for v in e.flat]).reshape(e.shape)
        out = np.empty(e.shape, dtype=np.complex128)
        out.real = value(e0)
        out.imag = e.imag * slope(e0)
        return out
    if is_complex(e):
        er = float(e.real)
        return complex(value(er), float(e.imag) * slope(er))
    return value(float(e))


def _pow_slope(e: float, a: float) -> float:
    """:math:`a|e|^{a-1}`, the slope of :math:`|e|^a\\operatorname{sign}e` (floored |e|)."""
    if a == 1.0:
        return 1.0
    return a * max(abs(e), SLOPE_FLOOR) ** (a - 1.0)


def reference_derivatives(ref: Reference, t: float, order: int) -> NDArray[np.float64]:
    r""":math:`(r, \dot r, \dots, r^{(order)})` at t: for a sine
    :math:`r^{(k)} = A\omega^k\sin(\omega t + \varphi + k\pi/2)`; a step's derivatives are 0;
    samples: the slope of the linear interpolation, higher ones 0.

    Parameters
    ----------
    ref
        The reference.
    t
        The time [s].
    order
        The highest derivative, ≥ 0.

    Returns
    -------
    ndarray
        Shape (order + 1,).
    """
    out = np.zeros(order + 1)
    if ref.kind == "sine":
        for k in range(order + 1):
            out[k] = (
                ref.amplitude * ref.omega**k * math.sin(ref.omega * t + ref.phase + k * math.pi / 2)
            )
        out[0] += ref.offset
        return out
    out[0] = float(ref.evaluate(t))
    if ref.kind == "samples" and order >= 1:
        i = int(t // ref.sample_dt)
        if 0 <= i < len(ref.samples) - 1:
            out[1] = (ref.samples[i + 1] - ref.samples[i]) / ref.sample_dt
    return out


class Nonlinearity:
    """One non-smooth scalar function of the loop: name, φ (real), its kinks."""

    def __init__(self, name: str, phi: Callable[[float], float], kinks: Sequence[float] = ()):
        """Parameters
        ----------
        name
            What it is (for messages).
        phi
            The function, e -> φ(e).
        kinks
            The values of |e| where φ is not smooth (δ of fal).
        """
        self.name, self.phi, self.kinks = name, phi, tuple(kinks)


class OrbitLoop(ClosedLoop):
    r""":math:`F(t, z)` of one closed loop with the exact nonlinearities, complex-step safe.

    Evaluated compiled (:attr:`ClosedLoop.compiled` with the exact non-smooth functions);
    :meth:`rhs` is the Python reference.

    Parameters
    ----------
    plant, controller, scenario
        As :class:`ClosedLoop`.
    dt
        Step of the RK4 integration of Han's TD (the run's step).
    """

    NL_MODE = 1
    compiled_integrator = True
    """Integrate compiled (:class:`aiofl.analysis.loop_radau.LoopIntegrator`, Radau IIA);
    False: scipy's BDF calls :meth:`field`'s F and J from Python (the reference)."""

    def __init__(
        self, plant: Plant, controller: Controller, scenario: Scenario, *, dt: float = 1e-4
    ) -> None:
        super().__init__(plant, controller, scenario, mode="linearise")
        self.dt = float(dt)
        self.describing: tuple[float, ...] | None = None
        self._record: list[Any] | None = None
        self._derivatives_checked = False
        # (start, dt, times, outputs (r1, r2) as the rows of a 2 x len(times) array)
        self._han: tuple[float, float, NDArray[np.float64], NDArray[np.float64]] | None = None
        c = controller
        self.nonsmooth = [
            "exact nonlinearities; fal slope δ^(α−1) inside δ, α|e|^(α−1) outside; |e|^a slopes "
            f"(a < 1) taken at |e| ≥ {SLOPE_FLOOR:g}"
        ]
        if c.td == "han":
            self.nonsmooth.append(
                "Han TD (18): a cascade driven by r, left out of the state; its outputs are an "
                f"input (RK4 at dt = {self.dt:g} s, averaged over 20 steps)"
            )

    # -------------------------------------------------------------- nonlinearities
    def nonlinearities(self) -> list[Nonlinearity]:
        """The non-smooth scalar functions, in the order their inputs are recorded: the SEF
        terms :math:`k_i\\mathrm{fal}(e_i)` or INLSEF terms (law AIOFL), then g(e) (INLESO)."""
        c, out = self.controller, []
        if c.law == "aiofl" and c.sef in ("nonlinear", "improved"):
            for i, (k, value, _, kinks) in enumerate(self._sef_functions, start=1):
                if c.sef == "nonlinear":
                    phi = lambda e, k=k, v=value: k * v(e)  # noqa: E731
                    out.append(Nonlinearity(f"k{i}·fal(e{i})", phi, kinks))
                else:
                    out.append(Nonlinearity(f"INLSEF term {i}", value, kinks))
        if c.eso == "improved":
            out.append(Nonlinearity("g(e)", self._injection_functions[0]))
        return out

    def _sef(self, e: NDArray[Any], rff: Any) -> Any:
        c, m = self.controller, self.m
        if c.sef == "linear" or c.law != "aiofl":
            return super()._sef(e, rff)
        if self._record is not None:
            self._record.extend(e[:m])
        if self.describing is not None:
            s = sum(self.describing[i] * e[i] for i in range(m))
            return s if c.sef == "nonlinear" else self._limit(s)
        total: Any = 0.0
        if c.sef == "nonlinear":
            for i, (k, value, slope, _) in enumerate(self._sef_functions):
                total = total + k * _cs(value, slope, e[i])
            return total
        for i, (_, value, slope, _) in enumerate(self._sef_functions):
            total = total + _cs(value, slope, e[i])
        return self._limit(total, by_component=True)

    @functools.cached_property
    def _sef_functions(self) -> list[tuple[float, Scalar, Scalar, tuple[float, ...]]]:
        r"""Per fed-back error: :math:`(k, \varphi, \varphi', \text{kinks})` of its term,
        :math:`k\,\mathrm{fal}` (17) (kink at δ) or the INLSEF term (20) (k = 1, unused),
        read from the controller once (the right-hand side runs ~10⁶ times per orbit)."""
        c = self.controller
        out: list[tuple[float, Scalar, Scalar, tuple[float, ...]]] = []
        for i in range(1, self.m + 1):
            if c.sef == "nonlinear":
                k, a, d = (c.value(f"sef.{p}{i}") for p in ("k", "alpha", "delta"))
                inner = d ** (a - 1.0)  # the slope of fal inside δ
                out.append(
                    (
                        k,
                        lambda x, a=a, d=d: fal(x, a, d),
                        lambda x, a=a, d=d, s=inner: s if abs(x) <= d else _pow_slope(x, a),
                        (d,),
                    )
                )
            else:
                k1, k2, mu, a = (c.value(f"sef.{p}{i}") for p in ("k", "kb", "mu", "alpha"))
                out.append(
                    (
                        1.0,
                        lambda x, k1=k1, k2=k2, mu=mu, a=a: inlsef_term(x, k1, k2, mu, a),
                        lambda x, k1=k1, k2=k2, mu=mu, a=a: _inlsef_slope(x, k1, k2, mu, a),
                        (),
                    )
                )
        return out

    @functools.cached_property
    def _injection_functions(self) -> tuple[Scalar, Scalar]:
        r"""(g, g') of the INLESO's injection (19), :math:`g'(e) = k_\alpha\alpha|e|^{\alpha-1}
        + k_\beta(\beta+1)|e|^\beta`, built once."""
        c = self.controller
        ka, kb, ga, gb = (
            c.value(k) for k in ("eso.k_alpha", "eso.k_beta", "eso.g_alpha", "eso.g_beta")
        )
        return (
            lambda x: inleso_injection(x, ka, kb, ga, gb),
            lambda x: ka * _pow_slope(x, ga) + (kb * (gb + 1.0) * abs(x) ** gb if kb else 0.0),
        )

    @functools.cached_property
    def _v_limit(self) -> float:
        """The INLSEF's limit :math:`v_l` (20), read once."""
        return self.controller.value("sef.v_limit")

    def _limit(self, s: Any, *, by_component: bool = False) -> Any:
        r"""The INLSEF's limit :math:`v_l\tanh(s/v_l)` (20).  On a batch, s/v_l divided as
        one column's s would be, to the last bit: ``by_component`` where that is a Python
        complex (the sum of :func:`_cs`'s terms; Python divides each part by v_l), by numpy
        otherwise (a numpy scalar, e.g. the describing gains' sum)."""
        vl = self._v_limit
        if by_component and isinstance(s, np.ndarray):
            q = np.empty_like(s)
            q.real, q.imag = s.real / vl, s.imag / vl
            return vl * np.tanh(q)
        return vl * np.tanh(s / vl) if is_complex(s) else inlsef_limit(float(s), vl)

    def _injection(self, e: Any) -> Any:
        c = self.controller
        if c.eso == "linear":
            return e
        if self._record is not None:
            self._record.append(e)
        if self.describing is not None:
            return self.describing[-1] * e
        return _cs(*self._injection_functions, e)

    # ------------------------------------------------------------------ inputs
    def han_signal(self, t0: float, t1: float) -> None:
        """Precompute Han's TD outputs over [t0 − 1 s, t1] by RK4 at :attr:`dt` (from
        :math:`(r, \\dot r)` at the start; module docstring)."""
        c = self.controller
        big_r = c.value("td.R")
        ref = self.scenario.reference
        start = t0 - 1.0
        n = math.ceil((t1 - start) / self.dt) + 2
        ts = start + self.dt * np.arange(n + 1)
        r = ref.evaluate(ts)
        rh = ref.evaluate(ts + 0.5 * self.dt)
        x0 = reference_derivatives(ref, start, 1)
        out = _han_rk4(float(x0[0]), float(x0[1]), r, rh, big_r, self.dt, n)
        ts = ts[:n]
        kernel = np.ones(20) / 20.0
        # one contiguous row per output: numpy's interp copies a strided column on every call
        smooth = np.stack([np.convolve(out[:, j], kernel, mode="same") for j in range(2)])
        self._han = (start, self.dt, ts, smooth)

    def inputs_at(self, t: float) -> NDArray[np.float64]:
        """The reference inputs at t: :math:`(r, \\dot r, \\dots, r^{(\\rho)})`, or with Han's
        TD its precomputed outputs :math:`(r_1, r_2)`."""
        if self.controller.td == "han":
            if self._han is None:
                raise ValueError("call han_signal(t0, t1) first")
            _, _, ts, sig = self._han
            return np.array([np.interp(t, ts, sig[0]), np.interp(t, ts, sig[1])])
        return reference_derivatives(self.scenario.reference, t, self.rho)

    def disturbance_at(self, t: float) -> float:
        """The step disturbance :math:`\\tau_d(t)`."""
        sc = self.scenario
        return float(sc.disturbance_amplitude) if t >= sc.disturbance_time else 0.0

    # --------------------------------------------------------------- functions
    def field(
        self, *, hold: bool = False, d: float | None = None
    ) -> tuple[Callable[[float, NDArray[np.float64]], NDArray[np.float64]], Callable[..., Any]]:
        """``(F(t, z), J(t, z))`` for :mod:`aiofl.analysis.variational`: with ``hold`` the
        reference held at its operating value; ``d`` a constant disturbance (default
        :meth:`disturbance_at`)."""

        last: list[Any] = [None, None]  # (t, inputs at t): BDF's Newton iterations, and
        # the Jacobian BDF takes with them, evaluate F several times at one t (read only)

        def inputs(t: float) -> tuple[Any, float]:
            if last[0] is None or t != last[0]:
                rd = None if hold else self.inputs_at(t)
                last[:] = [t, (rd, self.disturbance_at(t) if d is None else d)]
            return last[1]

        def f(t: float, z: NDArray[np.float64]) -> NDArray[np.float64]:
            rd, dd = inputs(t)
            return self.compiled.rhs(z, rd, dd)

        def jac(t: float, z: NDArray[np.float64]) -> NDArray[np.float64]:
            rd, dd = inputs(t)
            return self.jacobian_at(z, rd, dd)

        if self.compiled_integrator:  # the integrations run compiled, F and J in them
            f.integrator = LoopIntegrator(self, hold=hold, d=d)  # type: ignore[attr-defined]
        return f, jac

    def tangent_batch(self, z: NDArray[np.float64]) -> NDArray[np.complex128]:
        """:meth:`ClosedLoop.tangent_batch`; the first one of the loop checks the plant's
        complex-step derivatives there first (:meth:`ClosedLoop.verify_derivatives`: a
        plant written with ``numpy.abs`` would otherwise give the orbit a wrong Jacobian)."""
        if not self._derivatives_checked:
            self.verify_derivatives(z)
            self._derivatives_checked = True
        return super().tangent_batch(z)

    def jacobian_at(
        self, z: NDArray[np.float64], rd: Any = None, d: Any = None
    ) -> NDArray[np.float64]:
        r""":math:`\partial F/\partial z` at z with the given inputs, compiled
        (:meth:`aiofl.analysis.compiled_loop.CompiledLoop.state_jacobian`; with
        :attr:`describing` set, the describing-function loop's); the first call checks the
        plant's complex-step derivatives at z (:meth:`tangent_batch`'s check).

        Parameters
        ----------
        z
            The state.
        rd, d
            The reference and its derivatives, and the disturbance, as for :meth:`ClosedLoop.rhs`.

        Returns
        -------
        ndarray
            Shape (n_z, n_z).
        """
        return self._jacobian_rows(z, rd, d)[: self.n_z]

    def _jacobian_rows(self, z: NDArray[np.float64], rd: Any = None, d: Any = None) -> Any:
        z = np.asarray(z, dtype=np.float64)
        if not self._derivatives_checked:
            self.verify_derivatives(z)
            self._derivatives_checked = True
        cl = self.compiled
        settings = None if self.describing is None else cl.with_describing(self.describing)
        return cl.state_jacobian(z, rd, d, settings=settings)[1]

    def error_rows(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """∂e_i/∂z of the nonlinearities' inputs at z (rows in :meth:`nonlinearities`
        order), compiled."""
        return self.compiled.error_rows(self._jacobian_rows(z))

    def output_row(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """∂y/∂z at z, compiled."""
        return self._jacobian_rows(z)[self.n_z]


@njit(cache=False)
def _han_rk4(
    r1: float,
    r2: float,
    r: NDArray[np.float64],
    r_half: NDArray[np.float64],
    big_r: float,
    h: float,
    n: int,
) -> NDArray[np.float64]:
    """Han's TD (18) by RK4 over n steps of h from (r1, r2), r sampled at the steps and
    their midpoints: the outputs at the n steps."""
    out = np.empty((n, 2))
    for i in range(n):
        out[i, 0], out[i, 1] = r1, r2
        a1, b1 = han_td_rhs(r1, r2, r[i], big_r)
        a2, b2 = han_td_rhs(r1 + 0.5 * h * a1, r2 + 0.5 * h * b1, r_half[i], big_r)
        a3, b3 = han_td_rhs(r1 + 0.5 * h * a2, r2 + 0.5 * h * b2, r_half[i], big_r)
        a4, b4 = han_td_rhs(r1 + h * a3, r2 + h * b3, r[i + 1], big_r)
        r1 += h / 6.0 * (a1 + 2 * a2 + 2 * a3 + a4)
        r2 += h / 6.0 * (b1 + 2 * b2 + 2 * b3 + b4)
    return out


def _inlsef_slope(e: float, k1: float, k2: float, mu: float, a: float) -> float:
    """d/de of :func:`aiofl.components.feedback.inlsef_term` (module docstring)."""
    sig = 1.0 / (1.0 + math.exp(min(mu * e * e, 700.0))) if k2 else 0.0
    gain = k1 + k2 * sig
    ae = abs(e)
    d_sig = -sig * (1.0 - sig) * 2.0 * mu * e if k2 else 0.0
    return gain * _pow_slope(e, a) + k2 * d_sig * ae**a * math.copysign(1.0, e)
