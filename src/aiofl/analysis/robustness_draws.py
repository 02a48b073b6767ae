r"""Robustness of one design under model error: K draws of ``[uncertainty]``, batched.

:func:`run_robustness` draws the config's ``[uncertainty]`` table (common random numbers,
:mod:`aiofl.uncertainty`), turns every draw into an engine member (its scenario with the
drawn plant from t = 0, its drawn noise variance and sample time) and runs the nominal plant
plus the K draws through :func:`aiofl.engine.simulation.simulate_batch` — one call, split
only to keep each call's stored trajectories and noise rows within
:data:`CALL_TRAJECTORY_BYTES` — or as chunks on a Dask cluster.  Members are independent,
so the split never changes a number.

**Statistics.**  A diverged draw counts as :math:`\mathrm{ITAE} = \mathrm{ISU} = +\infty`
(it is unstable); ``stable_fraction`` is the fraction of draws that did not diverge.
Quantiles are taken over *all* K draws with ``numpy.quantile(method="inverted_cdf")`` (the
empirical quantile, :math:`\min\{x : \hat F(x) \ge q\}`, no interpolation, so it is
defined with +inf values); a quantile that falls on a diverged draw is written as ``null``
in the JSON (which never holds NaN or Infinity).  The worst draw is the one with the largest
ITAE, a diverged draw being worse than any finite one (the earliest divergence first).
The influence of a drawn quantity is its Spearman rank correlation with ITAE
(``scipy.stats.spearmanr``; a rank statistic, so with log ITAE too).

**Noise.**  With a noisy measurement (the config's ``[sensor]`` or ``[scenario]`` noise, or a
drawn ``noise_variance``) every draw runs its own noise realisation, seeded from the draw
(:meth:`aiofl.uncertainty.Draws.noise_seed`); the nominal member keeps the config's seed,
so it is ``aiofl simulate`` of the config.

**Trajectories.**  The tracking error :math:`e = y - r` of every draw is kept at
:math:`P \le` :data:`MAX_POINTS` decimated points, :math:`P` lowered so the (K, P) float32
table stays within :data:`ERROR_TABLE_BYTES`; the envelope is its pointwise min/max and
5-95 % band.
"""

from __future__ import annotations

import itertools
import math
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.uncertainty import ABSOLUTE, Draws, aggregate, sample_draws

__all__ = [
    "CALL_TRAJECTORY_BYTES",
    "ERROR_TABLE_BYTES",
    "MAX_POINTS",
    "DesignDraws",
    "RobustnessResult",
    "robustness_figure",
    "run_robustness",
    "simulate_designs",
    "simulate_draws",
]

#: most saved points of a draw's tracking error
MAX_POINTS = 401
#: most bytes of the (K, P) float32 error table kept for the envelope
ERROR_TABLE_BYTES = 64 * 2**20
#: most bytes one engine call allocates per member table: the stored trajectories
#: (members x points x columns x 8) and the held-noise rows (members x samples x 8)
CALL_TRAJECTORY_BYTES = 128 * 2**20
_LOCK = threading.Lock()
#: the quantiles reported
QUANTILES = {"q05": 0.05, "q50": 0.5, "q95": 0.95}


@dataclass(frozen=True)
class DrawRuns:
    """Engine results of the nominal plant (member 0) and the K draws (members 1..K)."""

    metrics: NDArray[np.float64]  # (K+1, 5)
    failed: NDArray[np.bool_]  # lost or diverged
    stopped_at: NDArray[np.float64]
    status: NDArray[np.int64]  # aiofl.layout.STATUS_*
    t: NDArray[np.float64]  # (P,)
    error: NDArray[np.float32]  # (K+1, P), y - r; NaN after a divergence
    engine_calls: int


