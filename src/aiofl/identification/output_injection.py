r"""The output-injection gain of a prediction-error model, for closed-loop logs.

An open-loop-unstable plant driven by its logged input cannot be simulated for long: the
smallest parameter error grows like :math:`e^{\lambda t}`.  The grey-box fit
(:mod:`aiofl.identification.grey_box`) then fits the predictor
:math:`\dot{\hat x} = f(\hat x) + g(\hat x)u + L\,(y_k - h(\hat x))` instead, with a fixed
gain L placed on the plant's linearisation :math:`A = \partial f/\partial x`,
:math:`C = \partial h/\partial x` at x0 (nominal parameters, u = 0): the eigenvalues of
:math:`A - LC` at :math:`-\omega(1, 1.2, 1.4, \dots)` (pole placement on the dual pair
:math:`(A^\top, C^\top)`, Kautsky, Nichols & Van Dooren, Int. J. Control 41, 1985, as
``scipy.signal.place_poles`` implements it), by default
:math:`\omega = 2\max(1, |\lambda(A)|_{\max})` rad/s (Ljung, *System Identification*,
2nd ed., 1999, §5.7: observer-based predictors of nonlinear state-space models).

**Continuation.**  The measured noise enters the predictor through L and, with an
output-only noise, biases the estimates in proportion to L (the predictor's implied noise
model is not the true one; Ljung §13.4).  So after the fit with L, :func:`continuation`
shrinks the gain by :data:`CONTINUATION` per step, polishing each time, while the
linearised predictor :math:`A(\hat\theta) - sLC` stays stable and the residual's RMS
grows by less than 20 %.  (Going on to s = 0, the consistent output-error fit, fails on an
unstable plant: its cost is so narrow that least squares leaves its basin.)

**The bias, estimated.**  The statistical :math:`s^2 (J^\top J)^{-1}` ignores the bias the
injection causes, and understates the error badly: on the grey-box test's inverted pendulum
(a closed-loop PRBS log, noise σ = 1e-3 rad, a 12-bit encoder) the estimates at gain factor
s = 0.24 were 0.8 % off with a statistical σ of 0.03-0.04 % of their values.  Fixed-gain
fits there show the bias growing linearly in the gain factor (0.77 % of ``a`` per unit of
s, from s = 1 down to 0.12), so :func:`continuation_bias` estimates it from the two last
estimates of the continuation, at :math:`s/c` and s (:math:`c` = :data:`CONTINUATION`;
when no step was accepted, a second polish at :math:`s/c` gives the other):
:math:`\hat b = |\hat\theta(s/c) - \hat\theta(s)|\,c/(1-c)` (the first-order term of a
Richardson extrapolation to s = 0; Richardson, Phil. Trans. R. Soc. A 210, 1911).  The
fit states :math:`\sqrt{\sigma^2 + \hat b^2}` as the standard error
(``ParameterEstimate.bias`` holds :math:`\hat b`; the correlation matrix is the statistical
one) and does not shift the estimate.  Measured on that pendulum over six noise seeds: the
truth lay 1.1-1.4 stated σ from the estimate, inside every 95 % interval (about ±0.7 % of
the values).  This is an error bound from a model of the bias, not a coverage proven like
the open-loop fit's.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl.plants.base import Plant

__all__ = [
    "CONTINUATION",
    "InjectionError",
    "continuation",
    "continuation_bias",
    "injection_gain",
    "linearisation",
]

CONTINUATION = 0.7
"""Each continuation step multiplies the output-injection gain by this factor."""


class InjectionError(ValueError):
    """No stabilising output injection (a bandwidth out of range, an unobservable pair)."""


def linearisation(
    plant: Plant, p: NDArray[np.float64], x0: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A = ∂f/∂x and C = ∂h/∂x at x0 (u = 0; central differences on the Python plant).

    Parameters
    ----------
    plant, p
        The plant and its parameter vector.
    x0
        The state to linearise at.

    Returns
    -------
    A, C : ndarray
        Shapes (n, n) and (n,).
    """
    n = plant.n_states
    a = np.empty((n, n))
    c = np.empty(n)
    for i in range(n):
        step = 1e-6 * max(1.0, abs(x0[i]))
        e = np.zeros(n)
        e[i] = step
        a[:, i] = (plant.rhs(x0 + e, 0.0, 0.0, p) - plant.rhs(x0 - e, 0.0, 0.0, p)) / (2 * step)
        c[i] = (plant.output(x0 + e, p) - plant.output(x0 - e, p)) / (2 * step)
    return a, c


