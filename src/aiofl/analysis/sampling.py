r"""How slow may the processor be: the largest sample time a design tolerates.

For a config (plant, scenario, controller, step dt) :func:`sampling_limits` runs the
controller sampled at a ladder of sample times :math:`T_s = k\,dt` (batched: every
candidate of every config of one plant is a member of one engine call) and finds

* ``ts_stable``: the largest :math:`T_s` such that the loop does not diverge over the
  scenario at that and every smaller sample time tried;
* ``ts_max``: the largest :math:`T_s` such that, in addition, the ITAE (eq. 22) is within
  ``tolerance`` (10 %) of the continuous controller's, at that and every smaller one.

"Every smaller one" makes both limits contiguous from :math:`T_s = dt` up: a design that
fails at some :math:`T_s` and recovers at a larger one is limited by the first failure.
The search starts with a geometric ladder of ``n_grid`` multiples of dt up to ``ts_upper``
and refines each bracket [last pass, first fail] with ``n_refine`` more multiples per round
until the bracket's ends are adjacent multiples of dt or within ``rtol`` of each other.
Stability means the engine's divergence test over the scenario's horizon (non-finite or
beyond ``divergence_threshold``): a slowly growing oscillation that stays below it within
the horizon counts as stable, and then normally fails the ITAE test.

The discretisation is the config's ``[controller.discrete]`` table (delay, quantisation,
methods) with only Ts varied, or the defaults (ZOH ESO for the linear ESO, Euler for the
INLESO, fhan for Han's TD, ...) when the config has none.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from aiofl.config import RunConfig
from aiofl.engine.discrete import Sampling
from aiofl.engine.simulation import simulate_batch

__all__ = ["SamplingLimits", "sampling_figure", "sampling_limits", "sampling_limits_many"]


@dataclass(frozen=True)
class SamplingLimits:
    """The sample-time limits of one config (see the module notes).

    ``ts_max``/``ts_stable`` are None when even :math:`T_s = dt` fails (or the continuous
    loop diverges); ``*_bracket`` is (last passing, first failing) :math:`T_s`, the failing
    end None when nothing up to ``ts_upper`` failed.  ``points`` are all runs:
    ``(ts, itae, diverged, diverged_at)``.
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
    points: list[tuple[float, float | None, bool, float | None]] = field(repr=False)
    discretisation: list[str] = field(default_factory=list)
    engine_calls: int = 0
    seconds: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``{"ts_max": ..., "ts_stable": ..., ...}``."""
        return {
            "config": self.name,
            "ts_max": self.ts_max,
            "ts_stable": self.ts_stable,
            "tolerance": self.tolerance,
            "itae_continuous": self.itae_continuous,
            "continuous_diverged": self.continuous_diverged,
            "dt": self.dt,
            "ts_upper": self.ts_upper,
            "ts_max_bracket": list(self.ts_max_bracket),
            "ts_stable_bracket": list(self.ts_stable_bracket),
            "discretisation": self.discretisation,
            "points": [
                {"ts": t, "itae": i, "diverged": d, "diverged_at": a} for t, i, d, a in self.points
            ],
            "engine_calls": self.engine_calls,
            "seconds": self.seconds,
        }


@dataclass
class _Search:
    cfg: RunConfig
    base: Sampling
    k_upper: int
    results: dict[int, tuple[float | None, bool, float | None]] = field(default_factory=dict)
    itae_c: float | None = None
    cont_diverged: bool = False

    def passes(self, k: int, perf: bool, tol: float) -> bool:
        itae, div, _ = self.results[k]
        if div or itae is None:
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


def sampling_limits_many(
    configs: Sequence[RunConfig],
    *,
    tolerance: float = 0.1,
    ts_upper: float = 0.05,
    n_grid: int = 14,
    n_refine: int = 8,
    rtol: float = 0.05,
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
    on_round
        Called as ``on_round(round, members)`` after each round.
    """
    if not tolerance > 0:
        raise ValueError(f"tolerance = {tolerance}; allowed: > 0")
    t0 = time.perf_counter()
    searches = []
    for cfg in configs:
        k_upper = max(1, int(min(ts_upper, cfg.scenario.t_final / 20) / cfg.dt + 1e-9))
        base = cfg.sampling or Sampling(cfg.dt)
        searches.append(_Search(cfg, base, k_upper))
    # round 0: the continuous run and the first ladder
    todo: dict[int, list[int]] = {
        i: [0, 1, *_ladder(1, s.k_upper, n_grid - 2), s.k_upper] for i, s in enumerate(searches)
    }
    calls = 0
    rnd = 0
    while any(todo.values()):
        calls += _run_round(searches, todo)
        rnd += 1
        if on_round is not None:
            on_round(rnd, sum(len(v) for v in todo.values()))
        todo = {}
        for i, s in enumerate(searches):
            if s.cont_diverged:
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
    out = []
    for s in searches:
        cfg = s.cfg

        def ts(k: int | None, cfg: RunConfig = cfg) -> float | None:
            return None if k is None else k * cfg.dt

        bm = s.bracket(True, tolerance) if not s.cont_diverged else (None, None)
        bs = s.bracket(False, tolerance) if not s.cont_diverged else (None, None)
        points = [(k * cfg.dt, *s.results[k]) for k in sorted(s.results)]
        out.append(
            SamplingLimits(
                name=cfg.name,
                dt=cfg.dt,
                tolerance=tolerance,
                itae_continuous=s.itae_c,
                continuous_diverged=s.cont_diverged,
                ts_max=ts(bm[0]),
                ts_stable=ts(bs[0]),
                ts_max_bracket=(ts(bm[0]), ts(bm[1])),
                ts_stable_bracket=(ts(bs[0]), ts(bs[1])),
                ts_upper=s.k_upper * cfg.dt,
                points=points,
                discretisation=s.base.describe(cfg.controller)[1:],
                engine_calls=calls,
                seconds=seconds,
            )
        )
    return out


