r"""Logs of a known plant, made by an independent simulator (scipy's ``solve_ivp``).

The identification routes are checked on these: a log whose truth is known, made by code
that shares nothing with the compiled engine being fitted.  The plant
:math:`\dot x = f(x,p) + g(x,p)\,u(t - \tau)` is integrated in Python with an adaptive
Runge–Kutta method (DOP853, tight tolerances) from one sample to the next, the input held
over each sample (zero-order hold) and delayed by ``delay`` seconds; the output
:math:`y_k = h(x(t_k))` is then corrupted as a rig would: additive Gaussian noise, and
quantisation to the encoder's step.

A closed-loop log (``feedback``): the input applied on :math:`[t_k, t_{k+1})` is computed at
:math:`t_k` by a sampled control law from the reference :math:`r_k` and the *measured*
output :math:`y_k` (noisy and quantised, as the rig's controller sees it), so the noise
reaches the input as it does on a rig.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike
from scipy.integrate import solve_ivp

from aiofl.identification.log import Log
from aiofl.plants.base import Plant

__all__ = ["measure", "simulate_log"]


def simulate_log(
    plant: Plant,
    t: ArrayLike,
    u: ArrayLike,
    *,
    x0: ArrayLike | None = None,
    params: ArrayLike | None = None,
    delay: float = 0.0,
    noise_std: float = 0.0,
    quantum: float = 0.0,
    seed: int = 0,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    feedback: Callable[[int, float, float], float] | None = None,
) -> Log:
    """Simulate ``plant`` driven by the sampled input ``u`` and return the log a rig would give.

    Parameters
    ----------
    plant
        The plant; its Python functions are called (nothing is compiled).
    t
        Uniform sample times [s].
    u
        Input samples, held over each sample interval.
    x0
        Initial state (zeros if omitted).
    params
        The plant's parameter vector (its nominal values if omitted).
    delay
        Input (transport) delay [s]: the plant sees ``u(t - delay)``, zero before ``t0 + delay``.
    noise_std
        Standard deviation of additive Gaussian output noise.
    quantum
        Quantisation step of the measured output (0: none): ``y = quantum * round(y / quantum)``.
    seed
        Seed of the noise.
    feedback
        A sampled control law ``u_k = feedback(k, r_k, y_k)`` closing the loop: ``u`` is
        then the reference :math:`r_k`, :math:`y_k` the measured output (the noise and
        quantisation of :func:`measure`, the same realisation); the log's ``u`` is the
        applied input and its ``r`` the reference.

    rtol, atol
        The tolerances of :func:`scipy.integrate.solve_ivp` (DOP853) on each interval.

    Returns
    -------
    Log
        Uniform samples ``t``, the applied ``u``, the measured ``y`` (and ``r`` with
        ``feedback``).
    """
    tt = np.asarray(t, dtype=np.float64)
    uu = np.asarray(u, dtype=np.float64)
    if tt.ndim != 1 or tt.shape != uu.shape or tt.shape[0] < 2:
        raise ValueError("t and u must be 1-D arrays of the same length (at least 2)")
    p = plant.param_vector() if params is None else np.asarray(params, dtype=np.float64)
    x = np.zeros(plant.n_states) if x0 is None else np.asarray(x0, dtype=np.float64).copy()
    ts = float(tt[1] - tt[0])
    # the input the plant sees on each interval: the held and delayed samples, split at the
    # instants where the delayed staircase steps
    whole = int(np.floor(delay / ts + 1e-9))
    frac = delay - whole * ts
    y_true = np.empty_like(tt)
    y_true[0] = plant.output(x, p)
    applied = uu.copy() if feedback is None else np.zeros_like(uu)
    noise = np.zeros_like(tt)
    if feedback is not None and noise_std > 0:  # the draws of measure(), in order
        noise = np.random.default_rng(seed).normal(0.0, noise_std, tt.shape)

    def held(k: int) -> float:
        return float(applied[k]) if k >= 0 else 0.0

    for k in range(tt.shape[0] - 1):
        if feedback is not None:
            y_k = y_true[k] + noise[k]
            y_k = quantum * np.round(y_k / quantum) if quantum > 0 else y_k
            applied[k] = float(feedback(k, float(uu[k]), float(y_k)))
        t0, t1 = float(tt[k]), float(tt[k + 1])
        pieces = []
        if frac > 1e-12 * ts:
            pieces.append((t0, t0 + frac, held(k - whole - 1)))
            pieces.append((t0 + frac, t1, held(k - whole)))
        else:
            pieces.append((t0, t1, held(k - whole)))
        for a, b, uk in pieces:
            sol = solve_ivp(
                lambda _t, s, uk=uk: plant.rhs(s, uk, 0.0, p),
                (a, b),
                x,
                method="DOP853",
                rtol=rtol,
                atol=atol,
            )
            if not sol.success:
                raise RuntimeError(f"the reference simulation failed at t = {a:g} s: {sol.message}")
            x = sol.y[:, -1]
        y_true[k + 1] = plant.output(x, p)
    y = measure(y_true, noise_std=noise_std, quantum=quantum, seed=seed)
    if feedback is None:
        return Log(tt.copy(), uu.copy(), y)
    y_last = float(y[-1])
    applied[-1] = float(feedback(tt.shape[0] - 1, float(uu[-1]), y_last))
    return Log(tt.copy(), applied, y, r=uu.copy())


def measure(
    y_true: ArrayLike, *, noise_std: float = 0.0, quantum: float = 0.0, seed: int = 0
) -> np.ndarray:
    """The measured output of a true one: Gaussian noise (seeded), then quantisation.

    One noiseless :func:`simulate_log` and many ``measure`` calls give many noise
    realisations of the same experiment cheaply (coverage tests).

    Parameters
    ----------
    y_true
        The true output samples.
    noise_std
        Standard deviation of the Gaussian noise (0: none).
    quantum
        Quantisation step (0: none).
    seed
        Seed of the noise.

    Returns
    -------
    ndarray
    """
    y = np.asarray(y_true, dtype=np.float64)
    rng = np.random.default_rng(seed)
    if noise_std > 0:
        y = y + rng.normal(0.0, noise_std, y.shape)
    if quantum > 0:
        y = quantum * np.round(y / quantum)
    return y