def injection_gain(
    plant: Plant, p: NDArray[np.float64], x0: NDArray[np.float64], omega: float | None
) -> NDArray[np.float64]:
    """L placing the linearised observer's poles at -ω(1, 1.2, ...) (module notes); ω None
    for the default.

    Parameters
    ----------
    plant, p, x0
        As for :func:`linearisation`.
    omega
        The bandwidth ω [rad/s] > 0; None: twice the largest |eigenvalue| of A (at least 2).

    Returns
    -------
    ndarray
        L, shape (n,).
    """
    from scipy.signal import place_poles

    n = plant.n_states
    a, c = linearisation(plant, p, x0)
    if omega is None:
        omega = 2.0 * max(1.0, float(np.max(np.abs(np.linalg.eigvals(a)))))
    if not (math.isfinite(omega) and omega > 0):
        raise InjectionError(
            f"closed_loop = {omega!r}; allowed: True or an observer bandwidth > 0 rad/s"
        )
    poles = -omega * (1.0 + 0.2 * np.arange(n))
    try:
        res = place_poles(a.T, c[:, None], poles)
    except ValueError as exc:
        raise InjectionError(
            f"closed_loop: no output injection for plant {plant.name!r} at x0 (its linearisation "
            f"is not observable from y: {exc})"
        ) from None
    return np.asarray(res.gain_matrix, dtype=np.float64).reshape(n)


def continuation(
    obj: Any,
    z: NDArray[np.float64],
    gain: NDArray[np.float64],
    polish: Callable[[Any, NDArray[np.float64]], NDArray[np.float64]],
) -> tuple[NDArray[np.float64], float, NDArray[np.float64]]:
    """Shrink the injection gain by :data:`CONTINUATION` per step, polishing each time,
    while the linearised predictor stays stable at the current estimate and the residual's
    RMS grows by less than 20 %; the last accepted estimate, its gain factor s, and the
    estimate at the gain factor s/:data:`CONTINUATION` (the step before; polished here
    when no step was accepted), for :func:`continuation_bias`.

    ``obj`` is the grey-box fit's objective (``one(z)`` the residuals, ``params``, ``plant``,
    ``x0`` and the ``gain`` it simulates with, set here); ``polish(obj, z)`` its local
    least-squares stage.

    Parameters
    ----------
    obj
        The grey-box fit's objective (above); its ``gain`` is set here.
    polish
        ``polish(obj, z)``: the fit's local least-squares stage.
    z
        The estimate to start from (the fit's coordinates).
    gain
        The full injection gain L.

    Returns
    -------
    z : ndarray
        The last accepted estimate.
    s : float
        Its gain factor.
    z_previous : ndarray
        The estimate at s/:data:`CONTINUATION`.
    """

    def rms(zz: NDArray[np.float64]) -> float:
        r = obj.one(zz)
        return float(np.sqrt(np.mean(r * r)))

    scale, best = 1.0, rms(z)
    previous: NDArray[np.float64] | None = None
    while scale > 1e-3:
        trial = scale * CONTINUATION
        p = obj.params(z[None, :])[0]
        a, c = linearisation(obj.plant, p, obj.x0)
        if np.max(np.linalg.eigvals(a - trial * np.outer(gain, c)).real) >= 0.0:
            break
        obj.gain = gain * trial
        z_try = polish(obj, z)
        value = rms(z_try)
        if not value < 1.2 * best:
            break
        previous = z
        z, scale, best = z_try, trial, value
    if previous is None:  # no step taken: the estimate at the larger gain s / 0.7
        obj.gain = gain * (scale / CONTINUATION)
        previous = polish(obj, z)
    obj.gain = gain * scale
    return z, scale, previous


def continuation_bias(
    theta_previous: NDArray[np.float64], theta: NDArray[np.float64]
) -> NDArray[np.float64]:
    """The estimated bias magnitude at the last gain factor s, linear in s (module notes):
    :math:`|\\hat\\theta(s/c) - \\hat\\theta(s)|\\,c/(1-c)`."""
    return np.abs(theta_previous - theta) * CONTINUATION / (1.0 - CONTINUATION)
