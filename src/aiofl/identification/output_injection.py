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
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from aiofl.plants.base import Plant

__all__ = ["InjectionError", "injection_gain", "linearisation"]


class InjectionError(ValueError):
    """No stabilising output injection (a bandwidth out of range, an unobservable pair)."""


def linearisation(
    plant: Plant, p: NDArray[np.float64], x0: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A = ∂f/∂x and C = ∂h/∂x at x0 (u = 0; central differences on the Python plant)."""
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
    for the default."""
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
