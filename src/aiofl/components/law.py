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

* Model-assisted AIOFL (:func:`model_assisted_law`): the nominal model's
  :math:`\alpha_0, \beta_0` at the observer's state estimate, and the ESO's extended state
  for what the model misses.

Both optionally saturate to the actuator range,
:math:`u \leftarrow \min(\max(u, u_{min}), u_{max})` (:func:`saturate_range`; the engine's
default range is :math:`u_{min} = -u_{max}`, :math:`u_{max} = \infty`, i.e. none).
"""

from __future__ import annotations

from numba import njit

from aiofl.components.fastmath import JIT_OPTIONS

__all__ = ["aiofl_law", "iofl_law", "model_assisted_law", "saturate", "saturate_range"]


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
    selects, which LLVM vectorizes in a loop over lanes (:mod:`aiofl.engine.kernel.loop`).

    Parameters
    ----------
    u
        The command.
    u_min, u_max
        The range, :math:`u_{min} < u_{max}` (±inf: open).

    Returns
    -------
    float
    """
    v = u_max if u > u_max else u
    return u_min if v < u_min else v


@njit(**JIT_OPTIONS)
def aiofl_law(v: float, xi_hat_ext: float, b0: float) -> float:
    r"""Active linearizing law, eq. (14): :math:`u = v - \hat\xi_{\rho+1}/b_0`.

    Parameters
    ----------
    v
        The SEF's output.
    xi_hat_ext
        :math:`\hat\xi_{\rho+1}`, the total-disturbance estimate.
    b0
        b₀ ≠ 0.

    Returns
    -------
    float
        u.
    """
    return v - xi_hat_ext / b0


@njit(**JIT_OPTIONS)
def model_assisted_law(
    v: float, xi_hat_ext: float, b0: float, alpha_hat: float, beta_hat: float
) -> float:
    r"""Model-assisted active law: :math:`u = (b_0 v - \hat\alpha - \hat\xi_{\rho+1})/\hat\beta`.

    With the model-assisted ESO (S. Zhao and Z. Gao's model-assisted ADRC, which gives the
    observer the known part of the model; Sira-Ramírez's GPI observers are the same idea)
    the ρ-th observer equation carries the nominal normal form,
    :math:`\dot{\hat\xi}_\rho = \hat\xi_{\rho+1} + \hat\alpha + \hat\beta u + \beta_\rho e`
    with :math:`\hat\alpha = \alpha_0(\hat x)`, :math:`\hat\beta = \beta_0(\hat x)`,
    :math:`\hat x = \Phi^{-1}(\hat\xi)`, and :math:`\hat\xi_{\rho+1}` estimates only the
    residual :math:`y^{(\rho)} - \alpha_0 - \beta_0 u`.  This law cancels all three, so
    :math:`y^{(\rho)} \approx b_0 v`: the same chain (14) as :func:`aiofl_law`, whose v (and
    SEF gains) it keeps.  With :math:`\hat\alpha = 0`, :math:`\hat\beta = b_0` it is
    :func:`aiofl_law`.

    Parameters
    ----------
    v, xi_hat_ext, b0
        As for :func:`aiofl_law`.
    alpha_hat, beta_hat
        :math:`\hat\alpha` and :math:`\hat\beta` ≠ 0 of the nominal model.

    Returns
    -------
    float
        u.
    """
    return (b0 * v - alpha_hat - xi_hat_ext) / beta_hat


@njit(**JIT_OPTIONS)
def iofl_law(v: float, alpha: float, beta: float) -> float:
    r"""Classical IOFL law (Section III): :math:`u = (-\alpha(x) + v)/\beta(x)`.

    Parameters
    ----------
    v
        The SEF's output.
    alpha, beta
        α(x) and β(x) ≠ 0 of the normal form.

    Returns
    -------
    float
        u.
    """
    return (-alpha + v) / beta
