r"""Multi-objective tuning's outputs: the Pareto front, the chosen design, its figure.

NSGA-II (pymoo) keeps only its last population; the front reported here is taken over
**every** evaluated design of the run: the feasible designs (no diverged member, every
constraint met) that no other feasible design dominates (:math:`a` dominates :math:`b` if
:math:`F_a \le F_b` in every objective and :math:`<` in one; pymoo's
``NonDominatedSorting``), duplicates removed.

The chosen point (``best.toml``) follows ``[tune] choose``:

``"best-first-under-constraints"`` (default)
    the front design with the lowest first objective (ties: the lowest second ...);
``"knee"``
    the front design closest (Euclidean) to the ideal point after normalising each
    objective to [0, 1] over the front, on a log10 scale when the objective is positive
    on the whole front (ITAE and ISU span decades).

Both pick from the front, whose designs are all feasible: a constraint-violating design is
never chosen.  With no feasible design there is no front and no choice
(:class:`NoFeasibleDesign`).
"""

from __future__ import annotations

import csv
import io
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl.config import ConfigError

__all__ = [
    "Front",
    "NoFeasibleDesign",
    "choose",
    "front_csv",
    "front_figure",
    "front_index",
    "front_of_run",
    "front_png",
    "pareto_front",
]


class NoFeasibleDesign(ConfigError):
    """No evaluated design met the constraints (and stayed stable on every draw): the
    ``[tune]`` table asks for the impossible, reported as bad input (exit status 2)."""


@dataclass(frozen=True)
class Front:
    """The Pareto front of a run.

    Attributes
    ----------
    names
        Tuned parameters; ``values`` (n, d) their values per front design.
    objectives, constraints
        The quantities as written in the config; ``F`` (n, n_obj) and ``raw`` (n, n_con)
        their values per design.
    chosen
        Row of the chosen design; ``rule`` the rule that chose it.
    """

    names: tuple[str, ...]
    objectives: tuple[str, ...]
    constraints: tuple[str, ...]
    values: NDArray[np.float64]
    F: NDArray[np.float64]
    raw: NDArray[np.float64]
    chosen: int
    rule: str


def pareto_front(F: NDArray[np.float64], G: NDArray[np.float64]) -> NDArray[np.int64]:
    """Indices of the feasible (``G <= 0``) rows of ``F`` that no feasible row dominates."""
    from pymoo.util.nds.non_dominated_sorting import NonDominatedSorting

    feasible = np.flatnonzero((G <= 0).all(axis=1) & np.isfinite(F).all(axis=1))
    if feasible.size == 0:
        return np.zeros(0, dtype=np.int64)
    nd = NonDominatedSorting().do(F[feasible], only_non_dominated_front=True)
    return np.sort(feasible[np.asarray(nd, dtype=np.int64)])


def choose(F: NDArray[np.float64], rule: str) -> int:
    """Row of ``F`` (a front) chosen by ``rule`` (see the module docstring)."""
    if F.shape[0] == 0:
        raise NoFeasibleDesign("no feasible design to choose from")
    if rule == "knee":
        z = np.array(F, dtype=np.float64)
        pos = (z > 0).all(axis=0)
        z[:, pos] = np.log10(z[:, pos])
        span = z.max(axis=0) - z.min(axis=0)
        span = np.where(span > 0, span, 1.0)
        zn = (z - z.min(axis=0)) / span
        return int(np.argmin(np.sqrt((zn**2).sum(axis=1))))
    if rule == "best-first-under-constraints":
        return int(np.lexsort(F.T[::-1])[0])
    raise ValueError(f"choose = {rule!r}; allowed: best-first-under-constraints, knee")


def front_of_run(prep: Any, gens: Sequence[Any], values: NDArray[np.float64]) -> Any:
    """The Pareto front over every evaluated design of a run, and the chosen one.

    Parameters
    ----------
    prep
        The run (:func:`aiofl.tuning.prepared.prepare`).
    gens
        Its generations (:class:`aiofl.tuning.problem.Generation`: ``scores.F``,
        ``scores.G``, ``scores.raw`` per candidate).
    values
        The parameter values of all N evaluated candidates, (N, d).

    Returns
    -------
    Front

    Raises
    ------
    NoFeasibleDesign
        When no evaluated design is feasible.
    """
    F = np.concatenate([g.scores.F for g in gens])
    G = np.concatenate([g.scores.G for g in gens])
    raw = np.concatenate([g.scores.raw for g in gens])
    objective = prep.objective
    idx = pareto_front(F, G)
    if idx.size == 0:
        raise NoFeasibleDesign(
            f"no design of the {F.shape[0]} evaluated stayed stable on every member and met "
            f"the constraints {[c.text() for c in objective.constraints]}; loosen them or widen "
            "the search"
        )
    # one row per distinct design (a design may be evaluated twice across generations)
    _, first = np.unique(values[idx], axis=0, return_index=True)
    idx = idx[np.sort(first)]
    st = prep.settings
    front = Front(
        names=prep.space.names,
        objectives=tuple(q.text() for q in objective.objectives),
        constraints=tuple(c.text() for c in objective.constraints),
        values=values[idx],
        F=F[idx] * np.array([q.sign for q in objective.objectives]),  # margins as themselves
        raw=raw[idx],
        chosen=choose(F[idx], st.choose),  # minimisation form
        rule=st.choose,
    )
    return front


