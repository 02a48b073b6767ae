r"""A plant driven by a sampled input, for a population of parameter vectors: one compiled call.

The grey-box fit (:mod:`aiofl.identification.grey_box`) scores candidate parameter vectors
:math:`p_m`, :math:`m = 1 \dots P`, by simulating the plant

.. math::
    \dot x = f(x, p_m) + g(x, p_m)\,u_{k-d} + L\,\big(y_k - h(x, p_m)\big),
    \qquad t \in [t_k, t_{k+1}),\qquad \hat y_k = h(x(t_k), p_m)

driven by the logged input :math:`u_k`, held over each sample (zero-order hold, as a
digital rig applies it) and delayed by ``d`` whole samples (:math:`u_{k-d} = 0` for
:math:`k < d`).  The last term is zero unless an output-injection gain :math:`L` is given:
then :math:`\hat y_k` is the one-step-ahead prediction of an observer fed the measured
:math:`y_k` (held over the sample), which keeps an open-loop-unstable model's prediction
bounded (a prediction-error model; Ljung, *System Identification*, 2nd ed., 1999, §4.3
and §5.7 on nonlinear state-space predictors).

Each sample interval is integrated by ``substeps`` steps of the classical fourth-order
Runge–Kutta method (Hairer, Nørsett & Wanner, *Solving ODEs I*, §II.1); every member runs
on its own thread slice (numba ``prange``), with no state shared between members, so a
member's output does not depend on the others in the call (the tests check it bit for bit).

**Members that fail.**  A member whose state becomes non-finite or leaves
:math:`|x_i| \le` ``limit`` stops at that sample: its ``stopped`` entry is the index of the
first sample it could not give, and its outputs from there on are NaN, the only NaN this
module returns (``stopped = -1``: the member ran to the end).  The caller decides what a
stopped member costs (the fit scores it as a large finite penalty).

**Compilation.**  The template (:mod:`aiofl.engine.kernel.driven_plant`) is built per plant
through the engine's compile factory (:mod:`aiofl.engine.build.driven_kernel`): compiled on
first use and cached on disk under a fingerprint of its file and the plant's functions,
like every engine kernel.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aiofl.engine.build.driven_kernel import driven_kernel
from aiofl.limits import MAX_POPULATION, MAX_STEPS
from aiofl.plants.base import Plant, PlantError

__all__ = ["DEFAULT_LIMIT", "DEFAULT_SUBSTEPS", "Driven", "simulate_driven"]

DEFAULT_SUBSTEPS = 4
"""RK4 steps per sample interval (the sampled input is constant over each)."""

DEFAULT_LIMIT = 1e8
"""A member whose state leaves ``|x_i| <= limit`` is stopped as diverged."""


class Driven(NamedTuple):
    """The outputs of a driven simulation.

    Attributes
    ----------
    y
        (P, N) simulated outputs :math:`\\hat y_k` per member; NaN only from a stopped
        member's ``stopped`` index on.
    stopped
        (P,) the sample index where each member stopped (diverged or left the limit), -1
        for a member that ran to the end.
    """

    y: NDArray[np.float64]
    stopped: NDArray[np.int64]

    @property
    def diverged(self) -> NDArray[np.bool_]:
        """(P,) whether each member stopped early."""
        return self.stopped >= 0


def _array(name: str, value: ArrayLike, shape: tuple[int, ...]) -> NDArray[np.float64]:
    arr = np.ascontiguousarray(np.asarray(value, dtype=np.float64))
    if arr.shape != shape:
        raise ValueError(f"{name} has shape {arr.shape}; allowed: {shape}")
    return arr


def simulate_driven(
    plant: Plant,
    u: ArrayLike,
    ts: float,
    params: ArrayLike,
    *,
    x0: ArrayLike | None = None,
    delay_samples: int = 0,
    substeps: int = DEFAULT_SUBSTEPS,
    gain: ArrayLike | None = None,
    y_measured: ArrayLike | None = None,
    limit: float = DEFAULT_LIMIT,
) -> Driven:
    r"""Simulate ``plant`` driven by the sampled input ``u`` for every parameter vector.

    Parameters
    ----------
    plant
        The plant (its compiled f, g, h are used).
    u
        (N,) input samples, held over each sample interval.
    ts
        The sample time [s].
    params
        (P, n_p) parameter vectors, one member each (a (n_p,) vector: one member).
    x0
        Initial state: (n,) for every member or (P, n) per member; zeros if omitted.
    delay_samples
        Input delay d in whole samples (the plant sees :math:`u_{k-d}`, 0 before).
    substeps
        RK4 steps per sample interval.
    gain
        (n,) output-injection gain L (see the module notes); zero (pure simulation) if
        omitted.  Needs ``y_measured``.
    y_measured
        (N,) the measured output the injection uses.
    limit
        The bound on every state component beyond which a member stops as diverged.

    Returns
    -------
    Driven
        ``y`` (P, N) and ``stopped`` (P,), see :class:`Driven`.
    """
    uu = np.ascontiguousarray(np.asarray(u, dtype=np.float64))
    if uu.ndim != 1 or uu.shape[0] < 2:
        raise ValueError(f"u has shape {uu.shape}; allowed: a 1-D array of at least 2 samples")
    n_samples = uu.shape[0]
    n = plant.n_states
    pp = np.asarray(params, dtype=np.float64)
    if pp.ndim == 1:
        pp = pp[None, :]
    n_p = len(plant.params)
    if pp.ndim != 2 or pp.shape[1] != n_p:
        raise ValueError(
            f"params has shape {np.shape(params)}; allowed: (P, {n_p}) (plant {plant.name!r} "
            f"has {n_p} parameters: {', '.join(plant.param_names)})"
        )
    n_members = pp.shape[0]
    if not 1 <= n_members <= MAX_POPULATION:
        raise ValueError(f"params has {n_members} rows; allowed: 1 .. {MAX_POPULATION} members")
    if not np.all(np.isfinite(pp)):
        raise ValueError("params holds a non-finite value; allowed: finite parameter values")
    if not (isinstance(substeps, int | np.integer) and 1 <= substeps <= 1000):
        raise ValueError(f"substeps = {substeps!r}; allowed: an integer 1 .. 1000")
    if not (isinstance(delay_samples, int | np.integer) and 0 <= delay_samples < n_samples):
        raise ValueError(
            f"delay_samples = {delay_samples!r}; allowed: an integer 0 .. {n_samples - 1}"
        )
    if not (np.isfinite(ts) and ts > 0):
        raise ValueError(f"ts = {ts!r}; allowed: a finite sample time > 0")
    if not (limit > 0):
        raise ValueError(f"limit = {limit!r}; allowed: > 0")
    if n_samples * substeps > MAX_STEPS:
        raise ValueError(
            f"{n_samples} samples x {substeps} substeps = {n_samples * substeps} steps per "
            f"member; allowed: at most {MAX_STEPS:.0e}"
        )
    if n_members * n_samples * 8 > 2**31:
        raise ValueError(
            f"{n_members} members x {n_samples} samples of output need "
            f"{n_members * n_samples * 8 / 2**30:.1f} GiB; allowed: at most 2 GiB per call"
        )
    if x0 is None:
        xx = np.zeros((n_members, n))
    else:
        xa = np.asarray(x0, dtype=np.float64)
        xx = np.ascontiguousarray(np.broadcast_to(xa, (n_members, n)) if xa.shape == (n,) else xa)
        if xx.shape != (n_members, n) or not np.all(np.isfinite(xx)):
            raise ValueError(
                f"x0 has shape {xa.shape}; allowed: ({n},) or ({n_members}, {n}), finite"
            )
    if gain is None:
        ll = np.zeros(n)
        ym = np.zeros(n_samples)
    else:
        ll = _array("gain", gain, (n,))
        if y_measured is None:
            raise ValueError(
                "gain is given without y_measured; the injection needs the measured output"
            )
        ym = _array("y_measured", y_measured, (n_samples,))
        if not (np.all(np.isfinite(ll)) and np.all(np.isfinite(ym))):
            raise ValueError("gain and y_measured must be finite")
    kernel = driven_kernel(plant)
    y_out = np.empty((n_members, n_samples))
    stopped = np.empty(n_members, dtype=np.int64)
    try:
        kernel(
            uu, float(ts), np.ascontiguousarray(pp), xx, int(delay_samples), int(substeps),
            float(limit), ll, ym, y_out, stopped,
        )  # fmt: skip
    except Exception as exc:  # a plant function that raised
        raise PlantError(
            f"plant {plant.name!r}: a plant function raised in the driven simulation: "
            f"{type(exc).__name__}: {exc}"
        ) from exc
    return Driven(y_out, stopped)
