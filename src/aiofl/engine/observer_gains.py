r"""The model-assisted observer's gains, resolved where the controller meets the plant.

A member with ``eso.model = "nominal"`` and bandwidth gains (``eso.gains = "bandwidth"``)
asks for its observer's error poles at :math:`\omega_0\lambda_i` (−ω0, ρ+1 times, with the
binomial α).  Its error dynamics include the nominal model's Jacobian J (see
:mod:`aiofl.components.model_gains`), which depends on the plant, so the gains are placed
here, per member, at the run's initial state :math:`\xi^* = \Phi(x_0)` with the nominal
parameters: :func:`model_jacobians` gives J per member (NaN rows for the others),
:func:`with_model_gains` a batch whose ``eso.alpha*`` are the placed continuous gains in
the engine's form :math:`\alpha_i = L_i/\omega_0^i` (what the continuous loop and forward
Euler read), and :func:`aiofl.engine.discrete_rows.sampling_rows` places the sampled observer's
current-observer gain from J itself.  Model-free members and Kalman gains are untouched.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.components.model_gains import design_point_jacobian, model_gain
from aiofl.controller import ControllerBatch
from aiofl.plants.base import Plant

__all__ = ["model_jacobians", "placed_members", "with_model_gains"]


def placed_members(batch: ControllerBatch) -> NDArray[np.bool_]:
    """The members whose observer gains are placed for the nominal model."""
    ints = batch.ints
    return (ints[:, L.I_ESO_MODEL] == L.ESO_MODEL_NOMINAL) & (
        ints[:, L.I_ESO_GAINS] == L.ESO_GAINS_BANDWIDTH
    )


def model_jacobians(
    plant: Plant, batch: ControllerBatch, x0s: Sequence[Sequence[float]]
) -> NDArray[np.float64] | None:
    r"""(B, ρ) Jacobians :math:`J = \partial(\hat\alpha + \hat\beta u^*)/\partial\xi` at
    :math:`\Phi(x_0)` of each placed member (NaN rows for the others); None when no member
    is placed.  ``x0s``: each member's initial state (empty: the origin).  One evaluation per
    distinct initial state.

    Parameters
    ----------
    plant
        The plant (needs ``alpha_beta_of_xi`` and ``normal_form``).
    batch
        The packed controllers.
    x0s
        Each member's initial state (empty: the origin).

    Returns
    -------
    ndarray or None
    """
    placed = placed_members(batch)
    if not placed.any():
        return None
    if plant.alpha_beta_of_xi is None or plant.normal_form is None:
        raise ValueError(
            f"eso.model = 'nominal' needs plant {plant.name!r}'s alpha_beta_of_xi and normal form"
        )
    rho = int(batch.ints[np.flatnonzero(placed)[0], L.I_RHO])
    p = plant.param_vector()
    out = np.full((len(batch), rho), np.nan)
    memo: dict[tuple[float, ...], NDArray[np.float64]] = {}
    for i in np.flatnonzero(placed):
        x0 = tuple(float(v) for v in x0s[i]) or (0.0,) * plant.n_states
        if x0 not in memo:
            xi_star = np.asarray(plant.normal_form(np.asarray(x0), p), dtype=np.float64)[:rho]
            memo[x0] = design_point_jacobian(plant.alpha_beta_of_xi, xi_star, p)
        out[i] = memo[x0]
    return out


def with_model_gains(batch: ControllerBatch, jac: NDArray[np.float64] | None) -> ControllerBatch:
    """``batch`` with the placed members' ``eso.alpha*`` replaced by the engine form of the
    gains :func:`aiofl.components.model_gains.model_gain` places (the batch itself when
    none is placed)."""
    if jac is None:
        return batch
    floats = batch.floats.copy()
    for i in np.flatnonzero(placed_members(batch)):
        rho = int(batch.ints[i, L.I_RHO])
        w0 = float(floats[i, L.F_OMEGA0])
        cols = slice(L.F_ESO_ALPHA, L.F_ESO_ALPHA + rho + 1)
        gains = model_gain(jac[i, :rho], floats[i, cols], w0)
        floats[i, cols] = gains / w0 ** np.arange(1, rho + 2)
    return ControllerBatch(batch.ints, floats)
