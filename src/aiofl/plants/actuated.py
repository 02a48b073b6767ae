r"""A plant on a rig: the actuator and the friction of :class:`aiofl.rig.Rig` in its state.

:func:`with_rig` returns a new :class:`~aiofl.plants.base.Plant` whose state is the plant's
:math:`x` followed by the actuator's states, and whose parameter vector is the plant's
followed by the rig's (named ``rig_*``, so ``[uncertainty.parameters]`` draws them as
factors like any plant parameter: ``rig_lag = { uniform = 0.5 }``).  With the rig's
actuator output :math:`u_a` and friction :math:`F(v) = F_c\tanh(v/\varepsilon) + b_v v`
(Olsson et al., Eur. J. Control 4(3), 1998):

.. math::

    \dot x = f(x) + g(x)\,(u_a - F(v)), \qquad y = h(x),

* no actuator: :math:`u_a = u` (the plant's own input channel, friction subtracted);
* first order: :math:`\dot u_a = (u - u_a)/\tau_a`;
* first order with a rate limit: :math:`\dot w = (u - w)/\tau_w`,
  :math:`\dot u_a = \operatorname{clip}((w - u_a)/\tau_a, -R, R)` (state order x, w, u_a);
* second order: :math:`\dot u_a = \dot u_a`, :math:`\ddot u_a = \omega_n^2(u - u_a) -
  2\zeta\omega_n\dot u_a` (state order x, u_a, u̇_a).

Every form stays affine in u, as the engine's plant interface requires.  The functions
are closures over the plant's numba-compiled functions and read the rig's values from the
parameter vector at run time, so the engine compiles them as any plant and a drawn rig
parameter changes the run.  They depend only on the rig's structure (which quantities are
set), not on its values: rigs of one structure on one plant share the functions and their
compilations (a config parsed again does not compile the plant again).

**What the controller is told.**  The augmented plant keeps the plant's ``relative_degree``
and its normal form (evaluated on :math:`x`, the plant's own states): a controller is
designed for the bare plant, and the rig's actuator is unmodelled dynamics (its true
relative degree is ρ plus the actuator's order).  So
:meth:`aiofl.controller.Controller.check_plant` accepts the design made for the plant and
still refuses a controller whose ρ is not the plant's.
"""

from __future__ import annotations

import weakref
from typing import Any

import numpy as np

from aiofl.plants.base import Plant, PlantError
from aiofl.rig import Rig

__all__ = ["RIG_PARAMS", "rig_params", "rig_x0", "with_rig"]

RIG_PARAMS = (
    "rig_lag",
    "rig_wn",
    "rig_zeta",
    "rig_rate",
    "rig_rate_filter",
    "rig_coulomb",
    "rig_viscous",
    "rig_eps",
)
"""Names of the rig's entries of the parameter vector (only the active ones are present)."""


def rig_params(rig: Rig) -> dict[str, float]:
    """The rig's active quantities as plant parameters (:data:`RIG_PARAMS`)."""
    out: dict[str, float] = {}
    if rig.lag > 0.0:
        out["rig_lag"] = rig.lag
    if rig.lag2 is not None:
        out["rig_wn"], out["rig_zeta"] = rig.lag2
    if rig.has_rate_limit:
        out["rig_rate"] = rig.rate_limit
        out["rig_rate_filter"] = rig.effective_rate_filter
    if rig.has_friction:
        out["rig_coulomb"] = rig.coulomb
        out["rig_viscous"] = rig.viscous
        out["rig_eps"] = rig.smoothing
    return out


def _friction_index(plant: Plant, rig: Rig) -> int:
    """Index of ``rig.friction_state`` in the plant's state; PlantError listing the states."""
    if not rig.has_friction:
        return -1
    if rig.friction_state not in plant.state_names:
        raise PlantError(
            f"rig.friction_state = {rig.friction_state!r} is not a state of plant "
            f"{plant.name!r}; allowed: one of {', '.join(plant.state_names)}"
        )
    return plant.state_names.index(rig.friction_state)


def with_rig(plant: Plant, rig: Rig) -> Plant:
    """``plant`` with ``rig``'s actuator and friction (module docstring); ``plant`` itself
    when the rig adds neither.  Delays and the sensor are not part of the plant (they go
    to the scenario and the sampling, :mod:`aiofl.config.rig_table`).

    Raises
    ------
    PlantError
        A friction state the plant does not have (naming its states), or a plant that
        already has a ``rig_*`` parameter or an actuator state name.
    """
    if not rig.augments_plant:
        return plant
    iv = _friction_index(plant, rig)
    extra = rig_params(rig)
    clash = sorted(set(extra) & set(plant.params))
    if clash:
        raise PlantError(
            f"plant {plant.name!r} already has parameter(s) {', '.join(clash)}; the rig's "
            "parameters would shadow them"
        )
    key = (iv, rig.lag2 is not None, rig.lag > 0.0, rig.has_rate_limit, tuple(extra))
    shared = _SHARED.setdefault(plant, {})
    if key not in shared:
        shared[key] = _functions(plant, rig, iv, tuple(extra))
    first, (f, g, h, bd, normal_form, alpha_beta) = shared[key]
    n = plant.n_states
    kind = 2 if rig.lag2 is not None else (1 if rig.lag > 0.0 else 0)
    rate = rig.has_rate_limit
    names: list[str] = []
    units: list[str] = []
    u_unit = plant.input_unit
    if rate:
        names.append("u_filt")
        units.append(u_unit)
    if kind > 0:
        names.append("u_act")
        units.append(u_unit)
    if kind == 2:
        names.append("u_act_rate")
        units.append(f"{u_unit}/s" if u_unit else "")
    taken = sorted(set(names) & set(plant.state_names))
    if taken:
        raise PlantError(
            f"plant {plant.name!r} already has state(s) {', '.join(taken)}; the rig's "
            "actuator states would shadow them"
        )
    out = Plant(
        name=f"{plant.name}+rig",
        n_states=n + rig.actuator_order,
        f=f,
        g=g,
        h=h,
        params={**plant.params, **extra},
        bd=bd,
        relative_degree=plant.relative_degree,
        normal_form=normal_form,
        alpha_beta_of_xi=alpha_beta,
        state_of_xi=None,
        state_names=(*plant.state_names, *names),
        description=f"{plant.description} on a rig ({rig.preset})"[:200],
        output_unit=plant.output_unit,
        input_unit=plant.input_unit,
        state_units=(*plant.state_units, *units),
        disturbance_unit=plant.disturbance_unit,
        state_bounds=dict(plant.state_bounds),
        output_range=plant.output_range,
    )
    if first:  # the compiled functions of the first plant of this structure, shared
        out.__dict__["compiled"] = first[0].compiled
    else:
        first.append(out)
    return out


