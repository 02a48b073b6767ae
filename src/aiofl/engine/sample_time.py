"""What a controller run by a user (not by the engine) can be given: the sample time, the
coefficients, and the measurement and reference, with one policy for a sample it cannot use.

Shared by :class:`aiofl.DiscreteController`, the exported C (:mod:`aiofl.export.c_code`)
and the FMU (:mod:`aiofl.export.fmu`), so the three refuse and hold alike:

- **at construction** (export): a sample time that is not a number (``True`` included),
  not finite, or outside [:data:`TS_MIN`, :data:`TS_MAX`] s (:func:`check_ts`); a sample
  time this design cannot be discretised at, with the range it can (:func:`discrete_row`,
  :func:`design_ts_range`); coefficients that are not finite (a parameter such as
  ``sef.omega_c = 1e308``);
- **at each sample**, the *fault* policy: a measurement y or a reference value the
  controller reads that is not finite or larger in magnitude than :data:`SIGNAL_MAX`, or an
  update that would make the command or the controller's memory non-finite, is a fault.
  A faulted sample changes nothing: the controller keeps its memory from before it and
  returns the last command it returned (before the first: the start's ``eso.u0``), and
  raises its fault flag, which stays up, the command held, every later sample ignored,
  until the controller is started again (``init`` / ``reset``; ``NAME_start`` /
  ``NAME_init`` / ``NAME_reset`` in C; ``fmi2Reset`` in the FMU), as firmware holds its
  output on a sensor fault until an operator clears it.  A measurement of the wrong type
  or shape is a programming error, not a fault: it raises.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl.controller import Controller, controller_batch
from aiofl.engine.discrete_rows import Sampling, known_delay_samples, sampling_rows

__all__ = [
    "SIGNAL_MAX",
    "TS_MAX",
    "TS_MIN",
    "check_ts",
    "design_ts_range",
    "discrete_row",
]

TS_MIN = 1e-9
"""Smallest sample time [s] of a controller run by a user (1 GHz: beyond any processor's
control loop; below it a design's updates vanish in rounding, e.g. an INLESO at
ts = 5e-324 returned u = 0 for ever)."""
TS_MAX = 1.0
"""Largest sample time [s] (as the config's ``[controller.discrete] ts``)."""
SIGNAL_MAX = 1e30
"""Largest magnitude of a measurement or reference value the controller uses: beyond any
physical signal in SI units, and inside float's range (a float build can carry it)."""


def check_ts(ts: Any, name: str = "ts") -> float:
    """``ts`` as a float if it is a sample time a controller can run at; else ValueError
    (TypeError for a value that is not a real number, ``True`` included) naming ``name``
    and the allowed range."""
    allowed = f"allowed: a number of seconds, {TS_MIN:g} <= {name} <= {TS_MAX:g}"
    if isinstance(ts, bool) or not isinstance(ts, int | float | np.integer | np.floating):
        raise TypeError(f"{name} = {ts!r} ({type(ts).__name__}); {allowed}")
    value = float(ts)
    if not (math.isfinite(value) and TS_MIN <= value <= TS_MAX):
        raise ValueError(f"{name} = {value:g} s; {allowed}")
    return value


def _row(
    controller: Controller, sampling: Sampling, jac: NDArray[np.float64] | None
) -> NDArray[np.float64]:
    return sampling_rows(controller_batch(controller), [sampling], sampling.ts, jac)[0]


def design_ts_range(
    controller: Controller, sampling: Sampling, jac: NDArray[np.float64] | None = None
) -> tuple[float, float] | None:
    """The smallest and largest sample time of a scan of [:data:`TS_MIN`, :data:`TS_MAX`]
    (four per decade) at which ``controller`` with ``sampling``'s other settings is
    discretised with finite coefficients, or None if at none.

    Parameters
    ----------
    controller, sampling
        The design and its sampling settings.
    jac
        A model-assisted observer's model Jacobian (None: none).

    Returns
    -------
    tuple of (float, float) or None
    """
    from dataclasses import replace

    good = []
    for ts in np.logspace(math.log10(TS_MIN), math.log10(TS_MAX), 37):
        try:
            with np.errstate(all="ignore"):
                _row(controller, replace(sampling, ts=float(ts)), jac)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError):
            continue
        good.append(float(ts))
    return (good[0], good[-1]) if good else None


def discrete_row(
    controller: Controller,
    sampling: Sampling,
    jac: NDArray[np.float64] | None = None,
    name: str = "ts",
) -> NDArray[np.float64]:
    """The engine's discrete coefficient row of ``controller`` sampled by ``sampling``
    (``jac``: a model-assisted observer's model Jacobian).  A sample time the design cannot
    be discretised at (non-finite coefficients, a pole placement that fails) raises
    ValueError naming ``name`` with the range a scan found (:func:`design_ts_range`); a
    known delay (``eso.delay``) that is not a whole number of samples, naming it.

    Parameters
    ----------
    controller, sampling, jac
        As for :func:`design_ts_range`.
    name
        The field named in the message (default ``"ts"``).

    Returns
    -------
    ndarray
    """
    known_delay_samples(controller.value("eso.delay"), sampling.ts)
    try:
        with np.errstate(all="ignore"):
            return _row(controller, sampling, jac)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        span = design_ts_range(controller, sampling, jac)
        if span is None:
            raise ValueError(
                f"{name} = {sampling.ts:g} s: this design cannot be discretised at any sample "
                f"time from {TS_MIN:g} to {TS_MAX:g} s ({exc})"
            ) from None
        raise ValueError(
            f"{name} = {sampling.ts:g} s: this design cannot be discretised at it ({exc}); "
            f"allowed for this design: about {span[0]:.3g} <= {name} <= {span[1]:.3g} s"
        ) from None
