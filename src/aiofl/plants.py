r"""Built-in plants, addressed by name in configs (``plant = "slfjm"``).

* ``slfjm``: the single-link flexible-joint manipulator of eq. (15), ρ = 4.
* ``pendulum``: a damped pendulum driven by a torque, ρ = 2.

:func:`get_plant` returns a plant by name; :func:`register_plant` adds one (other modules,
e.g. :mod:`aiofl.symbolic`, register more).
"""

from __future__ import annotations

from collections.abc import Callable
from math import sin

import numpy as np
from numpy.typing import NDArray

from aiofl.plant import Plant, PlantError

__all__ = ["available_plants", "get_plant", "pendulum", "register_plant", "slfjm"]

Vec = NDArray[np.float64]

# --------------------------------------------------------------------------- SLFJM
SLFJM_PARAMS = {
    "K_s": 1.61,  # link stiffness [N·m/rad]
    "J_h": 0.0021,  # hub inertia [kg·m²]
    "m": 0.403,  # link mass [kg]
    "g": -9.81,  # gravity as printed (negative: with +mgh/J_l·sin it is restoring) [m/s²]
    "h": 0.06,  # height of the link's centre of mass [m]
    "K_m": 0.00767,  # motor constant [V·s/rad]
    "K_g": 70.0,  # gear ratio [-]
    "J_l": 0.0059,  # load inertia [kg·m²]
    "R_m": 2.6,  # motor resistance [Ω]
}


def _slfjm_f(x: Vec, p: Vec) -> tuple[float, float, float, float]:
    ks, jh, m, g, h, km, kg, jl, rm = p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7], p[8]
    damp = km * km * kg * kg / (rm * jh)
    return (
        x[2],
        x[3],
        ks / jh * x[1] - damp * x[2],
        -ks / jh * x[1] - ks / jl * x[1] + damp * x[2] + m * g * h / jl * sin(x[0] + x[1]),
    )


def _slfjm_g(x: Vec, p: Vec) -> tuple[float, float, float, float]:
    b = p[5] * p[6] / (p[8] * p[1])
    return (0.0, 0.0, b, -b)


def _slfjm_bd(x: Vec, p: Vec) -> tuple[float, float, float, float]:
    return (0.0, 0.0, 1.0 / p[1], -1.0 / p[1])


def _slfjm_h(x: Vec, p: Vec) -> float:
    return x[0] + x[1]


def slfjm() -> Plant:
    r"""Single-link flexible-joint manipulator, eq. (15).

    State :math:`x = (\theta, \alpha, \dot\theta, \dot\alpha)` [rad, rad, rad/s, rad/s]
    (θ hub angle, α link deflection), input u [V], disturbance :math:`\tau_d` [N·m],
    output :math:`y = \theta + \alpha` [rad].

    .. math::
        f(x) = \begin{pmatrix} x_3 \\ x_4 \\
            \frac{K_s}{J_h}x_2 - \frac{K_m^2K_g^2}{R_mJ_h}x_3 \\
            -\frac{K_s}{J_h}x_2 - \frac{K_s}{J_l}x_2 + \frac{K_m^2K_g^2}{R_mJ_h}x_3
            + \frac{mgh}{J_l}\sin(x_1+x_2) \end{pmatrix},\quad
        b = \frac{K_mK_g}{R_mJ_h}\begin{pmatrix}0\\0\\1\\-1\end{pmatrix},\quad
        b_d = \frac{1}{J_h}\begin{pmatrix}0\\0\\1\\-1\end{pmatrix}

    Relative degree 4 with :math:`L_gL_f^3h = K_sK_mK_g/(J_lJ_hR_m) \approx 2.68\cdot10^4`.
    """
    return Plant(
        name="slfjm",
        n_states=4,
        f=_slfjm_f,
        g=_slfjm_g,
        h=_slfjm_h,
        bd=_slfjm_bd,
        params=SLFJM_PARAMS,
        relative_degree=4,
        state_names=("theta", "alpha", "theta_dot", "alpha_dot"),
        description="single-link flexible-joint manipulator, eq. (15)",
    )


# ------------------------------------------------------------------------ pendulum
PENDULUM_PARAMS = {"m": 1.0, "l": 0.5, "c": 0.1, "g": 9.81}


def _pend_f(x: Vec, p: Vec) -> tuple[float, float]:
    m, l, c, g = p[0], p[1], p[2], p[3]
    return (x[1], -g / l * sin(x[0]) - c / (m * l * l) * x[1])


def _pend_g(x: Vec, p: Vec) -> tuple[float, float]:
    return (0.0, 1.0 / (p[0] * p[1] * p[1]))


def _pend_h(x: Vec, p: Vec) -> float:
    return x[0]


def pendulum() -> Plant:
    r"""Damped pendulum, :math:`ml^2\ddot\theta = -mgl\sin\theta - c\dot\theta + u + \tau_d`.

    State :math:`(\theta, \dot\theta)`, y = θ, ρ = 2, :math:`\beta = 1/(ml^2)`.
    """
    return Plant(
        name="pendulum",
        n_states=2,
        f=_pend_f,
        g=_pend_g,
        h=_pend_h,
        bd=_pend_g,
        params=PENDULUM_PARAMS,
        relative_degree=2,
        state_names=("theta", "theta_dot"),
        description="damped pendulum driven by a torque",
    )


# ------------------------------------------------------------------------ registry
_REGISTRY: dict[str, Callable[[], Plant]] = {"slfjm": slfjm, "pendulum": pendulum}
_CACHE: dict[str, Plant] = {}


def register_plant(name: str, factory: Callable[[], Plant]) -> None:
    """Make ``factory()`` available as ``plant = "<name>"`` in configs."""
    _REGISTRY[name] = factory
    _CACHE.pop(name, None)


def available_plants() -> tuple[str, ...]:
    """Names of the registered plants."""
    return tuple(sorted(_REGISTRY))


def get_plant(name: str) -> Plant:
    """The registered plant ``name`` (one shared instance, so its kernel compiles once)."""
    if name not in _REGISTRY:
        raise PlantError(f"unknown plant {name!r}; available: {', '.join(available_plants())}")
    if name not in _CACHE:
        _CACHE[name] = _REGISTRY[name]()
    return _CACHE[name]
