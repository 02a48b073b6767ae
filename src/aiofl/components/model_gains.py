r"""Observer gains of the model-assisted ESO: its error poles where the bandwidth says.

With ``eso.model = "nominal"`` the observer (:func:`aiofl.components.law.model_assisted_law`)
is

.. math:: \dot{\hat\xi} = A\hat\xi + B\big(\hat\alpha(\hat\xi) + \hat\beta(\hat\xi)u\big)
          + L\,(y - \hat\xi_1),

with A the chain of ρ+1 integrators (6), B the ρ-th unit vector and
:math:`(\hat\alpha, \hat\beta) = (\alpha_0, \beta_0)(\Phi^{-1}(\hat\xi))`.  The model is
evaluated at the *estimate*, so linearised at a point :math:`\xi^*` (with the input
:math:`u^* = -\hat\alpha(\xi^*)/\hat\beta(\xi^*)` that holds :math:`y^{(\rho)} = 0` there) the
estimation error obeys

.. math:: \dot e = (A_m - LC)\,e,\qquad A_m = A + e_\rho\,[J,\ 0],\qquad
          J = \frac{\partial(\hat\alpha + \hat\beta u^*)}{\partial\xi}(\xi^*),

not :math:`\dot e = (A - LC)e`: Gao's gains :math:`\beta_i = \alpha_i\omega_0^i` then put
the poles elsewhere (for the flexible joint, J ≈ (−3.1·10⁴, −1.7·10⁴, −1.1·10³, −53) at
rest; at ω0 = 15 rad/s one observer pole moves to −0.13 rad/s).  :func:`model_gain` places
the poles of :math:`A_m - LC` at the bandwidth's :math:`\omega_0\lambda_i`
(:func:`aiofl.components.discrete.eso_continuous_poles`; −ω0, ρ+1 times, with the binomial
α), by Ackermann's formula (:func:`control.acker` on the dual pair).  Sampled,
:func:`discrete_model_gain` places the eigenvalues of the linearised error map
:math:`(I - LC)\Phi_m`, :math:`\Phi_m = \Phi + \bar\Gamma[J,\ 0]` (the ZOH prediction of
:mod:`aiofl.components.discrete` with the model's input :math:`\hat\alpha + \hat\beta u`
held, :math:`\bar\Gamma = \int_0^T e^{As}ds\,B`), at :math:`e^{s_iT}`, as
:func:`aiofl.components.discrete.current_observer_gain` does for the chain.

The engine linearises at the run's initial state, :math:`\xi^* = \Phi(x_0)`
(:func:`design_point_jacobian`); along a trajectory J changes, and the analysis of the
closed loop (:mod:`aiofl.analysis`) shows where the poles are at its operating point.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aiofl.components.discrete import eso_chain, eso_continuous_poles, zoh

__all__ = ["design_point_jacobian", "discrete_model_gain", "model_gain"]


def design_point_jacobian(
    alpha_beta_of_xi: Callable[..., ArrayLike], xi_star: ArrayLike, p: ArrayLike
) -> NDArray[np.float64]:
    r""":math:`J = \partial(\hat\alpha + \hat\beta u^*)/\partial\xi` at ``xi_star``, with
    :math:`u^* = -\hat\alpha(\xi^*)/\hat\beta(\xi^*)`, by :func:`scipy.differentiate.jacobian`
    (adaptive central differences with Richardson extrapolation) on the plant's
    ``alpha_beta_of_xi`` at the nominal parameters ``p``.

    Parameters
    ----------
    alpha_beta_of_xi
        The plant's ``(ξ, p) -> (α, β)``.
    xi_star
        ξ*, ρ entries.
    p
        The nominal parameters.

    Returns
    -------
    ndarray
        J, ρ entries.
    """
    from scipy.differentiate import jacobian

    xs = np.asarray(xi_star, dtype=np.float64)
    pv = np.asarray(p, dtype=np.float64)
    a0, b0 = (float(v) for v in alpha_beta_of_xi(xs, pv))
    if not (np.isfinite(a0) and np.isfinite(b0) and b0 != 0.0):
        raise ValueError(
            f"the nominal model at xi = {xs.tolist()} gives alpha = {a0}, beta = {b0}; the "
            "model-assisted observer needs a finite, nonzero beta at the initial state"
        )
    u_star = -a0 / b0
    n = xs.size

    def held(x: NDArray[np.float64]) -> NDArray[np.float64]:
        flat = x.reshape(n, -1)
        out = np.empty(flat.shape[1])
        for k in range(flat.shape[1]):
            a, b = alpha_beta_of_xi(np.ascontiguousarray(flat[:, k]), pv)
            out[k] = a + b * u_star
        return out.reshape(x.shape[1:])

    step = 0.01 * np.maximum(1.0, np.abs(xs))
    jac = np.asarray(jacobian(held, xs, initial_step=step).df, dtype=np.float64).reshape(n)
    if not np.all(np.isfinite(jac)):
        raise ValueError(f"the nominal model's Jacobian at xi = {xs.tolist()} is not finite")
    return jac


def _model_matrix(jac: NDArray[np.float64]) -> NDArray[np.float64]:
    """:math:`A_m = A + e_\\rho [J, 0]`."""
    rho = jac.size
    a, _ = eso_chain(rho)
    a = a.copy()
    a[rho - 1, :rho] += jac
    return a


def model_gain(jac: ArrayLike, alphas: ArrayLike, omega0: float) -> NDArray[np.float64]:
    r"""Continuous gains L with :math:`\operatorname{eig}(A_m - LC) = \omega_0\lambda_i`,
    the poles Gao's gains give the chain (module notes); J = 0 gives them back,
    :math:`L_i = \alpha_i\omega_0^i`.

    Parameters
    ----------
    jac
        J (ρ entries).
    alphas
        The ρ + 1 coefficients α.
    omega0
        ω₀ [rad/s].

    Returns
    -------
    ndarray
        L, ρ + 1 entries.
    """
    import control

    j = np.asarray(jac, dtype=np.float64)
    n = j.size + 1
    poles = eso_continuous_poles(alphas, omega0)
    # scaled by ω0 (ξ̃_i = ξ_i / ω0^(i-1), time in 1/ω0): unit poles, entries of order 1
    w = float(omega0)
    scale = w ** np.arange(n)
    a_m = _model_matrix(j)
    a_s = (a_m * scale[None, :] / scale[:, None]) / w
    c = np.eye(1, n)
    l_s = np.asarray(control.acker(a_s.T, c.T, poles / w), dtype=np.float64).reshape(n)
    return l_s * w * scale


def discrete_model_gain(
    jac: ArrayLike, alphas: ArrayLike, omega0: float, ts: float
) -> NDArray[np.float64]:
    r"""Current-observer gain L with :math:`\operatorname{eig}((I - LC)\Phi_m) = e^{s_iT}`
    (module notes), placed like :func:`aiofl.components.discrete.current_observer_gain`:
    the predictor gain :math:`L_p = \Phi_m L` by Ackermann's formula on
    :math:`\tilde\Phi_m - I` in the scaled coordinates :math:`\tilde\xi_i = T^{i-1}\xi_i`,
    eigenvalues :math:`\operatorname{expm1}(s_iT)`; J = 0 gives that function's gain.

    Parameters
    ----------
    jac, alphas, omega0
        As for :func:`model_gain`.
    ts
        The sample time T [s].

    Returns
    -------
    ndarray
        L, ρ + 1 entries.
    """
    import control

    j = np.asarray(jac, dtype=np.float64)
    rho = j.size
    n = rho + 1
    a, b = eso_chain(rho)
    phi, _, gam = zoh(a, b, ts)
    phi_m = np.triu(phi)
    phi_m[:, :rho] += np.outer(gam, j)
    scale = ts ** np.arange(n)  # ξ̃ = S ξ, S = diag(T^(i-1))
    phi_s = phi_m * scale[:, None] / scale[None, :]
    c = np.eye(1, n)
    delta = np.expm1(eso_continuous_poles(alphas, omega0) * ts)
    lp = np.asarray(control.acker((phi_s - np.eye(n)).T, c.T, delta), dtype=np.float64)
    l_scaled = np.linalg.solve(phi_s, lp.reshape(n))
    return l_scaled / scale
