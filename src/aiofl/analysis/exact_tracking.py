r"""Exact output tracking by inverting the nominal model (flatness, ρ = n).

When the relative degree equals the state dimension (ρ = n), the output y is a *flat
output*: the state and the input are algebraic functions of y and its first n derivatives.
Requiring :math:`y \equiv r` therefore fixes the state trajectory :math:`x^*(t)` and the
input :math:`u^*(t)` uniquely,

.. math::
    \xi(x^*) = (r, \dot r, \dots, r^{(\rho-1)}),\qquad
    u^* = \frac{r^{(\rho)} - L_f^\rho h(x^*)}{L_gL_f^{\rho-1}h(x^*)} - c\,\tau_d ,

(Section III; the last term cancels a *matched* disturbance :math:`b_d = c\,g`).  Since
:math:`u^*` is the only input that keeps :math:`y = r` for all t, its
:math:`\mathrm{ISU} = \int u^{*2}dt` is the least control energy with which *any*
controller can track the reference exactly; a controller's ISU beside it shows what its
tracking costs (eq. 22).  Caveat: :math:`x^*(0)` is generally not the rest state the
scenarios start from (for :math:`r = \tfrac{\pi}{4}\sin 2t`, :math:`\dot r(0) = \pi/2`),
so a real controller also pays for an initial transient.

For the single-link flexible-joint manipulator (eq. 15) the inversion is closed-form
(:func:`slfjm_inverse`).  With :math:`y = x_1 + x_2`, :math:`\Gamma = mgh`,

.. math::
    \ddot y = -\frac{K_s}{J_l}x_2 + \frac{\Gamma}{J_l}\sin y
    \;\Rightarrow\; x_2 = \frac{\Gamma\sin y - J_l\ddot y}{K_s},\quad
    x_4 = \dot x_2 = \frac{\Gamma\cos y\,\dot y - J_l y^{(3)}}{K_s},

:math:`x_1 = y - x_2`, :math:`x_3 = \dot y - x_4`, and :math:`u` follows from the fourth
state equation with :math:`\dot x_4 = (\Gamma(\cos y\,\ddot y - \sin y\,\dot y^2) -
J_l y^{(4)})/K_s`.  Other plants with ρ = n use their ``normal_form`` (solved for x by
Newton's method at each time point).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aiofl.components import metrics
from aiofl.plants.base import Plant
from aiofl.scenario import Reference, Scenario

if TYPE_CHECKING:  # pragma: no cover
    from aiofl.config import RunConfig

__all__ = [
    "ExactTracking",
    "exact_tracking",
    "exact_tracking_cost",
    "exact_tracking_input",
    "reference_derivatives",
    "slfjm_inverse",
]


@dataclass(frozen=True)
class ExactTracking:
    """The unique state and input trajectories that keep :math:`y \\equiv r`.

    Attributes
    ----------
    t
        Time points [s].
    x
        State :math:`x^*(t)`, shape (T, n).
    u
        Input :math:`u^*(t)`, shape (T,).
    """

    t: NDArray[np.float64]
    x: NDArray[np.float64]
    u: NDArray[np.float64]

    @property
    def isu(self) -> float:
        r""":math:`\int u^{*2}dt` over ``t`` (trapezoidal rule)."""
        return metrics.isu(self.t, self.u)

    @property
    def iau(self) -> float:
        r""":math:`\int |u^*|dt` over ``t`` (trapezoidal rule)."""
        return metrics.iau(self.t, self.u)


def reference_derivatives(reference: Reference, t: ArrayLike, order: int) -> NDArray[np.float64]:
    r""":math:`r, \dot r, \dots, r^{(order)}` at ``t``, shape (order+1, T).

    Only a sine reference is smooth enough: :math:`r^{(k)} = A\omega^k
    \sin(\omega t + \varphi + k\pi/2)` (plus the offset for k = 0).  A step or sampled
    reference has no ``order`` derivatives and cannot be tracked exactly by a plant of
    relative degree ``order``; that raises :class:`ValueError`.

    Parameters
    ----------
    reference
        The reference; only ``kind = "sine"`` is accepted.
    t
        The times [s], any shape T.
    order
        The highest derivative, ≥ 0 (the plant's relative degree).

    Returns
    -------
    ndarray
        Shape (order + 1, T).
    """
    if reference.kind != "sine":
        raise ValueError(
            f"reference.kind = {reference.kind!r} is not {order} times differentiable; exact "
            "tracking needs a smooth reference (allowed: 'sine')"
        )
    t = np.asarray(t, dtype=np.float64)
    out = np.empty((order + 1, *t.shape))
    ph = reference.omega * t + reference.phase
    for k in range(order + 1):
        out[k] = reference.amplitude * reference.omega**k * np.sin(ph + 0.5 * np.pi * k)
    out[0] += reference.offset
    return out


def slfjm_inverse(
    derivs: NDArray[np.float64], p: NDArray[np.float64], d: ArrayLike = 0.0
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Closed-form inverse of the SLFJM (eq. 15) along :math:`y, \\dot y, \\dots, y^{(4)}`.

    Parameters
    ----------
    derivs
        Shape (5, T): :math:`y, \\dot y, \\ddot y, y^{(3)}, y^{(4)}`.
    p
        Parameter vector in :data:`aiofl.plants.builtin.SLFJM_PARAMS` order.
    d
        Load torque :math:`\\tau_d` [N·m] at each time point (scalar or (T,)).

    Returns
    -------
    x, u
        State (T, 4) and input (T,).
    """
    ks, jh, m, g, h, km, kg, jl, rm = (float(v) for v in p)
    y, y1, y2, y3, y4 = derivs
    gam = m * g * h
    damp = km * km * kg * kg / (rm * jh)
    b = km * kg / (rm * jh)
    sy, cy = np.sin(y), np.cos(y)
    x2 = (gam * sy - jl * y2) / ks
    x4 = (gam * cy * y1 - jl * y3) / ks
    x4dot = (gam * (cy * y2 - sy * y1 * y1) - jl * y4) / ks
    x1 = y - x2
    x3 = y1 - x4
    f4 = -(ks / jh + ks / jl) * x2 + damp * x3 + gam / jl * sy
    # x4dot = f4 - b u - d / jh
    u = (f4 - x4dot - np.asarray(d, dtype=np.float64) / jh) / b
    return np.stack([x1, x2, x3, x4], axis=-1), np.broadcast_to(u, y.shape).copy()


def _matched_disturbance_gain(
    plant: Plant, x: NDArray[np.float64], p: NDArray[np.float64]
) -> float:
    """c with b_d(x) = c·g(x) (a matched disturbance), or raise ValueError."""
    if plant.bd is None:
        return 0.0
    g = np.asarray(plant.g(x, p), dtype=np.float64)
    bd = np.asarray(plant.bd(x, p), dtype=np.float64)
    k = int(np.argmax(np.abs(g)))
    c = bd[k] / g[k]
    if not np.allclose(bd, c * g, rtol=1e-12, atol=1e-12 * np.abs(bd).max()):
        raise ValueError(
            f"plant {plant.name!r}: the disturbance input b_d is not matched (b_d != c·g), "
            "so it cannot be cancelled through u; exact tracking under a disturbance is "
            "only available for matched disturbances"
        )
    return float(c)


def _normal_form_inverse(
    plant: Plant, derivs: NDArray[np.float64], p: NDArray[np.float64], d: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Invert ξ(x) = (y..y^(ρ-1)) with Newton's method, u = (y^(ρ) - α)/β - c·d."""
    from scipy.optimize import fsolve

    rho = plant.relative_degree
    n = plant.n_states
    nf = plant.normal_form
    assert nf is not None and rho is not None
    n_t = derivs.shape[1]
    xs = np.zeros((n_t, n))
    us = np.zeros(n_t)
    guess = np.zeros(n)
    for k in range(n_t):
        target = derivs[:rho, k]

        def resid(x: NDArray[np.float64], target: NDArray[np.float64] = target) -> Any:
            return np.asarray(nf(x, p), dtype=np.float64)[:rho] - target

        x, _info, ier, msg = fsolve(resid, guess, full_output=True, xtol=1e-13)
        if ier != 1 or np.max(np.abs(resid(x))) > 1e-9 * (1.0 + np.max(np.abs(target))):
            raise ValueError(
                f"plant {plant.name!r}: cannot invert the normal form at t[{k}]: {msg}"
            )
        vals = np.asarray(nf(x, p), dtype=np.float64)
        alpha, beta = vals[rho], vals[rho + 1]
        c = _matched_disturbance_gain(plant, x, p) if d[k] != 0.0 else 0.0
        us[k] = (derivs[rho, k] - alpha) / beta - c * d[k]
        xs[k] = x
        guess = x
    return xs, us


def exact_tracking_input(
    plant: Plant,
    reference: Reference,
    t: ArrayLike,
    *,
    params: NDArray[np.float64] | Mapping[str, float] | None = None,
    disturbance: ArrayLike = 0.0,
) -> ExactTracking:
    r"""The state :math:`x^*(t)` and input :math:`u^*(t)` that make :math:`y \equiv r`.

    Parameters
    ----------
    plant
        A plant with ρ = n (``relative_degree == n_states``).  The SLFJM is inverted in
        closed form; other plants need ``normal_form``.
    reference
        A sine reference (it must be ρ times differentiable).
    t
        Time points [s].
    params
        The plant's parameter vector (or overrides by name); nominal if omitted.
    disturbance
        :math:`\tau_d(t)` at the time points (scalar or array); it must be matched.

    Returns
    -------
    ExactTracking
        ``t``, ``x`` (T, n), ``u`` (T,).  Simulating the plant open loop from
        ``x[0]`` with ``u`` reproduces :math:`y = r`.
    """
    rho = plant.relative_degree
    if rho is None or rho != plant.n_states:
        raise ValueError(
            f"plant {plant.name!r}: exact tracking by inversion needs relative degree = number "
            f"of states (flat output); got rho={rho}, n={plant.n_states}"
        )
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    if params is None:
        p = plant.param_vector()
    elif isinstance(params, Mapping):
        p = plant.param_vector(params)
    else:
        p = np.asarray(params, dtype=np.float64)
    d = np.broadcast_to(np.asarray(disturbance, dtype=np.float64), t.shape).copy()
    derivs = reference_derivatives(reference, t, rho)
    if plant.name == "slfjm" and plant.n_states == 4:
        x, u = slfjm_inverse(derivs, p, d)
    elif plant.normal_form is not None:
        x, u = _normal_form_inverse(plant, derivs, p, d)
    else:
        raise ValueError(
            f"plant {plant.name!r} has no normal_form; exact tracking needs it (or use the "
            "built-in 'slfjm')"
        )
    return ExactTracking(t=t, x=x, u=u)


def exact_tracking(
    plant: Plant, scenario: Scenario, t: ArrayLike | None = None, *, dt: float = 1e-4
) -> ExactTracking:
    """Exact tracking of ``scenario``'s reference by its *true* plant.

    The plant parameters change at ``scenario.parameter_change_time`` (e.g. the paper's
    scenario 2: :math:`J_l \\times 1.4` from t = 0) and the step disturbance is cancelled
    through u (it is matched for the SLFJM).  Measurement noise does not change the true
    output, so it plays no part.  ``t`` defaults to a grid of step ``dt`` over the horizon.

    Parameters
    ----------
    plant, scenario
        The plant and the scenario whose reference, disturbance and parameter change apply.
    t
        The times [s] (default: step ``dt`` from 0 to ``t_final``).
    dt
        The grid step [s] when ``t`` is not given.

    Returns
    -------
    ExactTracking
    """
    if t is None:
        n = round(scenario.t_final / dt)
        t = np.linspace(0.0, n * dt, n + 1)
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    p_before = plant.param_vector()
    p_after = plant.param_vector(scenario.plant_overrides, scenario.plant_scale)
    d = np.where(t >= scenario.disturbance_time, scenario.disturbance_amplitude, 0.0)
    after = t >= scenario.parameter_change_time
    parts = []
    for mask, p in ((~after, p_before), (after, p_after)):
        if mask.any():
            parts.append(
                (
                    mask,
                    exact_tracking_input(
                        plant, scenario.reference, t[mask], params=p, disturbance=d[mask]
                    ),
                )
            )
    x = np.zeros((t.size, plant.n_states))
    u = np.zeros(t.size)
    for mask, part in parts:
        x[mask] = part.x
        u[mask] = part.u
    return ExactTracking(t=t, x=x, u=u)


def exact_tracking_cost(config: RunConfig, *, t_final: float | None = None) -> dict[str, float]:
    r"""ISU and IAU of the exact-tracking input for a run config's scenario (eq. 22).

    This is the least control energy with which any controller can keep :math:`y \equiv r`
    on the config's true plant over ``t_final`` (default: the scenario's horizon), on the
    config's step ``dt``.  Report tables show every controller's ISU beside it.

    Returns
    -------
    dict
        ``{"isu": ..., "iau": ..., "t_final": ..., "u_peak": ...}``.
    """
    from dataclasses import replace

    sc = config.scenario if t_final is None else replace(config.scenario, t_final=t_final)
    ex = exact_tracking(config.plant, sc, dt=config.dt)
    return {
        "isu": ex.isu,
        "iau": ex.iau,
        "t_final": float(sc.t_final),
        "u_peak": float(np.max(np.abs(ex.u))),
    }