#: per plant, per rig structure: ([the first augmented plant], its functions)
_SHARED: weakref.WeakKeyDictionary[Plant, dict[tuple[Any, ...], Any]] = weakref.WeakKeyDictionary()


def _functions(plant: Plant, rig: Rig, iv: int, names: tuple[str, ...]) -> tuple[list[Plant], Any]:
    """The augmented f, g, h, b_d, normal form and (α, β)(ξ) of ``plant`` for the rig's
    structure (its values are read from p at run time)."""
    n, m = plant.n_states, len(plant.params)
    idx = {name: m + j for j, name in enumerate(names)}
    f0, g0, h0, bd0, nf0, ab0 = plant.compiled
    kind = 2 if rig.lag2 is not None else (1 if rig.lag > 0.0 else 0)
    rate = rig.has_rate_limit
    k = rig.actuator_order
    na = n + k
    ia = n + (1 if rate else 0)  # index of u_a in the augmented state (kind > 0)
    friction = iv >= 0
    i_lag, i_wn, i_zeta = idx.get("rig_lag", 0), idx.get("rig_wn", 0), idx.get("rig_zeta", 0)
    i_rate, i_tw = idx.get("rig_rate", 0), idx.get("rig_rate_filter", 0)
    i_fc, i_bv, i_eps = idx.get("rig_coulomb", 0), idx.get("rig_viscous", 0), idx.get("rig_eps", 0)

    def f(x: Any, p: Any) -> Any:
        xs = x[:n]
        ps = p[:m]
        fx = f0(xs, ps)
        gx = g0(xs, ps)
        u_in = 0.0
        if kind > 0:
            u_in = x[ia]
        if friction:
            v = x[iv]
            u_in -= p[i_fc] * np.tanh(v / p[i_eps]) + p[i_bv] * v
        out = np.empty(na)
        for i in range(n):
            out[i] = fx[i] + gx[i] * u_in
        if rate:
            out[n] = -x[n] / p[i_tw]
            out[ia] = min(max((x[n] - x[ia]) / p[i_lag], -p[i_rate]), p[i_rate])
        elif kind == 1:
            out[ia] = -x[ia] / p[i_lag]
        elif kind == 2:
            wn = p[i_wn]
            out[ia] = x[ia + 1]
            out[ia + 1] = -wn * wn * x[ia] - 2.0 * p[i_zeta] * wn * x[ia + 1]
        return out

    def g(x: Any, p: Any) -> Any:
        out = np.zeros(na)
        if kind == 0:
            gx = g0(x[:n], p[:m])
            for i in range(n):
                out[i] = gx[i]
        elif rate:
            out[n] = 1.0 / p[i_tw]
        elif kind == 1:
            out[ia] = 1.0 / p[i_lag]
        else:
            out[ia + 1] = p[i_wn] * p[i_wn]
        return out

    def h(x: Any, p: Any) -> Any:
        return h0(x[:n], p[:m])

    def bd(x: Any, p: Any) -> Any:
        out = np.zeros(na)
        bx = bd0(x[:n], p[:m])
        for i in range(n):
            out[i] = bx[i]
        return out

    normal_form = alpha_beta = None
    if plant.normal_form is not None:

        def normal_form(x: Any, p: Any) -> Any:
            return nf0(x[:n], p[:m])

    if plant.alpha_beta_of_xi is not None:

        def alpha_beta(xi: Any, p: Any) -> Any:
            return ab0(xi[:n], p[:m])

    bd_out = bd if plant.bd is not None else None
    return [], (f, g, h, bd_out, normal_form, alpha_beta)


def rig_x0(plant: Plant, augmented: Plant, x0: tuple[float, ...]) -> tuple[float, ...]:
    """An initial state of ``augmented`` from one of ``plant`` (the actuator starts at rest
    at 0); ``x0`` unchanged when it already has the augmented length or is empty.

    Parameters
    ----------
    plant
        The plant.
    augmented
        The plant with its rig's actuator (:func:`with_rig`).
    x0
        A start state of ``plant`` (or of ``augmented``, or empty).

    Returns
    -------
    tuple of float
    """
    if not x0 or len(x0) == augmented.n_states:
        return x0
    if len(x0) != plant.n_states:
        return x0  # the length check names it
    return (*x0, *([0.0] * (augmented.n_states - plant.n_states)))
