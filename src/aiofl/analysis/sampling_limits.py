r"""How slow may the processor be: the largest sample time a design tolerates.

For a config (plant, scenario, controller, step dt) :func:`sampling_limits` runs the
controller sampled at a ladder of sample times :math:`T_s = k\,dt` (batched: every
candidate of every config of one plant is a member of one engine call) and finds

* ``ts_stable``: the largest :math:`T_s` such that the sampled loop is **stable** at that
  and every smaller sample time tried, where stable means all three of

  1. *linearisation*: the sampled loop linearised at its operating point has spectral
     radius :math:`\max|\lambda_i(M(T_s))| < 1` (:mod:`aiofl.analysis.sampled_loop`: the
     ZOH of the plant's continuous linearisation closed with the engine's discrete
     controller update, linearised by finite differences; skipped, and said so, where
     there is no linearisation, e.g. the IOFL law);
  2. *bounded*: the simulation over the scenario's horizon neither loses the plant (its
     envelope, :mod:`aiofl.engine.kernel.loop`) nor diverges (non-finite, or a plant state beyond
     ``divergence_threshold``);
  3. *off the saturation*: :math:`|u|` sits at its limit (``law.u_max``/``law.u_min``)
     for at most ``saturation_allowance`` (5 %) of the horizon more than the continuous
     design does (a loop held by a saturated command is bounded whatever its
     linearisation; it is not "stable" in any useful sense);

* ``ts_max``: the largest :math:`T_s` such that, in addition, the ITAE (eq. 22) is within
  ``tolerance`` (10 %) of the continuous controller's, at that and every smaller one.

A design whose continuous loop diverges (in the simulation, or whose linearisation is
unstable) has neither: there is nothing to sample.  Each run is reported with
:math:`\omega_0T_s` (the ESO bandwidth times the sample time; the ZOH ESO is exact at any
value, but :math:`\omega_0T_s \gtrsim 1` leaves the observer one sample per time
constant).

"Every smaller one" makes both limits contiguous from :math:`T_s = dt` up: a design that
fails at some :math:`T_s` and recovers at a larger one is limited by the first failure.
The search starts with a geometric ladder of ``n_grid`` multiples of dt up to ``ts_upper``
and refines each bracket [last pass, first fail] with ``n_refine`` more multiples per round
until the bracket's ends are adjacent multiples of dt or within ``rtol`` of each other.
The saturation time is measured on the stored trajectory (every ``decimation``-th step,
about 4000 points over the horizon).

The discretisation is the config's ``[controller.discrete]`` table (delay, quantisation,
methods) with only Ts varied, or the defaults (ZOH ESO for the linear ESO, Euler for the
INLESO, fhan for Han's TD, ...) when the config has none.

**Delay margins.**  Beside the limits, the largest unmodelled transport delay the loop
tolerates, at ``delay_ts`` (the config's ``[controller.discrete] ts``, else
:data:`DELAY_TS` = 1 ms): the *sampled* loop's, from its discrete linearisation with the
delay as a shift register and a fractional-delay ZOH
(:meth:`aiofl.analysis.sampled_loop.SampledLoop.delay_margin`), and the *continuous*
loop's, :math:`\min_i\varphi_{m,i}/\omega_{gc,i}` of the loop broken at the plant input
(:func:`aiofl.analysis.frequency.loop_margins`).  They differ: the hold's half-sample lag
is in the first, and the discrete observer's phase is not the continuous one's.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl.analysis.budget import budget_spent
from aiofl.config import RunConfig
from aiofl.engine.discrete_rows import Sampling
from aiofl.engine.simulation import simulate_batch

__all__ = [
    "CRITERIA",
    "SATURATION_ALLOWANCE",
    "SamplingLimits",
    "SamplingPoint",
    "sampling_figure",
    "sampling_limits",
    "sampling_limits_many",
]


DELAY_TS = 1e-3
"""Sample time [s] of the sampled delay margin of a config without ``[controller.discrete]``."""

SATURATION_ALLOWANCE = 0.05
"""Largest extra fraction of the horizon a stable sampled loop may spend at abs(u) = u_max."""

CRITERIA = (
    "stable at Ts: (1) the sampled loop linearised at its operating point (ZOH of the "
    "plant's continuous linearisation closed with the engine's discrete controller update, "
    "finite differences) has spectral radius < 1; (2) the simulation over the horizon "
    "stays bounded; (3) |u| sits at its limit for at most {sat:g} % of the horizon more "
    "than the continuous design does. ts_stable: the largest Ts stable at it and every "
    "smaller Ts tried; ts_max: in addition ITAE within {tol:g} % of the continuous ITAE."
)
"""The definitions, as printed and written to the JSON (``criteria``)."""


@dataclass(frozen=True)
class SamplingPoint:
    r"""One sampled run: Ts, ITAE (None if diverged), divergence, the fraction of the
    horizon at the saturation, the linearised loop's spectral radius (None: not
    available) and :math:`\omega_0T_s` (None: the ESO has no ω0)."""

    ts: float
    itae: float | None
    failed: bool
    stopped_at: float | None
    saturated: float | None
    radius: float | None
    omega0_ts: float | None

    def __iter__(self) -> Any:  # (ts, itae, diverged, stopped_at) unpacking, as before
        return iter((self.ts, self.itae, self.failed, self.stopped_at))

    def __getitem__(self, i: int) -> Any:
        return (self.ts, self.itae, self.failed, self.stopped_at)[i]

    def failures(self, sat_continuous: float, allowance: float) -> list[str]:
        """Which stability criteria this run fails (empty: stable)."""
        out = []
        if self.radius is not None and not self.radius < 1.0:
            out.append("linearisation")
        if self.failed or self.itae is None:
            out.append("lost or diverged")
        if self.saturated is not None and self.saturated > sat_continuous + allowance:
            out.append("saturation")
        return out


@dataclass(frozen=True)
class SamplingLimits:
    """The sample-time limits of one config (see the module notes).

    ``ts_max``/``ts_stable`` are None when even :math:`T_s = dt` fails (or the continuous
    loop diverges); ``*_bracket`` is (last passing, first failing) :math:`T_s`, the failing
    end None when nothing up to ``ts_upper`` failed.  ``points`` are all runs
    (:class:`SamplingPoint`); ``criteria`` the definitions in words.
    """

    name: str
    dt: float
    tolerance: float
    itae_continuous: float | None
    continuous_diverged: bool
    ts_max: float | None
    ts_stable: float | None
    ts_max_bracket: tuple[float | None, float | None]
    ts_stable_bracket: tuple[float | None, float | None]
    ts_upper: float
    points: list[SamplingPoint] = field(repr=False)
    discretisation: list[str] = field(default_factory=list)
    engine_calls: int = 0
    seconds: float = 0.0
    saturation_allowance: float = SATURATION_ALLOWANCE
    saturated_continuous: float | None = None
    continuous_linear_stable: bool | None = None
    linearisation_note: str = ""
    omega0: float | None = None
    delay_ts: float | None = None
    delay_margin_sampled: float | None = None
    delay_margin_continuous: float | None = None
    gave_up: float | None = None  # the time budget [s] that stopped the refining, if any

    @property
    def criteria(self) -> str:
        """The definitions of stable, ts_stable and ts_max."""
        return CRITERIA.format(sat=100 * self.saturation_allowance, tol=100 * self.tolerance)

    @property
    def first_failure(self) -> list[str]:
        """The criteria the first failing Ts of ``ts_stable`` fails ([] if none failed)."""
        bad = self.ts_stable_bracket[1]
        for p in self.points:
            if p.ts == bad:
                return p.failures(self.saturated_continuous or 0.0, self.saturation_allowance)
        return []

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``{"ts_max": ..., "ts_stable": ..., "criteria": ..., ...}``."""
        sat_c = self.saturated_continuous or 0.0
        return {
            "config": self.name,
            "ts_max": self.ts_max,
            "ts_stable": self.ts_stable,
            "criteria": self.criteria,
            "tolerance": self.tolerance,
            "saturation_allowance": self.saturation_allowance,
            "itae_continuous": self.itae_continuous,
            "continuous_diverged": self.continuous_diverged,
            "continuous_linear_stable": self.continuous_linear_stable,
            "saturated_continuous": self.saturated_continuous,
            "linearisation_note": self.linearisation_note,
            "omega0": self.omega0,
            "dt": self.dt,
            "ts_upper": self.ts_upper,
            "ts_max_bracket": list(self.ts_max_bracket),
            "ts_stable_bracket": list(self.ts_stable_bracket),
            "first_failure": self.first_failure,
            "delay_ts": self.delay_ts,
            "delay_margin_sampled_s": _finite(self.delay_margin_sampled),
            "delay_margin_continuous_s": _finite(self.delay_margin_continuous),
            "discretisation": self.discretisation,
            "points": [
                {
                    "ts": p.ts,
                    "omega0_ts": p.omega0_ts,
                    "itae": p.itae,
                    "failed": p.failed,
                    "stopped_at": p.stopped_at,
                    "saturated_fraction": p.saturated,
                    "spectral_radius": p.radius,
                    "fails": p.failures(sat_c, self.saturation_allowance),
                }
                for p in self.points
            ],
            "engine_calls": self.engine_calls,
            "seconds": self.seconds,
            "gave_up_after_s": self.gave_up,
        }


