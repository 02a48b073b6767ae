r"""The worst cases of the uncertainty box: its corners, a local search and the β/b0 range.

Random draws of a ±20 % box rarely land near its corners (with k = 4 uniform factors the
chance that a draw has every factor within 2 % of an edge is :math:`0.1^4`), yet the
extremes of the true plant's high-frequency gain :math:`\beta = L_gL_f^{\rho-1}h` — what
decides the stability of an ESO-based loop designed for :math:`b_0` — sit there (for
``slfjm`` :math:`\beta = K_sK_mK_g/(J_lJ_hR_m)`: J_l, J_h, R_m × 0.8 and K_s × 1.2 give
β × 2.34).  Three checks complete the draws of :mod:`aiofl.analysis.robustness_draws`:

**Corners.**  :func:`aiofl.uncertainty.corner_draws`: all :math:`2^k` corners of the box of
``[uncertainty]`` for :math:`k \le 12` drawn quantities, a resolution-IV two-level
fractional factorial of :math:`2^{12}` corners beyond (:func:`aiofl.uncertainty.corner_design`).
They run in the same batched engine call as the draws
(:func:`aiofl.analysis.robustness_draws.run_robustness` with ``corners``).

**Local worst-case search** (:func:`worst_case_search`): from the worst corner or draw,
maximise ITAE over the box with ``scipy.optimize.minimize(method="L-BFGS-B")`` on
:math:`-\ln \mathrm{ITAE}(u)`, :math:`u \in [0, 1]^k` the box in unit coordinates (Byrd,
Lu, Nocedal & Zhu, *A limited memory algorithm for bound constrained optimization*, SIAM
J. Sci. Comput. 16(5), 1995).  Each evaluation is one engine call of :math:`k + 1` plants:
the point and its k one-sided finite-difference neighbours (step
:data:`FD_STEP`, inwards at an edge), which give the gradient.  A diverged plant (ITAE
:math:`+\infty`) ends the search: divergence is the worst case.  If the start itself
diverged, nothing is searched.

**β/b0 stability range** (:func:`beta_ranges`): the true plant's β scaled by a factor s
alone, every other term of the plant unchanged, through a combination of its parameters
found by :func:`beta_scaling` (for ``slfjm``: :math:`K_g \times s^{-1}`,
:math:`R_m \times s^{-2}`, which keeps the back-EMF damping :math:`K_m^2K_g^2/(R_mJ_h)` and
scales the input gain :math:`K_mK_g/(R_mJ_h)` by s).  On each side of s = 1 a grid of
:data:`BETA_GRID` log-spaced factors up to the cap (:data:`BETA_CAP`) runs for every design
in one engine call; the first unstable factor and the last stable one before it are then
bisected in :math:`\ln s`, :data:`BETA_STEPS` times, each step one engine call for every
design and side.  "Stable" means "did not diverge within the scenario's horizon" (the
engine's divergence threshold): just beyond the bound a slowly growing oscillation may not
reach the threshold, so the range is the one the simulations see, not an eigenvalue bound.
The range is reported as :math:`s` and as :math:`\beta/b_0 = s\,\beta_{nom}/b_0`, with
:math:`\beta_{nom}` the scenario's plant's β at :math:`x_0` (its own parameter change,
e.g. scenario 2's J_l × 1.4, included).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.uncertainty import Draws, UncertaintyModel, box_bounds, box_draws

__all__ = [
    "BETA_CAP",
    "BETA_GRID",
    "BETA_STEPS",
    "FD_STEP",
    "BetaRange",
    "WorstCase",
    "beta_ranges",
    "beta_scaling",
    "corner_summary",
    "run_box_robustness",
    "worst_case_search",
]

#: the finite-difference step of the worst-case search, in unit box coordinates
FD_STEP = 0.02
#: the most evaluations (engine calls) of the worst-case search
SEARCH_EVALUATIONS = 12
#: the range searched for the β factor s: [1 / 20, 20]
BETA_CAP = (0.05, 20.0)
#: grid points per side of s = 1
BETA_GRID = 6
#: bisection steps per side after the grid
BETA_STEPS = 5


# --------------------------------------------------------------------------- corners
def corner_summary(res: Any, design: str) -> dict[str, Any]:
    """The ``corners`` record of a :class:`~aiofl.analysis.robustness_draws.RobustnessResult` run
    with corners: design, count, ``corners_stable`` (fraction) and ``stable`` (count), the
    diverged corners (index, time, factors) and the worst corner."""
    d: Draws = res.corners
    cols = d.columns()
    div = res.corner_failed
    itae = res.corner_itae
    n = len(d)
    if div.any():
        idx = np.flatnonzero(div)
        w = int(idx[np.argmin(res.corner_stopped_at[idx])])
    else:
        w = int(np.argmax(itae))

    def point(i: int) -> dict[str, float]:
        return {k: float(v[i]) for k, v in cols.items()}

    return {
        "design": design,
        "count": n,
        "corners_stable": float(np.mean(~div)),
        "stable": int(n - div.sum()),
        "failed": [
            {
                "corner": int(i),
                "status": L.STATUS_NAMES[int(res.corner_status[i])],
                "t": float(res.corner_stopped_at[i]),
                "point": point(int(i)),
            }
            for i in np.flatnonzero(div)
        ],
        "worst": {
            "corner": w,
            "itae": float(itae[w]) if np.isfinite(itae[w]) else None,
            "status": L.STATUS_NAMES[int(res.corner_status[w])],
            "stopped_at": float(res.corner_stopped_at[w]) if div[w] else None,
            "point": point(w),
        },
    }


# ------------------------------------------------------------------ worst-case search
@dataclass(frozen=True)
class WorstCase:
    """The worst plant found by :func:`worst_case_search`.

    ``point`` holds the drawn quantities (parameter factors, ``ts``, ``noise_variance``);
    ``itae`` is None when it was lost or diverged (``status``, at ``stopped_at``);
    ``start`` says where the search began and ``improved`` whether it found something
    worse than the start.
    """

    point: dict[str, float]
    itae: float | None
    stopped_at: float | None
    start: str
    start_itae: float | None
    evaluations: int
    engine_calls: int
    improved: bool
    message: str
    status: str = "ok"

    def to_dict(self) -> dict[str, Any]:
        """Plain data for ``robustness.json``."""
        return {
            "method": f"scipy L-BFGS-B on -ln ITAE over the box, <= {SEARCH_EVALUATIONS} "
            "evaluations of k+1 plants (finite-difference gradient); a lost or diverged run "
            "ends it",
            "status": self.status,
            "start": self.start,
            "start_itae": self.start_itae,
            "itae": self.itae,
            "stopped_at": self.stopped_at,
            "point": self.point,
            "improved": self.improved,
            "evaluations": self.evaluations,
            "engine_calls": self.engine_calls,
            "message": self.message,
        }


class _Budget(Exception):
    """The search's evaluations are spent."""


