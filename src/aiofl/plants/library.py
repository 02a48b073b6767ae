r"""More plants, of other relative degrees, defined symbolically and compiled ahead of time.

Every plant here is written once as a symbolic model (the TOML format of
:meth:`aiofl.plants.symbolic.SymbolicPlant.from_dict`, held in :data:`SPECS`).  From it sympy
generates the plain-Python functions ``f, g, h, bd`` and ``normal_form`` (ξ, α, β for the
classical IOFL law of Section III) into :mod:`aiofl.plants.library_generated`, so importing
a plant never imports sympy and the engine compiles them like any hand-written plant.
Regenerate after editing a spec with ``python -m aiofl.plants.library``; a test checks the
generated functions against the symbolic models.

Plants (beside the paper's ``slfjm``, eq. 15, and ``pendulum``, whose symbolic models are
here too so ``aiofl analyze`` can explain them and IOFL can use their normal forms):

* ``tank`` — a tank with Torricelli outflow and a pump, n = 1, **ρ = 1**.
* ``dcmotor_arm`` — a single-link arm driven by a DC motor with armature inductance,
  n = 3, **ρ = 3** (u is a voltage; it reaches the angle through the current).
* ``flexjoint_hub`` — a flexible-joint arm with link damping whose *motor* angle is the
  output (collocated), n = 4, **ρ = 2 < n**; its zero dynamics are the link swinging on
  the spring with the motor held still, a damped pendulum: stable, minimum phase.

:data:`FACTORIES` maps names to factories; :mod:`aiofl.plants.registry` registers them.
:func:`symbolic_model` builds the symbolic model of a shipped plant; it and
:func:`generated_source` import sympy (:mod:`aiofl.plants.symbolic`,
:mod:`aiofl.plants.codegen`) only when called, so importing this module does not.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import aiofl.plants.library_generated as _generated
from aiofl.plants.base import Plant, unit_from_label

if TYPE_CHECKING:
    from aiofl.plants.symbolic import SymbolicPlant

__all__ = [
    "EXTRA_PLANTS",
    "FACTORIES",
    "SPECS",
    "dcmotor_arm",
    "flexjoint_hub",
    "generated_source",
    "symbolic_model",
    "symbolic_plant_names",
    "tank",
]

SPECS: dict[str, dict[str, Any]] = {
    "slfjm": {
        "name": "slfjm",
        "description": "single-link flexible-joint manipulator, eq. (15)",
        "output_unit": "rad",
        "input_unit": "V",
        "disturbance_unit": "N·m",
        "states": {
            "x1": "hub angle θ [rad]",
            "x2": "link deflection α [rad]",
            "x3": "θ' [rad/s]",
            "x4": "α' [rad/s]",
        },
        "f": [
            "x3",
            "x4",
            "K_s/J_h*x2 - K_m**2*K_g**2/(R_m*J_h)*x3",
            "-K_s/J_h*x2 - K_s/J_l*x2 + K_m**2*K_g**2/(R_m*J_h)*x3 + m*g*h/J_l*sin(x1 + x2)",
        ],
        "g": ["0", "0", "K_m*K_g/(R_m*J_h)", "-K_m*K_g/(R_m*J_h)"],
        "h": "x1 + x2",
        "bd": ["0", "0", "1/J_h", "-1/J_h"],
        "params": {
            "K_s": 1.61,
            "J_h": 0.0021,
            "m": 0.403,
            "g": -9.81,
            "h": 0.06,
            "K_m": 0.00767,
            "K_g": 70.0,
            "J_l": 0.0059,
            "R_m": 2.6,
        },
    },
    "pendulum": {
        "name": "pendulum",
        "description": "damped pendulum driven by a torque",
        "output_unit": "rad",
        "input_unit": "N·m",
        "disturbance_unit": "N·m",
        "states": {"theta": "angle [rad]", "theta_dot": "angular rate [rad/s]"},
        "f": ["theta_dot", "-g/l*sin(theta) - c/(m*l**2)*theta_dot"],
        "g": ["0", "1/(m*l**2)"],
        "h": "theta",
        "bd": ["0", "1/(m*l**2)"],
        "params": {"m": 1.0, "l": 0.5, "c": 0.1, "g": 9.81},
    },
    "tank": {
        "name": "tank",
        "description": "tank with Torricelli outflow filled by a pump (u [V], level [m])",
        "output_unit": "m",
        "input_unit": "V",
        "disturbance_unit": "m^3/s",
        "states": {"level": "liquid level [m]"},
        "f": ["-a/A*sqrt(2*g*abs(level))"],
        "g": ["k_p/A"],
        "h": "level",
        "bd": ["1/A"],  # extra inflow [m^3/s]
        "params": {"A": 0.5, "a": 0.005, "g": 9.81, "k_p": 0.02},
    },
    "dcmotor_arm": {
        "name": "dcmotor_arm",
        "description": "single-link arm driven by a DC motor with armature inductance (u [V])",
        "output_unit": "rad",
        "input_unit": "V",
        "disturbance_unit": "N·m",
        "states": {"theta": "arm angle [rad]", "omega": "arm rate [rad/s]", "i": "current [A]"},
        "f": [
            "omega",
            "(K_t*i - b*omega - m*g*l*sin(theta))/J",
            "(-R*i - K_e*omega)/L",
        ],
        "g": ["0", "0", "1/L"],
        "h": "theta",
        "bd": ["0", "1/J", "0"],  # load torque [N·m]
        "params": {
            "J": 0.02,
            "b": 0.02,
            "m": 0.5,
            "g": 9.81,
            "l": 0.2,
            "K_t": 0.5,
            "K_e": 0.5,
            "R": 2.0,
            "L": 0.05,
        },
    },
    "flexjoint_hub": {
        "name": "flexjoint_hub",
        "description": (
            "flexible-joint arm with link damping, output = motor angle (collocated, ρ = 2 < n)"
        ),
        "output_unit": "rad",
        "input_unit": "N·m",  # motor torque
        "disturbance_unit": "N·m",
        "states": {
            "q_m": "motor angle [rad]",
            "q_l": "link angle [rad]",
            "w_m": "motor rate [rad/s]",
            "w_l": "link rate [rad/s]",
        },
        "f": [
            "w_m",
            "w_l",
            "(k*(q_l - q_m) - b_m*w_m)/J_m",
            "(-k*(q_l - q_m) - b_l*w_l - M*g*d*sin(q_l))/J_l",
        ],
        "g": ["0", "0", "1/J_m", "0"],
        "h": "q_m",
        "bd": ["0", "0", "0", "1/J_l"],  # load torque on the link [N·m]
        "params": {
            "J_m": 0.01,
            "J_l": 0.02,
            "k": 5.0,
            "b_m": 0.01,
            "b_l": 0.05,
            "M": 0.5,
            "g": 9.81,
            "d": 0.2,
        },
    },
}
"""Symbolic models of the shipped plants, in the TOML format of
:meth:`aiofl.plants.symbolic.SymbolicPlant.from_dict`."""

EXTRA_PLANTS = ("tank", "dcmotor_arm", "flexjoint_hub")
"""Plants this module adds to the registry (:mod:`aiofl.plants.registry`; ``slfjm`` and
``pendulum`` live in :mod:`aiofl.plants.builtin`)."""

_RHO = {"slfjm": 4, "pendulum": 2, "tank": 1, "dcmotor_arm": 3, "flexjoint_hub": 2}
_SYMBOLIC: dict[str, SymbolicPlant] = {}


def symbolic_plant_names() -> tuple[str, ...]:
    """Names of the plants with a symbolic model."""
    return tuple(SPECS)


def symbolic_model(name: str) -> SymbolicPlant:
    """The :class:`aiofl.plants.symbolic.SymbolicPlant` of a shipped plant (imports sympy)."""
    from aiofl.plants.expressions import SymbolicPlantError
    from aiofl.plants.symbolic import SymbolicPlant

    if name not in SPECS:
        raise SymbolicPlantError(
            f"no symbolic model for plant {name!r}; available: {', '.join(SPECS)}"
        )
    if name not in _SYMBOLIC:
        _SYMBOLIC[name] = SymbolicPlant.from_dict(SPECS[name], f"plant {name!r}")
    return _SYMBOLIC[name]


def _from_generated(name: str) -> Plant:
    spec = SPECS[name]
    return Plant(
        name=name,
        n_states=len(spec["states"]),
        f=getattr(_generated, f"{name}_f"),
        g=getattr(_generated, f"{name}_g"),
        h=getattr(_generated, f"{name}_h"),
        bd=getattr(_generated, f"{name}_bd", None),
        params=spec["params"],
        relative_degree=_RHO[name],
        normal_form=getattr(_generated, f"{name}_normal_form"),
        alpha_beta_of_xi=getattr(_generated, f"{name}_alpha_beta_of_xi", None),
        state_of_xi=getattr(_generated, f"{name}_state_of_xi", None),
        state_names=tuple(spec["states"]),
        description=spec["description"],
        output_unit=spec.get("output_unit", ""),
        input_unit=spec.get("input_unit", ""),
        state_units=tuple(unit_from_label(label) for label in spec["states"].values()),
        disturbance_unit=spec.get("disturbance_unit", ""),
    )


def tank() -> Plant:
    r"""Tank with Torricelli outflow, ρ = 1.

    .. math:: A\dot H = -a\sqrt{2g|H|} + k_p u + \tau_d,\qquad y = H

    :math:`\beta = k_p/A = 0.04` m/(s·V); holding H = 1 m takes u ≈ 1.11 V.
    """
    return _from_generated("tank")


def dcmotor_arm() -> Plant:
    r"""Single-link arm on a DC motor with armature inductance, ρ = 3.

    .. math::
        \dot\theta = \omega,\quad J\dot\omega = K_t i - b\omega - mgl\sin\theta + \tau_d,\quad
        L\dot i = -Ri - K_e\omega + u,\qquad y = \theta

    :math:`\beta = L_gL_f^2h = K_t/(JL) = 500` rad/(s³·V), constant: ρ = 3 = n everywhere.
    """
    return _from_generated("dcmotor_arm")


def flexjoint_hub() -> Plant:
    r"""Flexible-joint arm with the motor angle as output, ρ = 2 < n = 4 (minimum phase).

    .. math::
        J_m\ddot q_m = k(q_l - q_m) - b_m\dot q_m + u,\quad
        J_l\ddot q_l = -k(q_l - q_m) - b_l\dot q_l - Mgd\sin q_l + \tau_d,\qquad y = q_m

    :math:`\beta = 1/J_m`.  Zero dynamics (y ≡ 0): :math:`J_l\ddot q_l = -kq_l - b_l\dot q_l
    - Mgd\sin q_l`, a damped pendulum on a spring: eigenvalues
    :math:`-1.25 \pm 17.2j` at rest, minimum phase.
    """
    return _from_generated("flexjoint_hub")


FACTORIES: dict[str, Callable[[], Plant]] = {
    "tank": tank,
    "dcmotor_arm": dcmotor_arm,
    "flexjoint_hub": flexjoint_hub,
}
"""Factories of the extra plants, registered by :mod:`aiofl.plants.registry`."""

_HEADER = """Generated by aiofl.plants.library from the symbolic models in SPECS. Do not edit.