def _finite(v: float | None) -> float | None:
    return v if v is None or math.isfinite(v) else None


# (itae, diverged, stopped_at, saturated fraction)
_Run = tuple[float | None, bool, float | None, float | None]


@dataclass
class _Search:
    cfg: RunConfig
    base: Sampling
    k_upper: int
    allowance: float
    results: dict[int, _Run] = field(default_factory=dict)
    radius: dict[int, float | None] = field(default_factory=dict)
    itae_c: float | None = None
    cont_failed: bool = False
    sat_c: float | None = None
    linear: Any = None

    def passes(self, k: int, perf: bool, tol: float) -> bool:
        itae, div, _, sat = self.results[k]
        if div or itae is None:
            return False
        if sat is not None and sat > (self.sat_c or 0.0) + self.allowance:
            return False
        rad = self.radius.get(k)
        if rad is not None and not rad < 1.0:
            return False
        if not perf:
            return True
        return self.itae_c is not None and itae <= (1.0 + tol) * self.itae_c

    def bracket(self, perf: bool, tol: float) -> tuple[int | None, int | None]:
        """(last passing k, first failing k), contiguous from the smallest k tried."""
        good = None
        for k in sorted(self.results):
            if not self.passes(k, perf, tol):
                return good, k
            good = k
        return good, None