def front_index(front: Any, values: NDArray[np.float64]) -> int:
    """Row of ``values`` that is the front's chosen design (its first evaluation)."""
    hit = np.flatnonzero((values == front.values[front.chosen]).all(axis=1))
    return int(hit[0])


def _csv_float(v: float) -> str:
    return repr(float(v)) if np.isfinite(v) else ""


def front_csv(front: Front) -> str:
    """``front.csv``: one row per front design (parameters, objectives, constraint values),
    sorted by the first objective, with a ``chosen`` flag."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([*front.names, *front.objectives, *front.constraints, "chosen"])
    for i in np.argsort(front.F[:, 0], kind="stable"):
        w.writerow(
            [
                *(_csv_float(v) for v in front.values[i]),
                *(_csv_float(v) for v in front.F[i]),
                *(_csv_float(v) for v in front.raw[i]),
                int(i == front.chosen),
            ]
        )
    return buf.getvalue()


def front_figure(
    front: Front,
    title: str,
    markers: Sequence[tuple[str, float, float]] = (),
    isu_floor: float | None = None,
    notes: Sequence[str] = (),
) -> Any:
    """The figure of ``front.png`` (a matplotlib ``Figure``): objective 1 against objective 2.

    ``markers`` are labelled reference points (the paper's printed designs, the y ≡ 0
    controller); ``isu_floor`` draws the exact-tracking ISU floor as a vertical line when
    the second objective is an ISU (or a horizontal one when the first is); ``notes`` are
    printed under the title, one per line (e.g. why the paper's designs or the floor are
    not shown).  An axis is logarithmic where all its values are > 0; one holding a zero
    (the y ≡ 0 controller's ISU) is symmetric-log starting at 0, so no negative decades
    are drawn to place it.  Title, notes and axis labels are plain text, never mathtext: a
    ``$`` in a config's path or an error message cannot break the figure.

    Parameters
    ----------
    front
        The front.
    title
        The figure's title (plain text).
    markers
        ``(label, objective 2, objective 1)`` reference points.
    isu_floor
        The exact-tracking ISU floor, drawn as a line (None: not drawn).
    notes
        Lines printed under the title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.figure import Figure

    x, y = front.F[:, 1], front.F[:, 0]
    fig = Figure(figsize=(7, 4.8), dpi=110)
    ax = fig.add_subplot(1, 1, 1)
    order = np.argsort(x)
    ax.plot(x[order], y[order], "o-", ms=4, lw=1, label=f"Pareto front ({x.size} designs)")
    c = front.chosen
    ax.plot(x[c], y[c], "*", ms=14, color="C3", label=f"chosen ({front.rule})")
    xs, ys = list(x), list(y)
    for k, (label, mx, my) in enumerate(markers):
        if np.isfinite(mx) and np.isfinite(my):
            ax.plot(mx, my, "s", ms=7, color=f"C{(k + 4) % 10}", label=label)
            xs.append(mx)
            ys.append(my)
    if isu_floor is not None and np.isfinite(isu_floor):
        if front.objectives[1].split(":")[0] == "isu":
            ax.axvline(isu_floor, ls="--", color="k", lw=1, label="exact-tracking ISU floor")
            xs.append(isu_floor)
        elif front.objectives[0].split(":")[0] == "isu":
            ax.axhline(isu_floor, ls="--", color="k", lw=1, label="exact-tracking ISU floor")
            ys.append(isu_floor)
    _objective_scale(ax, "x", xs)
    _objective_scale(ax, "y", ys)
    ax.set_xlabel(front.objectives[1], parse_math=False)
    ax.set_ylabel(front.objectives[0], parse_math=False)
    # one line per note, wrapped; the text (a path, an error message) is not mathtext
    lines = [title, *(ln for note in notes for ln in textwrap.wrap(note, 110))]
    ax.set_title("\n".join(lines), fontsize=8, parse_math=False)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    return fig


def _objective_scale(ax: Any, which: str, values: Sequence[float]) -> None:
    """Log axis where every value is > 0; with a zero (and no negative value) a
    symmetric-log axis from 0, linear below the smallest positive value / 10; linear if
    a value is negative."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    set_scale, set_lim = (
        (ax.set_xscale, ax.set_xlim) if which == "x" else (ax.set_yscale, ax.set_ylim)
    )
    if v.size == 0 or v.min() < 0:
        return
    if v.min() > 0:
        set_scale("log")
        return
    pos = v[v > 0]
    set_scale("symlog", linthresh=max(1e-6, pos.min() / 10) if pos.size else 1.0)
    set_lim(0.0, None)  # a zero is the axis's start: no negative decades


def front_png(
    front: Front,
    title: str,
    markers: Sequence[tuple[str, float, float]] = (),
    isu_floor: float | None = None,
    notes: Sequence[str] = (),
) -> bytes:
    """``front.png``: :func:`front_figure` rendered to PNG bytes (Agg, no pyplot state).

    Parameters
    ----------
    front, title, markers, isu_floor, notes
        As for :func:`front_figure`.

    Returns
    -------
    bytes
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = front_figure(front, title, markers, isu_floor, notes)
    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()