class _Failed(Exception):
    """A point of the search whose plant was lost or whose numbers diverged."""

    def __init__(self, u: NDArray[np.float64], t: float, status: str) -> None:
        self.u, self.t, self.status = u, t, status


def worst_case_search(
    cfg: Any,
    spec: UncertaintyModel,
    start: NDArray[np.float64],
    *,
    start_label: str = "given point",
    evaluations: int = SEARCH_EVALUATIONS,
    noise_seed: int | None = None,
) -> WorstCase:
    r"""Maximise ITAE over the box of ``spec`` from ``start`` (unit coordinates, (k,)).

    See the module docstring.  Each evaluation runs the point and its k finite-difference
    neighbours in one :func:`~aiofl.analysis.robustness_draws.simulate_designs` call; the first
    diverged plant ends the search and is returned.  With a noisy measurement every point
    runs the noise realisation ``noise_seed`` (:attr:`aiofl.uncertainty.Draws.noise_seeds`;
    give the start's, so the search compares plants on the start's noise, common random
    numbers); None: the box points' own seeds.

    Parameters
    ----------
    cfg, spec
        The run config (:class:`aiofl.config.RunConfig`) and the model whose box is searched.
    start
        The start point in unit box coordinates, shape (k,), k the box's dimensions.
    start_label
        How the result names the start (``"corner 3"``, ``"draw 17"``, ...).
    evaluations
        The most engine calls the search makes (default :data:`SEARCH_EVALUATIONS`).
    noise_seed
        The noise realisation every point runs (above); None: the points' own seeds.

    Returns
    -------
    WorstCase
    """
    from scipy.optimize import minimize

    from aiofl.analysis.robustness_draws import simulate_designs

    box = box_bounds(spec, dt=cfg.dt)
    k = len(box)
    names = list(box)
    calls = 0
    best: list[Any] = [None, -math.inf]

    def run(u: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        nonlocal calls
        if calls >= evaluations:
            raise _Budget
        pts = np.repeat(u[None, :], k + 1, axis=0)
        steps = np.where(u + FD_STEP <= 1.0, FD_STEP, -FD_STEP)
        pts[1 + np.arange(k), np.arange(k)] += steps
        d = box_draws(spec, pts, dt=cfg.dt)
        if noise_seed is not None:
            d = replace(d, noise_seeds=np.full(len(pts), noise_seed, dtype=np.int64))
        r = simulate_designs([cfg], d)[0]
        calls += 1
        if r.failed.any():
            i = int(np.flatnonzero(r.failed)[np.argmin(r.stopped_at[r.failed])])
            raise _Failed(pts[i], float(r.stopped_at[i]), L.STATUS_NAMES[int(r.status[i])])
        i = int(np.argmax(r.itae))
        if r.itae[i] > best[1]:
            best[:] = [pts[i].copy(), float(r.itae[i])]
        return r.itae, steps

    def fun(u: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
        itae, steps = run(np.clip(u, 0.0, 1.0))
        f = -np.log(itae)
        return float(f[0]), (f[1:] - f[0]) / steps

    u0 = np.clip(np.asarray(start, dtype=np.float64), 0.0, 1.0)

    def point(u: NDArray[np.float64]) -> dict[str, float]:
        d = box_draws(spec, u[None, :], dt=cfg.dt).columns()
        return {n: float(d[n][0]) for n in names}

    start_itae = None
    try:
        start_itae = float(run(u0)[0][0])
        best[:] = [u0.copy(), start_itae] if best[0] is None else best
        opt = minimize(
            fun,
            u0,
            jac=True,
            method="L-BFGS-B",
            bounds=[(0.0, 1.0)] * k,
            options={"maxfun": evaluations, "maxiter": evaluations},
        )
        message = str(opt.message)
    except _Budget:
        message = f"stopped after {evaluations} evaluations"
    except _Failed as exc:
        return WorstCase(
            point=point(exc.u),
            itae=None,
            stopped_at=exc.t,
            start=start_label,
            start_itae=start_itae,
            evaluations=calls,
            engine_calls=calls,
            improved=True,
            message=f"{exc.status} at t = {exc.t:g} s: the search stops at the first failure",
            status=exc.status,
        )
    u_best, itae_best = best
    return WorstCase(
        point=point(u_best),
        itae=float(itae_best),
        stopped_at=None,
        start=start_label,
        start_itae=start_itae,
        evaluations=calls,
        engine_calls=calls,
        improved=bool(start_itae is not None and itae_best > start_itae * (1 + 1e-9)),
        message=message,
    )


# ------------------------------------------------------------------------ β / b0 range
_EXPONENTS = (1.0, -1.0, 2.0, -2.0, 0.5, -0.5)


def beta_scaling(plant: Any, *, rtol: float = 1e-9) -> dict[str, float] | None:
    r"""Exponents :math:`e_p` such that parameters :math:`p \times s^{e_p}` scale the input
    vector field g by s and leave f, h (and b_d) unchanged — hence scale β alone.

    Tried in order: one parameter (exponent ±1), then pairs of parameters (exponents in
    ±1, ±2, ±1/2), names in the plant's order; each candidate is checked numerically at
    five random states (seed 0) for s = 2 and s = 1/3.  A combination that also keeps the
    disturbance input :math:`b_d` is preferred; failing that, one that scales :math:`b_d`
    along (e.g. the pendulum's :math:`m \times s^{-1}, c \times s^{-1}`: a torque
    disturbance enters like the input, so it scales with β).  None if no such combination
    exists (then no β/b0 range is computed).
    """
    names = list(plant.param_names)
    p0 = plant.param_vector()
    rng = np.random.default_rng(0)
    xs = rng.uniform(-1.0, 1.0, (5, plant.n_states)) + 0.3

    def ev(fn: Any, x: NDArray[np.float64], p: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.atleast_1d(np.asarray(fn(x, p), dtype=np.float64))

    def works(expo: Mapping[str, float], with_bd: bool) -> bool:
        for s in (2.0, 1.0 / 3.0):
            p = plant.param_vector(scale={n: s**e for n, e in expo.items()})
            for x in xs:
                with np.errstate(all="ignore"):
                    try:
                        same = [
                            (ev(fn, x, p), ev(fn, x, p0))
                            for fn in (plant.f, plant.h, plant.bd if with_bd else None)
                            if fn is not None
                        ]
                        g1, g0 = ev(plant.g, x, p), ev(plant.g, x, p0)
                    except (ValueError, ZeroDivisionError, ArithmeticError):
                        return False
                if not all(np.allclose(a, b, rtol=rtol, atol=0.0) for a, b in same):
                    return False
                if not np.allclose(g1, s * g0, rtol=rtol, atol=0.0) or not np.any(g0):
                    return False
        return True

    if not np.all(np.isfinite(p0)):
        return None
    cands: list[dict[str, float]] = [{n: e} for n in names for e in (1.0, -1.0)]
    cands += [
        {a: ea, b: eb}
        for a, b in itertools.combinations(names, 2)
        for ea in _EXPONENTS
        for eb in _EXPONENTS
    ]
    for with_bd in (True, False) if plant.bd is not None else (True,):
        for expo in cands:
            if works(expo, with_bd):
                return expo
    return None


@dataclass(frozen=True)
class BetaRange:
    """The β factors s around 1 (β alone scaled by s) over which a design stays stable.

    ``s_low``/``s_high`` are None when s = 1 itself diverged (or no scaling exists, see
    ``reason``); ``capped_low``/``capped_high`` say the cap was reached stable.
    """

    name: str
    scaling: dict[str, float] = field(default_factory=dict)
    beta_nominal: float | None = None
    b0: float | None = None
    s_low: float | None = None
    s_high: float | None = None
    capped_low: bool = False
    capped_high: bool = False
    reason: str = ""

    @property
    def ratio(self) -> float | None:
        """:math:`\\beta_{nom}/b_0` at s = 1 (None without a constant β or b0)."""
        if self.beta_nominal is None or not self.b0:
            return None
        return self.beta_nominal / self.b0

    def to_dict(self) -> dict[str, Any]:
        """Plain data (``beta_over_b0`` = [low, high] of :math:`s\\beta_{nom}/b_0`)."""
        r = self.ratio
        lo, hi = self.s_low, self.s_high
        return {
            "scaling": " ".join(f"{n} x s^{e:g}" for n, e in self.scaling.items()) or None,
            "beta_nominal": self.beta_nominal,
            "b0": self.b0,
            "beta_over_b0_nominal": r,
            "s": [lo, hi] if lo is not None and hi is not None else None,
            "beta_over_b0": [lo * r, hi * r]
            if r is not None and lo is not None and hi is not None
            else None,
            "capped": [self.capped_low, self.capped_high],
            "cap": list(BETA_CAP),
            "reason": self.reason or None,
        }


def _scaled_members(cfgs: Sequence[Any], scales: Sequence[Mapping[str, float]]) -> NDArray[Any]:
    """Divergence of design i on its plant scaled by ``scales[i]`` (one engine call per
    group of designs sharing plant, horizon, step and method; every member has its own
    scenario)."""
    from aiofl.analysis.robustness_draws import _design_key
    from aiofl.engine.simulation import simulate_batch

    out = np.zeros(len(cfgs), dtype=bool)
    groups: dict[Any, list[int]] = {}
    for i, c in enumerate(cfgs):
        groups.setdefault(_design_key(c), []).append(i)
    for idx in groups.values():
        base = cfgs[idx[0]]
        scen = []
        for i in idx:
            d = Draws(seed=0, factors={n: np.array([v]) for n, v in scales[i].items()})
            scen.append(d.scenarios(cfgs[i].scenario)[0])
        samp = [cfgs[i].sampling for i in idx]
        res = simulate_batch(
            base.plant,
            [cfgs[i].controller for i in idx],
            scen,
            dt=base.dt,
            method=base.method,
            divergence_threshold=base.divergence_threshold,
            sampling=samp if any(s is not None for s in samp) else None,
        )
        out[idx] = res.failed
    return out


def _nominal_beta(cfg: Any) -> float | None:
    plant, sc = cfg.plant, cfg.scenario
    nf, rd = plant.normal_form, plant.relative_degree
    if nf is None or rd is None:
        return None
    x0 = np.asarray(sc.x0, dtype=np.float64) if sc.x0 else np.zeros(plant.n_states)
    p = plant.param_vector(overrides=sc.plant_overrides, scale=sc.plant_scale)
    try:
        beta = float(np.asarray(nf(x0, p), dtype=np.float64).ravel()[rd + 1])
    except Exception:  # a normal form that fails at x0: no ratio, the s range stays
        return None
    return beta if math.isfinite(beta) and beta != 0.0 else None


def beta_ranges(
    cfgs: Sequence[Any],
    *,
    cap: tuple[float, float] = BETA_CAP,
    grid: int = BETA_GRID,
    steps: int = BETA_STEPS,
) -> tuple[list[BetaRange], int]:
    """The β/b0 stability range of every design (module docstring); returns the ranges
    (in the order of ``cfgs``) and the number of engine calls made.  A design whose plant
    has no :func:`beta_scaling`, or whose scenario changes the plant at t > 0, gets a range
    with ``reason`` set and no numbers.

    Parameters
    ----------
    cfgs
        The designs (run configs).
    cap
        The widest β/b0 range searched, (low, high) (default :data:`BETA_CAP`).
    grid, steps
        Grid points, then bisection steps, per side of s = 1 (defaults :data:`BETA_GRID`,
        :data:`BETA_STEPS`).

    Returns
    -------
    ranges : list of BetaRange
        One per design, in the order of ``cfgs``.
    calls : int
        The engine calls made.
    """
    out: list[BetaRange | None] = [None] * len(cfgs)
    live: list[int] = []
    scal: dict[int, dict[str, float]] = {}
    cache: dict[int, dict[str, float] | None] = {}
    for i, c in enumerate(cfgs):
        if id(c.plant) not in cache:
            cache[id(c.plant)] = beta_scaling(c.plant)
        e = cache[id(c.plant)]
        law = c.controller.law
        b0 = None if law == "iofl" else float(c.controller.value("law.b0"))
        common = {"name": c.name, "beta_nominal": _nominal_beta(c), "b0": b0}
        if e is None:
            out[i] = BetaRange(**common, reason="no parameter combination scales beta alone")
            continue
        sc = c.scenario
        if (sc.plant_scale or sc.plant_overrides) and sc.parameter_change_time > 0:
            out[i] = BetaRange(
                **common, scaling=e, reason="the scenario changes the plant at t > 0"
            )
            continue
        scal[i] = e
        live.append(i)
        out[i] = BetaRange(**common, scaling=e)
    calls = 0
    if not live:
        return [r for r in out if r is not None], 0

    def run(pairs: list[tuple[int, float]]) -> NDArray[np.bool_]:
        nonlocal calls
        calls += 1
        return _scaled_members(
            [cfgs[i] for i, _ in pairs],
            [{n: s**e for n, e in scal[i].items()} for i, s in pairs],
        )

    lo_cap, hi_cap = cap
    ups = np.geomspace(1.0, hi_cap, grid + 1)
    downs = np.geomspace(1.0, lo_cap, grid + 1)
    pairs = [(i, float(s)) for i in live for s in (1.0, *ups[1:], *downs[1:])]
    div = run(pairs).reshape(len(live), 1 + 2 * grid)
    bracket: dict[tuple[int, int], tuple[float, float]] = {}
    for j, i in enumerate(live):
        if div[j, 0]:
            out[i] = BetaRange(**{**out[i].__dict__, "reason": "diverged at s = 1"})  # type: ignore[union-attr]
            continue
        for side, (vals, row) in enumerate(
            ((ups, div[j, 1 : 1 + grid]), (downs, div[j, 1 + grid :]))
        ):
            bad = np.flatnonzero(row)
            if bad.size == 0:
                bracket[(i, side)] = (float(vals[-1]), math.nan)  # capped, stable
            else:
                b = int(bad[0])
                bracket[(i, side)] = (float(vals[b]), float(vals[b + 1]))
    todo = [key for key, (_, bad) in bracket.items() if not math.isnan(bad)]
    for _ in range(steps):
        if not todo:
            break
        mids = [math.sqrt(bracket[key][0] * bracket[key][1]) for key in todo]
        d = run([(key[0], m) for key, m in zip(todo, mids, strict=True)])
        for key, m, dv in zip(todo, mids, d, strict=True):
            good, bad = bracket[key]
            bracket[key] = (good, m) if dv else (m, bad)
    for i in live:
        r = out[i]
        assert r is not None
        if r.reason:
            continue
        hi, lo = bracket[(i, 0)], bracket[(i, 1)]
        out[i] = BetaRange(
            **{
                **r.__dict__,
                "s_low": lo[0],
                "s_high": hi[0],
                "capped_low": math.isnan(lo[1]),
                "capped_high": math.isnan(hi[1]),
            }
        )
    return [r for r in out if r is not None], calls


# ----------------------------------------------------------------------- the whole run
def _seed(d: Draws, i: int) -> int | None:
    return None if d.noise_seeds is None else int(d.noise_seeds[i])


def run_box_robustness(
    cfg: Any,
    *,
    draws: int | None = None,
    seed: int | None = None,
    client: Any = None,
    chunks: int | None = None,
    search: bool = True,
    beta: bool = True,
) -> Any:
    """``aiofl robustness``: the draws and the box corners in one batched run
    (:func:`~aiofl.analysis.robustness_draws.run_robustness`), then the worst-case search from
    the worst corner or draw and the β/b0 range; their records go into the result's
    ``extra`` (``corners``, ``worst_case``, ``beta_range``).

    Parameters
    ----------
    cfg
        The run config; without ``[uncertainty]`` only :func:`run_robustness` runs.
    draws, seed, client, chunks
        As for :func:`~aiofl.analysis.robustness_draws.run_robustness`: the number of draws and
        their seed (None: the config's), a ``distributed.Client`` (None: this process) and
        its number of tasks (default: one per worker).
    search, beta
        Run the worst-case search; measure the β/b0 stability range (both by default).

    Returns
    -------
    RobustnessResult
        The robustness run, the corners, worst case and β range in its ``extra``.
    """
    from aiofl.analysis.robustness_draws import run_robustness
    from aiofl.uncertainty import corner_draws

    if cfg.uncertainty is None:
        return run_robustness(cfg, draws=draws, seed=seed, client=client, chunks=chunks)
    corners, design = corner_draws(cfg.uncertainty, dt=cfg.dt)
    res = run_robustness(cfg, draws=draws, seed=seed, client=client, chunks=chunks, corners=corners)
    extra: dict[str, Any] = {"corners": corner_summary(res, design)}
    calls = 0
    if search:
        box = box_bounds(cfg.uncertainty, dt=cfg.dt)
        cols = res.draws.columns()
        cands = [  # (diverged, how bad, point, label): a divergence, the earliest, is worst
            (
                bool(res.corner_failed[i]),
                -res.corner_stopped_at[i] if res.corner_failed[i] else res.corner_itae[i],
                {k: float(v[i]) for k, v in res.corners.columns().items()},
                f"corner {i}",
                float(res.corner_stopped_at[i]),
                _seed(res.corners, i),
                L.STATUS_NAMES[int(res.corner_status[i])],
            )
            for i in [int(extra["corners"]["worst"]["corner"])]
        ]
        dw = res.worst_index()
        cands.append(
            (
                bool(res.failed[dw]),
                -res.stopped_at[dw] if res.failed[dw] else res.itae[dw],
                {k: float(v[dw]) for k, v in cols.items()},
                f"draw {dw}",
                float(res.stopped_at[dw]),
                _seed(res.draws, dw),
                L.STATUS_NAMES[int(res.status[dw])],
            )
        )
        div0, _, src, label, t_div, n_seed, how = max(cands, key=lambda c: (c[0], c[1]))
        u = np.array([(src[n] - lo) / (hi - lo) if hi > lo else 0.5 for n, (lo, hi) in box.items()])
        if div0:
            wc = WorstCase(
                point=dict(src),
                itae=None,
                stopped_at=t_div,
                start=label,
                start_itae=None,
                evaluations=0,
                engine_calls=0,
                improved=False,
                message=f"the start was {how}: nothing to search",
                status=how,
            )
        else:
            wc = worst_case_search(cfg, cfg.uncertainty, u, start_label=label, noise_seed=n_seed)
        calls += wc.engine_calls
        extra["worst_case"] = wc.to_dict()
    if beta:
        (br,), n = beta_ranges([cfg])
        calls += n
        extra["beta_range"] = {**br.to_dict(), "engine_calls": n}
    extra["box_engine_calls"] = calls
    return replace(res, extra=extra)