def _ladder(lo: int, hi: int, n: int) -> list[int]:
    """Up to n distinct integers strictly between lo and hi, geometrically spaced."""
    if hi - lo <= 1:
        return []
    pts = np.unique(np.round(np.geomspace(max(lo, 1), hi, n + 2)[1:-1]).astype(int))
    return [int(k) for k in pts if lo < k < hi]


def _needs_refining(b: tuple[int | None, int | None], rtol: float) -> bool:
    good, bad = b
    if bad is None:
        return False
    lo = good or 0
    return bad - lo > 1 and (lo == 0 or bad / lo > 1.0 + rtol)


def _omega0(cfg: RunConfig) -> float | None:
    try:
        w = float(cfg.controller.value("eso.omega0"))
    except (KeyError, ValueError):
        return None
    return w if math.isfinite(w) and w > 0 else None


def sampling_limits_many(
    configs: Sequence[RunConfig],
    *,
    tolerance: float = 0.1,
    ts_upper: float = 0.05,
    n_grid: int = 14,
    n_refine: int = 8,
    rtol: float = 0.05,
    saturation_allowance: float = SATURATION_ALLOWANCE,
    linearise: bool = True,
    on_round: Callable[[int, int], None] | None = None,
) -> list[SamplingLimits]:
    """:func:`sampling_limits` for several configs, batched: each round is one engine call
    per group of configs that share plant, step, method, horizon and threshold.

    Parameters
    ----------
    configs
        Run configs (their ``[controller.discrete]`` settings, if any, are kept with Ts
        varied).
    tolerance
        ITAE allowance over the continuous design for ``ts_max`` (0.1 = 10 %).
    ts_upper
        Largest sample time tried [s] (capped at a twentieth of the horizon).
    n_grid, n_refine
        Sample times in the first ladder, and per bracket in each refining round.
    rtol
        Stop refining a bracket once its ends are within this ratio.
    saturation_allowance
        Criterion 3 of the module notes (0.05 = 5 % of the horizon).
    linearise
        Apply criterion 1 (the linearised sampled loop's spectral radius).
    on_round
        Called as ``on_round(round, members)`` after each round.

    Notes
    -----
    Inside a time budget (:func:`aiofl.analysis.budget.time_budget`) the refining rounds
    stop once it is spent: the brackets are then the coarser ones found so far and
    ``gave_up`` holds the budget (the first round, the ladder, always runs).

    Returns
    -------
    list of SamplingLimits
        One per config, in order.
    """
    if not tolerance > 0:
        raise ValueError(f"tolerance = {tolerance}; allowed: > 0")
    if not 0 <= saturation_allowance <= 1:
        raise ValueError(f"saturation_allowance = {saturation_allowance}; allowed: 0..1")
    t0 = time.perf_counter()
    searches = []
    for cfg in configs:
        k_upper = max(1, int(min(ts_upper, cfg.scenario.t_final / 20) / cfg.dt + 1e-9))
        base = cfg.sampling or Sampling(cfg.dt)
        s = _Search(cfg, base, k_upper, saturation_allowance)
        if linearise:
            from aiofl.analysis.sampled_loop import SampledLoop

            s.linear = SampledLoop(cfg)
        searches.append(s)
    # round 0: the continuous run and the first ladder
    todo: dict[int, list[int]] = {
        i: [0, 1, *_ladder(1, s.k_upper, n_grid - 2), s.k_upper] for i, s in enumerate(searches)
    }
    calls = 0
    rnd = 0
    gave_up = None
    while any(todo.values()):
        if rnd > 0:
            gave_up = budget_spent()
            if gave_up is not None:
                break
        calls += _run_round(searches, todo)
        rnd += 1
        if on_round is not None:
            on_round(rnd, sum(len(v) for v in todo.values()))
        todo = {}
        for i, s in enumerate(searches):
            if s.cont_failed:
                continue
            ks: set[int] = set()
            for perf in (True, False):
                b = s.bracket(perf, tolerance)
                if _needs_refining(b, rtol):
                    ks.update(_ladder(b[0] or 0, b[1], n_refine))  # type: ignore[arg-type]
            ks -= set(s.results)
            if ks:
                todo[i] = sorted(ks)
    seconds = time.perf_counter() - t0
    return [replace(_limits(s, tolerance, calls, seconds), gave_up=gave_up) for s in searches]


