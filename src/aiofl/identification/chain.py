r"""The model-free route: what an ADRC design needs from a log alone (ρ, b0, a delay).

ADRC models the plant as the chain :math:`y^{(\rho)} = f + b_0 u` (Han 2009; Gao 2003):
the design needs the order ρ, the high-frequency gain :math:`b_0` (the coefficient of u in
:math:`y^{(\rho)}`) and, for the observer's bandwidth, the input delay and the noise.
:func:`identify_chain` fits, for each candidate order ρ = 1 … ``rho_max``, the
continuous-time process model

.. math::
    y^{(\rho)} + a_{\rho-1}y^{(\rho-1)} + \dots + a_0 y = b_0\,u(t-\tau) + c\;[-\;F_c
    \operatorname{sign}\dot y]

to the log by the output-error method (:mod:`aiofl.identification.chain_fit`: exact
sampling with a sub-sample delay, variable projection, least squares on the simulated
output — not finite differences of a quantised signal).  The a's, c and the friction are
the part of the total disturbance f the data explain; b0 is the coefficient ADRC needs.

**Order.**  Each order's fit is scored by the Bayesian information criterion
:math:`\mathrm{BIC} = N\ln(\mathrm{RSS}/N) + n_p\ln N` (Schwarz, "Estimating the dimension
of a model", Ann. Stat. 6, 1978; Ljung 1999, Sec. 16.4), which, unlike Akaike's, does not
favour a needlessly high order as N grows; the lowest score wins and every candidate's is
reported.  A higher order than the plant's can only mimic a lower one with a pole at the
edge of what the sampling resolves (:data:`~aiofl.identification.chain_fit.POLE_MAX`),
so its extra parameters buy almost nothing and the criterion refuses them.

**Friction.**  A Coulomb friction force :math:`F_c\operatorname{sign}\dot y` is a
disturbance a linear chain cannot explain; left out, it biases b0 (a friction of 15 % of
b0·abs(u) biased it by +39 % in ``benchmarks/bench_identify.py``).  With ``friction=None``
(automatic) the orders ρ ≥ 2 are fitted with the term (the sign of ẏ from a
Savitzky–Golay slope of the log, :func:`~aiofl.identification.chain_fit.velocity_sign`),
and the chosen order keeps it only when its BIC is lower with it.  For ρ = 1 sign(ẏ) is
the sign of u under a binary input, so the term cannot be told from b0 u and is not fitted.

**Uncertainty.**  ``b0_std`` and ``delay_std`` come from the least-squares covariance at
the optimum, made robust to correlated residuals (Newey–West;
:func:`~aiofl.identification.chain_fit.fit_chain`): the stated assumption is an output
error that is stationary and short-correlated (sensor noise, quantisation), not
unmodelled dynamics.  ``noise_std`` is the residual's standard deviation of the chosen fit
(sensor noise and quantisation together: what the observer will see).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl.identification.chain_fit import ChainFit, fit_chain, velocity_sign
from aiofl.identification.log import Log, LogError

__all__ = [
    "MAX_CHAIN_SAMPLES",
    "MAX_DELAY_SAMPLES",
    "MAX_RHO",
    "ChainCandidate",
    "ChainEstimate",
    "identify_chain",
]

#: the highest chain order tried
MAX_RHO = 6
#: most samples of a log the model-free route fits (about 0.1 s of fitting per 10^4 samples
#: and order)
MAX_CHAIN_SAMPLES = 2_000_000
#: the longest delay searched, in samples
MAX_DELAY_SAMPLES = 2_000
#: fewest samples per fitted parameter
MIN_SAMPLES_PER_PARAMETER = 20
#: the window half-width (samples) of the velocity sign the friction term uses
SIGN_WIDTH = 10
#: the largest deviation of a time step from the mean step (the fit assumes uniform samples)
UNIFORM_TOLERANCE = 0.01


@dataclass(frozen=True)
class ChainCandidate:
    """One order's fit: its b0 (± std), delay, criterion score and NRMSE fit [%]."""

    rho: int
    b0: float
    b0_std: float
    delay: float
    score: float
    fit_percent: float

    def to_record(self) -> dict[str, Any]:
        """JSON-ready dict (keys named as the fields)."""
        return {
            "rho": self.rho,
            "b0": self.b0,
            "b0_std": self.b0_std,
            "delay": self.delay,
            "score": self.score,
            "fit_percent": self.fit_percent,
        }


