r"""Residual analysis of a fitted model: is what it leaves white, and independent of the input?

A model that explains the data leaves a residual :math:`\varepsilon_k = y_k - \hat y_k` that
is (i) white — no correlation between its own past and present — and (ii) independent of
the past input; a wrong structure (a missing state, a missing parameter, a wrong delay)
shows up in one or both (Ljung, *System Identification: Theory for the User*, 2nd ed.,
1999, §16.6 "Model validation"; MATLAB's ``resid``).

With :math:`\hat R_\varepsilon(\tau) = \frac1N\sum_k \varepsilon_{k+\tau}\varepsilon_k`
and :math:`\hat R_{\varepsilon u}(\tau) = \frac1N\sum_k \varepsilon_{k+\tau}u_k` (means
removed), the normalised correlations are

.. math::
    r_\varepsilon(\tau) = \hat R_\varepsilon(\tau)/\hat R_\varepsilon(0),\quad
    \tau = 1\dots M,\qquad
    r_{\varepsilon u}(\tau) = \hat R_{\varepsilon u}(\tau)\big/\sqrt{\hat R_\varepsilon(0)
    \hat R_u(0)},\quad \tau = -M\dots M .

For a white residual independent of u each is asymptotically :math:`N(0, 1/N)`, whence the
plotted 99 % band :math:`\pm 2.58/\sqrt N`.  The verdicts use the joint tests of Ljung
§16.6, since 25 lags each inside a 99 % band would flag a perfect model one time in
five:

* **white**: :math:`\zeta_\varepsilon = N\sum_{\tau=1}^{M} r_\varepsilon^2(\tau)` below the
  99 % quantile of :math:`\chi^2(M)` (the portmanteau statistic; Box & Pierce, J. Amer.
  Statist. Assoc. 65, 1970);
* **independent**: :math:`\zeta_{\varepsilon u} = N\,\hat r^\top \hat R_u^{-1} \hat r /
  \hat R_\varepsilon(0)` below the 99 % quantile of :math:`\chi^2(2M+1)`, with
  :math:`\hat r` the cross-covariances at lags :math:`-M\dots M` and :math:`\hat R_u` the
  (2M+1)×(2M+1) Toeplitz matrix of u's autocovariances: correct for a coloured
  input too, where the lags of :math:`r_{\varepsilon u}` are correlated with each other.

A positive lag τ of the cross-correlation relates :math:`\varepsilon_{k+\tau}` to
:math:`u_k` (the past input); negative lags, the future input, show feedback in a
closed-loop log (where they are expected to be nonzero, Ljung §16.6).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["CONFIDENCE", "ResidualTests", "residual_tests"]

CONFIDENCE = 0.99
"""The level of the band and of the χ² tests."""

_Z99 = 2.576  # the two-sided 99 % point of N(0, 1)


@dataclass(frozen=True)
class ResidualTests:
    """Correlations of a residual with itself and with the input, and their verdicts.

    Attributes
    ----------
    lags
        The lags of :attr:`cross_correlation`, -M .. M (the autocorrelation's are 1 .. M).
    autocorrelation
        :math:`r_\\varepsilon(\\tau)`, τ = 1 .. M.
    cross_correlation
        :math:`r_{\\varepsilon u}(\\tau)`, τ = -M .. M.
    band
        The 99 % band :math:`2.58/\\sqrt N` of each normalised correlation.
    white, independent
        The verdicts of the joint χ² tests at 99 % (module notes).
    white_statistic, independent_statistic
        :math:`\\zeta_\\varepsilon` and :math:`\\zeta_{\\varepsilon u}`.
    white_threshold, independent_threshold
        Their 99 % χ² quantiles (M and 2M+1 degrees of freedom).
    """

    lags: NDArray[np.int64]
    autocorrelation: NDArray[np.float64]
    cross_correlation: NDArray[np.float64]
    band: float
    white: bool
    independent: bool
    white_statistic: float = float("nan")
    independent_statistic: float = float("nan")
    white_threshold: float = float("nan")
    independent_threshold: float = float("nan")

    def to_record(self) -> dict[str, Any]:
        """JSON-ready: the correlations, the band, the verdicts and their statistics."""
        m = int(self.lags[-1])
        return {
            "max_lag": m,
            "confidence": CONFIDENCE,
            "band": self.band,
            "white": self.white,
            "independent": self.independent,
            "white_statistic": self.white_statistic,
            "white_threshold": self.white_threshold,
            "independent_statistic": self.independent_statistic,
            "independent_threshold": self.independent_threshold,
            "autocorrelation": {
                "lags": list(range(1, m + 1)),
                "values": self.autocorrelation.tolist(),
            },
            "cross_correlation": {
                "lags": self.lags.tolist(),
                "values": self.cross_correlation.tolist(),
            },
            "outside_band": {
                "autocorrelation": int(np.sum(np.abs(self.autocorrelation) > self.band)),
                "cross_correlation": int(np.sum(np.abs(self.cross_correlation) > self.band)),
            },
        }


def _covariance(a: NDArray[np.float64], b: NDArray[np.float64], tau: int) -> float:
    """:math:`\\frac1N\\sum_k a_{k+\\tau} b_k` (zero-mean a, b; τ of either sign)."""
    n = a.shape[0]
    if tau >= 0:
        return float(np.dot(a[tau:], b[: n - tau]) / n)
    return float(np.dot(a[: n + tau], b[-tau:]) / n)


def residual_tests(residual: ArrayLike, u: ArrayLike, *, max_lag: int = 25) -> ResidualTests:
    """The whiteness and independence tests of a residual (see the module notes).

    Parameters
    ----------
    residual
        ε, (N,) finite values.
    u
        The input over the same samples, (N,).
    max_lag
        M, the largest lag; 1 <= M < N/4.

    Returns
    -------
    ResidualTests

    Raises
    ------
    ValueError
        Naming the argument at fault (shapes, non-finite values, M, a constant residual or
        input).
    """
    from scipy.linalg import toeplitz
    from scipy.stats import chi2

    e = np.asarray(residual, dtype=np.float64)
    uu = np.asarray(u, dtype=np.float64)
    if e.ndim != 1 or e.shape != uu.shape:
        raise ValueError(f"residual {e.shape} and u {uu.shape} must be 1-D of the same length")
    n = e.shape[0]
    if not (isinstance(max_lag, int | np.integer) and max_lag >= 1 and 4 * max_lag < n):
        raise ValueError(
            f"max_lag = {max_lag!r} for {n} samples; allowed: an integer 1 <= max_lag < N/4"
        )
    for name, arr in (("residual", e), ("u", uu)):
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            raise ValueError(f"{name}[{bad[0]}] = {arr[bad[0]]}; allowed: finite values")
    e = e - e.mean()
    uu = uu - uu.mean()
    r_e0 = float(np.dot(e, e) / n)
    r_u0 = float(np.dot(uu, uu) / n)
    if r_e0 <= 0.0:
        raise ValueError("the residual is constant; nothing to test")
    if r_u0 <= 0.0:
        raise ValueError("u is constant; its cross-correlation with the residual is undefined")
    m = int(max_lag)
    auto = np.array([_covariance(e, e, tau) for tau in range(1, m + 1)]) / r_e0
    lags = np.arange(-m, m + 1, dtype=np.int64)
    cross_cov = np.array([_covariance(e, uu, int(tau)) for tau in lags])
    cross = cross_cov / np.sqrt(r_e0 * r_u0)
    band = _Z99 / np.sqrt(n)
    zeta_e = float(n * np.sum(auto**2))
    r_u = np.array([_covariance(uu, uu, tau) for tau in range(2 * m + 1)])
    ru_matrix = toeplitz(r_u)
    try:
        sol = np.linalg.solve(ru_matrix, cross_cov)
        zeta_eu = float(n * cross_cov @ sol / r_e0)
    except np.linalg.LinAlgError:  # an input without 2M+1 independent lags: the plain sum
        zeta_eu = float(n * np.sum(cross**2))
    t_e = float(chi2.ppf(CONFIDENCE, m))
    t_eu = float(chi2.ppf(CONFIDENCE, 2 * m + 1))
    return ResidualTests(
        lags=lags,
        autocorrelation=auto,
        cross_correlation=cross,
        band=float(band),
        white=bool(zeta_e < t_e),
        independent=bool(zeta_eu < t_eu),
        white_statistic=zeta_e,
        independent_statistic=zeta_eu,
        white_threshold=t_e,
        independent_threshold=t_eu,
    )
