r"""Scenario 3's noise trade-off fronts: nominal ITAE against robust ITAE at ISU ≤ 20.

The question of the paper, "which structure is best", asked for output noise: scenario 3
(sine tracking, output noise of variance 1e-4 held 1 ms) with the controller sampled at
1 ms, for the model-free LADRC and the model-assisted LADRC (``[controller.eso] model =
"nominal"``).  The fronts are *read*, not recomputed:

* ``aiofl/presets/fronts/s3-noise-{structure}.csv`` (:data:`NOISE_FRONTS`): the
  ``front.csv`` of an NSGA-II ``aiofl tune`` run of the recipe ``s3-noise-{structure}.toml``
  beside it, objectives ``itae:nominal`` and ``itae:cvar`` (CVaR of ITAE over model-error
  draws), constraints ``isu:nominal <= 20`` and ``stable_fraction >= 1``: a header of the
  tuned parameters, the objectives, the constraint values and ``chosen``, one row per
  design;
* ``s3-noise-{structure}-robust.csv``: per front design (the parameter columns first) its
  ITAE and ISU quantiles over 256 model-error draws (each draw its own noise realisation),
  ``stable_fraction`` and ``draws`` (``benchmarks/front_robustness.py``).

:func:`noise_answer` says from these numbers which observer is best under noise: the one
with the lower 95 % ITAE quantile at its front's best nominal ITAE within the budget.  A
missing file is reported as missing; a malformed one is left out with its message
(:class:`~aiofl.reporting.fronts.FrontFileError`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl.reporting.cases import Reproduction
from aiofl.reporting.front_files import (
    FoundFronts,
    FrontFile,
    FrontFileError,
    checked_rows,
    front_folder,
    parse_robust,
    read_rows,
)
from aiofl.reporting.section import TableSection
from aiofl.reporting.tables import DASH, fmt, metric_units

__all__ = [
    "NOISE_BUDGET",
    "NOISE_FRONTS",
    "NOISE_HEADER",
    "NOISE_SCENARIO",
    "NOISE_TITLE",
    "NoiseFront",
    "NoiseFrontSection",
    "NoiseFronts",
    "best_nominal",
    "load_noise_fronts",
    "lowest_q95",
    "noise_answer",
    "noise_figure",
    "noise_markers",
    "noise_notes",
    "noise_rows",
    "parse_noise_front",
    "winner",
]

#: the scenario and the control-energy budget of the comparison
NOISE_SCENARIO = 3
NOISE_BUDGET = 20.0
#: (structure as in the file names, label)
NOISE_FRONTS: tuple[tuple[str, str], ...] = (
    ("ladrc", "model-free LADRC"),
    ("assisted", "model-assisted LADRC"),
)
NOISE_TITLE = f"Noise: nominal against robust ITAE at ISU ≤ {NOISE_BUDGET:g} (scenario 3)"
_COLORS = {"ladrc": "C2", "assisted": "C3"}


@dataclass(frozen=True, kw_only=True)
class NoiseFront(FrontFile):
    """One observer's noise front, as read from its file(s)
    (:class:`~aiofl.reporting.front_files.FrontFile`): ``itae`` and ``cvar`` are the
    objectives (nominal ITAE, CVaR of ITAE over the tuner's draws), ``isu`` the nominal ISU
    and ``stable`` the tuner's stable fraction (the constraint columns); ``label`` names the
    observer.
    """

    label: str
    cvar: NDArray[np.float64]
    stable: NDArray[np.float64]

    @property
    def q95(self) -> NDArray[np.float64]:
        """The 95 % ITAE quantile over the robust file's draws: NaN where the design has
        no robust row, +inf where the quantile falls on a diverged draw (an empty cell)."""
        q = self.robust.get("itae_q95", np.full(len(self.itae), np.nan))
        has_row = np.isfinite(self.robust.get("draws", np.full(len(self.itae), np.nan)))
        return np.where(has_row & np.isnan(q), np.inf, q)

    @property
    def stable_draws(self) -> NDArray[np.float64]:
        """The share of the robust file's draws that did not diverge (NaN: no row)."""
        return self.robust.get("stable_fraction", np.full(len(self.itae), np.nan))


NoiseFronts = FoundFronts[str, NoiseFront]
"""The noise fronts found, by structure (:func:`load_noise_fronts`)."""


def _col(header: Sequence[str], want: str, name: str) -> int:
    for i, h in enumerate(header):
        if h.replace(" ", "").split("<=")[0].split(">=")[0] == want:
            return i
    raise FrontFileError(
        f"{name}: no {want!r} column; header is {', '.join(header)}; expected the front.csv "
        "of aiofl tune with objectives ['itae:nominal', 'itae:cvar'] and constraints "
        "['isu:nominal <= 20', 'stable_fraction >= 1']"
    )


def parse_noise_front(text: str, *, name: str, structure: str, label: str = "") -> NoiseFront:
    """Read a noise front's ``front.csv`` text; raises :class:`FrontFileError`.

    Checks: the columns ``itae:nominal``, ``itae:cvar``, ``isu:nominal <= ...``,
    ``stable_fraction >= ...`` and a last column ``chosen``; the parameters are the columns
    before ``itae:nominal``; every row numeric, finite parameters, ITAE > 0, ISU >= 0, one
    row chosen.

    Parameters
    ----------
    text
        The file's text.
    name
        The file's name, for messages.
    structure, label
        The controller structure, and the front's label (default: the structure).

    Returns
    -------
    NoiseFront
    """
    header, body = read_rows(text, name)
    if header[-1] != "chosen":
        raise FrontFileError(f"{name}: the last column must be 'chosen', got {header[-1]!r}")
    i_itae, i_cvar = _col(header, "itae:nominal", name), _col(header, "itae:cvar", name)
    i_isu, i_st = _col(header, "isu:nominal", name), _col(header, "stable_fraction", name)
    if i_itae == 0:
        raise FrontFileError(f"{name}: no parameter columns before 'itae:nominal'")
    columns = {"itae": i_itae, "cvar": i_cvar, "isu": i_isu, "stable": i_st}
    values, cols, chosen = checked_rows(header, body, name, i_itae, columns)
    return NoiseFront(
        structure=structure,
        label=label or structure,
        path=name,
        names=tuple(header[:i_itae]),
        values=values,
        **cols,  # type: ignore[arg-type]
        chosen=chosen,
    )


def load_noise_fronts(folder: str | Path | None = None) -> NoiseFronts:
    """Read every ``s3-noise-{structure}.csv`` (and ``-robust.csv``) in ``folder``
    (default: the package's ``presets/fronts``); missing files are listed, malformed ones
    left out with their message."""
    base, shown = front_folder(folder)
    fronts: dict[str, NoiseFront] = {}
    missing: list[str] = []
    errors: dict[str, str] = {}
    for st, label in NOISE_FRONTS:
        f = base / f"s{NOISE_SCENARIO}-noise-{st}.csv"
        if not f.is_file():
            missing.append(f.name)
            continue
        try:
            front = parse_noise_front(
                f.read_text(encoding="utf-8"), name=f.name, structure=st, label=label
            )
        except (FrontFileError, UnicodeDecodeError) as exc:
            errors[f.name] = str(exc)
            continue
        r = base / f"s{NOISE_SCENARIO}-noise-{st}-robust.csv"
        if r.is_file():
            try:
                text = r.read_text(encoding="utf-8")
                front = parse_robust(text, front, name=r.name, required=("itae_q95",))
            except (FrontFileError, UnicodeDecodeError) as exc:
                errors[r.name] = str(exc)
        else:
            missing.append(r.name)
        fronts[st] = front
    return NoiseFronts(fronts=fronts, missing=missing, folder=shown, errors=errors)


# --------------------------------------------------------------------------- answers
def _feasible(front: NoiseFront) -> NDArray[np.bool_]:
    return (front.isu <= NOISE_BUDGET) & (front.stable >= 1.0) & np.isfinite(front.itae)


def best_nominal(front: NoiseFront) -> int | None:
    """The row of lowest nominal ITAE within the budget (stable on the tuner's draws)."""
    ok = np.flatnonzero(_feasible(front))
    return int(ok[np.argmin(front.itae[ok])]) if ok.size else None


def lowest_q95(front: NoiseFront) -> int | None:
    """The row of lowest (finite) ITAE 95 % over the robust file's draws within the budget
    (a design may diverge on up to 5 % of the draws and still have one)."""
    idx = np.flatnonzero(_feasible(front) & np.isfinite(front.q95))
    return int(idx[np.argmin(front.q95[idx])]) if idx.size else None


def winner(nf: NoiseFronts) -> str | None:
    """The structure with the lower ITAE 95 % at its front's best nominal design (a
    quantile on a diverged draw counts as +inf); None when fewer than two fronts have that
    number or neither is finite."""
    at = {
        st: float(f.q95[i])
        for st, f in nf.fronts.items()
        if (i := best_nominal(f)) is not None and not math.isnan(f.q95[i])
    }
    if len(at) < 2 or not any(math.isfinite(v) for v in at.values()):
        return None
    return min(at, key=at.__getitem__)


def _q(v: float) -> str:
    """An ITAE 95 % as text ("diverged" where it falls on a diverged draw)."""
    return "on a diverged draw" if v == math.inf else fmt(v, 3)


def _stable(f: NoiseFront, i: int) -> str:
    v = f.stable_draws[i]
    return "" if math.isnan(v) else f" (stable on {100 * v:.3g} % of the draws)"


def _draws(front: NoiseFront) -> str:
    d = front.robust.get("draws")
    ok = d[np.isfinite(d)] if d is not None else np.array([])
    return f"{int(ok[0])}" if ok.size else "the robust file's"


def noise_answer(nf: NoiseFronts | None) -> list[str]:
    """Sentences answering which observer is best under noise, from the files' numbers."""
    b = f"ISU ≤ {NOISE_BUDGET:g}"
    if nf is None or not nf.fronts:
        return [f"No noise front is shipped, so the observers are not compared at {b} here."]
    out = []
    parts = []
    for f in nf.fronts.values():
        i, j = best_nominal(f), lowest_q95(f)
        if i is None:
            parts.append(f"{f.label}: no design of its front within {b}")
            continue
        txt = (
            f"{f.label}: best nominal ITAE {fmt(f.itae[i], 3)} (ISU {fmt(f.isu[i], 3)}), "
            f"ITAE 95 % there {_q(f.q95[i])}{_stable(f, i)}"
        )
        txt += (
            f"; lowest ITAE 95 % on its front {_q(f.q95[j])}{_stable(f, j)} at nominal "
            f"ITAE {fmt(f.itae[j], 3)}"
            if j is not None
            else "; no design of its front has a finite ITAE 95 %"
        )
        parts.append(txt)
    w = winner(nf)
    if w is not None:
        f = nf.fronts[w]
        others = [o for o in nf.fronts.values() if o is not f]
        i = best_nominal(f)
        assert i is not None
        o = others[0]
        k = best_nominal(o)
        assert k is not None
        ratio = float(o.q95[k] / f.q95[i])
        than = (
            f"{ratio:.3g}× lower than the {o.label}'s {fmt(o.q95[k], 3)}"
            if math.isfinite(ratio)
            else f"where the {o.label}'s falls on a diverged draw"
        )
        out.append(
            f"Under noise (scenario 3, sampled at 1 ms, {b}), the {f.label} is best: at its "
            f"front's best nominal ITAE ({fmt(f.itae[i], 3)}) its ITAE 95 % over "
            f"{_draws(f)} ±20 % model-error draws is {fmt(f.q95[i], 3)}{_stable(f, i)}, "
            f"{than}{_stable(o, k)} at its best nominal ITAE ({fmt(o.itae[k], 3)})."
        )
    else:
        out.append(
            f"Under noise (scenario 3, {b}) the observers cannot be ranked here: a front, its "
            "robust file or a design within the budget is missing."
        )
    out.append("Per front: " + "; ".join(parts) + ".")
    return out


NOISE_HEADER = (
    "Observer",
    "front designs",
    f"best nominal ITAE at ISU ≤ {NOISE_BUDGET:g} (ISU)",
    "ITAE 95 % there (stable share of the draws)",
    "lowest ITAE 95 % (its nominal ITAE)",
    "chosen design: nominal ITAE, ITAE 95 %",
)


def noise_rows(rep: Reproduction) -> list[list[str]]:
    """One row per observer (:data:`NOISE_HEADER`)."""
    nf: NoiseFronts | None = getattr(rep, "noise_fronts", None)
    rows = []
    for st, label in NOISE_FRONTS:
        f = nf.fronts.get(st) if nf else None
        if f is None:
            rows.append([label, "no front file", "—", "—", "—", "—"])
            continue
        i, j, c = best_nominal(f), lowest_q95(f), f.chosen
        rows.append(
            [
                label,
                str(len(f.itae)),
                DASH if i is None else f"{fmt(f.itae[i], 3)} ({fmt(f.isu[i], 3)})",
                DASH if i is None else f"{_q(f.q95[i])} ({_pct(f.stable_draws[i])})",
                DASH if j is None else f"{_q(f.q95[j])} ({fmt(f.itae[j], 3)})",
                f"{fmt(f.itae[c], 3)}, {_q(f.q95[c])}",
            ]
        )
    return rows


def _pct(v: float) -> str:
    return DASH if math.isnan(v) else f"{100 * v:.1f} %"


def noise_markers(rep: Reproduction) -> list[tuple[str, float, float | None, float]]:
    """This run's shipped scenario-3 designs to mark (frontier, assisted, retuned within
    the budget): ``(preset, nominal ITAE, ITAE 95 % over this run's draws or None, ISU)``;
    diverged ones and those over the budget are left out."""
    table = rep.robustness
    out = []
    for run in rep.scenario_runs(NOISE_SCENARIO):
        if run.case.source not in ("robust", "assisted", "retuned"):
            continue
        rec = run.record
        if rec["failed"] or not rec["isu"] or rec["isu"] > NOISE_BUDGET:
            continue
        got = table.results.get(run.case.preset) if table is not None else None
        q95 = None if got is None else got["itae"]["q95"]
        out.append((run.case.preset, float(rec["itae"]), q95, float(rec["isu"])))
    return out


def noise_figure(rep: Reproduction) -> Any:
    """Nominal ITAE (x) against ITAE 95 % over the robust file's draws (y), log axes: one
    colour per observer's front (designs with a finite 95 % quantile), its best nominal
    design within the budget ringed; this run's shipped designs as stars (y: ITAE 95 % over
    the report's own draws).  A matplotlib ``Figure``."""
    from matplotlib.figure import Figure

    nf: NoiseFronts | None = getattr(rep, "noise_fronts", None)
    fig = Figure(figsize=(7.5, 5.2), layout="constrained")
    ax = fig.subplots()
    drawn = False
    for st, label in NOISE_FRONTS:
        f = nf.fronts.get(st) if nf else None
        if f is None:
            continue
        keep = _feasible(f) & np.isfinite(f.q95) & (f.q95 > 0)
        o = np.argsort(f.itae[keep])
        x, y = f.itae[keep][o], f.q95[keep][o]
        n = len(f.itae)
        shown = f"{x.size} designs" if x.size == n else f"{x.size} of {n}: a finite ITAE 95 %"
        ax.plot(x, y, "o", ms=4, color=_COLORS[st], label=f"{label} front ({shown})")
        drawn = drawn or bool(x.size)
        i = best_nominal(f)
        if i is not None and keep[i]:
            ax.plot(f.itae[i], f.q95[i], "o", ms=11, mfc="none", color=_COLORS[st])
    ax.plot([], [], "o", ms=11, mfc="none", color="0.3", label="best nominal ITAE of a front")
    table = rep.robustness
    not_shown = []
    for k, (preset, itae, q95, _isu) in enumerate(noise_markers(rep)):
        if q95 is None or not (q95 > 0 and itae > 0):
            not_shown.append(preset)
            continue
        ax.plot(itae, q95, "*", ms=11, mec="k", color=f"C{(k + 4) % 10}", label=preset)
        drawn = True
    if drawn:
        ax.set_xscale("log")
        ax.set_yscale("log")
    runs = rep.scenario_runs(NOISE_SCENARIO)
    u = metric_units(runs[0].case.config.plant)["itae"] if runs else ""
    unit = f" [{u}]" if u else ""
    ax.set(
        xlabel=f"nominal ITAE (fronts: mean over 2 noise realisations; stars: seed 0){unit}",
        ylabel=f"ITAE 95 % over ±20 % model-error draws{unit}",
    )
    title = f"Scenario 3 under noise: nominal against robust ITAE at ISU ≤ {NOISE_BUDGET:g}"
    if table is not None:
        title += f"\nstars: this run's designs over its {table.draws} draws (seed {table.seed})"
    if not_shown:
        title += "\nno 95 % over the draws (skipped or diverged): " + ", ".join(not_shown)
    missing = [m for m in (nf.missing if nf else []) if not m.endswith("-robust.csv")]
    if missing:
        title += "\nnot shipped: " + ", ".join(missing)
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    return fig


def noise_notes(rep: Reproduction) -> list[str]:
    """Where the noise fronts come from and how the markers differ from them."""
    nf: NoiseFronts | None = getattr(rep, "noise_fronts", None)
    if nf is None:
        return ["The noise fronts were not read in this run."]
    notes = [
        f"Read from {nf.folder} (s3-noise-ladrc and s3-noise-assisted; not recomputed here): "
        "the fronts of two NSGA-II runs of aiofl tune on scenario 3 with the controller "
        "sampled at 1 ms and the output noise (variance 1e-4, held 1 ms), objectives the "
        "nominal ITAE and the CVaR (α = 0.9) of ITAE over 16 draws of ±20 % on J_l, K_s, "
        f"R_m, J_h, each over 2 noise realisations, constraints nominal ISU ≤ {NOISE_BUDGET:g} "
        "and no divergence on any draw; model-free LADRC (observer gains only, tuned "
        "ω0, ωc, b0) and model-assisted LADRC (the nominal model in the observer and the "
        "law, tuned ω0, ωc). The y axis of the fronts is each design's ITAE 95 % over the "
        "companion files' draws (256, seed 0, each its own noise realisation), the x axis "
        "its nominal ITAE as the tuner scored it: the mean over its 2 noise realisations "
        "(seed 0 and the next); the nominal ISU likewise.",
    ]
    table = rep.robustness
    if table is not None:
        notes.append(
            f"The stars are this run's shipped scenario-3 designs within ISU ≤ "
            f"{NOISE_BUDGET:g}: nominal ITAE of this run (noise seed 0), ITAE 95 % over this run's "
            f"{table.draws} draws (seed {table.seed}) — other draws than the fronts', so "
            "stars and fronts compare to within the draws' sampling spread — each run as "
            "its preset ships it (the frontier and retuned designs continuous, not sampled "
            "at 1 ms like the fronts). Designs whose ITAE 95 % falls on a diverged draw "
            "are named in the figure's title instead."
        )
    if nf.missing:
        notes.append("Not shipped (yet): " + ", ".join(nf.missing) + ".")
    for why in nf.errors.values():
        notes.append(f"Not read, malformed: {why}")
    return notes


@dataclass
class NoiseFrontSection(TableSection):
    """The noise-front section of the report: the answer (:func:`noise_answer`), the table
    (:func:`noise_rows`), the notes (:func:`noise_notes`) and, in the page,
    ``noise-front-s3.png``."""

    rep: Reproduction
    figures: Mapping[str, bytes] = field(default_factory=dict)
    title = NOISE_TITLE
    header = NOISE_HEADER
    notes_summary = "Where the noise fronts come from"
    shown_without_rows = True
    table_class = "settings"
    figure = ("noise-front-s3.png", "Noise fronts, scenario 3")

    def lead(self) -> list[str]:
        """:func:`noise_answer`."""
        return noise_answer(getattr(self.rep, "noise_fronts", None))

    def rows(self) -> list[list[str]]:
        """:func:`noise_rows`."""
        return noise_rows(self.rep)

    def notes(self) -> list[str]:
        """:func:`noise_notes`."""
        return noise_notes(self.rep)