@dataclass(frozen=True)
class ChainEstimate:
    r"""What the model-free route found (module notes).

    Attributes
    ----------
    rho, b0, b0_std
        The chosen order, the coefficient of u in :math:`y^{(\rho)}` and its standard error.
    delay, delay_std
        The input delay [s] (clipped at 0) and its standard error.
    noise_std
        The residual's standard deviation: the output noise (and quantisation) level.
    criterion
        How the order was chosen (``"BIC"``, or ``"given"``).
    candidates
        Every order's fit, in order.
    fit_percent
        NRMSE fit of the chosen model on the log, :math:`100(1 - \|y - \hat y\| /
        \|y - \bar y\|)` (MATLAB ``compare``'s definition).
    coefficients, offset, friction
        :math:`a_0 \dots a_{\rho-1}`, c and :math:`F_c` of the chosen model (friction 0
        when not fitted).
    """

    rho: int
    b0: float
    b0_std: float
    delay: float
    delay_std: float
    noise_std: float
    criterion: str
    candidates: tuple[ChainCandidate, ...]
    fit_percent: float
    coefficients: tuple[float, ...] = ()
    offset: float = 0.0
    friction: float = 0.0

    def to_record(self) -> dict[str, Any]:
        """JSON-ready dict: rho, b0, b0_std, delay, delay_std, noise_std, criterion,
        fit_percent, coefficients, offset, friction, candidates = [...]."""
        return {
            "rho": self.rho,
            "b0": self.b0,
            "b0_std": self.b0_std,
            "delay": self.delay,
            "delay_std": self.delay_std,
            "noise_std": self.noise_std,
            "criterion": self.criterion,
            "fit_percent": self.fit_percent,
            "coefficients": list(self.coefficients),
            "offset": self.offset,
            "friction": self.friction,
            "candidates": [c.to_record() for c in self.candidates],
        }


def _check(log: Log, rho_max: int, rho: int | None, delay_max: float | None) -> tuple[int, float]:
    """Refuse what cannot be fitted, by name; return the orders' top and the delay bound."""
    if not isinstance(rho_max, int) or isinstance(rho_max, bool) or not 1 <= rho_max <= MAX_RHO:
        raise ValueError(f"rho_max = {rho_max!r}; allowed: an integer 1..{MAX_RHO}")
    if rho is not None and (
        not isinstance(rho, int) or isinstance(rho, bool) or not 1 <= rho <= MAX_RHO
    ):
        raise ValueError(f"rho = {rho!r}; allowed: an integer 1..{MAX_RHO}")
    top = rho if rho is not None else rho_max
    n = log.n_samples
    if n > MAX_CHAIN_SAMPLES:
        raise LogError(f"log has {n} samples; allowed: at most {MAX_CHAIN_SAMPLES}")
    for name in ("t", "u", "y"):
        col = np.asarray(getattr(log, name))
        if col.ndim != 1 or col.shape[0] != n:
            raise LogError(f"column {name!r}: {col.shape} values; allowed: {n} (one per row)")
        bad = np.flatnonzero(~np.isfinite(col))
        if bad.size:
            raise LogError(f"column {name!r}, row {int(bad[0])}: {col[bad[0]]}; allowed: finite")
    need = MIN_SAMPLES_PER_PARAMETER * (2 * top + 4)
    if n < need:
        raise LogError(f"log has {n} samples; allowed: at least {need} for rho <= {top}")
    steps = np.diff(log.t)
    if np.any(steps <= 0):
        row = int(np.flatnonzero(steps <= 0)[0]) + 1
        raise LogError(f"column 't', row {row}: time does not increase; allowed: increasing")
    ts_mean = (log.t[-1] - log.t[0]) / (n - 1)
    off = np.flatnonzero(np.abs(steps - ts_mean) > UNIFORM_TOLERANCE * ts_mean)
    if off.size:
        row = int(off[0]) + 1
        raise LogError(
            f"column 't', row {row}: step {steps[off[0]]:.6g} s; allowed: uniform sampling, "
            f"every step within {UNIFORM_TOLERANCE:.0%} of {ts_mean:.6g} s (resample the log)"
        )
    if np.ptp(log.u) == 0:
        raise LogError(
            "column 'u': constant input; allowed: an input that excites the plant (a step, "
            "PRBS or chirp)"
        )
    ts = log.ts
    limit = min(MAX_DELAY_SAMPLES * ts, 0.25 * log.duration)
    if delay_max is None:
        bound = min(50.0 * ts, 0.05 * log.duration)
    else:
        if not math.isfinite(delay_max) or not 0.0 <= delay_max <= limit:
            raise ValueError(
                f"delay_max = {delay_max!r} s; allowed: 0 <= delay_max <= {limit:g} s "
                f"(min of {MAX_DELAY_SAMPLES} samples and a quarter of the log)"
            )
        bound = float(delay_max)
    return top, bound


