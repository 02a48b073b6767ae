r"""The operating point: the equilibrium that holds a plant's output at a given value.

For :math:`\dot x = f(x) + g(x)u`, :math:`y = h(x)` and a wanted output :math:`y^*`,
:func:`trim` solves the n + 1 equations

.. math:: f(x_e) + g(x_e)\,u_e = 0,\qquad h(x_e) = y^*

for the n + 1 unknowns :math:`(x_e, u_e)` with :func:`scipy.optimize.root` (Powell's hybrid
method, the unknowns scaled by the guess), then reports what a designer needs there:

- the holding input :math:`u_e` (what a bumpless start carries over, and what ISU/IAU are
  measured about with ``[scenario] u_ref = "trim"``);
- the high-frequency gain :math:`\beta(x_e) = L_g L_f^{\rho-1} h(x_e)`, the coefficient of u
  in :math:`y^{(\rho)} = \alpha(x) + \beta(x)u` (the normal form of eq. 2 of the paper; the
  b0 an ESO-based design should approximate), when the plant has its normal form;
- the open-loop poles, the eigenvalues of
  :math:`A = \partial(f + g u_e)/\partial x` at :math:`x_e` (central differences), and
  whether the operating point is open-loop unstable (a pole with positive real part: the
  closed loop's bandwidth must exceed the fastest unstable pole).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["OperatingPoint", "TrimError", "holding_input", "trim"]

#: the largest residual |F| (scaled) accepted as a solution
TRIM_TOLERANCE = 1e-9


class TrimError(ValueError):
    """No equilibrium was found (the message says why and what to try)."""


@dataclass(frozen=True)
class OperatingPoint:
    """An equilibrium of a plant (see the module notes).

    Attributes
    ----------
    y
        The output held, :math:`y^* = h(x_e)`.
    x, u
        The state :math:`x_e` and the holding input :math:`u_e`.
    beta
        :math:`\\beta(x_e)`, or None when the plant has no normal form.
    poles
        The open-loop poles at :math:`(x_e, u_e)`.
    state_names
        The plant's state names, in the order of ``x``.
    """

    y: float
    x: NDArray[np.float64]
    u: float
    beta: float | None
    poles: NDArray[np.complex128]
    state_names: tuple[str, ...]

    @property
    def unstable(self) -> bool:
        """Whether a pole has a positive real part (open-loop unstable there)."""
        return bool(np.any(self.poles.real > 1e-9 * max(1.0, float(np.max(np.abs(self.poles))))))

    @property
    def fastest_unstable(self) -> float | None:
        """The largest real part of an unstable pole [rad/s], or None."""
        re = self.poles.real[self.poles.real > 0]
        return float(re.max()) if self.unstable else None

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON)."""
        return {
            "y": self.y,
            "x": {n: float(v) for n, v in zip(self.state_names, self.x, strict=True)},
            "u": self.u,
            "beta": self.beta,
            "poles": [[float(p.real), float(p.imag)] for p in self.poles],
            "open_loop_unstable": self.unstable,
            "fastest_unstable_pole": self.fastest_unstable,
        }

    def text(self, output_unit: str = "", input_unit: str = "") -> str:
        """A few lines for a terminal."""
        ou = f" {output_unit}" if output_unit else ""
        iu = f" {input_unit}" if input_unit else ""
        xs = ", ".join(f"{n} = {v:.6g}" for n, v in zip(self.state_names, self.x, strict=True))
        poles = ", ".join(_pole(p) for p in self.poles)
        lines = [
            f"operating point: y = {self.y:.6g}{ou}",
            f"  state: {xs}",
            f"  holding input u_e = {self.u:.6g}{iu}",
            "  beta(x_e) = "
            + ("n/a (no normal form)" if self.beta is None else f"{self.beta:.6g}"),
            f"  open-loop poles: {poles}",
        ]
        if self.unstable:
            lines.append(
                f"  open-loop UNSTABLE: fastest unstable pole {self.fastest_unstable:.4g} rad/s "
                "(the closed loop must be faster)"
            )
        else:
            lines.append("  open-loop stable (no pole in the right half plane)")
        return "\n".join(lines)


def _pole(p: complex) -> str:
    if abs(p.imag) <= 1e-12 * max(1.0, abs(p)):
        return f"{p.real:.4g}"
    return f"{p.real:.4g}{p.imag:+.4g}j"


