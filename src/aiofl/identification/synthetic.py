r"""Logs of a known plant, made by an independent simulator (scipy's ``solve_ivp``).

The identification routes are checked on these: a log whose truth is known, made by code
that shares nothing with the compiled engine being fitted.  The plant
:math:`\dot x = f(x,p) + g(x,p)\,u(t - \tau)` is integrated in Python with an adaptive
Runge–Kutta method (DOP853, tight tolerances) from one sample to the next, the input held
over each sample (zero-order hold) and delayed by ``delay`` seconds; the output
:math:`y_k = h(x(t_k))` is then corrupted as a rig would: additive Gaussian noise, and
quantisation to the encoder's step.
"""

from __future__ import annotations

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

    def held(k: int) -> float:
        return float(uu[k]) if k >= 0 else 0.0

    for k in range(tt.shape[0] - 1):
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
    return Log(
        tt.copy(), uu.copy(), measure(y_true, noise_std=noise_std, quantum=quantum, seed=seed)
    )


def measure(
    y_true: ArrayLike, *, noise_std: float = 0.0, quantum: float = 0.0, seed: int = 0
) -> np.ndarray:
    """The measured output of a true one: Gaussian noise (seeded), then quantisation.

    One noiseless :func:`simulate_log` and many ``measure`` calls give many noise
    realisations of the same experiment cheaply (coverage tests).
    """
    y = np.asarray(y_true, dtype=np.float64)
    rng = np.random.default_rng(seed)
    if noise_std > 0:
        y = y + rng.normal(0.0, noise_std, y.shape)
    if quantum > 0:
        y = quantum * np.round(y / quantum)
    return y
