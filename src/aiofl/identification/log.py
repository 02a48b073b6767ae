r"""A logged experiment: time, input, output (and the reference, when a controller closed the loop).

A :class:`Log` is plain data, uniformly sampled at :attr:`Log.ts`: the samples
:math:`(t_k, u_k, y_k)`, :math:`k = 0 \dots N-1`, with :math:`u_k` held over
:math:`[t_k, t_{k+1})` (zero-order hold, as a digital rig applies it) and :math:`y_k` measured
at :math:`t_k`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np
from numpy.typing import NDArray

__all__ = ["Log", "LogError"]


class LogError(ValueError):
    """A log that cannot be used, with the column (and row) at fault in its message."""


@dataclass(frozen=True)
class Log:
    """Uniformly sampled input/output data of one experiment.

    Parameters
    ----------
    t, u, y
        Sample times [s], input and output, 1-D float arrays of the same length.
    r
        The reference, for a closed-loop log; None for an open-loop test.
    units
        Units of ``"t"``, ``"u"``, ``"y"`` (and ``"r"``) as plain text; ``""`` when undeclared.
    source
        Where the log came from (a file name), for messages and reports.
    """

    t: NDArray[np.float64]
    u: NDArray[np.float64]
    y: NDArray[np.float64]
    r: NDArray[np.float64] | None = None
    units: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}))
    source: str = ""

    @property
    def n_samples(self) -> int:
        """N, the number of samples."""
        return int(self.t.shape[0])

    @property
    def ts(self) -> float:
        """The sample time [s] (the mean step of :attr:`t`)."""
        return float((self.t[-1] - self.t[0]) / (self.t.shape[0] - 1))

    @property
    def duration(self) -> float:
        """t_{N-1} - t_0 [s]."""
        return float(self.t[-1] - self.t[0])

    def part(self, start: int, stop: int) -> Log:
        """Samples ``start:stop`` as a log of their own (an estimation or a validation part)."""
        r = None if self.r is None else self.r[start:stop]
        return Log(
            self.t[start:stop], self.u[start:stop], self.y[start:stop], r, self.units, self.source
        )
