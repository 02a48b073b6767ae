r"""Variational equation, Floquet multipliers, Lyapunov exponents, limit cycles, harmonic balance.

Generic numerical tools for an ODE :math:`\dot z = F(t, z)` with an exact Jacobian
:math:`J(t, z) = \partial F/\partial z` (in :mod:`aiofl.analysis.orbit` the closed loop's,
by the complex step); nothing here knows about controllers.

Variational equation and Floquet multipliers
--------------------------------------------
Along a solution :math:`z(t)` a small perturbation obeys :math:`\dot{\delta z} = J(t,
z(t))\,\delta z`, so :math:`\delta z(t) = \Phi(t)\,\delta z(t_0)` with

.. math:: \dot\Phi = J(t, z(t))\,\Phi,\qquad \Phi(t_0) = I,

integrated *together with* :math:`\dot z = F(t, z)` (:func:`variational_flow`).  For a
T-periodic F and a T-periodic solution, :math:`\Phi(t_0 + T)` is the monodromy matrix and
its eigenvalues are the Floquet multipliers :math:`\mu_i`; the orbit is asymptotically
stable when every :math:`|\mu_i| < 1` (Floquet theory; e.g. Hale, *Ordinary Differential
Equations*, ch. III; Chicone, *Ordinary Differential Equations with Applications*, §2.4).
For an autonomous system :math:`\dot z = F(z)` with the orbit's period a multiplier is
exactly 1 (the direction along the orbit); a forced loop (the reference is a sine) has
none.  The periodic state (:func:`periodic_orbit`): a few periods of plain simulation
from the start, then variational passes over the following periods until the orbit
closes, :math:`z(t_0 + T) \approx z(t_0)` (optionally Newton shooting steps
:math:`z_0 \leftarrow z_0 + (I - \Phi)^{-1}(z(t_0 + T) - z_0)`; with a non-smooth loop whose
Φ depends sharply on the orbit they need not converge, so the default is the plain return
map); the multipliers are those of the last pass, and the range of the largest over the
passes is reported.  z is integrated with the exact Jacobian (the loops are stiff:
observer poles near :math:`-\omega_0 \approx -2000`): the closed loop by the compiled
Radau IIA of :mod:`aiofl.analysis.loop_radau` (z and Φ in one compiled call), any other
F by :func:`scipy.integrate.solve_ivp`, method BDF; Φ by the exponential midpoint rule
on the solver's steps, :math:`\Phi_{k+1} = \exp(h_k J(t_k + h_k/2))\,\Phi_k` (Magnus'
method of order 2), in the coordinates z / (typical magnitudes) so that the observer's
couplings (:math:`\omega_0^5 \approx 10^{16}`) do not overflow the exponential.  Not finite
differences of the flow: a difference quotient of a stiff flow with non-smooth elements
depends on its step (25.7 or 214 for one design, where the variational equation gives
about 0.7).

Lyapunov exponents
------------------
For a reference that is not periodic (step, samples) the largest finite-time Lyapunov
exponent over :math:`[t_0, t_1]` (:func:`finite_time_lyapunov`): Φ is integrated in
chunks of ``renorm`` seconds and re-orthonormalised by a QR decomposition after each
(Benettin et al., *Meccanica* 15, 1980; Dieci, Russell & Van Vleck, *SIAM J. Numer.
Anal.* 34, 1997), :math:`\lambda_i = \frac{1}{t_1 - t_0}\sum_k \log|R^{(k)}_{ii}|`.

Limit cycles and describing functions
-------------------------------------
:func:`measure_oscillation` takes the last part of a simulated signal: peak amplitude
:math:`(\max - \min)/2` and the dominant frequency (FFT peak of the Hann-windowed,
mean-free signal, refined by a parabola through the three bins around it).

The describing function of an odd memoryless nonlinearity φ driven by :math:`A\sin\theta`
is its first-harmonic gain (Gelb & Vander Velde, *Multiple-Input Describing Functions and
Nonlinear System Design*, 1968, ch. 2)

.. math:: N(A) = \frac{2}{\pi A}\int_0^{\pi}\varphi(A\sin\theta)\sin\theta\,d\theta
          = \frac{4}{\pi A}\int_0^{\pi/2}\varphi(A\sin\theta)\sin\theta\,d\theta

(:func:`describing_gain`, by :func:`scipy.integrate.quad`, split at the kinks).  For the
ideal relay :math:`\varphi = h\operatorname{sign}` it is :math:`4h/(\pi A)`.  With several
nonlinearities :math:`\varphi_i(e_i)`, :math:`e_i = E_i z`, the harmonic balance
(:func:`harmonic_balance`) looks for an amplitude a of the output :math:`c z` at which the
quasi-linear system :math:`M(N_1(A_1), \dots)` has a pair of eigenvalues on the imaginary
axis, :math:`\pm j\omega`, with :math:`A_i = a\,|E_i v| / |c v|` from that mode's shape v
(a fixed point in v).  For one nonlinearity in a loop with transfer function G this is the
classical :math:`1 + N(A)G(j\omega) = 0`; for a relay around a third-order plant it gives
:math:`A = 4h|G(j\omega_{180})|/\pi` at the phase crossover :math:`\omega_{180}`.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl.analysis.budget import check_budget

__all__ = [
    "OrbitDiverges",
    "Oscillation",
    "PeriodicOrbit",
    "describing_gain",
    "expm_small",
    "finite_time_lyapunov",
    "harmonic_balance",
    "measure_oscillation",
    "periodic_orbit",
    "variational_flow",
]

Vector = NDArray[np.float64]
Rhs = Callable[[float, Vector], Vector]
Jac = Callable[[float, Vector], NDArray[np.float64]]

RTOL = 1e-6
"""Relative tolerance of the integrations (absolute: this times the states' typical
magnitudes)."""
SPLIT = 1
"""Exponential-midpoint steps per step of the trajectory's solver."""