def _points(k: int, n_steps: int) -> tuple[int, int]:
    """(decimation, saved points) for K draws of ``n_steps``: P <= MAX_POINTS and the
    (K, P) float32 table within ERROR_TABLE_BYTES."""
    p_max = max(2, min(MAX_POINTS, ERROR_TABLE_BYTES // (4 * (k + 1))))
    dec = max(1, math.ceil(n_steps / (p_max - 1)))
    return dec, n_steps // dec + 1


def _chunk(config: Any, draws: Draws, nominal: bool, decimation: int) -> tuple[Any, ...]:
    """Simulate ``draws`` (and the nominal plant first if ``nominal``) of ``config`` (a
    RunConfig, or its raw dict on a Dask worker) in one engine call."""
    from aiofl.config import parse_config
    from aiofl.engine.simulation import simulate_batch

    cfg = parse_config(dict(config), "robustness chunk") if isinstance(config, dict) else config
    scenarios = draws.scenarios(cfg.scenario)
    samplings = draws.samplings(cfg.sampling)
    if nominal:
        scenarios, samplings = [cfg.scenario, *scenarios], [cfg.sampling, *samplings]
    if not scenarios:
        none = np.zeros(0, np.int64)
        return np.zeros((0, L.N_METRIC)), np.zeros(0, bool), np.zeros(0), np.zeros((0, 0)), none
    with _LOCK:  # one engine call at a time per process (threaded Dask workers)
        res = simulate_batch(
            cfg.plant,
            [cfg.controller] * len(scenarios),
            scenarios,
            dt=cfg.dt,
            method=cfg.method,
            store=True,
            decimation=decimation,
            divergence_threshold=cfg.divergence_threshold,
            sampling=samplings if any(s is not None for s in samplings) else None,
        )
    traj = res.trajectories
    assert traj is not None
    cols = list(res.columns)
    err = (traj[:, :, cols.index("y")] - traj[:, :, cols.index("r")]).astype(np.float32)
    return res.metrics.copy(), res.failed.copy(), res.stopped_at.copy(), err, res.status.copy()


def _subset(draws: Draws, idx: slice) -> Draws:
    return draws.subset(idx)


def simulate_draws(
    cfg: Any, draws: Draws, *, client: Any = None, chunks: int | None = None
) -> DrawRuns:
    """Run the nominal plant and every draw of ``cfg`` (a :class:`~aiofl.config.RunConfig`).

    Locally: one :func:`~aiofl.engine.simulation.simulate_batch` call, split into the fewest
    calls that keep each call's stored trajectories and noise rows within
    :data:`CALL_TRAJECTORY_BYTES`.
    With a ``distributed.Client``: ``chunks`` tasks (default: the number of workers).

    Parameters
    ----------
    cfg, draws, client, chunks
        The run config, its draws, a ``distributed.Client`` (None: here) and its task count.

    Returns
    -------
    DrawRuns
    """
    from aiofl.limits import check_run_size

    k = len(draws)
    n_steps = check_run_size(cfg.scenario.t_final, cfg.dt, what="robustness")
    dec, n_pts = _points(k, n_steps)
    # the stored trajectory and the engine's per-scenario noise table (every draw is its
    # own scenario, so simulate_batch holds one held-noise row per member)
    n_cols = len(L.trajectory_columns(cfg.plant.n_states))
    per_member = (n_pts * n_cols + cfg.scenario.noise_samples) * 8
    per_call = max(1, CALL_TRAJECTORY_BYTES // per_member)
    if client is not None:
        if chunks is None:
            chunks = max(1, len(client.scheduler_info(n_workers=-1).get("workers", {})))
        per_call = min(per_call, math.ceil((k + 1) / chunks))
    bounds = [*range(0, k + 1, per_call), k + 1]
    # member m is draw m - 1; member 0 is the nominal plant
    tasks = [
        (_subset(draws, slice(max(a - 1, 0), b - 1)), a == 0) for a, b in itertools.pairwise(bounds)
    ]
    if client is None:
        parts = [_chunk(cfg, d, nom, dec) for d, nom in tasks]
    else:
        raw_f = client.scatter(dict(cfg.raw), broadcast=True, hash=False)
        futures = [client.submit(_chunk, raw_f, d, nom, dec, pure=False) for d, nom in tasks]
        parts = client.gather(futures)
    t = np.arange(n_pts) * (dec * cfg.dt)
    return DrawRuns(
        metrics=np.concatenate([p[0] for p in parts]),
        failed=np.concatenate([p[1] for p in parts]),
        stopped_at=np.concatenate([p[2] for p in parts]),
        status=np.concatenate([p[4] for p in parts]),
        t=t,
        error=np.concatenate([p[3] for p in parts]),
        engine_calls=len(tasks),
    )


def _num(x: float) -> float | None:
    """A JSON number, or None for +-inf / NaN."""
    return float(x) if math.isfinite(x) else None


class _DrawStatistics:
    """Statistics over the K draws of a result with ``failed`` and ``status`` (K,) and
    metric arrays."""

    failed: NDArray[np.bool_]
    status: NDArray[np.int64]

    @property
    def stable_fraction(self) -> float:
        """Fraction of draws whose plant was neither lost nor diverged."""
        return float(np.mean(~self.failed))

    def status_counts(self) -> dict[str, int]:
        """How many draws were ``ok``, ``lost`` and ``diverged``."""
        return {
            name: int(np.count_nonzero(self.status == code))
            for code, name in L.STATUS_NAMES.items()
        }

    def quantiles(self, values: NDArray[np.float64]) -> dict[str, float | None]:
        """q05, q50, q95 (empirical, ``inverted_cdf``) and max; None where +inf."""
        out = {k: _num(np.quantile(values, q, method="inverted_cdf")) for k, q in QUANTILES.items()}
        out["max"] = _num(np.max(values))
        return out


@dataclass(frozen=True)
class RobustnessResult(_DrawStatistics):
    """The outcome of :func:`run_robustness` (arrays over the K draws)."""

    name: str
    draws: Draws
    nominal_params: dict[str, float]
    itae: NDArray[np.float64]  # +inf where diverged
    isu: NDArray[np.float64]
    failed: NDArray[np.bool_]  # lost or diverged
    stopped_at: NDArray[np.float64]
    status: NDArray[np.int64]  # aiofl.layout.STATUS_*
    nominal: dict[str, Any]
    t: NDArray[np.float64]
    error: NDArray[np.float32]  # (K, P)
    engine_calls: int
    seconds: float
    uncertainty: dict[str, Any] = field(default_factory=dict)
    #: the box corners run with the draws (:func:`aiofl.uncertainty.corner_draws`), or None
    corners: Draws | None = None
    corner_itae: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    corner_failed: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, bool))
    corner_stopped_at: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    corner_status: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    #: records added to :meth:`to_dict` (:func:`aiofl.analysis.corners.run_box_robustness`)
    extra: dict[str, Any] = field(default_factory=dict)

    def worst_index(self) -> int:
        """The worst draw: largest ITAE; a diverged draw (earliest first) beats any finite."""
        if self.failed.any():
            idx = np.flatnonzero(self.failed)
            return int(idx[np.argmin(self.stopped_at[idx])])
        return int(np.argmax(self.itae))

    def influence(self) -> list[tuple[str, float | None]]:
        """Drawn quantities by decreasing absolute Spearman correlation with ITAE."""
        from scipy.stats import spearmanr

        ranked = []
        for name, col in self.draws.columns().items():
            if np.ptp(col) == 0 or np.ptp(np.where(np.isinf(self.itae), 1e300, self.itae)) == 0:
                ranked.append((name, None))
                continue
            ranked.append((name, _num(spearmanr(col, self.itae).statistic)))
        return sorted(ranked, key=lambda p: -abs(p[1]) if p[1] is not None else 1.0)

    def to_dict(self) -> dict[str, Any]:
        """The ``robustness.json`` record (no NaN or Infinity: +inf is ``null``)."""
        w = self.worst_index()
        cols = self.draws.columns()
        worst: dict[str, Any] = {
            "draw": w,
            "itae": _num(self.itae[w]),
            "isu": _num(self.isu[w]),
            "status": L.STATUS_NAMES[int(self.status[w])],
            "stopped_at": float(self.stopped_at[w]) if self.failed[w] else None,
            "factors": {k: float(v[w]) for k, v in self.draws.factors.items()},
            "parameters": {
                k: float(v[w]) * self.nominal_params[k] for k, v in self.draws.factors.items()
            },
        }
        for key in ABSOLUTE:
            if key in cols:
                worst[key] = float(cols[key][w])
        return {
            "name": self.name,
            "draws": len(self.draws),
            "seed": self.draws.seed,
            "uncertainty": self.uncertainty,
            "stable_fraction": self.stable_fraction,
            "status_counts": self.status_counts(),
            "failed": [
                {
                    "draw": int(i),
                    "status": L.STATUS_NAMES[int(self.status[i])],
                    "t": float(self.stopped_at[i]),
                }
                for i in np.flatnonzero(self.failed)
            ],
            "itae": self.quantiles(self.itae),
            "isu": self.quantiles(self.isu),
            "aggregates": {
                "itae_mean": _num(aggregate(self.itae, "mean")),
                "itae_cvar90": _num(aggregate(self.itae, "cvar", alpha=0.9)),
            },
            "worst": worst,
            "nominal": self.nominal,
            "influence": [{"name": n, "spearman_itae": r} for n, r in self.influence()],
            "notes": (
                "quantiles: numpy inverted_cdf over all draws, a draw whose plant was lost "
                "or whose numbers diverged counting as +inf; null = the value falls on such "
                "a draw (infeasible); stable = neither lost nor diverged"
            ),
            **self.extra,
        }


def run_robustness(
    cfg: Any,
    *,
    draws: int | None = None,
    seed: int | None = None,
    client: Any = None,
    chunks: int | None = None,
    corners: Draws | None = None,
) -> RobustnessResult:
    """Draw ``cfg.uncertainty`` and run the design over the draws (module docstring).

    ``corners`` (e.g. :func:`aiofl.uncertainty.corner_draws`) run in the same engine
    call(s), after the draws; their results are the ``corner_*`` fields.  Raises
    ``ValueError`` if the config has no ``[uncertainty]`` table or ``draws``/``seed`` are
    out of range (before anything runs).

    Parameters
    ----------
    cfg, draws, seed
        The run config, with ``[uncertainty]``; the draws and seed (None: the table's).
    client, chunks, corners
        As for :func:`simulate_draws`; extra draws (the box's corners) run after the draws.

    Returns
    -------
    RobustnessResult
    """
    if cfg.uncertainty is None:
        raise ValueError(
            f"config {cfg.name!r} has no [uncertainty] table; add one, e.g.\n"
            "  [uncertainty]\n  draws = 64\n  seed = 0\n  [uncertainty.parameters]\n"
            "  J_l = { uniform = 0.2 }"
        )
    d = sample_draws(cfg.uncertainty, draws=draws, seed=seed, dt=cfg.dt)
    d.scenarios(cfg.scenario)  # refuses an incompatible scenario before anything runs
    t0 = time.perf_counter()
    n_c = 0 if corners is None else len(corners)
    runs = simulate_draws(
        cfg, d if corners is None else d.concat(corners), client=client, chunks=chunks
    )
    seconds = time.perf_counter() - t0
    m, div = runs.metrics, runs.failed
    itae = np.where(div, np.inf, m[:, L.METRIC_NAMES.index("itae")])
    isu = np.where(div, np.inf, m[:, L.METRIC_NAMES.index("isu")])
    k_end = len(div) - n_c  # members 1..K are the draws, then the corners
    nominal = {
        "itae": _num(itae[0]),
        "isu": _num(isu[0]),
        "status": L.STATUS_NAMES[int(runs.status[0])],
        "failed": bool(div[0]),
        "stopped_at": float(runs.stopped_at[0]) if div[0] else None,
    }
    spec = cfg.uncertainty.model_dump(exclude_none=True)
    spec.update(draws=len(d), seed=d.seed)
    return RobustnessResult(
        name=cfg.name,
        draws=d,
        nominal_params=dict(cfg.plant.params),
        itae=itae[1:k_end],
        isu=isu[1:k_end],
        failed=div[1:k_end],
        stopped_at=runs.stopped_at[1:k_end],
        status=runs.status[1:k_end],
        nominal=nominal,
        t=runs.t,
        error=runs.error[1:k_end],
        engine_calls=runs.engine_calls,
        seconds=seconds,
        uncertainty=spec,
        corners=corners,
        corner_itae=itae[k_end:],
        corner_failed=div[k_end:],
        corner_stopped_at=runs.stopped_at[k_end:],
        corner_status=runs.status[k_end:],
    )


# ---------------------------------------------------------- several designs, one call
@dataclass(frozen=True)
class DesignDraws(_DrawStatistics):
    """One design's results over the K draws of :func:`simulate_designs` (no trajectories,
    no nominal run); the statistics are those of :class:`RobustnessResult`."""

    draws: Draws
    itae: NDArray[np.float64]  # +inf where diverged
    isu: NDArray[np.float64]
    failed: NDArray[np.bool_]
    stopped_at: NDArray[np.float64]
    status: NDArray[np.int64]
    group: int  # designs of one group ran in the same engine call(s)
    engine_calls: int  # the calls of its group

    def to_dict(self) -> dict[str, Any]:
        """``{"draws", "seed", "stable_fraction", "diverged", "itae": {q05, q50, q95, max},
        "isu": {...}}`` (``diverged``: the number of diverged draws; no NaN or Infinity)."""
        return {
            "draws": len(self.draws),
            "seed": self.draws.seed,
            "stable_fraction": self.stable_fraction,
            "failed": int(np.count_nonzero(self.failed)),
            "status_counts": self.status_counts(),
            "itae": self.quantiles(self.itae),
            "isu": self.quantiles(self.isu),
        }


def _design_key(cfg: Any) -> tuple[Any, ...]:
    """What members of one engine call must share (the scenario is compared by value)."""
    return (id(cfg.plant), cfg.scenario.t_final, cfg.dt, cfg.method, cfg.divergence_threshold)


def simulate_designs(cfgs: Sequence[Any], draws: Draws) -> list[DesignDraws]:
    """Run every design (a :class:`~aiofl.config.RunConfig`) over the same ``draws``.

    Designs that share the plant, the scenario (by value), the horizon, the step, the
    method and the divergence threshold run together: one
    :func:`~aiofl.engine.simulation.simulate_batch` call holds every such design on every
    draw (design-major), split over the draws only to keep each call's held-noise rows (one
    per draw: the draws' scenarios are shared by all designs of the call) within
    :data:`CALL_TRAJECTORY_BYTES`.  No trajectory is stored and the nominal plant is not
    run.  Common random numbers: every design sees the same draws.

    Raises ``ValueError`` (before anything runs) for zero draws or a design whose scenario
    cannot take the draws (:meth:`aiofl.uncertainty.Draws.scenarios`).

    Returns
    -------
    list of DesignDraws
        In the order of ``cfgs``.
    """
    from aiofl.engine.simulation import simulate_batch

    k = len(draws)
    if k == 0:
        raise ValueError("simulate_designs needs at least one draw")
    groups: list[tuple[Any, list[int]]] = []
    for i, cfg in enumerate(cfgs):
        for first, idx in groups:
            if (
                _design_key(cfgs[first]) == _design_key(cfg)
                and cfgs[first].scenario == cfg.scenario
            ):
                idx.append(i)
                break
        else:
            groups.append((i, [i]))
    scen = {first: draws.scenarios(cfgs[first].scenario) for first, _ in groups}  # may raise
    out: dict[int, DesignDraws] = {}
    for g, (first, idx) in enumerate(groups):
        base = cfgs[first]
        per_call = max(1, CALL_TRAJECTORY_BYTES // (base.scenario.noise_samples * 8))
        bounds = [*range(0, k, per_call), k]
        parts = []
        for a, b in itertools.pairwise(bounds):
            sc = scen[first][a:b]
            sub = _subset(draws, slice(a, b))
            sampling = [s for i in idx for s in sub.samplings(cfgs[i].sampling)]
            res = simulate_batch(
                base.plant,
                [cfgs[i].controller for i in idx for _ in sc],
                [s for _ in idx for s in sc],
                dt=base.dt,
                method=base.method,
                divergence_threshold=base.divergence_threshold,
                sampling=sampling if any(s is not None for s in sampling) else None,
            )
            parts.append(
                (
                    res.metrics.reshape(len(idx), b - a, -1),
                    res.failed.reshape(len(idx), b - a),
                    res.stopped_at.reshape(len(idx), b - a),
                    res.status.reshape(len(idx), b - a),
                )
            )
        metrics = np.concatenate([p[0] for p in parts], axis=1)
        div = np.concatenate([p[1] for p in parts], axis=1)
        t_div = np.concatenate([p[2] for p in parts], axis=1)
        for j, i in enumerate(idx):
            out[i] = DesignDraws(
                draws=draws,
                itae=np.where(div[j], np.inf, metrics[j, :, L.METRIC_NAMES.index("itae")]),
                isu=np.where(div[j], np.inf, metrics[j, :, L.METRIC_NAMES.index("isu")]),
                failed=div[j].copy(),
                stopped_at=t_div[j].copy(),
                status=np.concatenate([p[3] for p in parts], axis=1)[j].copy(),
                group=g,
                engine_calls=len(parts),
            )
    return [out[i] for i in range(len(cfgs))]


LOG_SPAN = 100.0
"""A metric axis is logarithmic when its positive values span at least this ratio (two
decades: at least two labelled decade ticks); a narrower spread is drawn on a linear axis
with a few ticks, whose labels do not run into each other."""


def _metric_scale(ax: Any, which: str, values: NDArray[np.float64]) -> None:
    """Log or linear ``which`` ("x" or "y") axis for a metric's finite ``values`` (see
    :data:`LOG_SPAN`); on a log axis only the decades are labelled."""
    from matplotlib.ticker import MaxNLocator, NullFormatter

    v = values[np.isfinite(values)]
    axis = ax.xaxis if which == "x" else ax.yaxis
    if v.size and v.min() > 0 and v.max() >= LOG_SPAN * v.min():
        (ax.set_xscale if which == "x" else ax.set_yscale)("log")
        axis.set_minor_formatter(NullFormatter())
    else:
        axis.set_major_locator(MaxNLocator(nbins=4))


def _no_data(ax: Any, text: str) -> None:
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", color="0.4")


def _ecdf(ax: Any, res: RobustnessResult, values: NDArray[np.float64], name: str) -> None:
    """The ECDF of one metric over the draws (a diverged draw counts as +inf: the curve
    stops at the stable fraction), with the nominal plant's value."""
    k = len(values)
    finite = np.sort(values[np.isfinite(values)])
    if finite.size:
        ax.step(finite, np.arange(1, finite.size + 1) / k, where="post", label=f"{name} ECDF")
        _metric_scale(ax, "x", finite)
    else:
        _no_data(ax, "every draw diverged")
    ax.set_ylim(0, 1.02)
    ax.axhline(res.stable_fraction, color="0.6", ls=":", label="stable fraction")
    nominal = res.nominal.get(name.lower())
    if nominal is not None:
        ax.axvline(nominal, color="k", ls="--", label="nominal")
    ax.set(xlabel=name, ylabel="fraction of draws", title=f"ECDF of {name} ({k} draws)")
    ax.legend(loc="lower right", fontsize=8)


def _mark_corners(ax: Any, res: RobustnessResult, xname: str, top: float) -> None:
    """The box corners on an ITAE-against-parameter panel: black squares, a diverged
    corner a red square at the top."""
    xc = res.corners.columns()[xname]  # type: ignore[union-attr]
    ok = ~res.corner_failed
    if ok.any():
        top = max(top, 2.0 * float(res.corner_itae[ok].max()))
    if ok.any():
        ax.scatter(
            xc[ok],
            res.corner_itae[ok],
            marker="s",
            s=24,
            facecolors="none",
            edgecolors="k",
            label="corners",
        )
    if (~ok).any():
        ax.scatter(
            xc[~ok],
            np.full(int((~ok).sum()), top),
            marker="s",
            s=30,
            color="r",
            label="diverged corner",
        )
    ax.legend(loc="best", fontsize=8)


def robustness_figure(res: RobustnessResult) -> Any:
    """A matplotlib ``Figure`` of a robustness run, in two rows of three panels.

    Top: the ECDFs of ITAE and of ISU over the draws (with the stable fraction and the
    nominal plant's value) and the envelope of :math:`y - r` across the stable draws;
    bottom: ITAE against the two most influential drawn quantities and ISU against ITAE
    per draw (diverged draws drawn as red crosses at the top).  A metric axis is
    logarithmic only when its values span two decades (:data:`LOG_SPAN`), so tick labels
    never overlap; a panel without data (every draw diverged) says so instead of being
    left empty, and no matplotlib warning is raised.  The title (the config's name) is
    plain text, not mathtext.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(15, 8), layout="constrained")
    axes = fig.subplots(2, 3).ravel()
    k = len(res.itae)
    _ecdf(axes[0], res, res.itae, "ITAE")
    _ecdf(axes[1], res, res.isu, "ISU")

    ax = axes[2]
    err = res.error.astype(np.float64)
    ok = ~res.failed
    if ok.any():
        e = err[ok]
        lo, hi = np.quantile(e, [0.05, 0.95], axis=0)
        ax.fill_between(res.t, e.min(axis=0), e.max(axis=0), color="C0", alpha=0.2, label="min-max")
        ax.fill_between(res.t, lo, hi, color="C0", alpha=0.5, label="5-95 %")
        ax.legend(loc="upper right", fontsize=8)
    else:
        _no_data(ax, "every draw diverged: no envelope")
    ax.set(xlabel="t [s]", ylabel="y - r", title="tracking error across stable draws")

    finite = np.isfinite(res.itae) & np.isfinite(res.isu)
    ranked = [n for n, r in res.influence() if r is not None][:2]
    cols = res.draws.columns()
    panels = [(name, cols[name], res.itae, "ITAE") for name in ranked]
    panels.append(("ITAE", res.itae, res.isu, "ISU"))
    slots = [*axes[3 : 3 + len(ranked)], axes[5]]
    for ax in axes[3 + len(ranked) : 5]:
        ax.set_axis_off()
    for ax, (xname, x, y, yname) in zip(slots, panels, strict=True):
        if finite.any():
            ax.scatter(x[finite], y[finite], s=8, alpha=0.6)
            top = float(y[finite].max()) * 2
            _metric_scale(ax, "y", y[finite])
            if xname == "ITAE":
                _metric_scale(ax, "x", x[finite])
        else:
            top = 1.0
            _no_data(ax, "every draw diverged")
        if (~finite).any() and xname != "ITAE":
            n_bad = int((~finite).sum())
            ax.scatter(x[~finite], np.full(n_bad, top), marker="x", color="r", label="diverged")
            ax.legend(loc="upper left", fontsize=8)
        if res.corners is not None and xname in res.corners.columns():
            _mark_corners(ax, res, xname, top)
        if xname == "ITAE":
            title = "ISU against ITAE per stable draw"
        else:
            title = f"ITAE vs {xname} (Spearman {dict(res.influence())[xname]:+.2f})"
        label = xname + (" factor" if xname in res.draws.factors else "")
        ax.set(xlabel=label, ylabel=yname)
        ax.set_title(title, parse_math=False)
    corners = ""
    if res.corners is not None:
        n_c = len(res.corners)
        corners = f"; corners stable {n_c - int(res.corner_failed.sum())} of {n_c}"
    fig.suptitle(  # the config's name: plain text, never mathtext
        f"{res.name}: stable {100 * res.stable_fraction:.1f} % of {k} draws "
        f"(seed {res.draws.seed}){corners}",
        parse_math=False,
    )
    return fig
