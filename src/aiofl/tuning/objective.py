r"""What a tuning run minimises: the objective, the multi-objective quantities and
constraints, their aggregates over model draws, and the scores of a population.

**One objective** (``algorithm = "ga" | "de" | "cmaes"``).  It is linear in the engine's
metrics, :math:`J = c^T m` with
:math:`m = (\mathrm{ITAE}, \mathrm{IAE}, \mathrm{ISE}, \mathrm{ISU}, \mathrm{IAU})` over
the tuning horizon (:func:`objective_coefficients`); the OPI of eq. (22) is
:math:`c = (w_1/N_1, 0, 0, w_2/N_2, w_3/N_3)` with the config's ``[metrics]`` weights.  A
member that diverges at :math:`t_d` scores :math:`P\,(2 - t_d/t_f)` (P =
``divergence_penalty``): finite, worse than any stable member with J < P, and better the
later it diverges, which steers the search towards stability (:func:`objective_values`).

**Over model draws.**  With ``[tune] robust = { draws = K, aggregate = ..., alpha = 0.9 }``
every candidate is simulated on the nominal plant and on the same K perturbed plants
(common random numbers: the draws depend on the config's ``[uncertainty]`` table and seed
only, never on the candidate; :func:`aiofl.tuning.prepared.draw_fields`), all
:math:`P\times(K+1)` members of a generation in one batched engine call.  A metric
:math:`m` of a candidate is then aggregated over its :math:`K+1` values :math:`m_0`
(nominal), :math:`m_1..m_K` (draws) by :func:`aggregate`:

``mean``
    :math:`\frac{1}{K+1}\sum_k m_k`;
``worst``
    :math:`\max_k m_k`;
``cvar``
    :math:`\mathrm{CVaR}_\alpha`, the mean of the worst :math:`\lceil(1-\alpha)(K+1)\rceil`
    values (Rockafellar & Uryasev, 2000, the discrete form of eq. (3) with equal weights
    when :math:`(1-\alpha)(K+1)` is an integer, the tail rounded up otherwise);
``nominal``
    :math:`m_0` (for objectives/constraints that name it).

A diverged member has :math:`m_k = +\infty`, so any aggregate but ``nominal`` of a
candidate with a diverged draw is :math:`+\infty`: **infeasible**.  The single-objective
algorithms (GA, DE, CMA-ES) see the finite penalty instead of :math:`+\infty`
(:func:`objective_values` with ``kind``): CMA-ES has no constraint handling in pymoo, the
penalty is ordered by how many draws stayed stable and how long the unstable ones lasted,
and the non-robust objective and checkpoints stay unchanged.

**Several objectives** (``algorithm = "nsga2"``): ``objectives`` and ``constraints`` name
quantities, ``METRIC`` or ``METRIC:AGGREGATE`` (:func:`parse_quantity`,
:func:`parse_constraint`); NSGA-II gets pymoo's ``F`` and ``G`` (:func:`objective_matrix`),
with a real constraint ``G = (diverged members) > 0``.

:class:`Objective` gathers all of it for one run (built once by
:func:`aiofl.tuning.prepared.prepare`); :meth:`Objective.score` scores a population
(:class:`Scores`).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L

if TYPE_CHECKING:  # pragma: no cover
    from aiofl.config import RunConfig

__all__ = [
    "AGGREGATES",
    "Constraint",
    "Objective",
    "Quantity",
    "Scores",
    "aggregate",
    "objective_coefficients",
    "objective_matrix",
    "objective_values",
    "parse_constraint",
    "parse_quantity",
    "quantity_values",
]

AGGREGATES = ("mean", "worst", "cvar", "nominal")
#: quantities a constraint or objective may name besides the engine metrics: the fraction
#: of stable members, and the stability margins of the loop broken at the plant input
#: (:mod:`aiofl.tuning.margins`: ``pm`` [deg], ``gm`` [dB], ``dm`` [s], ``ms``)
MARGINS = ("pm", "gm", "dm", "ms")
EXTRA_QUANTITIES = ("stable_fraction", *MARGINS)


def aggregate(values: NDArray[np.float64], kind: str, alpha: float = 0.9) -> NDArray[np.float64]:
    r"""Aggregate ``values`` (..., K+1) over the last axis (column 0 = nominal plant).

    ``mean``, ``worst`` and ``cvar`` are :func:`aiofl.uncertainty.aggregate` (non-finite
    entries, i.e. diverged members, count as :math:`+\infty`); ``nominal`` is column 0.

    Parameters
    ----------
    values
        Shape (..., K+1).
    kind
        ``"mean"``, ``"worst"``, ``"cvar"`` or ``"nominal"`` (:data:`AGGREGATES`).
    alpha
        The CVaR level.

    Returns
    -------
    ndarray
        Shape (...).
    """
    from aiofl.uncertainty import aggregate as over_draws

    v = np.asarray(values, dtype=np.float64)
    v = np.where(np.isfinite(v), v, np.inf)
    if kind == "nominal":
        return v[..., 0]
    if kind not in AGGREGATES:
        raise ValueError(f"aggregate {kind!r}; allowed: {', '.join(AGGREGATES)}")
    return over_draws(v, kind, alpha=alpha)  # type: ignore[arg-type]


# ----------------------------------------------------------------- the grammar
_NAME = r"[a-z_]+"
_QUANTITY = re.compile(rf"^\s*({_NAME})\s*(?::\s*({_NAME})\s*)?$")
_CONSTRAINT = re.compile(
    rf"^\s*({_NAME}(?:\s*:\s*{_NAME})?)\s*(<=|>=)\s*"
    r"([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*$"
)


@dataclass(frozen=True)
class Quantity:
    """A metric of a candidate, aggregated over the draws: ``itae``, ``isu:cvar`` ...

    ``aggregate`` None means the run's ``robust.aggregate`` (or the nominal plant alone
    when the run is not robust).
    """

    metric: str
    aggregate: str | None = None

    def text(self) -> str:
        """The quantity as written in the config."""
        return self.metric + (f":{self.aggregate}" if self.aggregate else "")

    @property
    def sign(self) -> float:
        """+1 for a quantity minimised as an objective, −1 for a margin that is maximised
        (``pm``, ``gm``, ``dm``: pymoo minimises their negatives)."""
        return -1.0 if self.metric in ("pm", "gm", "dm") else 1.0

    @property
    def is_margin(self) -> bool:
        """Whether the quantity is a stability margin (:mod:`aiofl.tuning.margins`)."""
        return self.metric in MARGINS


@dataclass(frozen=True)
class Constraint:
    """``quantity <= bound`` (``upper``) or ``quantity >= bound``."""

    quantity: Quantity
    upper: bool
    bound: float

    def text(self) -> str:
        """The constraint as written in the config."""
        return f"{self.quantity.text()} {'<=' if self.upper else '>='} {self.bound:g}"


def parse_quantity(text: str) -> Quantity:
    """Parse ``METRIC`` or ``METRIC:AGGREGATE`` (no eval: a regular expression).

    METRIC is one of :data:`aiofl.layout.SCORE_NAMES` (the integrals of eq. 22, then the
    step metrics and the command's figures of :mod:`aiofl.engine.response`; one that does
    not apply, or a step that never settled, counts as +inf), ``stable_fraction`` (the
    fraction of the K+1 members neither lost nor diverged) or a margin ``pm``, ``gm``, ``dm``,
    ``ms`` (of the nominal plant's linearised loop, :mod:`aiofl.tuning.margins`); those
    take no aggregate (a margin ``:nominal`` is allowed).  AGGREGATE one of ``mean``,
    ``worst``, ``cvar``, ``nominal``.  Raises ``ValueError`` naming the
    allowed values.
    """
    m = _QUANTITY.match(text) if isinstance(text, str) else None
    allowed = (*L.SCORE_NAMES, *EXTRA_QUANTITIES)
    if m is None:
        raise ValueError(
            f"{text!r} is not METRIC or METRIC:AGGREGATE; METRIC one of {', '.join(allowed)}, "
            f"AGGREGATE one of {', '.join(AGGREGATES)}"
        )
    metric, agg = m.group(1), m.group(2)
    if metric not in allowed:
        raise ValueError(f"unknown metric {metric!r} in {text!r}; allowed: {', '.join(allowed)}")
    if agg is not None and agg not in AGGREGATES:
        raise ValueError(f"unknown aggregate {agg!r} in {text!r}; allowed: {', '.join(AGGREGATES)}")
    if metric in MARGINS and agg not in (None, "nominal"):
        raise ValueError(
            f"{metric} is a margin of the nominal plant's linearised loop; it takes no "
            f"aggregate over draws (got {text!r}; allowed: {metric} or {metric}:nominal)"
        )
    if metric == "stable_fraction" and agg is not None:
        raise ValueError(f"{metric} takes no aggregate (got {text!r})")
    return Quantity(metric, agg)


def parse_constraint(text: str) -> Constraint:
    """Parse ``QUANTITY <= NUMBER`` or ``QUANTITY >= NUMBER`` (e.g. ``"isu:worst <= 15.5"``).

    A regular expression, never ``eval``: one quantity (:func:`parse_quantity`), one of
    the two comparisons, one finite decimal number.
    """
    m = _CONSTRAINT.match(text) if isinstance(text, str) else None
    if m is None:
        raise ValueError(
            f"constraint {text!r} is not 'QUANTITY <= NUMBER' or 'QUANTITY >= NUMBER' "
            "(e.g. 'isu <= 15.5', 'stable_fraction >= 1', 'itae:cvar <= 0.05')"
        )
    bound = float(m.group(3))
    if not math.isfinite(bound):
        raise ValueError(f"constraint {text!r}: the bound must be finite")
    return Constraint(parse_quantity(m.group(1)), m.group(2) == "<=", bound)


# --------------------------------------------------------------------- scoring
def _as_draws(
    metrics: NDArray[np.float64], diverged: NDArray[np.bool_]
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Metrics as (B, K+1, 5) and divergence as (B, K+1) (a non-robust run has K = 0)."""
    m = np.asarray(metrics, dtype=np.float64)
    d = np.asarray(diverged, dtype=bool)
    if m.ndim == 2:
        m, d = m[:, None, :], d[:, None]
    return m, d


def quantity_values(
    q: Quantity,
    metrics: NDArray[np.float64],
    failed: NDArray[np.bool_],
    default: str,
    alpha: float,
    margins: Mapping[str, NDArray[np.float64]] | None = None,
) -> NDArray[np.float64]:
    """Per candidate value (B,) of quantity ``q`` (``default``: the run's aggregate;
    ``margins``: :func:`aiofl.tuning.margins.candidate_margins`, needed for a margin).

    Parameters
    ----------
    q
        The quantity.
    metrics, failed
        The engine's metrics (B, K+1, metrics) and divergence flags (B, K+1) of the B
        candidates over the K+1 members.
    default, alpha
        The run's aggregate and CVaR level.
    margins
        :func:`aiofl.tuning.margins.candidate_margins` (None: a margin is refused).

    Returns
    -------
    ndarray
        Shape (B,).
    """
    m, d = _as_draws(metrics, failed)
    if q.is_margin:
        if margins is None:
            raise ValueError(f"{q.text()}: the candidates' margins were not computed")
        return np.asarray(margins[q.metric], dtype=np.float64)
    if q.metric == "stable_fraction":
        return 1.0 - d.mean(axis=1)
    j = L.SCORE_NAMES.index(q.metric)
    if j >= m.shape[-1]:
        raise ValueError(f"{q.text()}: the evaluator gives only {', '.join(L.METRIC_NAMES)}")
    col = m[:, :, j]
    col = np.where(d, np.inf, col)
    return aggregate(col, q.aggregate or default, alpha)


def objective_matrix(
    objectives: Sequence[Quantity],
    constraints: Sequence[Constraint],
    metrics: NDArray[np.float64],
    failed: NDArray[np.bool_],
    default: str,
    alpha: float,
    cap: float,
    margins: Mapping[str, NDArray[np.float64]] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """pymoo's ``F`` (B, n_obj), ``G`` (B, 1 + n_con) and the raw constraint values.

    ``F`` is in minimisation form: a maximised margin (``pm``, ``gm``, ``dm``) enters as
    its negative (:attr:`Quantity.sign`).

    ``G[:, 0]`` is the number of diverged members (> 0: infeasible); ``G[:, 1+i]`` is
    ``value - bound`` for ``<=`` and ``bound - value`` for ``>=`` (pymoo: feasible iff
    ``G <= 0``).  Infinite objectives and constraint values are clipped to ``±cap`` (NaN
    to ``cap``) so that pymoo's sorting stays well defined: a diverged candidate (+inf) is
    infeasible through ``G[:, 0]``, an infinite margin (no crossover, −inf in minimisation
    form) stays the best.

    Parameters
    ----------
    objectives, constraints
        The run's objectives and constraints.
    metrics, failed, default, alpha, margins
        As for :func:`quantity_values`.
    cap
        The clipping value.

    Returns
    -------
    F, G, raw : ndarray
    """
    _, d = _as_draws(metrics, failed)
    f = np.column_stack(
        [q.sign * quantity_values(q, metrics, failed, default, alpha, margins) for q in objectives]
    )
    raw = np.zeros((f.shape[0], len(constraints)))
    g = np.zeros((f.shape[0], 1 + len(constraints)))
    g[:, 0] = d.sum(axis=1).astype(np.float64)
    for i, c in enumerate(constraints):
        v = quantity_values(c.quantity, metrics, failed, default, alpha, margins)
        raw[:, i] = v
        viol = v - c.bound if c.upper else c.bound - v
        # an infinite margin (no crossover) satisfies any bound: -inf stays feasible
        g[:, 1 + i] = np.where(np.isnan(viol), cap, np.clip(viol, -cap, cap))
    f = np.where(np.isnan(f), cap, np.clip(f, -cap, cap))
    return f, g, raw


# -------------------------------------------------------------- one objective
def objective_coefficients(settings: Any, config: RunConfig) -> NDArray[np.float64]:
    """Coefficients c over :data:`aiofl.layout.METRIC_NAMES` with objective :math:`J = c^T m`.

    ``settings`` is the run's :class:`aiofl.tuning.space.TuneSettings` (its ``objective``:
    ``"opi"`` with ``config``'s ``[metrics]`` weights, one metric, or a table of weights).
    """
    c = np.zeros(L.N_METRIC)
    obj = settings.objective
    if obj == "opi":
        w = config.weights
        c[L.M_ITAE] = w.w_itae / w.n_itae
        c[L.M_ISU] = w.w_isu / w.n_isu
        c[L.M_IAU] = w.w_iau / w.n_iau
    elif isinstance(obj, str):
        c[L.METRIC_NAMES.index(obj)] = 1.0
    else:
        for name, weight in obj.items():
            c[L.METRIC_NAMES.index(name)] = weight
    return c


def objective_values(
    metrics: NDArray[np.float64],
    failed: NDArray[np.bool_],
    stopped_at: NDArray[np.float64],
    coefficients: NDArray[np.float64],
    penalty: float,
    t_final: float,
    kind: str | None = None,
    alpha: float = 0.9,
) -> NDArray[np.float64]:
    r"""Objective of each candidate: :math:`c^T m`, or a finite penalty if it diverged.

    ``kind`` None (one plant per candidate): :math:`J = c^T m`, or :math:`P(2 - t_d/t_f)`
    if the member diverged at :math:`t_d`.  ``kind`` an aggregate (robust runs, metrics
    over the K+1 members): :math:`J = \mathrm{agg}_k(c^T m_k)` when every member is
    stable; otherwise :math:`P\,(2 - \bar f)` with :math:`\bar f` the mean over the K+1
    members of :math:`t_{d,k}/t_f` (1 for a stable member): worse than any feasible
    :math:`J < P`, and better the more draws stay stable and the later the others
    diverge (with K = 0 the two agree).  A non-finite :math:`J` scores :math:`2P`: every
    value is finite.

    Parameters
    ----------
    metrics
        The engine's metrics, (..., metrics); with ``kind``, (B, K+1, metrics).
    failed, stopped_at
        Whether each member diverged, and when [s]; with ``kind``, (B, K+1).
    coefficients
        c, the weights of the metrics.
    penalty
        P.
    t_final
        The horizon :math:`t_f` [s].
    kind, alpha
        The aggregate over the members and its CVaR level (:func:`aggregate`); None: a
        single plant.

    Returns
    -------
    ndarray
        One value per candidate.
    """
    if kind is not None:
        m, d = _as_draws(metrics, failed)
        t = np.asarray(stopped_at, dtype=np.float64).reshape(d.shape)
        with np.errstate(all="ignore"):
            per = m[..., : L.N_METRIC] @ coefficients  # (B, K+1)
        per = np.where(d, np.inf, per)
        j = aggregate(per, kind, alpha)
        frac = np.where(d, np.clip(np.nan_to_num(t / t_final, nan=0.0), 0.0, 1.0), 1.0)
        pen = penalty * (2.0 - frac.mean(axis=1))
        j = np.where(d.any(axis=1), pen, j)
        return np.where(np.isfinite(j), j, 2.0 * penalty)
    with np.errstate(all="ignore"):
        j = metrics[..., : L.N_METRIC] @ coefficients  # the integrals (SCORE_NAMES' first)
    frac = np.clip(np.nan_to_num(stopped_at / t_final, nan=0.0), 0.0, 1.0)
    pen = penalty * (2.0 - frac)
    j = np.where(failed, pen, j)
    return np.where(np.isfinite(j), j, 2.0 * penalty)


# ---------------------------------------------------------------- the run's
@dataclass(frozen=True)
class Scores:
    """A population's scores (B candidates).

    Attributes
    ----------
    objective
        (B,): the single objective; with several objectives the first one of a feasible
        candidate and ``2 P`` otherwise (``history.csv``'s).
    diverged
        (B,): lost or diverged on any member.
    F, G
        pymoo's objectives (B, n_obj) and inequality constraints (B, n_ieq), in
        minimisation form (one objective: ``F`` is ``objective`` as a column, ``G`` empty).
    raw
        (B, n_con): the constraints' quantities as themselves (empty with one objective).
    """

    objective: NDArray[np.float64]
    diverged: NDArray[np.bool_]
    F: NDArray[np.float64]
    G: NDArray[np.float64]
    raw: NDArray[np.float64]


@dataclass(frozen=True)
class Objective:
    """What a run minimises (:meth:`from_settings`), and its scores of a population.

    Attributes
    ----------
    coefficients
        c of the single objective :math:`J = c^T m` (:func:`objective_coefficients`).
    penalty, t_final
        ``divergence_penalty`` P and the tuning horizon [s].
    kind, alpha
        The robust aggregate over the draws and its CVaR level (None: not robust).
    objectives, constraints
        NSGA-II's quantities (empty: one objective).
    """

    coefficients: NDArray[np.float64]
    penalty: float
    t_final: float
    kind: str | None = None
    alpha: float = 0.9
    objectives: tuple[Quantity, ...] = ()
    constraints: tuple[Constraint, ...] = ()

    @classmethod
    def from_settings(cls, settings: Any, config: RunConfig) -> Objective:
        """The objective of validated ``[tune]`` settings (a
        :class:`aiofl.tuning.space.TuneSettings` with its horizon resolved) on ``config``."""
        r = settings.robust
        return cls(
            coefficients=objective_coefficients(settings, config),
            penalty=settings.divergence_penalty,
            t_final=settings.t_final,
            kind=r.aggregate if r is not None else None,
            alpha=r.alpha if r is not None else 0.9,
            objectives=tuple(parse_quantity(q) for q in settings.objectives or ()),
            constraints=tuple(parse_constraint(c) for c in settings.constraints),
        )

    @property
    def n_obj(self) -> int:
        """pymoo's number of objectives."""
        return max(1, len(self.objectives))

    @property
    def n_ieq_constr(self) -> int:
        """pymoo's number of inequality constraints (the divergence one first)."""
        return 1 + len(self.constraints) if self.objectives else 0

    @property
    def needs_margins(self) -> bool:
        """Whether an objective or constraint names a stability margin."""
        named = [*self.objectives, *(c.quantity for c in self.constraints)]
        return any(q.is_margin for q in named)

    def score(
        self,
        metrics: NDArray[np.float64],
        failed: NDArray[np.bool_],
        stopped_at: NDArray[np.float64],
        margins: Mapping[str, NDArray[np.float64]] | None = None,
    ) -> Scores:
        """Score B candidates from their members' metrics.

        Parameters
        ----------
        metrics, failed, stopped_at
            The evaluation's metrics (B, [K+1,] metrics), lost-or-diverged flags and times
            (B, [K+1]).
        margins
            The candidates' margins (:func:`aiofl.tuning.margins.candidate_margins`),
            needed when :attr:`needs_margins`.

        Returns
        -------
        Scores
        """
        diverged = failed.any(axis=1) if failed.ndim == 2 else failed
        if self.objectives:
            cap = 2.0 * self.penalty
            default = self.kind or "nominal"
            F, G, raw = objective_matrix(
                self.objectives,
                self.constraints,
                metrics,
                failed,
                default,
                self.alpha,
                cap,
                margins,
            )
            feasible = (G <= 0).all(axis=1)
            obj = np.where(feasible, F[:, 0], cap)  # history: the first objective when feasible
            return Scores(obj, diverged, F, G, raw)
        obj = objective_values(
            metrics,
            failed,
            stopped_at,
            self.coefficients,
            self.penalty,
            self.t_final,
            self.kind,
            self.alpha,
        )
        empty = np.zeros((obj.shape[0], 0))
        return Scores(obj, diverged, obj[:, None], empty, empty)
