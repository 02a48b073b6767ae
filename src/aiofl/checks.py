"""Checks of single values, shared by the Python API and the TOML schema.

The dataclasses a notebook builds (:class:`aiofl.scenario.Scenario`,
:class:`aiofl.controller.Controller`) and the engine's arguments
(:func:`aiofl.engine.simulation.simulate_batch`) refuse a value the config schema
(:mod:`aiofl.config.schema`) refuses, with a ``ValueError`` whose message names the field,
the value and the allowed range, as a config error does::

    scenario.noise_variance = nan; allowed: a finite number, >= 0

A number is a Python or numpy ``int`` / ``float``, never a ``bool`` or a string (the
schema is strict the same way: ``true`` or ``"50"`` is no number).
"""

from __future__ import annotations

import math
import numbers
from typing import Any

__all__ = ["allowed_text", "check_integer", "check_number", "is_number"]


def is_number(value: Any) -> bool:
    """Whether ``value`` is a real number (``int``, ``float`` or a numpy scalar), not a bool."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def allowed_text(
    *,
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
    finite: bool = True,
    kind: str = "number",
) -> str:
    """``"a finite number, > 0, <= 0.1"``: the allowed range as the config errors word it.

    Parameters
    ----------
    gt, ge, lt, le
        The bounds (None: none).
    finite
        Whether ±inf is refused.
    kind
        ``"number"`` or ``"integer"``.

    Returns
    -------
    str
    """
    words = [f"a finite {kind}" if finite else f"a {kind} (±inf allowed)"]
    for sym, bound in ((">", gt), (">=", ge), ("<", lt), ("<=", le)):
        if bound is not None:
            words.append(f"{sym} {bound:g}")
    text = ", ".join(words)
    return text.replace("a finite integer", "an integer")


def check_number(
    field: str,
    value: Any,
    *,
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
    finite: bool = True,
) -> float:
    """``value`` as a float if it is a number within the bounds; else ``ValueError`` naming
    ``field``, the value and the allowed range.  NaN is always refused; ±inf unless
    ``finite`` is False.

    Parameters
    ----------
    field
        The field, for the message.
    value
        The value (a bool is refused).
    gt, ge, lt, le
        The bounds (None: none).
    finite
        Refuse ±inf (default True).

    Returns
    -------
    float
    """
    allowed = allowed_text(gt=gt, ge=ge, lt=lt, le=le, finite=finite)
    if not is_number(value):
        raise ValueError(f"{field} = {value!r}; allowed: {allowed}")
    x = float(value)
    ok = not math.isnan(x) and (math.isfinite(x) or not finite)
    ok = ok and (gt is None or x > gt) and (ge is None or x >= ge)
    ok = ok and (lt is None or x < lt) and (le is None or x <= le)
    if not ok:
        raise ValueError(f"{field} = {value!r}; allowed: {allowed}")
    return x


def check_integer(
    field: str,
    value: Any,
    *,
    ge: int | None = None,
    lt: int | None = None,
    le: int | None = None,
) -> int:
    """``value`` as an int if it is an integer (Python or numpy, not a bool, not a float)
    within the bounds; else ``ValueError`` naming ``field``.

    Parameters
    ----------
    field
        The field, for the message.
    value
        The value.
    ge, lt, le
        The bounds (None: none).

    Returns
    -------
    int
    """
    allowed = allowed_text(ge=ge, lt=lt, le=le, kind="integer")
    if not isinstance(value, numbers.Integral) or isinstance(value, bool):
        raise ValueError(f"{field} = {value!r}; allowed: {allowed}")
    n = int(value)
    if (ge is not None and n < ge) or (lt is not None and n >= lt) or (le is not None and n > le):
        raise ValueError(f"{field} = {value!r}; allowed: {allowed}")
    return n
