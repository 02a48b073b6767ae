r"""Stability margins of tuning candidates, and the warnings on a chosen design.

**Margins as quantities.**  ``pm``, ``gm``, ``dm`` and ``ms`` may be named in ``[tune]``
``objectives`` and ``constraints`` (``"pm >= 45"``, ``"ms <= 2"``, ``"gm >= 6"``,
``"dm >= 0.002"``) like the engine metrics.  They are those of the loop broken at the plant
input, linearised at the operating point (:func:`aiofl.analysis.linearize.
linearize_closed_loop`, :mod:`aiofl.analysis.frequency`; Åström & Murray, *Feedback
Systems*, 2nd ed., ch. 10):

``pm``
    phase margin :math:`\varphi_m = 180° + \angle L(j\omega_{gc})` [deg];
``gm``
    gain margin :math:`20\log_{10}(1/|L(j\omega_{pc})|)` [dB] (``inf`` without a phase
    crossover);
``dm``
    delay margin :math:`\min_i \varphi_{m,i}/\omega_{gc,i}` [s] (``inf`` without a gain
    crossover);
``ms``
    sensitivity peak :math:`M_s = \max_\omega |1/(1 + L(j\omega))|`.

They are computed on the nominal plant only (no aggregate over robust draws: the
linearisation does not see the draws' plants), and only when an objective or constraint
names one: a linearisation costs 0.05–0.2 s, some seconds per generation of 30.  A
candidate whose linearised closed loop is not stable, that has no operating point, or
whose simulation diverged gets the worst value of each margin (``pm``, ``gm``, ``dm``
:math:`-\infty`, ``ms`` :math:`+\infty`): infeasible for any margin constraint.  As an
objective ``ms`` is minimised and ``pm``, ``gm``, ``dm`` are maximised (pymoo minimises
their negatives; the front and the summaries show the margins themselves).

**Warnings.**  :func:`design_warnings` checks a chosen design: a tuned parameter within
1 % of a bound of its search interval (in the interval's own scale, log or linear), a
phase margin below :data:`PM_WARN` or an :math:`M_s` above :data:`MS_WARN`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "BOUND_FRACTION",
    "MARGIN_QUANTITIES",
    "MAXIMISED",
    "MS_WARN",
    "PM_WARN",
    "candidate_margins",
    "design_margins",
    "design_warnings",
]

MARGIN_QUANTITIES = ("pm", "gm", "dm", "ms")
"""The margin quantities an objective or constraint may name."""
MAXIMISED = ("pm", "gm", "dm")
"""Margins that are better when larger (maximised as objectives)."""
PM_WARN = 30.0
"""A chosen design with a phase margin below this [deg] gets a warning."""
MS_WARN = 2.5
"""A chosen design with a sensitivity peak above this gets a warning."""
BOUND_FRACTION = 0.01
"""A tuned value within this fraction of its interval from a bound gets a warning."""

_WORST = {"pm": -math.inf, "gm": -math.inf, "dm": -math.inf, "ms": math.inf}


def design_margins(plant: Any, controller: Any, scenario: Any) -> dict[str, float]:
    """``{"pm", "gm", "dm", "ms"}`` of one design (module docstring); the worst values
    when the linearised closed loop is not stable or has no operating point.

    Parameters
    ----------
    plant, controller, scenario
        The design.

    Returns
    -------
    dict of str to float
        ``pm`` [deg], ``gm`` [dB], ``dm`` [s], ``ms``.
    """
    from aiofl.analysis.linearize import linearize_closed_loop

    try:
        lin = linearize_closed_loop(plant=plant, controller=controller, scenario=scenario)
        if lin.verdict() != "stable":
            return dict(_WORST)
        m = lin.margins
    except (ValueError, ArithmeticError, np.linalg.LinAlgError):
        return dict(_WORST)
    out = {"pm": m.phase_margin_deg, "gm": m.gain_margin_db, "dm": m.delay_margin_s, "ms": m.ms}
    return {k: (float(v) if not math.isnan(v) else _WORST[k]) for k, v in out.items()}


def candidate_margins(
    config: Any,
    names: Sequence[str],
    values: NDArray[np.float64],
    skip: NDArray[np.bool_] | None = None,
) -> dict[str, NDArray[np.float64]]:
    """The margins of every candidate: ``{"pm": (B,), ...}``.

    Parameters
    ----------
    config
        The tuned :class:`aiofl.config.RunConfig` (its plant, scenario and controller).
    names, values
        Tuned parameter names and their values, (B, d).
    skip
        Candidates not to linearise (e.g. diverged in simulation); they get the worst
        values.

    Returns
    -------
    dict of str to ndarray
    """
    values = np.atleast_2d(np.asarray(values, dtype=np.float64))
    out = {k: np.full(values.shape[0], _WORST[k]) for k in MARGIN_QUANTITIES}
    for i, row in enumerate(values):
        if skip is not None and skip[i]:
            continue
        ctrl = config.controller.with_values(**dict(zip(names, map(float, row), strict=True)))
        for k, v in design_margins(config.plant, ctrl, config.scenario).items():
            out[k][i] = v
    return out


def _near_bound(value: float, lo: float, hi: float, log: bool) -> str | None:
    if log and lo > 0 and value > 0:
        v, a, b = math.log(value), math.log(lo), math.log(hi)
    else:
        v, a, b = value, lo, hi
    span = b - a
    if v - a <= BOUND_FRACTION * span:
        return "lower"
    if b - v <= BOUND_FRACTION * span:
        return "upper"
    return None


def design_warnings(
    config: Any, parameters: Mapping[str, Any], values: Mapping[str, float]
) -> tuple[list[str], dict[str, float] | None]:
    """Warnings on a chosen design, and its margins (None if they could not be computed).

    ``parameters`` are the ``[tune]`` search intervals (objects with ``lo``, ``hi``,
    ``log``), ``values`` the chosen values; ``config`` the chosen design's run config.

    Parameters
    ----------
    config
        The chosen design's run config.
    parameters
        The ``[tune]`` search intervals (``lo``, ``hi``, ``log``), by name.
    values
        The chosen values, by name.

    Returns
    -------
    warnings : list of str
    margins : dict of str to float or None
    """
    warn = []
    for name, b in parameters.items():
        side = _near_bound(float(values[name]), float(b.lo), float(b.hi), bool(b.log))
        if side is not None:
            bound = b.lo if side == "lower" else b.hi
            scale = "log" if b.log else "linear"
            warn.append(
                f"{name} = {values[name]:.6g} is within {100 * BOUND_FRACTION:g} % ({scale} "
                f"scale) of its {side} search bound {bound:g}: the optimum may lie outside "
                "the interval; widen it and tune again"
            )
    margins = None
    try:
        margins = design_margins(config.plant, config.controller, config.scenario)
    except Exception as exc:  # a warning check must not fail the run
        warn.append(f"margins of the chosen design not computed: {type(exc).__name__}: {exc}")
        return warn, None
    if math.isinf(margins["ms"]) and margins["pm"] == -math.inf:
        warn.append(
            "the chosen design's closed loop linearised at its operating point is not "
            "stable (or has no operating point): no margins"
        )
        return warn, margins
    if margins["pm"] < PM_WARN:
        warn.append(
            f"phase margin {margins['pm']:.3g}° < {PM_WARN:g}° (loop broken at the plant "
            "input): little robustness to delay and unmodelled dynamics"
        )
    if margins["ms"] > MS_WARN:
        warn.append(
            f"sensitivity peak Ms = {margins['ms']:.3g} > {MS_WARN:g}: the loop amplifies "
            "disturbances and is close to the critical point −1"
        )
    return warn, margins
