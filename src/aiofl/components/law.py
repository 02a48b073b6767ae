r"""Linearizing control laws: the active law (AIOFL, eq. 14) and classical IOFL (Section III).

* AIOFL, text before eq. (14):

  .. math:: u = v - \frac{\hat\xi_{\rho+1}}{b_0}

  With the ESO converged, :math:`\dot\xi_\rho = \xi_{\rho+1} + b_0 u \approx b_0 v`: the
  plant seen by v is the chain of ρ integrators (14), whatever f, β(x) and the disturbance
  are.  Only ρ and :math:`b_0` are needed.

* Classical IOFL (Section III):

  .. math:: u = \frac{-\alpha(x) + v}{\beta(x)},\quad
            \alpha = L_f^\rho h,\ \beta = L_g L_f^{\rho-1} h

  which needs the full model.

Both optionally saturate to the actuator range,
:math:`u \leftarrow \min(\max(u, u_{min}), u_{max})` (:func:`saturate_range`; the engine's
default range is :math:`u_{min} = -u_{max}`, :math:`u_{max} = \infty`, i.e. none).
"""

from __future__ import annotations

from numba import njit

from aiofl.components.fastmath import JIT_OPTIONS

__all__ = ["aiofl_law", "iofl_law", "saturate", "saturate_range"]


@njit(**JIT_OPTIONS)
def saturate(u: float, u_max: float) -> float:
    """Clip ``u`` to ``[-u_max, u_max]`` (``u_max = inf`` disables it)."""
    v = u_max if u > u_max else u  # two plain selects: vectorizable in a loop over lanes
    return -u_max if v < -u_max else v


@njit(**JIT_OPTIONS)
def saturate_range(u: float, u_min: float, u_max: float) -> float:
    r"""Clip ``u`` to the actuator range :math:`[u_{min}, u_{max}]` (asymmetric allowed).

    .. math:: \operatorname{sat}(u) = \begin{cases} u_{max} & u > u_{max} \\
              u_{min} & u < u_{min} \\ u & \text{otherwise} \end{cases}

    ``u_min = -inf`` / ``u_max = inf`` leave that side open; NaN passes through (so the
    engine's divergence check sees it).  With ``u_min = -u_max`` this is :func:`saturate`
    exactly.  The caller guarantees :math:`u_{min} < u_{max}`.  Written as two plain
    selects, which LLVM vectorizes in a loop over lanes (:mod:`aiofl.engine.loop`).
    """
    v = u_max if u > u_max else u
    return u_min if v < u_min else v


@njit(**JIT_OPTIONS)
def aiofl_law(v: float, xi_hat_ext: float, b0: float) -> float:
    r"""Active linearizing law, eq. (14): :math:`u = v - \hat\xi_{\rho+1}/b_0`."""
    return v - xi_hat_ext / b0


@njit(**JIT_OPTIONS)
def iofl_law(v: float, alpha: float, beta: float) -> float:
    r"""Classical IOFL law (Section III): :math:`u = (-\alpha(x) + v)/\beta(x)`."""
    return (-alpha + v) / beta
