"""A time budget for an analysis: a deadline its long computations check.

An analysis that integrates a stiff loop (the reconciled orbit verdict's limit-cycle
simulation, :mod:`aiofl.analysis.orbit`) or runs a ladder of engine calls (the sampling
limits, :mod:`aiofl.analysis.sampling_limits`) can take minutes on a hard design.  Wrapped in
:func:`time_budget`, such a computation stops cleanly once the budget is spent: the places
that loop call :func:`check_budget` (every right-hand-side evaluation of
:func:`aiofl.analysis.variational.trajectory`, every round of the sampling ladder), which
raises :class:`BudgetExceeded`; the analysis catches it and reports "gave up after N s"
for the part it did not finish.  ``aiofl analyze --budget SECONDS`` sets it.

The check is cooperative (no signal interrupts compiled code or a file write): a single
long call that never returns to a check point (a sympy simplification, one engine batch)
is not cut short, so an analysis stops within one such call of its budget.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar

__all__ = ["DEFAULT_BUDGET", "BudgetExceeded", "budget_spent", "check_budget", "time_budget"]

DEFAULT_BUDGET = 120.0
"""Seconds ``aiofl analyze`` gives an analysis unless ``--budget`` says otherwise."""

# (monotonic deadline, the budget in seconds) of the innermost time_budget, or None
_DEADLINE: ContextVar[tuple[float, float] | None] = ContextVar("aiofl_deadline", default=None)


class BudgetExceeded(RuntimeError):
    """The time budget of an analysis is spent (:func:`check_budget`)."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds
        super().__init__(f"gave up after {seconds:g} s (the analysis' time budget)")


@contextmanager
def time_budget(seconds: float | None) -> Iterator[None]:
    """Give the computations inside at most ``seconds`` (None: no budget).

    Nested budgets keep the earlier deadline: an inner budget cannot extend an outer one.
    """
    if seconds is None:
        yield
        return
    if not seconds > 0:
        raise ValueError(f"time budget = {seconds}; allowed: > 0 seconds")
    deadline = time.monotonic() + seconds
    outer = _DEADLINE.get()
    if outer is not None and outer[0] < deadline:
        deadline, seconds = outer
    token = _DEADLINE.set((deadline, seconds))
    try:
        yield
    finally:
        _DEADLINE.reset(token)


def budget_spent() -> float | None:
    """The budget in seconds if the innermost :func:`time_budget` is spent, else None (for
    a computation that stops early with what it has rather than raising)."""
    current = _DEADLINE.get()
    if current is not None and time.monotonic() > current[0]:
        return current[1]
    return None


def check_budget() -> None:
    """Raise :class:`BudgetExceeded` if the innermost :func:`time_budget` is spent."""
    spent = budget_spent()
    if spent is not None:
        raise BudgetExceeded(spent)
