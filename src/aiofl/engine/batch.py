"""A batch as the compiled time loop reads it: one record of packed arrays, and its outputs.

:class:`Batch` holds, for every member of a batch, one row of each table the loop reads
(the controller's integer and float rows, the plant's parameter vectors, the scenario row,
the initial state, the discrete controller's coefficient row) and the run's settings;
:class:`Outputs` holds what the loop writes.  Both are named tuples, so numba passes them
to the compiled loop as one argument each and the loop reads ``batch.dt``,
``batch.floats[i]``, ... by name.  :func:`aiofl.engine.simulation.simulate_batch` packs
them (:func:`pack`); members share the horizon and the step.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

__all__ = ["Batch", "Outputs"]


class Batch(NamedTuple):
    """The inputs of one batch, as the time loop reads them (B members).

    Attributes
    ----------
    ints
        (B, :data:`aiofl.layout.N_INT`) component kinds, ρ, feedback length, ESO start.
    floats
        (B, :data:`aiofl.layout.N_FLOAT`) controller parameters, by
        :data:`aiofl.layout.FLOAT_COLUMNS`.
    p_before, p_after
        (B, n_p) the true plant's parameters before and after the scenario's change.
    p_nom
        (B, n_p) the nominal parameters (the classical IOFL law's model).
    scen
        (B, :data:`aiofl.layout.N_SCEN`) the scenario rows (reference, disturbance, noise).
    x0
        (B, n) the plant's initial state.
    ref_table, ref_row
        Sampled references, one row per distinct scenario, and each member's row.
    noise_table, noise_row
        Unit-variance noise sequences, one row per distinct scenario, and each member's row.
    disc
        (B, :data:`aiofl.engine.discrete_rows.N_DISC`) the discrete controller's rows (zeros for
        a continuous member).
    bounds
        (B, n + 1, 2) the plant's declared ranges, ``[low, high]``: rows 0..n-1 the
        states, row n the output (``-inf, inf`` where none); leaving one makes a member
        lost (:func:`aiofl.engine.kernel.loop._tpl_watch`).
    plant_table
        (:data:`aiofl.engine.kernel.plant_calls.N_TABLE`,) the addresses of the plant's functions
        a plant-independent instance calls (:mod:`aiofl.engine.build.plant_table`; set by
        :func:`aiofl.engine.build.instances.run` before such an instance runs, unread by the
        others).
    dt, n_steps, method, decimation, store, threshold
        The step [s], the number of steps, the method (:data:`aiofl.layout.METHODS`), the
        trajectory's decimation, whether to store it, the divergence threshold.
    """

    ints: NDArray[np.int64]
    floats: NDArray[np.float64]
    p_before: NDArray[np.float64]
    p_after: NDArray[np.float64]
    p_nom: NDArray[np.float64]
    scen: NDArray[np.float64]
    x0: NDArray[np.float64]
    ref_table: NDArray[np.float64]
    ref_row: NDArray[np.int64]
    noise_table: NDArray[np.float64]
    noise_row: NDArray[np.int64]
    disc: NDArray[np.float64]
    bounds: NDArray[np.float64]
    plant_table: NDArray[np.int64]
    dt: float
    n_steps: int
    method: int
    decimation: int
    store: bool
    threshold: float


class Outputs(NamedTuple):
    """What the time loop writes, per member: ``metrics`` (B, :data:`aiofl.layout.N_METRIC`)
    at the end or where the member stopped, ``status`` (B,) :data:`aiofl.layout.STATUS_OK`,
    ``STATUS_LOST`` or ``STATUS_DIVERGED``, ``t_stop`` (B,) the time it was lost or
    diverged (NaN if neither), ``stats`` (B, :data:`aiofl.layout.N_STAT`) what the loop
    watched (peaks, saturation, step response, steady-state window) and ``traj`` (B, T, C)
    the stored trajectory (rows after the stop set to NaN; T = 0 when not stored)."""

    metrics: NDArray[np.float64]
    status: NDArray[np.int64]
    t_stop: NDArray[np.float64]
    stats: NDArray[np.float64]
    traj: NDArray[np.float64]
