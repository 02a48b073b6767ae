r"""The coordinate change of the normal form, inverted: :math:`x = \Phi^{-1}(\xi)` where ρ = n.

A model-assisted observer (``eso.model = "nominal"``, :mod:`aiofl.components.law`) estimates
:math:`\hat\xi = (y, \dot y, \dots, y^{(\rho-1)})` and evaluates the nominal
:math:`\alpha, \beta` of eq. (3) at the state with those coordinates.  Where ρ = n the
map :math:`\xi = \Phi(x) = (h, L_fh, \dots, L_f^{n-1}h)` is a change of coordinates;
:func:`invert_coordinates` finds its inverse in closed form when each :math:`\xi_i`,
with the states found before substituted, is linear in one new state, as for every
mechanical chain the plant library ships.  :attr:`aiofl.plants.normal_form.Analysis.inverse`
calls it, and :mod:`aiofl.plants.codegen` prints the result as ``state_of_xi`` and
``alpha_beta_of_xi``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import sympy as sp

__all__ = ["invert_coordinates"]


def invert_coordinates(
    xi: Sequence[Any],
    states: Sequence[Any],
    xi_symbols: Sequence[Any],
    tidy: Callable[[Any], Any] = sp.cancel,
) -> tuple[tuple[Any, ...] | None, str]:
    r"""Solve :math:`\xi = \Phi(x)` for x by elimination, when ρ = n.

    Repeatedly takes an equation :math:`\xi_i = \Phi_i(x)` that, with the states found so
    far substituted, is linear in one remaining state whose coefficient depends on no
    remaining state, and solves it for that state.  This covers the chains of the
    flexible-joint, motor and pendulum models (each derivative of y brings in one new state
    linearly) and costs a few polynomial checks per equation, so it never hangs on a hostile
    model.  Returns ``(x_of_xi, note)``; ``x_of_xi`` is None, with the reason in ``note``,
    when the elimination stops.  ``tidy`` simplifies each solution (the analysis passes its
    bounded simplification, which refuses expressions that grow too large).

    Parameters
    ----------
    xi
        :math:`\Phi_1(x) .. \Phi_n(x)`, sympy expressions.
    states
        The state symbols x.
    xi_symbols
        The symbols ξ₁..ξₙ.
    tidy
        The simplification applied to each solution (default :func:`sympy.cancel`).

    Returns
    -------
    x_of_xi : tuple or None
    note : str
    """
    eqs = [sp.sympify(e) - z for e, z in zip(xi, xi_symbols, strict=True)]
    left = list(states)
    found: dict[Any, Any] = {}
    pending = list(range(len(eqs)))
    while pending:
        for i in pending:
            eq = eqs[i].xreplace(found) if found else eqs[i]
            pick = _linear_unknown(eq, left, tidy)
            if pick is not None:
                s, sol = pick
                found = {k: v.xreplace({s: sol}) for k, v in found.items()}
                found[s] = sol
                left.remove(s)
                pending.remove(i)
                break
        else:
            names = ", ".join(str(s) for s in left)
            return None, (
                f"Φ⁻¹ not found in closed form: no ξ_i is linear in one of {names} with a "
                "coefficient free of the others"
            )
    return tuple(tidy(found[s]) for s in states), "by elimination"


def _linear_unknown(
    eq: Any, left: Sequence[Any], tidy: Callable[[Any], Any]
) -> tuple[Any, Any] | None:
    """``(s, solution)`` for the first state s in ``left`` in which ``eq = 0`` is linear with a
    nonzero coefficient free of the other states of ``left``; else None."""
    present = [s for s in left if s in eq.free_symbols]
    for s in present:
        poly = eq.as_poly(s)
        if poly is None or poly.degree() != 1:
            continue
        a, b = poly.all_coeffs()
        if a.free_symbols & set(present) or a == 0:
            continue
        return s, tidy(-b / a)
    return None
