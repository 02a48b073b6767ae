r"""Performance indices of eq. (22) and their objective performance index (OPI).

.. math::
    \mathrm{ITAE} = \int_0^{t_f} t\,|y-r|\,dt,\quad
    \mathrm{IAE} = \int_0^{t_f} |y-r|\,dt,\quad
    \mathrm{ISE} = \int_0^{t_f} (y-r)^2\,dt,

.. math::
    \mathrm{ISU} = \int_0^{t_f} u^2\,dt,\quad \mathrm{IAU} = \int_0^{t_f} |u|\,dt,\quad
    \mathrm{OPI} = w_1\frac{\mathrm{ITAE}}{N_1} + w_2\frac{\mathrm{ISU}}{N_2}
                 + w_3\frac{\mathrm{IAU}}{N_3}.

The engine integrates these as extra states with the same RK4 step as the loop (so they
are as accurate as the trajectory); the functions here evaluate them on sampled signals
(trapezoidal rule) for post-processing and tests.  ``y`` is the true plant output and ``r``
the raw reference (not the differentiator's profile), as in the paper's definitions.

Paper defaults (text after eq. 22): w = (0.6, 0.2, 0.6), N = (10, 2, 2.7).  The printed
weights sum to 1.4 although the text requires 1; :class:`OPIWeights` keeps the printed
values by default and lets a user choose.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["OPIWeights", "iae", "iau", "ise", "isu", "itae", "opi"]


def _trapz(values: ArrayLike, t: ArrayLike) -> float:
    return float(np.trapezoid(np.asarray(values, dtype=float), np.asarray(t, dtype=float)))


def itae(t: ArrayLike, y: ArrayLike, r: ArrayLike) -> float:
    r"""Integral of time-weighted absolute error :math:`\int t|y-r|dt` (eq. 22).

    Parameters
    ----------
    t
        The sample times [s].
    y, r
        The output and the reference at ``t``.

    Returns
    -------
    float
    """
    t = np.asarray(t, dtype=float)
    return _trapz(t * np.abs(np.asarray(y) - np.asarray(r)), t)


def iae(t: ArrayLike, y: ArrayLike, r: ArrayLike) -> float:
    r"""Integral of absolute error :math:`\int |y-r|dt`.

    Parameters
    ----------
    t, y, r
        As for :func:`itae`.

    Returns
    -------
    float
    """
    return _trapz(np.abs(np.asarray(y) - np.asarray(r)), t)


def ise(t: ArrayLike, y: ArrayLike, r: ArrayLike) -> float:
    r"""Integral of squared error :math:`\int (y-r)^2 dt`.

    Parameters
    ----------
    t, y, r
        As for :func:`itae`.

    Returns
    -------
    float
    """
    return _trapz((np.asarray(y) - np.asarray(r)) ** 2, t)


def isu(t: ArrayLike, u: ArrayLike) -> float:
    r"""Integral of squared control :math:`\int u^2 dt` (eq. 22)."""
    return _trapz(np.asarray(u) ** 2, t)


def iau(t: ArrayLike, u: ArrayLike) -> float:
    r"""Integral of absolute control :math:`\int |u| dt` (eq. 22)."""
    return _trapz(np.abs(np.asarray(u)), t)


@dataclass(frozen=True, slots=True)
class OPIWeights:
    r"""Weights :math:`w_i` and normalisers :math:`N_i` of the OPI, eq. (22).

    Defaults are the paper's printed values (w sums to 1.4, not 1: see module notes).
    """

    w_itae: float = 0.6
    w_isu: float = 0.2
    w_iau: float = 0.6
    n_itae: float = 10.0
    n_isu: float = 2.0
    n_iau: float = 2.7

    def __post_init__(self) -> None:
        for name in ("w_itae", "w_isu", "w_iau"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"OPI weight {name} must be >= 0, got {getattr(self, name)}")
        for name in ("n_itae", "n_isu", "n_iau"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"OPI normaliser {name} must be > 0, got {getattr(self, name)}")


def opi(
    itae_value: ArrayLike,
    isu_value: ArrayLike,
    iau_value: ArrayLike,
    weights: OPIWeights | None = None,
) -> np.ndarray | float:
    r"""Objective performance index, eq. (22); works elementwise on arrays.

    Parameters
    ----------
    itae_value, isu_value, iau_value
        ITAE, ISU and IAU (numbers or arrays of one shape).
    weights
        The weights and normalisations (default :class:`OPIWeights`, the paper's).

    Returns
    -------
    float or ndarray
    """
    w = weights or OPIWeights()
    out = (
        w.w_itae * np.asarray(itae_value, dtype=float) / w.n_itae
        + w.w_isu * np.asarray(isu_value, dtype=float) / w.n_isu
        + w.w_iau * np.asarray(iau_value, dtype=float) / w.n_iau
    )
    return float(out) if out.ndim == 0 else out