def _limits(s: _Search, tolerance: float, calls: int, seconds: float) -> SamplingLimits:
    cfg = s.cfg

    def ts(k: int | None) -> float | None:
        return None if k is None else k * cfg.dt

    lin = s.linear
    lin_stable = None if lin is None else lin.continuous_stable
    note = (
        "criterion 1 not applied (linearise = False)"
        if lin is None
        else (lin.reason if not lin.available else "")
    )
    if lin_stable is False and not s.cont_failed:
        note = (
            "the continuous loop's linearisation is unstable (it stayed bounded over the "
            "horizon): no sampled limits"
        )
    dead = s.cont_failed or lin_stable is False
    bm = s.bracket(True, tolerance) if not dead else (None, None)
    bs = s.bracket(False, tolerance) if not dead else (None, None)
    w0 = _omega0(cfg)
    d_ts = cfg.sampling.ts if cfg.sampling is not None else DELAY_TS
    dm_s = dm_c = None
    if lin is not None and lin.available and not dead:
        dm_s, dm_c = lin.delay_margin(d_ts), lin.continuous_delay_margin()
    points = [
        SamplingPoint(
            k * cfg.dt, *s.results[k], s.radius.get(k), None if w0 is None else w0 * k * cfg.dt
        )
        for k in sorted(s.results)
    ]
    return SamplingLimits(
        name=cfg.name,
        dt=cfg.dt,
        tolerance=tolerance,
        itae_continuous=s.itae_c,
        continuous_diverged=dead,
        ts_max=ts(bm[0]),
        ts_stable=ts(bs[0]),
        ts_max_bracket=(ts(bm[0]), ts(bm[1])),
        ts_stable_bracket=(ts(bs[0]), ts(bs[1])),
        ts_upper=s.k_upper * cfg.dt,
        points=points,
        discretisation=s.base.describe(cfg.controller)[1:],
        engine_calls=calls,
        seconds=seconds,
        saturation_allowance=s.allowance,
        saturated_continuous=s.sat_c,
        continuous_linear_stable=lin_stable,
        linearisation_note=note,
        omega0=w0,
        delay_ts=d_ts,
        delay_margin_sampled=dm_s,
        delay_margin_continuous=dm_c,
    )


