r"""The sampled closed loop linearised at its operating point: is it stable at a given Ts?

The sampled loop is a hybrid system: the plant runs in continuous time between samples,
driven by the held command; the controller updates once per sample
(:mod:`aiofl.engine.kernel.sampled`).  Its linearisation at the operating point is a
discrete-time system in the deviations :math:`(\delta x_k, \delta c_k)` of the plant
state and the discrete controller's state at :math:`t_k = kT_s`, built here from two
exact-or-nearly pieces:

* **the plant**: the continuous linearisation at the operating point
  :math:`(x^*, u^*)` of :meth:`aiofl.analysis.closed_loop.ClosedLoop.linear_model` (the
  loop broken at the plant input, complex-step Jacobians),
  :math:`\dot{\delta x} = A_p\delta x + B_p\delta u`, :math:`\delta y = C_p\delta x`,
  discretised exactly under the zero-order hold,

  .. math:: \Phi_p = e^{A_pT_s},\qquad \Gamma_p = \int_0^{T_s} e^{A_p s}\,ds\,B_p

  (one matrix exponential of the augmented matrix :math:`[[A_p, B_p], [0, 0]]T_s`; Franklin,
  Powell & Workman, *Digital Control of Dynamic Systems*, 3rd ed., §4.3.3);
* **the controller**: the engine's own one-sample update
  (:class:`aiofl.discrete_controller.DiscreteController`, the coefficients of
  :func:`aiofl.engine.discrete_rows.sampling_rows`), linearised by central finite differences
  in its state and in the measurement,
  :math:`\delta c_{k+1} = J_{cc}\delta c_k + J_{cy}\delta y_k`,
  :math:`\delta u_k = J_{uc}\delta c_k + J_{uy}\delta y_k`, at its equilibrium
  :math:`c^*` for :math:`y = y^*, r = r^*, u = u^*` (Newton on the fixed point, least
  squares for the ESO's one-parameter family of equilibria).  The linear ESO, the linear
  SEF and the prefilter are affine, so the differences are exact up to rounding; fal, fhan
  and the INLSEF give their slope at zero error (the local linearisation).

Closing the loop, :math:`\delta u_k` is applied over :math:`[t_k, t_{k+1})`, or with a
one-sample computation delay the previous command (a controller state), so

.. math:: \begin{bmatrix}\delta x\\ \delta c\end{bmatrix}_{k+1} =
          \begin{bmatrix}\Phi_p + \Gamma_pJ_{uy}C_p & \Gamma_pJ_{uc}\\
          J_{cy}C_p & J_{cc}\end{bmatrix}
          \begin{bmatrix}\delta x\\ \delta c\end{bmatrix}_k

(delay: the first row is :math:`[\Phi_p,\ \Gamma_p e_{u_{k-1}}^T]`).  The loop is
locally asymptotically stable at the operating point iff the spectral radius of this
matrix is below 1.  Controller states the update neither reads nor writes (unused slots
of the engine's fixed-size state) are dropped; quantisation is ignored (it is not
differentiable).  The IOFL law evaluates the plant model inside the controller and has no
:class:`DiscreteController`: no linearisation then.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl.analysis.closed_loop import DEFAULT_AMPLITUDE, ClosedLoop
from aiofl.engine.discrete_rows import Sampling

__all__ = ["SampledLoop", "sampled_margins", "unit_circle_margins", "zoh"]


def zoh(a: NDArray[np.float64], b: NDArray[np.float64], ts: float) -> tuple[Any, Any]:
    r""":math:`(\Phi, \Gamma) = (e^{AT_s}, \int_0^{T_s}e^{As}ds\,B)` by one matrix
    exponential of :math:`\begin{bmatrix}A & B\\0 & 0\end{bmatrix}T_s`.

    Parameters
    ----------
    a, b
        The continuous system's matrices, (n, n) and (n, m).
    ts
        The sample time [s].

    Returns
    -------
    Phi, Gamma : ndarray
    """
    from scipy.linalg import expm

    n, m = a.shape[0], b.shape[1]
    big = np.zeros((n + m, n + m))
    big[:n, :n], big[:n, n:] = a * ts, b * ts
    e = expm(big)
    return e[:n, :n], e[:n, n:]


class SampledLoop:
    """The linearised sampled loop of one config (module docstring), for any Ts.

    The continuous linearisation (operating point, :math:`A_p, B_p, C_p`) is computed once
    on construction; :meth:`matrix` and :meth:`spectral_radius` then cost one matrix
    exponential and a few dozen controller steps per Ts.  ``available`` is False (and
    ``reason`` says why) when there is no linearisation: the IOFL law, or no operating
    point.

    Parameters
    ----------
    config
        A :class:`aiofl.config.RunConfig`.
    amplitude
        Error amplitude of the continuous linearisation's secant gains (only the plant's
        Jacobians are used here, which do not depend on it).
    """

    def __init__(self, config: Any, amplitude: float = DEFAULT_AMPLITUDE) -> None:
        self.config = config
        self.base: Sampling = config.sampling or Sampling(config.dt)
        self.available, self.reason = True, ""
        c = config.controller
        if c.law != "aiofl":
            self.available, self.reason = False, "the IOFL law has no discrete controller model"
            return
        try:
            loop = ClosedLoop(
                config.plant, c, config.scenario, mode="linearise", amplitude=amplitude
            )
            z = loop.operating_point()
            a, b, _, _ = loop.linear_model(z, broken=True)
            a_cl, _, c_cl, _ = loop.linear_model(z)
            self.broken = loop.linear_model(z, broken=True)
        except Exception as exc:  # no operating point, a plant without derivatives, ...
            self.available, self.reason = False, f"no linearisation: {exc}"
            return
        n = loop.n
        self.ap, self.bp, self.cp = a[:n, :n], b[:n, :1], c_cl[:1, :n]
        self.continuous_eigenvalues = np.linalg.eigvals(a_cl)
        _, y, u = loop.rhs(z)
        self.y_op, self.u_op, self.r_op = float(y), float(u), float(loop.r_op)
        self.rho = c.rho
        self._pieces: dict[float, tuple[Any, ...]] = {}

    @property
    def continuous_stable(self) -> bool | None:
        """Whether the continuous loop's linearisation is stable (None: not available)."""
        if not self.available:
            return None
        eig = self.continuous_eigenvalues
        return bool(np.all(eig.real < -1e-9 * max(1.0, float(np.max(np.abs(eig))))))

    def _controller(self, ts: float) -> Any:
        from aiofl.discrete_controller import DiscreteController

        cfg = self.config
        c = cfg.controller
        plant = cfg.plant if c.eso_model != "none" else None
        return DiscreteController(c, replace(self.base, ts=ts), plant, x0=cfg.scenario.x0)

    def _jacobian(
        self, dc: Any, c0: NDArray[np.float64], rr: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """``(J, c+, u)`` at ``c0``: J (n_c+1, n_c+1) maps (δc, δy) to (δc+, δu)."""
        y0 = self.y_op
        nc = c0.size
        # rows: c0, then ±h along each state and along y (central differences)
        hs = 1e-6 * np.maximum(1.0, np.abs(np.append(c0, y0)))
        states = np.repeat(c0[None, :], 2 * nc + 3, axis=0)
        ys = np.full(2 * nc + 3, y0)
        for j in range(nc + 1):
            for row, sign in ((1 + 2 * j, 1.0), (2 + 2 * j, -1.0)):
                if j < nc:
                    states[row, j] += sign * hs[j]
                else:
                    ys[row] += sign * hs[j]
        nxt, us = dc.step_each(states, rr, ys)
        out = np.column_stack([nxt, us])
        jac = ((out[1::2] - out[2::2]) / (2 * hs[:, None])).T
        return jac, out[0, :nc], out[0, nc]

    def _equilibrium(self, dc: Any, rr: NDArray[np.float64]) -> NDArray[np.float64]:
        """The controller state with :math:`c^+ = c` and :math:`u = u^*` at
        :math:`y^*, r^*`: from a few steps at :math:`y^*` (if they stay finite), two
        Newton steps solved by least squares."""
        dc.init(self.y_op)
        c = dc.state
        dc.run(50, rr, self.y_op)
        if np.all(np.isfinite(dc.state)) and np.max(np.abs(dc.state)) < 1e8:
            c = dc.state
        for _ in range(3):
            jac, cn, u = self._jacobian(dc, c, rr)
            nc = c.size
            lhs = np.vstack([jac[:nc, :nc] - np.eye(nc), jac[nc:, :nc]])
            rhs = -np.append(cn - c, u - self.u_op)
            if np.max(np.abs(rhs)) <= 1e-12 * max(1.0, float(np.max(np.abs(c)))):
                break
            c = c + np.linalg.lstsq(lhs, rhs, rcond=None)[0]
        return c

    def _controller_pieces(self, ts: float) -> tuple[Any, ...]:
        """``(jcc, jcy, juc, juy, keep, i_uprev)`` of the controller's one-sample
        linearisation at ``ts`` (module docstring), cached per Ts."""
        from aiofl.engine.kernel.sampled import C_UPREV

        if ts in self._pieces:
            return self._pieces[ts]
        dc = self._controller(ts)
        rr = np.zeros(self.rho + 1)
        rr[0] = self.r_op
        c = self._equilibrium(dc, rr)
        jac, _, _ = self._jacobian(dc, c, rr)
        nc = c.size
        jcc, jcy, juc, juy = jac[:nc, :nc], jac[:nc, nc], jac[nc, :nc], jac[nc, nc]
        # a state is inert (dropped) when its row and column of jcc are the identity's, u
        # does not depend on it and y does not act on it; u_{k-1} is always kept
        near = np.abs(jcc - np.eye(nc)) <= 1e-9
        inert = near.all(axis=0) & near.all(axis=1) & (np.abs(juc) < 1e-12) & (np.abs(jcy) < 1e-12)
        inert[C_UPREV] = False
        keep = np.flatnonzero(~inert)
        i_uprev = int(np.nonzero(keep == C_UPREV)[0][0])
        out = (jcc[np.ix_(keep, keep)], jcy[keep], juc[keep], float(juy), keep, i_uprev)
        self._pieces[ts] = out
        return out

    def matrix(self, ts: float, delay: float = 0.0) -> NDArray[np.float64]:
        r"""The closed loop's one-sample matrix at sample time ``ts`` (module docstring),
        with an unmodelled transport delay ``delay`` [s] in the loop.

        The delay :math:`\tau = kT_s + \theta`, :math:`0 \le \theta < T_s`, shifts the
        DAC's output :math:`v_i` (:math:`u_i`, or :math:`u_{i-1}` with the computation
        delay): over :math:`[t_i, t_i + \theta)` the plant sees :math:`v_{i-k-1}`, over
        :math:`[t_i + \theta, t_{i+1})` :math:`v_{i-k}`, so (the modified z-transform;
        Franklin, Powell & Workman §4.3.4)

        .. math:: \delta x_{i+1} = \Phi_p\delta x_i + \Gamma_b v_{i-k} + \Gamma_a v_{i-k-1},
                  \quad \Gamma_b = \Gamma(T_s - \theta),
                  \quad \Gamma_a = e^{A_p(T_s-\theta)}\Gamma(\theta),

        with :math:`\Gamma(h) = \int_0^h e^{A_ps}ds\,B_p`; the past outputs
        :math:`v_{i-1}, ..., v_{i-k-1}` are k + 1 more states (a shift register).  A delay
        on the sensor side has the same loop (the plant and a delay commute), so one margin
        covers both.  ``delay = 0`` gives the undelayed matrix (no shift register).
        """
        if not self.available:
            raise ValueError(self.reason)
        if not delay >= 0.0:
            raise ValueError(f"delay = {delay}; allowed: >= 0")
        jcc, jcy, juc, juy, keep, i_up = self._controller_pieces(ts)
        phi, gam = zoh(self.ap, self.bp, ts)
        n, nk = phi.shape[0], keep.size
        cp = self.cp[0]
        v = np.zeros(n + nk)  # v_i as a row of (δx, δc)
        if self.base.delay:
            v[n + i_up] = 1.0
        else:
            v[:n], v[n:] = juy * cp, juc
        k = int(np.floor(delay / ts + 1e-12)) if delay > 0.0 else -1
        nw = k + 1  # shift register v_{i-1}, ..., v_{i-k-1}
        m = np.zeros((n + nk + nw, n + nk + nw))
        m[:n, :n] = phi
        m[n : n + nk, :n] = np.outer(jcy, cp)
        m[n : n + nk, n : n + nk] = jcc
        if k < 0:
            m[:n, : n + nk] += np.outer(gam[:, 0], v)
            return m
        theta = max(delay - k * ts, 0.0)
        if theta >= ts:  # (rounding of floor)
            theta = 0.0
        gb = zoh(self.ap, self.bp, ts - theta)[1][:, 0]
        ga = zoh(self.ap, self.bp, theta)[1][:, 0] if theta > 0.0 else np.zeros(n)
        if theta > 0.0:
            ga = zoh(self.ap, self.bp, ts - theta)[0] @ ga
        w0 = n + nk  # column of v_{i-1}
        if k == 0:
            m[:n, : n + nk] += np.outer(gb, v)
        else:
            m[:n, w0 + k - 1] += gb
        m[:n, w0 + k] += ga
        m[w0, : n + nk] = v
        for j in range(1, nw):
            m[w0 + j, w0 + j - 1] = 1.0
        return m

    def broken_loop(
        self, ts: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        r"""``(A, B, C)`` of the sampled loop broken at the plant input: state
        :math:`(\delta x, \delta c)`, input the held :math:`\delta u_p`, output the
        command the DAC applies; closing :math:`u_p = ` output gives :meth:`matrix` (``ts``).
        """
        if not self.available:
            raise ValueError(self.reason)
        jcc, jcy, juc, juy, keep, i_up = self._controller_pieces(ts)
        phi, gam = zoh(self.ap, self.bp, ts)
        n, nk = phi.shape[0], keep.size
        cp = self.cp[0]
        a = np.zeros((n + nk, n + nk))
        a[:n, :n] = phi
        a[n:, :n] = np.outer(jcy, cp)
        a[n:, n:] = jcc
        b = np.zeros((n + nk, 1))
        b[:n, 0] = gam[:, 0]
        c = np.zeros((1, n + nk))
        if self.base.delay:
            c[0, n + i_up] = 1.0
        else:
            c[0, :n], c[0, n:] = juy * cp, juc
        return a, b, c

    def delay_margin(
        self, ts: float, *, d_max: float | None = None, rtol: float = 1e-4
    ) -> float | None:
        r"""The sampled loop's delay margin at ``ts`` [s]: the smallest transport delay
        :math:`\tau` at which the spectral radius of :meth:`matrix` (``ts``, τ) reaches 1.

        Scanned from 0 in steps of :math:`\max(T_s/4, \tau_c/40)`, :math:`\tau_c` the
        continuous loop's margin (:meth:`continuous_delay_margin`; the radius is not
        monotonic in τ in general: the first crossing found is the margin), then bisected
        on the fractional-delay model to ``rtol``.  Returns 0.0 when the loop is not stable
        without a delay, ``inf`` when it stays stable up to ``d_max`` (default
        :math:`\min(\max(100T_s, 4\tau_c), 500T_s)`: the shift register has a state per
        sample of delay), None when there is no linearisation (:attr:`reason`).

        Parameters
        ----------
        ts
            The sample time [s].
        d_max
            The largest delay scanned [s] (default above).
        rtol
            The bisection's relative tolerance.

        Returns
        -------
        float or None
        """
        if self.spectral_radius(ts) is None:
            return None
        tau_c = self.continuous_delay_margin() or 0.0
        if d_max is None:
            d_max = min(max(100.0 * ts, 4.0 * tau_c), 500.0 * ts)

        def stable(d: float) -> bool:
            m = self.matrix(ts, d)
            return bool(np.all(np.isfinite(m)) and np.max(np.abs(np.linalg.eigvals(m))) < 1.0)

        if not stable(0.0):
            return 0.0
        step = max(ts / 4.0, tau_c / 40.0)
        lo, hi = 0.0, None
        d = step
        while d <= d_max * (1 + 1e-12):
            if not stable(d):
                hi = d
                break
            lo, d = d, d + step
        if hi is None:
            return float("inf")
        while hi - lo > rtol * hi:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if stable(mid) else (lo, mid)
        return lo

    def continuous_delay_margin(self) -> float | None:
        """The continuous loop's delay margin [s] at the same operating point
        (:func:`aiofl.analysis.frequency.loop_margins` of the loop broken at the plant input;
        None: no linearisation, or no finite margin)."""
        from aiofl.analysis.frequency import loop_margins, loop_transfer

        if not self.available:
            return None
        if hasattr(self, "_tau_c"):
            return self._tau_c  # type: ignore[no-any-return]
        dm = loop_margins(loop_transfer(*self.broken), self.continuous_eigenvalues).delay_margin_s
        self._tau_c = float(dm) if np.isfinite(dm) else None
        return self._tau_c

    def spectral_radius(self, ts: float) -> float | None:
        """:math:`\\max_i|\\lambda_i|` of :meth:`matrix` (None when not available, when the
        controller cannot be built at ``ts`` (``reason`` says why) or the matrix is not
        finite)."""
        if not self.available:
            return None
        try:
            m = self.matrix(ts)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
            self.reason = f"no linearisation at Ts = {ts:g}: {exc}"
            return None
        if not np.all(np.isfinite(m)):
            return None
        return float(np.max(np.abs(np.linalg.eigvals(m))))


def unit_circle_margins(
    a: NDArray[np.float64], b: NDArray[np.float64], c: NDArray[np.float64], ts: float
) -> dict[str, Any]:
    r"""Gain and phase margins of :math:`L(z) = -c(zI-a)^{-1}b` on the unit circle
    :math:`z = e^{j\omega T_s}`, :math:`\omega` up to the Nyquist frequency :math:`\pi/T_s`:
    crossings bracketed on a log grid (3000 points over six decades), refined by
    :func:`scipy.optimize.brentq`; the headline margins chosen as the continuous ones (the
    gain margin closest to 0 dB, the smallest absolute phase margin), distances at the crossings.
    The delay margin is :math:`\min_i \varphi_i/\omega_{gc,i}` over the gain crossovers
    (:math:`\varphi_i` in :math:`[0, 2\pi)`): the delay :math:`e^{-j\omega\tau}` that puts a
    crossing on −1 (exact for a whole number of samples, :math:`z^{-k}`; a fraction of a
    sample acts through the hold, :meth:`SampledLoop.delay_margin`).

    Returns ``{"gain_margin_db", "phase_crossover", "phase_margin_deg", "gain_crossover",
    "delay_margin_s"}`` (None where there is no crossing).

    Parameters
    ----------
    a, b, c
        The discrete loop :math:`L(z) = -c(zI-a)^{-1}b`.
    ts
        The sample time [s].

    Returns
    -------
    dict
    """
    import math

    from scipy.optimize import brentq

    eye = np.eye(a.shape[0])

    def at(w: float) -> complex:
        return complex(-(c @ np.linalg.solve(np.exp(1j * w * ts) * eye - a, b))[0, 0])

    nyquist = math.pi / ts
    w = np.logspace(math.log10(nyquist) - 6, math.log10(nyquist), 3000)[:-1]
    lw = np.array([at(x) for x in w])

    def roots(fun: Any, fw: NDArray[np.float64]) -> list[float]:
        ok = np.isfinite(fw[:-1]) & np.isfinite(fw[1:]) & (np.sign(fw[:-1]) != np.sign(fw[1:]))
        return [brentq(fun, w[i], w[i + 1], xtol=1e-14 * w[i]) for i in np.nonzero(ok)[0]]

    with np.errstate(divide="ignore", invalid="ignore"):
        w_gc = roots(lambda x: math.log(abs(at(x))), np.log(np.abs(lw)))
        w_pc = [x for x in roots(lambda x: at(x).imag, lw.imag) if at(x).real < 0]
    gm_db = wpc = pm = wgc = dm = None
    if w_pc:
        gms = [-20.0 * math.log10(abs(at(x))) for x in w_pc]
        i = int(np.argmin(np.abs(gms)))
        gm_db, wpc = gms[i], w_pc[i]
    if w_gc:
        pms = [float(np.remainder(np.angle(at(x), deg=True), 360.0) - 180.0) for x in w_gc]
        i = int(np.argmin(np.abs(pms)))
        pm, wgc = pms[i], w_gc[i]
        dm = min(
            math.radians(float(np.remainder(p, 360.0))) / x for p, x in zip(pms, w_gc, strict=True)
        )
    return {
        "gain_margin_db": gm_db,
        "phase_crossover": wpc,
        "phase_margin_deg": pm,
        "gain_crossover": wgc,
        "delay_margin_s": dm,
    }


def sampled_margins(config: Any, ts: float | None = None) -> dict[str, Any]:
    r"""The sampled loop's stability and margins at ``ts`` (default: the config's own
    sample time), to stand beside the continuous loop's (:mod:`aiofl.analysis.frequency`).

    Returns ``{"ts", "spectral_radius", "stable", "gain_margin_db", "phase_crossover",
    "phase_margin_deg", "gain_crossover", "delay_margin_s"}``: the gain and phase margins
    of :math:`L(z) = -C(zI-A)^{-1}B` (:meth:`SampledLoop.broken_loop`) on the unit circle
    :math:`z = e^{j\omega T_s}`, :math:`\omega` up to the Nyquist frequency
    :math:`\pi/T_s` (crossings bracketed on a log grid, refined by
    :func:`scipy.optimize.brentq`; headline margins chosen as the continuous ones: the gain
    margin closest to 0 dB, the smallest phase margin; like them, distances at the
    crossings); the delay margin the smallest transport delay that makes the loop
    unstable (:meth:`SampledLoop.delay_margin`).  ``{"ts", "reason"}`` when there is no
    linearisation.
    """
    ts = float(ts if ts is not None else (config.sampling.ts if config.sampling else config.dt))
    loop = SampledLoop(config)
    radius = loop.spectral_radius(ts)
    if radius is None:
        return {"ts": ts, "reason": loop.reason or "the sampled loop's matrix is not finite"}
    a, b, c = loop.broken_loop(ts)
    m = unit_circle_margins(a, b, c, ts)
    gm_db, wpc, pm, wgc = (
        m[k] for k in ("gain_margin_db", "phase_crossover", "phase_margin_deg", "gain_crossover")
    )
    dm = loop.delay_margin(ts)
    return {
        "ts": ts,
        "spectral_radius": radius,
        "stable": radius < 1.0,
        "gain_margin_db": gm_db,
        "phase_crossover": wpc,
        "phase_margin_deg": pm,
        "gain_crossover": wgc,
        "delay_margin_s": dm,
    }