def _atol(scale: Vector, rtol: float) -> Vector:
    return rtol * np.maximum(np.abs(scale), 1e-6)


_PADE = (1.0, 0.5, 5.0 / 44.0, 1.0 / 66.0, 1.0 / 792.0, 1.0 / 15840.0, 1.0 / 665280.0)


def expm_small(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """:math:`e^A` of a small matrix: diagonal Padé (6, 6) approximant with scaling and
    squaring (Higham, *SIAM J. Matrix Anal. Appl.* 26, 2005; the degree and the threshold
    ‖A/2^s‖₁ ≤ 0.5 give a relative error near rounding).  In plain numpy: scipy's
    :func:`scipy.linalg.expm` of a 9 × 9 matrix costs 10 ms under a busy threaded BLAS
    here, this 20 µs."""
    norm = float(np.max(np.sum(np.abs(a), axis=0))) if a.size else 0.0
    s = max(0, math.ceil(math.log2(norm / 0.5))) if norm > 0.5 else 0
    x = a / 2.0**s
    n = a.shape[0]
    ident = np.eye(n)
    x2 = x @ x
    x4 = x2 @ x2
    x6 = x4 @ x2
    c = _PADE
    even = c[0] * ident + c[2] * x2 + c[4] * x4 + c[6] * x6
    odd = x @ (c[1] * ident + c[3] * x2 + c[5] * x4)
    r = np.linalg.solve(even - odd, even + odd)
    for _ in range(s):
        r = r @ r
    return r


def trajectory(
    f: Rhs,
    jac: Jac,
    z0: Vector,
    t0: float,
    t1: float,
    *,
    scale: Vector | None = None,
    rtol: float = RTOL,
) -> Any:
    r""":func:`scipy.integrate.solve_ivp` (BDF, exact Jacobian, dense output) of
    :math:`\dot z = F(t, z)`; absolute tolerance ``rtol`` × the typical magnitudes
    ``scale`` (default :math:`|z_0|`, floored).  Every evaluation of F checks the time
    budget (:func:`aiofl.analysis.budget.check_budget`): a spent budget raises
    :class:`~aiofl.analysis.budget.BudgetExceeded` out of the solver.

    Parameters
    ----------
    f, jac
        The right-hand side F(t, z) and its Jacobian ∂F/∂z.
    z0, t0, t1
        The start state and the interval [s].
    scale
        The typical magnitudes of z (default |z0|).
    rtol
        The relative tolerance (default :data:`RTOL`).

    Returns
    -------
    scipy.integrate.OdeResult
        With dense output ``sol``.
    """
    z0 = np.asarray(z0, dtype=np.float64)
    sc = np.abs(z0) if scale is None else np.asarray(scale, dtype=np.float64)
    compiled = _compiled(f, z0)
    if compiled is not None:
        return compiled.integrate(z0, t0, t1, atol=_atol(sc, rtol), rtol=rtol)[0]
    from scipy.integrate import solve_ivp

    def budgeted(t: float, z: Vector) -> Vector:
        check_budget()
        return f(t, z)

    sol = solve_ivp(
        budgeted,
        (t0, t1),
        z0,
        method="BDF",
        jac=jac,
        rtol=rtol,
        atol=_atol(sc, rtol),
        dense_output=True,
    )
    if not sol.success:
        raise ArithmeticError(f"integration failed: {sol.message}")
    return sol


def variational_flow(
    f: Rhs,
    jac: Jac,
    z0: Vector,
    t0: float,
    t1: float,
    *,
    phi0: NDArray[np.float64] | None = None,
    scale: Vector | None = None,
    rtol: float = RTOL,
    split: int = SPLIT,
) -> tuple[Vector, NDArray[np.float64]]:
    r"""Integrate :math:`\dot z = F(t,z)` and :math:`\dot\Phi = J(t,z)\Phi` from
    :math:`t_0` to :math:`t_1` (module docstring).

    z by :func:`trajectory`; Φ by the exponential midpoint rule on the solver's steps,
    each cut into ``split`` parts, :math:`\Phi_{k+1} = \exp(h_k J(t_k + h_k/2,
    z(t_k + h_k/2)))\,\Phi_k` (Magnus' method of order 2; Iserles & Nørsett, *Phil.
    Trans. R. Soc. A* 357, 1999), stable for the stiff observer poles at any step.

    Parameters
    ----------
    f, jac
        Right-hand side and its exact Jacobian ∂F/∂z (n × n).
    z0
        State at :math:`t_0`.
    phi0
        :math:`\Phi(t_0)` (n × k; default the identity).
    scale
        Typical magnitudes of z for the absolute tolerance (default :math:`|z_0|`).

    t0, t1
        The interval [s].
    rtol
        The relative tolerance of :func:`trajectory` (default :data:`RTOL`).
    split
        Parts each solver step is cut into (default :data:`SPLIT`).

    Returns
    -------
    z1, phi1
        :math:`z(t_1)` and :math:`\Phi(t_1)`.
    """
    n = np.asarray(z0).size
    d = np.ones(n) if scale is None else np.maximum(np.asarray(scale, dtype=np.float64), 1e-300)
    # Φ in the coordinates z / scale (balanced: the observer's couplings span 1e16)
    phi = np.eye(n) if phi0 is None else np.asarray(phi0, dtype=np.float64) / d[:, None]
    if (compiled := _compiled(f, np.asarray(z0, dtype=np.float64))) is not None:
        sc = np.abs(np.asarray(z0, dtype=np.float64)) if scale is None else scale
        sol, phi = compiled.integrate(  # z and Φ in one compiled integration
            z0, t0, t1, atol=_atol(sc, rtol), rtol=rtol, phi=phi, dscale=d, split=split
        )
    else:
        sol = trajectory(f, jac, z0, t0, t1, scale=scale, rtol=rtol)
        phi = _midpoint_flow(jac, sol, phi, d, split)
    if phi0 is None:
        return sol.y[:, -1], phi * d[:, None] / d[None, :]
    return sol.y[:, -1], phi * d[:, None]


def _midpoint_flow(
    jac: Jac, sol: Any, phi: NDArray[np.float64], d: Vector, split: int
) -> NDArray[np.float64]:
    """Φ (scaled by d) advanced by the exponential midpoint rule over the steps of ``sol``,
    each cut into ``split`` parts (:func:`variational_flow`)."""
    grid = np.asarray(sol.t, dtype=np.float64)
    fine = (
        grid
        if split == 1  # linspace(a, b, 1, endpoint=False) is [a]
        else np.concatenate(
            [np.linspace(a, b, split, endpoint=False) for a, b in itertools.pairwise(grid)]
            + [grid[-1:]]
        )
    )
    for a, b in itertools.pairwise(fine):
        check_budget()
        tm = 0.5 * (a + b)
        jw = jac(tm, sol.sol(tm)) * d[None, :] / d[:, None]
        phi = expm_small((b - a) * jw) @ phi
    return phi


def _compiled(f: Rhs, z0: Vector) -> Any:
    """``f.integrator`` (:class:`aiofl.analysis.loop_radau.LoopIntegrator`) when it applies
    at z0, else None (scipy integrates)."""
    integrator = getattr(f, "integrator", None)
    if integrator is None or not integrator.usable(z0):
        return None
    return integrator


class OrbitDiverges(ArithmeticError):
    """The solution leaves every bounded set while settling: there is no periodic orbit."""


@dataclass(frozen=True)
class PeriodicOrbit:
    """A T-periodic solution and its Floquet multipliers (:func:`periodic_orbit`).

    Attributes
    ----------
    z0
        The state on the orbit at ``t0``.
    t0, period
        Start time and period T.
    monodromy
        :math:`\\Phi(t_0 + T)`.
    multipliers
        Its eigenvalues, by decreasing modulus.
    closing
        :math:`\\max_i |z_i(t_0+T) - z_i(t_0)| / s_i` of the last pass (s: the typical
        magnitudes): how well the orbit closes.
    newton_steps
        Variational passes taken.
    largest_range
        (min, max) of the largest multiplier's modulus over those passes: how far the
        answer moved from one period to the next.
    """

    z0: Vector
    t0: float
    period: float
    monodromy: NDArray[np.float64]
    multipliers: NDArray[np.complex128]
    closing: float
    newton_steps: int
    largest_range: tuple[float, float] = (0.0, 0.0)

    @property
    def largest(self) -> float:
        """The largest modulus :math:`\\max_i |\\mu_i|`."""
        return float(np.abs(self.multipliers[0]))


def periodic_orbit(
    f: Rhs,
    jac: Jac,
    z0: Vector,
    period: float,
    *,
    t0: float = 0.0,
    settle: int = 3,
    max_newton: int = 3,
    tol: float = 1e-6,
    rtol: float = RTOL,
    split: int = SPLIT,
    close_on: Sequence[int] | None = None,
    newton: bool = False,
    bound: float = 10.0,
) -> PeriodicOrbit:
    r"""The T-periodic steady state reached from z0 at :math:`t_0` and its Floquet multipliers.

    ``settle`` periods of plain simulation (at 100 × ``rtol``), then variational passes
    over the following periods (with ``newton``, shooting steps instead; module
    docstring) until the states ``close_on`` (default all) close to ``tol`` relative to
    their typical magnitudes (the largest |z_i| seen while settling, floored at 1e-3 times
    the largest of them) or ``max_newton`` passes; the multipliers are those of the last
    pass.  Raises :class:`OrbitDiverges` when, while settling, the peak of a state of
    ``close_on`` over a period grows more than ``bound``-fold over that of the period
    before.

    Parameters
    ----------
    f, jac
        The right-hand side F(t, z) and its Jacobian.
    z0
        The start state.
    period
        The period T [s].
    t0
        The start time [s].
    settle, max_newton
        Periods of plain simulation, and the most variational (or shooting) passes.
    tol
        The closing tolerance, relative to the states' magnitudes.
    rtol, split
        As for :func:`variational_flow`.
    close_on
        The indices of the states that must close (None: all).
    newton
        Take shooting (Newton) steps instead of plain passes.
    bound
        The growth of a period's peak that counts as diverging.

    Returns
    -------
    PeriodicOrbit
    """
    idx = np.arange(np.asarray(z0).size) if close_on is None else np.asarray(close_on)
    z = np.asarray(z0, dtype=np.float64)
    sc = np.maximum(np.abs(z), 1e-6 * max(float(np.max(np.abs(z))), 1.0))
    t = t0
    peak = None
    for _ in range(settle):
        sol = trajectory(f, jac, z, t, t + period, scale=sc, rtol=100 * rtol)
        new_peak = np.max(np.abs(sol.y[idx]), axis=1)
        if not np.all(np.isfinite(sol.y)) or (
            peak is not None and np.max(new_peak / np.maximum(peak, 1e-300)) > bound
        ):
            raise OrbitDiverges(
                f"a state's peak grows more than {bound:g}-fold from one period to the next "
                "while settling: no periodic orbit"
            )
        peak = new_peak
        sc = np.maximum(sc, np.max(np.abs(sol.y), axis=1))
        z = sol.y[:, -1]
        t += period
    sc = np.maximum(sc, 1e-3 * float(np.max(sc[idx])))
    best: tuple[float, Vector, NDArray[np.float64]] | None = None
    largest: list[float] = []
    steps = 0
    for steps in range(1, max_newton + 1):  # noqa: B007 (steps is returned)
        z1, phi = variational_flow(f, jac, z, t, t + period, scale=sc, rtol=rtol, split=split)
        closing = float(np.max(np.abs(z1 - z)[idx] / sc[idx]))
        mu = np.linalg.eigvals(phi)
        largest.append(float(np.max(np.abs(mu))))
        best = (closing, z, phi)
        if closing <= tol:
            break
        if newton:
            try:
                step = np.linalg.solve(np.eye(z.size) - phi, z1 - z)
            except np.linalg.LinAlgError:
                step = z1 - z
            z = z + step if np.all(np.isfinite(step)) else z1
        else:  # the next period (F is T-periodic)
            z = z1
    assert best is not None
    closing, zs, phi = best
    mu = np.linalg.eigvals(phi)
    mu = mu[np.argsort(-np.abs(mu), kind="stable")]
    return PeriodicOrbit(zs, t, period, phi, mu, closing, steps, (min(largest), max(largest)))


def finite_time_lyapunov(
    f: Rhs,
    jac: Jac,
    z0: Vector,
    t0: float,
    t1: float,
    *,
    renorm: float = 0.5,
    scale: Vector | None = None,
    rtol: float = 1e-6,
) -> NDArray[np.float64]:
    """Finite-time Lyapunov exponents over :math:`[t_0, t_1]` [1/s], largest first (QR
    re-orthonormalisation every ``renorm`` seconds; module docstring).

    Parameters
    ----------
    f, jac
        The right-hand side F(t, z) and its Jacobian.
    z0, t0, t1
        The start state and the interval [s].
    renorm
        The re-orthonormalisation interval [s].
    scale, rtol
        As for :func:`variational_flow`.

    Returns
    -------
    ndarray
        The n exponents [1/s], largest first.
    """
    z = np.asarray(z0, dtype=np.float64)
    n = z.size
    q = np.eye(n)
    logs = np.zeros(n)
    t = t0
    sc = np.abs(z) if scale is None else np.asarray(scale)
    while t < t1 - 1e-12:
        t_next = min(t + renorm, t1)
        z, phi = variational_flow(f, jac, z, t, t_next, phi0=q, scale=sc, rtol=rtol)
        q, r = np.linalg.qr(phi)
        d = np.abs(np.diag(r))
        logs += np.log(np.maximum(d, np.finfo(np.float64).tiny))
        t = t_next
    return np.sort(logs / (t1 - t0))[::-1]


@dataclass(frozen=True)
class Oscillation:
    """Peak amplitude and dominant frequency of a signal's last part."""

    amplitude: float
    frequency: float  # rad/s
    centre: float


def measure_oscillation(t: Vector, x: Vector) -> Oscillation:
    """Amplitude :math:`(\\max - \\min)/2`, centre and dominant frequency [rad/s] of x(t)
    on a uniform grid t: the FFT peak of the Hann-windowed, mean-free signal (a parabola
    through the log-magnitudes of the three bins around it), replaced by the mean period
    between upward crossings of the centre when that is within 20 % of it (finer than a
    bin)."""
    t = np.asarray(t, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    hi, lo = float(np.max(x)), float(np.min(x))
    dt = float(t[1] - t[0])
    xc = (x - x.mean()) * np.hanning(x.size)
    spec = np.abs(np.fft.rfft(xc))
    k = int(np.argmax(spec[1:]) + 1) if spec.size > 2 else 0
    shift = 0.0
    if 1 <= k < spec.size - 1 and np.all(spec[k - 1 : k + 2] > 0):
        a, b, c = np.log(spec[k - 1 : k + 2])
        den = a - 2 * b + c
        shift = 0.5 * (a - c) / den if den != 0 else 0.0
    freq = 2.0 * math.pi * (k + shift) / (x.size * dt)
    # refine by the mean period between upward crossings of the centre (linear interpolation)
    xm = x - 0.5 * (hi + lo)
    up = np.nonzero((xm[:-1] < 0) & (xm[1:] >= 0))[0]
    if up.size >= 3:
        tc = t[up] - xm[up] * dt / (xm[up + 1] - xm[up])
        f_cross = 2.0 * math.pi * (up.size - 1) / float(tc[-1] - tc[0])
        if abs(f_cross - freq) <= 0.2 * freq:
            freq = f_cross
    return Oscillation(0.5 * (hi - lo), float(freq), 0.5 * (hi + lo))


def describing_gain(
    phi: Callable[[float], float], amplitude: float, kinks: Sequence[float] = ()
) -> float:
    r"""First-harmonic gain N(A) of an odd memoryless φ (module docstring), by
    :func:`scipy.integrate.quad` over :math:`[0, \pi/2]`, split where
    :math:`A\sin\theta` crosses a kink (|e| = δ of fal).

    Parameters
    ----------
    phi
        The odd memoryless nonlinearity.
    amplitude
        The amplitude A > 0.
    kinks
        The values of |e| where φ is not smooth.

    Returns
    -------
    float
    """
    from scipy.integrate import quad

    a = float(amplitude)
    if not a > 0:
        raise ValueError(f"amplitude = {a}; allowed: > 0")
    pts = sorted(math.asin(k / a) for k in kinks if 0 < k < a)
    edges = [0.0, *pts, 0.5 * math.pi]
    total = 0.0
    for lo, hi in itertools.pairwise(edges):
        total += quad(lambda th: phi(a * math.sin(th)) * math.sin(th), lo, hi, limit=200)[0]
    return 4.0 * total / (math.pi * a)


@dataclass(frozen=True)
class Balance:
    """A harmonic-balance solution: output amplitude a at frequency ω [rad/s], with the
    amplitudes A_i and describing gains N_i of the nonlinearities' inputs."""

    amplitude: float
    frequency: float
    input_amplitudes: tuple[float, ...]
    gains: tuple[float, ...]


def _critical_mode(
    m: NDArray[np.float64],
) -> tuple[complex, NDArray[np.complex128]]:
    lam, vec = np.linalg.eig(m)
    osc = [i for i in range(lam.size) if lam[i].imag > 1e-9 * max(1.0, abs(lam[i]))]
    pool = osc or list(range(lam.size))
    i = max(pool, key=lambda j: lam[j].real)
    return complex(lam[i]), vec[:, i]


def harmonic_balance(
    quasi_linear: Callable[[Sequence[float]], NDArray[np.float64]],
    error_rows: NDArray[np.float64],
    output_row: NDArray[np.float64],
    describing: Sequence[Callable[[float], float]],
    mode0: NDArray[np.complex128],
    *,
    a_range: tuple[float, float] = (1e-12, 1e2),
    grid: int = 57,
    fixed_point: int = 6,
) -> Balance | None:
    r"""Amplitude a of :math:`c z` and frequency ω at which the quasi-linear system has
    eigenvalues :math:`\pm j\omega` (module docstring).

    Parameters
    ----------
    quasi_linear
        :math:`(N_1, \dots, N_m) \mapsto M`, the system matrix with each nonlinearity
        replaced by its gain.
    error_rows
        :math:`E` (m × n): the nonlinearities' inputs :math:`e_i = E_i z`.
    output_row
        c: the output whose amplitude is a.
    describing
        :math:`A \mapsto N_i(A)`, one per nonlinearity.
    mode0
        A starting mode shape (the unstable eigenvector of the linearisation).

    a_range
        The amplitudes searched, (low, high).
    grid
        Log-spaced amplitudes in ``a_range`` scanned for a sign change.
    fixed_point
        Fixed-point iterations of the mode shape per amplitude.

    Returns
    -------
    Balance or None
        The stable balance (Re λ goes from > 0 below a to < 0 above it; the limit cycle
        an unstable equilibrium settles on), or None when Re λ does not change sign so
        over ``a_range`` (log-spaced ``grid`` points, then :func:`scipy.optimize.brentq`).
    """
    from scipy.optimize import brentq

    e_rows = np.atleast_2d(np.asarray(error_rows, dtype=np.float64))
    c = np.asarray(output_row, dtype=np.float64)
    state = {"v": np.asarray(mode0, dtype=np.complex128)}

    def evaluate(a: float) -> tuple[complex, tuple[float, ...], tuple[float, ...]]:
        check_budget()
        v = state["v"]
        lam, amps, gains = 0j, (), ()
        for _ in range(fixed_point):
            cv = abs(c @ v)
            if cv == 0:
                cv = 1.0
            amps = tuple(max(a * abs(row @ v) / cv, 1e-300) for row in e_rows)
            gains = tuple(n_i(x) for n_i, x in zip(describing, amps, strict=True))
            lam, v_new = _critical_mode(quasi_linear(gains))
            if np.allclose(
                np.abs(e_rows @ v_new) / max(abs(c @ v_new), 1e-300),
                np.abs(e_rows @ v) / cv,
                rtol=1e-6,
            ):
                v = v_new
                break
            v = v_new
        state["v"] = v
        return lam, amps, gains

    a_grid = np.geomspace(a_range[0], a_range[1], grid)
    re = []
    for a in a_grid:
        re.append(evaluate(float(a))[0].real)
        if len(re) > 1 and re[-2] > 0 >= re[-1]:
            lo, hi = float(a_grid[len(re) - 2]), float(a)
            root = brentq(
                lambda la: evaluate(math.exp(la))[0].real, math.log(lo), math.log(hi), xtol=1e-10
            )
            a_star = math.exp(root)
            lam, amps, gains = evaluate(a_star)
            return Balance(a_star, abs(lam.imag), amps, gains)
    return None