def _fit_percent(y: NDArray[np.float64], model: NDArray[np.float64]) -> float:
    spread = float(np.linalg.norm(y - y.mean()))
    return 100.0 * (1.0 - float(np.linalg.norm(y - model)) / spread) if spread > 0 else 0.0


def _bic(fit: ChainFit) -> float:
    return fit.n_fit * math.log(max(fit.rss, 1e-300) / fit.n_fit) + fit.n_params * math.log(
        fit.n_fit
    )


def identify_chain(
    log: Log,
    *,
    rho_max: int = 4,
    rho: int | None = None,
    delay_max: float | None = None,
    friction: bool | None = None,
) -> ChainEstimate:
    """Estimate ρ, b0 (± std), the input delay and the noise level from an open-loop log.

    Parameters
    ----------
    log
        The log (uniform sampling; u held over each sample).
    rho_max
        The highest order tried (1..:data:`MAX_RHO`).
    rho
        Fit this order only (the criterion is then ``"given"``).
    delay_max
        The longest input delay searched [s] (default: 50 samples or 5 % of the log,
        whichever is shorter).
    friction
        Fit a Coulomb-friction term: None chooses by BIC (module notes), True fits it for
        every order ≥ 2, False never.

    Returns
    -------
    ChainEstimate
        The chosen order's estimates and every candidate's score.
    """
    from aiofl.blas_threads import one_blas_thread

    top, bound = _check(log, rho_max, rho, delay_max)
    y = np.ascontiguousarray(log.y, dtype=np.float64)
    u = np.ascontiguousarray(log.u, dtype=np.float64)
    ts = log.ts
    orders = [rho] if rho is not None else list(range(1, top + 1))
    w = -velocity_sign(y, SIGN_WIDTH)
    use_w = friction is not False and np.any(w != 0)
    fits: dict[int, ChainFit] = {}
    with one_blas_thread():
        for r in orders:
            term = w if use_w and r >= 2 else None
            fits[r] = fit_chain(y, u, ts, r, delay_max=bound, friction=term)
        scores = {r: _bic(f) for r, f in fits.items()}
        chosen = min(scores, key=lambda r: scores[r]) if rho is None else rho
        best = fits[chosen]
        if friction is None and use_w and chosen >= 2:  # keep the term only if it pays
            plain = fit_chain(y, u, ts, chosen, delay_max=bound, friction=None)
            if _bic(plain) <= scores[chosen]:
                best = fits[chosen] = plain
                scores[chosen] = _bic(plain)
    candidates = tuple(
        ChainCandidate(
            rho=r,
            b0=f.b0,
            b0_std=f.b0_std,
            delay=f.delay,
            score=scores[r],
            fit_percent=_fit_percent(y[f.k0 :], f.y_model),
        )
        for r, f in fits.items()
    )
    return ChainEstimate(
        rho=chosen,
        b0=best.b0,
        b0_std=best.b0_std,
        delay=best.delay,
        delay_std=best.delay_std,
        noise_std=math.sqrt(best.rss / max(best.n_fit - best.n_params, 1)),
        criterion="BIC" if rho is None else "given",
        candidates=candidates,
        fit_percent=_fit_percent(y[best.k0 :], best.y_model),
        coefficients=best.a,
        offset=best.c,
        friction=best.friction,
    )
