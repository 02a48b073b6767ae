r"""The shipped Pareto fronts in ``aiofl reproduce``: ITAE against ISU per structure.

The fronts are *read*, not recomputed (:mod:`aiofl.reporting.front_files`):
``aiofl/presets/fronts/s{N}-{structure}.csv`` (N in :data:`FRONT_SCENARIOS`, structure
``leso``, ``inleso`` or ``ladrc``), each with an optional companion
``s{N}-{structure}-robust.csv`` of statistics over model-error draws.

:func:`answer` states, from these numbers and this run's robustness rows of the
``frontier-*`` presets, which structure tracks best at equal control energy
(:data:`ISU_BUDGET`), nominally and under model error; :class:`FrontsSection` is the
report's section of them, :func:`front_figure` their figure.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aiofl.reporting.cases import Reproduction
from aiofl.reporting.front_files import (
    FRONT_SCENARIOS,
    STRUCTURES,
    ShippedFront,
    ShippedFronts,
)
from aiofl.reporting.page import details, escape, html_table, img, item_list
from aiofl.reporting.section import Section, md_table
from aiofl.reporting.tables import fmt, metric_units

__all__ = [
    "ISU_BUDGET",
    "FrontsSection",
    "answer",
    "front_figure",
    "front_header",
    "front_notes",
    "front_rows",
    "front_scenarios",
    "has_front_content",
]

#: the control-energy budget at which the structures are compared, per scenario
ISU_BUDGET: dict[int, float] = {1: 15.5, 3: 20.0}


# --------------------------------------------------------------------------- answers
def _label(structure: str) -> str:
    return structure.upper()


def _frontier_runs(rep: Reproduction, scenario: int) -> dict[str, Any]:
    return {
        r.case.structure.lower(): r
        for r in rep.scenario_runs(scenario)
        if r.case.source == "robust"
    }


def _best_nominal(front: ShippedFront, budget: float) -> int | None:
    ok = np.flatnonzero(front.isu <= budget)
    return int(ok[np.argmin(front.itae[ok])]) if ok.size else None


def _best_robust(front: ShippedFront, budget: float) -> tuple[int, str] | None:
    """Front row with the lowest robust ITAE (q95, else q50) within the budget among the
    rows stable on every draw (when ``stable_fraction`` is given)."""
    rb = front.robust
    key = next((k for k in ("itae_q95", "itae_q50") if k in rb), None)
    if key is None:
        return None
    isu = rb.get("isu", front.isu)
    ok = (isu <= budget) & np.isfinite(rb[key])
    if "stable_fraction" in rb:
        ok &= rb["stable_fraction"] >= 1.0
    idx = np.flatnonzero(ok)
    return (int(idx[np.argmin(rb[key][idx])]), key) if idx.size else None


def front_rows(rep: Reproduction, scenario: int) -> list[list[str]]:
    """Per structure: front size, best nominal ITAE within the budget (its ISU), the best
    robust ITAE of the companion file within the budget, and the frontier preset of this
    run (nominal ITAE, ISU, stable share, ITAE 95 % over the report's draws)."""
    sf: ShippedFronts | None = rep.fronts
    budget = ISU_BUDGET[scenario]
    presets = _frontier_runs(rep, scenario)
    table = rep.robustness
    rows = []
    for st in STRUCTURES:
        front = sf.fronts.get((scenario, st)) if sf else None
        cells = [_label(st)]
        if front is None:
            cells += ["no front file", "—", "—"]
        else:
            b = _best_nominal(front, budget)
            lo = int(np.argmin(front.isu))
            cells.append(str(len(front.itae)))
            cells.append(
                f"{fmt(front.itae[b], 3)} (ISU {fmt(front.isu[b], 4)})"
                if b is not None
                else f"none (least ISU {fmt(front.isu[lo], 4)}, ITAE {fmt(front.itae[lo], 3)})"
            )
            rb = _best_robust(front, budget)
            if rb is None:
                cells.append(
                    "no robust file"
                    if not front.robust
                    else "none within budget"
                    if {"itae_q95", "itae_q50"} & set(front.robust)
                    else "robust file has no itae_q50/itae_q95 column"
                )
            else:
                i, key = rb
                q = key.split("_")[1].replace("q", "")
                cells.append(f"{fmt(front.robust[key][i], 3)} ({q} %)")
        run = presets.get(st)
        if run is None:
            cells.append("not shipped")
        else:
            rec = run.record
            got = table.results.get(run.case.preset) if table is not None else None
            nominal = (
                f"{rec['status']} at t = {rec['stopped_at']:.2f} s"
                if rec["failed"]
                else f"ITAE {fmt(rec['itae'], 3)} at ISU {fmt(rec['isu'], 4)}"
            )
            if got is not None:
                q95 = got["itae"]["q95"]
                nominal += f"; stable {100 * got['stable_fraction']:.0f} %, ITAE 95 % " + (
                    "diverged" if q95 is None else fmt(q95, 3)
                )
            cells.append(f"{run.case.preset}: {nominal}")
        rows.append(cells)
    return rows


FRONT_HEADER_TEMPLATE = (
    "Structure",
    "front designs",
    "best nominal ITAE at ISU ≤ {b}",
    "best robust ITAE at ISU ≤ {b} (front's robust file)",
    "frontier preset (this run)",
)


def front_header(scenario: int) -> list[str]:
    """Columns of :func:`front_rows`."""
    return [h.format(b=f"{ISU_BUDGET[scenario]:g}") for h in FRONT_HEADER_TEMPLATE]


def _ranking(items: Sequence[tuple[str, float]], what: str) -> str:
    ranked = sorted(items, key=lambda p: p[1])
    head = f"{ranked[0][0]} ({what} {fmt(ranked[0][1], 3)})"
    if len(ranked) == 1:
        return f"only {head} has a number"
    rest = ", then ".join(f"{n} ({fmt(v, 3)}, ×{v / ranked[0][1]:.3g})" for n, v in ranked[1:])
    return f"{head}, then {rest}"


def _preset_sentences(rep: Reproduction, scenario: int, b: str, budget: float) -> list[str]:
    """Rankings of this run's frontier presets within the budget: nominal ITAE, and ITAE
    95 % over the report's draws."""
    presets = _frontier_runs(rep, scenario)
    if not presets:
        return []
    table = rep.robustness
    nominal, robust, outside = [], [], []
    for st, run in presets.items():
        rec = run.record
        if rec["failed"]:
            outside.append(f"{run.case.preset} ({rec['status']} at t = {rec['stopped_at']:.2f} s)")
            continue
        if rec["isu"] > budget:
            outside.append(f"{run.case.preset} (ISU {fmt(rec['isu'], 4)})")
            continue
        nominal.append((_label(st), float(rec["itae"])))
        got = table.results.get(run.case.preset) if table is not None else None
        if got is None:
            continue
        if got["itae"]["q95"] is None:
            outside.append(
                f"{run.case.preset} under model error (ITAE 95 % falls on a diverged draw; "
                f"stable {100 * got['stable_fraction']:.0f} %)"
            )
        else:
            robust.append((_label(st), float(got["itae"]["q95"])))
    out = []
    if nominal:
        out.append(
            f"Scenario {scenario}, nominal plant, the frontier presets within {b} (this run): "
            f"{_ranking(nominal, 'ITAE')}."
        )
    if robust and table is not None:
        out.append(
            f"Scenario {scenario}, ±20 % model error, the frontier presets within {b} over "
            f"this run's {table.draws} draws (seed {table.seed}): "
            f"{_ranking(robust, 'ITAE 95 %')}."
        )
    if outside:
        out.append("Not comparable at this energy or not robust: " + "; ".join(outside) + ".")
    return out


def answer(rep: Reproduction, scenario: int) -> list[str]:
    """Sentences answering, from the numbers: at ISU within the scenario's budget, which
    structure tracks best nominally and under ±20 % model error — from the shipped fronts
    (and their robust files) and from this run's rows of the ``frontier-*`` presets."""
    sf: ShippedFronts | None = rep.fronts
    budget = ISU_BUDGET[scenario]
    b = f"ISU ≤ {budget:g}"
    out = []
    fronts = {
        st: sf.fronts[(scenario, st)] for st in STRUCTURES if sf and (scenario, st) in sf.fronts
    }
    nominal = [
        (_label(st), float(f.itae[i]))
        for st, f in fronts.items()
        if (i := _best_nominal(f, budget)) is not None
    ]
    outside = [_label(st) for st, f in fronts.items() if _best_nominal(f, budget) is None]
    if nominal:
        out.append(
            f"Scenario {scenario}, nominal plant, {b}: lowest ITAE on the shipped fronts: "
            f"{_ranking(nominal, 'ITAE')}."
        )
    if outside:
        out.append(
            f"Scenario {scenario}: no design on the front of {', '.join(outside)} stays within {b}."
        )
    robust = [
        (_label(st), float(f.robust[r[1]][r[0]]), r[1])
        for st, f in fronts.items()
        if (r := _best_robust(f, budget))
    ]
    if robust:
        keys = {k for _, _, k in robust}
        what = "ITAE 95 %" if keys == {"itae_q95"} else "ITAE " + "/".join(sorted(keys))
        out.append(
            f"Scenario {scenario}, ±20 % model error ({b}, stable on every draw, the fronts' "
            "robust files): "
            f"{_ranking([(n, v) for n, v, _ in robust], what)}."
        )
    presets = _preset_sentences(rep, scenario, b, budget)
    out += presets
    if not fronts and not presets:
        return [
            f"Scenario {scenario}: neither a front file nor a frontier preset is shipped, so "
            "the structures are not compared here."
        ]
    if not robust and not any("model error" in t for t in presets):
        why = "this run skipped the draws" if rep.robustness is None else "no frontier preset"
        out.append(
            f"Scenario {scenario}: no robustness numbers within {b} (no robust front file; "
            f"{why}), so the question under model error stays open here."
        )
    return out


def has_front_content(rep: Reproduction, scenario: int) -> bool:
    """Whether a scenario has a shipped front or a frontier preset (else its table is
    left out and one sentence says so)."""
    sf: ShippedFronts | None = rep.fronts
    shipped = bool(sf) and any(k[0] == scenario for k in sf.fronts)  # type: ignore[union-attr]
    return shipped or bool(_frontier_runs(rep, scenario))


# ---------------------------------------------------------------------------- figure
_COLORS = {"leso": "C0", "inleso": "C1", "ladrc": "C2"}


def front_figure(rep: Reproduction, scenario: int, isu_floor: float | None) -> Any:
    """ITAE against ISU (log axes, in the metrics' units from the scenario's plant): one
    colour per structure's front, its chosen design ringed; this run's printed paper
    designs (squares) and frontier presets (stars); the exact-tracking ISU floor (dashed)
    and the budget (dotted).

    Parameters
    ----------
    rep
        The reproduction (its fronts and runs).
    scenario
        The scenario of :data:`FRONT_SCENARIOS`.
    isu_floor
        The exact-tracking ISU floor (None: not drawn).

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.figure import Figure

    sf: ShippedFronts | None = rep.fronts
    fig = Figure(figsize=(7.5, 5.2), layout="constrained")
    ax = fig.subplots()
    xs: list[float] = []
    ys: list[float] = []
    for st in STRUCTURES:
        f = sf.fronts.get((scenario, st)) if sf else None
        if f is None:
            continue
        keep = (f.itae > 0) & (f.isu > 0)
        o = np.argsort(f.isu[keep])
        x, y = f.isu[keep][o], f.itae[keep][o]
        ax.plot(x, y, "o-", ms=3.5, lw=1, color=_COLORS[st], label=f"{_label(st)} front ({x.size})")
        xs += list(x)
        ys += list(y)
        c = f.chosen
        if keep[c]:
            ax.plot(f.isu[c], f.itae[c], "o", ms=10, mfc="none", color=_COLORS[st])
    ax.plot([], [], "o", ms=10, mfc="none", color="0.3", label="chosen design of a front")
    not_shown = []
    for run in rep.scenario_runs(scenario):
        rec = run.record
        if run.case.source in ("printed", "robust") and rec["failed"]:
            not_shown.append(f"{run.case.preset} {rec['status']} at t = {rec['stopped_at']:.2f} s")
        if rec["failed"] or not rec["itae"] or not rec["isu"]:
            continue
        st = run.case.structure.lower()
        if run.case.source == "printed":
            mk, label = "s", f"paper {run.case.structure} (printed, this run)"
        elif run.case.source == "robust":
            mk, label = "*", f"{run.case.preset} (this run)"
        else:
            continue
        ax.plot(
            rec["isu"],
            rec["itae"],
            mk,
            ms=11 if mk == "*" else 8,
            color=_COLORS.get(st, "k"),
            mec="k",
            label=label,
        )
        xs.append(rec["isu"])
        ys.append(rec["itae"])
    if isu_floor is not None and math.isfinite(isu_floor) and isu_floor > 0:
        ax.axvline(
            isu_floor, ls="--", color="k", lw=1, label=f"exact-tracking ISU floor {isu_floor:.4g}"
        )
        xs.append(isu_floor)
    ax.axvline(
        ISU_BUDGET[scenario],
        ls=":",
        color="0.4",
        lw=1,
        label=f"ISU budget {ISU_BUDGET[scenario]:g}",
    )
    if xs and ys:
        ax.set_xscale("log")
        ax.set_yscale("log")
    runs = rep.scenario_runs(scenario)
    units = metric_units(runs[0].case.config.plant) if runs else {"isu": "", "itae": ""}
    ax.set(
        xlabel="ISU = ∫ u² dt" + (f" [{units['isu']}]" if units["isu"] else ""),
        ylabel="ITAE = ∫ t|y − r| dt" + (f" [{units['itae']}]" if units["itae"] else ""),
    )
    missing = [m for m in (sf.missing if sf else []) if m.startswith(f"s{scenario}-")]
    title = f"Scenario {scenario}: shipped Pareto fronts (ITAE vs ISU)"
    if missing:
        title += "\nnot shipped: " + ", ".join(m.removesuffix(".csv") for m in missing)
    if not_shown:
        title += "\nnot shown: " + ", ".join(not_shown)
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    return fig


def front_notes(rep: Reproduction) -> list[str]:
    """What the fronts are and where they come from (or that they are missing)."""
    sf: ShippedFronts | None = rep.fronts
    if sf is None:
        return ["The Pareto fronts were not read in this run."]
    notes = [
        f"Read from {sf.folder} (one file per scenario and structure, written by an NSGA-II "
        "run of aiofl tune with objectives ITAE and ISU; not recomputed here): every design "
        "that no other feasible design of that run beats in both. The front values are the "
        "tuner's, over its own horizon; the markers (paper designs, frontier presets, this "
        "run's metrics) and the exact-tracking ISU floor are over the scenario's horizon. "
        "Companion robust files, where shipped, give each front design's ITAE quantiles "
        "over model-error draws."
    ]
    for s in FRONT_SCENARIOS:
        horizons = {
            run.case.preset: run.case.config.raw.get("tune", {}).get("t_final")
            for run in _frontier_runs(rep, s).values()
        }
        known = {p: h for p, h in horizons.items() if h is not None}
        if known:
            t_f = rep.scenario_runs(s)[0].case.config.scenario.t_final
            notes.append(
                f"Scenario {s}: the frontier presets' [tune] tables state tuning horizons of "
                + ", ".join(f"{h:g} s ({p})" for p, h in known.items())
                + f" (the scenario's horizon is {t_f:g} s"
                + (
                    ""
                    if all(abs(h - t_f) < 1e-9 for h in known.values())
                    else "; front ITAE/ISU over a shorter horizon are smaller than the markers'"
                )
                + ")."
            )
    if sf.missing:
        names = ", ".join(m.removesuffix(".csv") for m in sf.missing)
        notes.append(f"Not shipped (yet): the fronts {names}.")
    for why in sf.errors.values():
        notes.append(f"Not read, malformed: {why}")
    return notes


def front_scenarios(rep: Reproduction) -> Mapping[int, list[str]]:
    """The answers per front scenario (:func:`answer`)."""
    return {s: answer(rep, s) for s in FRONT_SCENARIOS}


@dataclass
class FrontsSection(Section):
    """The Pareto-front section of the report: :func:`front_notes`, then per scenario of
    :data:`FRONT_SCENARIOS` its table (:func:`front_rows`, when it has a front or a
    frontier preset), its answers (:func:`answer`) and, in the page, ``fronts-s{N}.png``."""

    rep: Reproduction
    figures: Mapping[str, bytes] = field(default_factory=dict)
    title = "Pareto fronts: which structure tracks best at equal control energy?"

    def markdown(self) -> str:
        """The notes as a list, then a ``###`` part per scenario."""
        rep = self.rep
        out = [f"## {self.title}", ""]
        out += [f"- {n}" for n in front_notes(rep)]
        for s, sentences in front_scenarios(rep).items():
            out += ["", f"### Scenario {s} (ISU ≤ {ISU_BUDGET[s]:g})", ""]
            if has_front_content(rep, s):
                out += [md_table(front_header(s), front_rows(rep, s)), ""]
            out += [f"- {t}" for t in sentences]
        return "\n".join(out) + "\n"

    def html(self) -> list[str]:
        """The folded notes, then an ``<h3>`` part per scenario with its figure."""
        rep = self.rep
        body = [f"<h2>{escape(self.title)}</h2>"]
        body.append(details("Where the fronts come from", [item_list(front_notes(rep), "notes")]))
        for s, sentences in front_scenarios(rep).items():
            body.append(f"<h3>Scenario {s} (ISU ≤ {ISU_BUDGET[s]:g})</h3>")
            if has_front_content(rep, s):
                body.append(html_table(front_header(s), front_rows(rep, s), cls="settings"))
            body.append(item_list(sentences, "answers"))
            body += img(self.figures, f"fronts-s{s}.png", f"Pareto fronts, scenario {s}")
        return body