def _run_round(searches: list[_Search], todo: dict[int, list[int]]) -> int:
    """Run the requested sample times (k = 0: continuous), one engine call per group."""
    groups: dict[tuple[Any, ...], list[tuple[int, int]]] = {}
    for i, ks in todo.items():
        c = searches[i].cfg
        key = (id(c.plant), c.dt, c.method, c.scenario.t_final, c.divergence_threshold)
        groups.setdefault(key, []).extend((i, k) for k in ks)
    for members in groups.values():
        first = searches[members[0][0]].cfg
        res = simulate_batch(
            first.plant,
            [searches[i].cfg.controller for i, _ in members],
            [searches[i].cfg.scenario for i, _ in members],
            dt=first.dt,
            method=first.method,
            store=False,
            divergence_threshold=first.divergence_threshold,
            sampling=[
                None if k == 0 else replace(searches[i].base, ts=k * first.dt) for i, k in members
            ],
        )
        itae = res.metric("itae")
        for j, (i, k) in enumerate(members):
            s = searches[i]
            div = bool(res.diverged[j])
            val = None if div or not math.isfinite(itae[j]) else float(itae[j])
            at = float(res.diverged_at[j]) if div else None
            if k == 0:
                s.itae_c, s.cont_diverged = val, div
            else:
                s.results[k] = (val, div, at)
    return len(groups)


def sampling_limits(cfg: RunConfig, **kwargs: Any) -> SamplingLimits:
    """The largest sample times at which ``cfg``'s design is stable (``ts_stable``) and
    within ``tolerance`` of its continuous ITAE (``ts_max``); see the module notes and
    :func:`sampling_limits_many` for the options."""
    return sampling_limits_many([cfg], **kwargs)[0]


def sampling_figure(lim: SamplingLimits) -> Any:
    """ITAE against Ts (log-log): the runs, the continuous ITAE and its allowance, the
    limits; diverged runs are marked at the top.  The title (the config's name) is plain
    text, not mathtext.  Returns a matplotlib Figure."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.0, 4.2), dpi=110)
    ax = fig.add_subplot(1, 1, 1)
    ok = [(t, i) for t, i, d, _ in lim.points if not d and i is not None]
    bad = [t for t, i, d, _ in lim.points if d or i is None]
    if ok:
        ax.loglog(*zip(*ok, strict=True), "o-", ms=3.5, lw=1, label="sampled")
    top = max([i for _, i in ok] + [lim.itae_continuous or 1.0]) * 3
    if bad:
        ax.loglog(bad, [top] * len(bad), "x", color="C3", label="diverged")
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