def _saturated(u: NDArray[np.float64], cfg: RunConfig) -> float | None:
    """Fraction of the stored samples of u at the actuator's limits (None: no limits)."""
    u_min, u_max = cfg.controller.u_range()
    if not (math.isfinite(u_max) or math.isfinite(u_min)) or u.size == 0:
        return None
    tol = 1e-9 * max(
        abs(u_max) if math.isfinite(u_max) else 0.0,
        abs(u_min) if math.isfinite(u_min) else 0.0,
        1.0,
    )
    at = (u >= u_max - tol) | (u <= u_min + tol)
    return float(np.mean(at))


def _run_round(searches: list[_Search], todo: dict[int, list[int]]) -> int:
    """Run the requested sample times (k = 0: continuous), one engine call per group."""
    groups: dict[tuple[Any, ...], list[tuple[int, int]]] = {}
    for i, ks in todo.items():
        c = searches[i].cfg
        key = (id(c.plant), c.dt, c.method, c.scenario.t_final, c.divergence_threshold)
        groups.setdefault(key, []).extend((i, k) for k in ks)
    for members in groups.values():
        first = searches[members[0][0]].cfg
        n_steps = round(first.scenario.t_final / first.dt)
        res = simulate_batch(
            first.plant,
            [searches[i].cfg.controller for i, _ in members],
            [searches[i].cfg.scenario for i, _ in members],
            dt=first.dt,
            method=first.method,
            store=True,
            decimation=max(1, n_steps // 4000),
            divergence_threshold=first.divergence_threshold,
            sampling=[
                None if k == 0 else replace(searches[i].base, ts=k * first.dt) for i, k in members
            ],
        )
        itae = res.metric("itae")
        assert res.trajectories is not None
        u_col = res.columns.index("u")
        for j, (i, k) in enumerate(members):
            s = searches[i]
            div = bool(res.failed[j])
            val = None if div or not math.isfinite(itae[j]) else float(itae[j])
            at = float(res.stopped_at[j]) if div else None
            sat = None if div else _saturated(res.trajectories[j, :, u_col], s.cfg)
            if k == 0:
                s.itae_c, s.cont_failed, s.sat_c = val, div, sat
            else:
                s.results[k] = (val, div, at, sat)
                if s.linear is not None and s.linear.available:
                    s.radius[k] = s.linear.spectral_radius(k * first.dt)
    return len(groups)


def sampling_limits(cfg: RunConfig, **kwargs: Any) -> SamplingLimits:
    """The largest sample times at which ``cfg``'s design is stable (``ts_stable``) and
    within ``tolerance`` of its continuous ITAE (``ts_max``); see the module notes and
    :func:`sampling_limits_many` for the options."""
    return sampling_limits_many([cfg], **kwargs)[0]


def sampling_figure(lim: SamplingLimits) -> Any:
    """ITAE against Ts (log-log): the runs, the continuous ITAE and its allowance, the
    limits; runs that are not stable (module notes: any of the three criteria) are marked
    at the top.  The title (the config's name) is plain
    text, not mathtext.  Returns a matplotlib Figure."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.0, 4.2), dpi=110)
    ax = fig.add_subplot(1, 1, 1)
    sat_c, allow = lim.saturated_continuous or 0.0, lim.saturation_allowance
    ok = [(p.ts, p.itae) for p in lim.points if not p.failures(sat_c, allow)]
    bad = [p.ts for p in lim.points if p.failures(sat_c, allow)]
    if ok:
        ax.loglog(*zip(*ok, strict=True), "o-", ms=3.5, lw=1, label="sampled")
    top = max([i for _, i in ok] + [lim.itae_continuous or 1.0]) * 3
    if bad:
        ax.loglog(bad, [top] * len(bad), "x", color="C3", label="not stable")
    if lim.itae_continuous is not None:
        c = lim.itae_continuous
        ax.axhline(c, color="k", lw=0.8, label=f"continuous ITAE {c:.4g}")
        tol = f"+{100 * lim.tolerance:g} %"
        ax.axhline(c * (1 + lim.tolerance), color="k", lw=0.8, ls="--", label=tol)
    for val, name, col in ((lim.ts_max, "ts_max", "C2"), (lim.ts_stable, "ts_stable", "C1")):
        if val is not None:
            ax.axvline(val, color=col, lw=1, ls=":", label=f"{name} = {val:.3g} s")
    ax.set_xlabel("sample time Ts [s]")
    ax.set_ylabel("ITAE")
    ax.set_title(f"{lim.name}: ITAE against the sample time", parse_math=False)  # user text
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    return fig