def _call(fn: Any, x: NDArray[np.float64], p: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.atleast_1d(np.asarray(fn(x, p), dtype=np.float64))


def jacobian_x(
    plant: Any, x: NDArray[np.float64], u: float, p: NDArray[np.float64]
) -> NDArray[np.float64]:
    r""":math:`\partial(f + g u)/\partial x` at (x, u) by central differences.

    Parameters
    ----------
    plant
        The plant.
    x, u
        The state and input.
    p
        The parameter vector.

    Returns
    -------
    ndarray
        Shape (n, n).
    """
    n = plant.n_states
    a = np.zeros((n, n))
    for j in range(n):
        h = 1e-6 * max(1.0, abs(x[j]))
        xp, xm = x.copy(), x.copy()
        xp[j] += h
        xm[j] -= h
        fp = _call(plant.f, xp, p) + _call(plant.g, xp, p) * u
        fm = _call(plant.f, xm, p) + _call(plant.g, xm, p) * u
        a[:, j] = (fp - fm) / (2.0 * h)
    return a


def trim(
    plant: Any,
    y: float,
    *,
    x_guess: Any = None,
    u_guess: float = 0.0,
    params: Any = None,
) -> OperatingPoint:
    """The equilibrium holding ``plant``'s output at ``y`` (see the module notes).

    Parameters
    ----------
    plant
        An :class:`aiofl.plants.base.Plant`.
    y
        The output to hold (a finite number).
    x_guess, u_guess
        Where the search starts (default: the zero state, with the state that h reads
        most directly set to y when h is the identity on one state).  A plant with several
        equilibria at that output returns the one nearest the guess.
    params
        The parameter vector (default: the nominal one).

    Returns
    -------
    OperatingPoint

    Raises
    ------
    TrimError
        When no equilibrium is found (a plant that cannot hold that output, or a guess
        too far from one); the message names the residual and suggests a guess.
    """
    from scipy.optimize import root

    if isinstance(y, bool) or not isinstance(y, (int, float)) or not math.isfinite(y):
        raise TrimError(f"trim: y = {y!r}; allowed: a finite number")
    n = plant.n_states
    p = plant.param_vector() if params is None else np.asarray(params, dtype=np.float64)
    x0 = np.zeros(n) if x_guess is None or len(x_guess) == 0 else np.array(x_guess, float)
    if x0.shape != (n,) or not np.all(np.isfinite(x0)):
        raise TrimError(f"trim: the guess x has {x0.size} entries; the plant has {n} states")
    if x_guess is None or len(x_guess) == 0:
        x0 = _output_guess(plant, x0, p, float(y))
    scale = np.maximum(np.abs(np.append(x0, u_guess)), 1e-3)

    def residual(w: NDArray[np.float64]) -> NDArray[np.float64]:
        z = w * scale
        x, u = z[:n], z[n]
        with np.errstate(all="ignore"):
            dx = _call(plant.f, x, p) + _call(plant.g, x, p) * u
            out = np.append(dx, float(plant.h(x, p)) - y)
        return np.where(np.isfinite(out), out, 1e300)

    w0 = np.append(x0, u_guess) / scale
    sol = root(residual, w0, method="hybr", options={"xtol": 1e-13, "maxfev": 4000})
    z = sol.x * scale
    res = residual(sol.x)
    size = max(1.0, abs(y), float(np.max(np.abs(z))))
    if not np.all(np.isfinite(z)) or float(np.max(np.abs(res))) > TRIM_TOLERANCE * size:
        raise TrimError(
            f"trim: no equilibrium of plant {plant.name!r} with y = {y:g} found from the guess "
            f"x = {list(map(float, x0))} (largest residual {float(np.max(np.abs(res))):.3g}; "
            f"{sol.message.strip()}); give a guess near the operating point "
            "([scenario] x0, or aiofl trim --x0)"
        )
    x_e, u_e = z[:n], float(z[n])
    # a component the solver left at rounding level is zero (a velocity at rest: 1e-34)
    x_e = np.where(np.abs(x_e) <= 1e-13 * max(1.0, float(np.max(np.abs(x_e)))), 0.0, x_e)
    beta = None
    if plant.normal_form is not None:
        with np.errstate(all="ignore"):
            nf = _call(plant.normal_form, x_e, p)
        beta = float(nf[-1]) if math.isfinite(float(nf[-1])) else None
    poles = np.linalg.eigvals(jacobian_x(plant, x_e, u_e, p)).astype(np.complex128)
    poles = poles[np.lexsort((poles.imag, -poles.real))]
    return OperatingPoint(
        y=float(y), x=x_e, u=u_e, beta=beta, poles=poles, state_names=tuple(plant.state_names)
    )


def holding_input(plant: Any, scenario: Any, field: str = "scenario.u_ref") -> float:
    """``[scenario] u_ref = "trim"`` (or ``[controller.eso] u0 = "trim"``): the input
    :math:`u_e` holding ``plant`` at the scenario's :math:`r(0)`, the search started at its
    x0; a ``ValueError`` naming ``field`` when there is none.

    Parameters
    ----------
    plant, scenario
        The plant and the scenario (its reference's initial value and x0).
    field
        The config field named in the error (default ``"scenario.u_ref"``).

    Returns
    -------
    float
        :math:`u_e`.
    """
    try:
        return trim(plant, scenario.initial_value(), x_guess=scenario.x0 or None).u
    except ValueError as exc:
        raise ValueError(f'{field} = "trim": {exc}') from None


def _output_guess(
    plant: Any, x: NDArray[np.float64], p: NDArray[np.float64], y: float
) -> NDArray[np.float64]:
    """The zero state with the state the output reads set to y, when h(x) = x_j (the
    usual case: a position, a level, an angle); else the zero state."""
    for j in range(plant.n_states):
        e = np.zeros(plant.n_states)
        e[j] = 1.0
        try:
            with np.errstate(all="ignore"):
                if (
                    abs(float(plant.h(e, p)) - 1.0) < 1e-12
                    and abs(float(plant.h(2 * e, p)) - 2.0) < 1e-12
                ):
                    out = x.copy()
                    out[j] = y
                    return out
        except Exception:  # a plant whose h fails at a unit vector: no guess from it
            continue
    return x