Regenerate with ``python -m aiofl.plants.library``.  Each plant has ``<name>_f``, ``_g``,
``_h``, ``_bd`` (x, p) and ``<name>_normal_form(x, p) -> (xi_1..xi_rho, alpha, beta)``;
where rho = n also ``<name>_alpha_beta_of_xi(xi, p) -> (alpha, beta)`` and
``<name>_state_of_xi(xi, p) -> x`` (their first argument, named x, holds xi).
"""


def generated_source() -> str:
    """Source text of :mod:`aiofl.plants.library_generated` (imports sympy)."""
    from aiofl.plants.codegen import generate_module_source

    return generate_module_source([(n, symbolic_model(n)) for n in SPECS], header=_HEADER)


def write_generated() -> str:
    """Regenerate :mod:`aiofl.plants.library_generated` (formatted with ruff if available)."""
    import shutil
    import subprocess
    from pathlib import Path

    path = Path(__file__).with_name("library_generated.py")
    path.write_text(generated_source(), encoding="utf-8")
    ruff = shutil.which("ruff") or str(Path(__import__("sys").executable).with_name("ruff"))
    if Path(ruff).exists():
        subprocess.run([ruff, "format", "-q", str(path)], check=False)
    return str(path)


if __name__ == "__main__":  # pragma: no cover
    print(write_generated())
