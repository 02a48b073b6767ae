"""The one-screen summary that leads the report: the paper's question answered per scenario.

The paper (Tables I–III) compares two AIOFL structures, LESO and INLESO, by ITAE in three
scenarios and gives one of them the lower ITAE.  The summary states, per scenario and from
this run's records (those written to ``metrics.json``; nothing is hard-coded):

* what the paper's printed parameter sets do here (track, stay bounded, grow, or diverge
  at t), beside the printed ITAE;
* the best design by the report's criterion (:data:`CRITERION`: the lowest nominal ITAE
  among the ESO-based designs that do not diverge) and the most robust one (the lowest
  ITAE 95 % over the model-error draws among those stable on every draw);
* whether the paper's claim holds as measured, for the printed sets and for the best
  design of each of the two structures;

and, per structure and scenario, the best design of that structure (:func:`structure_rows`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from aiofl.reporting.cases import CaseRun, Reproduction, controller_access
from aiofl.reporting.page import escape, html_table
from aiofl.reporting.paper import PAPER_TABLES, SCENARIOS
from aiofl.reporting.section import Section, md_table
from aiofl.reporting.tables import fmt, metric_units

__all__ = [
    "CRITERION",
    "ROBUST_CRITERION",
    "SummarySection",
    "best_design",
    "claim_text",
    "most_robust",
    "paper_winner",
    "structure_header",
    "structure_rows",
    "summary_header",
    "summary_intro",
    "summary_rows",
]

CRITERION = (
    "the lowest ITAE over the scenario's horizon among this run's designs that see only the "
    "measured output (ESO-based, not IOFL) and do not diverge"
)
"""How the summary picks a scenario's best design."""

ROBUST_CRITERION = (
    "the lowest ITAE 95 % over the model-error draws among the ESO-based designs stable on "
    "every draw"
)
"""How the summary picks a scenario's most robust design."""

Pick = tuple[CaseRun, dict[str, Any]]


def _candidates(rep: Reproduction, scenario: int, structure: str | None) -> list[Pick]:
    recs = rep.records_by_preset()
    return [
        (r, recs[r.case.preset])
        for r in rep.scenario_runs(scenario)
        if (structure is None or r.case.structure == structure)
        and (structure is not None or controller_access(r.case.config) is None)
        and not recs[r.case.preset]["failed"]
        and recs[r.case.preset]["itae"] is not None
    ]


def best_design(rep: Reproduction, scenario: int, structure: str | None = None) -> Pick | None:
    """The run with the lowest nominal ITAE that does not diverge (None if every one does).

    Parameters
    ----------
    rep
        The reproduction.
    scenario
        The paper scenario.
    structure
        Only designs of this structure (``"LESO"``, ``"IOFL"``, ...); None: every ESO-based
        design (:data:`CRITERION`).

    Returns
    -------
    tuple of (CaseRun, dict) or None
        The run and its metrics.json record.
    """
    cands = _candidates(rep, scenario, structure)
    return min(cands, key=lambda p: p[1]["itae"]) if cands else None


def most_robust(rep: Reproduction, scenario: int) -> Pick | None:
    """The ESO-based run with the lowest ITAE 95 % over the draws among those stable on
    every draw (:data:`ROBUST_CRITERION`); None without draws or when none qualifies."""
    cands = [
        (r, rec)
        for r, rec in _candidates(rep, scenario, None)
        if (rob := rec.get("robustness")) and rob["failed"] == 0 and rob["itae"]["q95"] is not None
    ]
    return min(cands, key=lambda p: p[1]["robustness"]["itae"]["q95"]) if cands else None


def paper_winner(scenario: int) -> tuple[str, str] | None:
    """(structure with the lower printed ITAE, the other) of the scenario's table."""
    table = PAPER_TABLES.get(scenario, {})
    if len(table) != 2:
        return None
    lo, hi = sorted(table, key=lambda k: table[k]["itae"])
    return lo, hi


def _does(run: CaseRun, rec: dict[str, Any]) -> str:
    """What a run does, briefly: ``diverges at t = 12.42 s``, ``loses the plant at t = 0.43
    s``, ``tracks (max |e| 0.002 rad)``."""
    if rec["failed"]:
        verb = "loses the plant" if rec.get("status") == "lost" else "diverges"
        return f"{verb} at t = {rec['stopped_at']:.2f} s"
    tr = rec.get("tracking") or {}
    kind, err = tr.get("behaviour"), tr.get("max_abs_error")
    what = {"tracks": "tracks", "bounded": "stays bounded", "growing": "grows"}.get(kind, "runs")
    return what + (f" (max |e| {fmt(err, 3)}{run.unit_suffix})" if err is not None else "")


def _printed(rep: Reproduction, scenario: int) -> str:
    """What the paper's printed parameter sets do in this run, with the printed ITAE."""
    recs = rep.records_by_preset()
    paper = PAPER_TABLES.get(scenario, {})
    parts = []
    for run in rep.scenario_runs(scenario):
        if run.case.source != "printed":
            continue
        rec = recs[run.case.preset]
        text = f"{run.case.structure} {_does(run, rec)}"
        if not rec["failed"]:
            p = paper.get(run.case.structure)
            ref = [f"paper {fmt(p['itae'], 4)}"] if p else []
            ref.append(f"y ≡ 0: {fmt(rep.trivial[scenario], 4)}")
            text += f", ITAE {fmt(rec['itae'], 4)} ({'; '.join(ref)})"
        parts.append(text)
    return "; ".join(parts) if parts else "not run"


def _compare(win: Pick | None, lose: Pick | None, w: str, lo: str) -> str:
    """``holds``/``fails``/``untested`` with the reason, for a pick of structure ``w`` (the
    paper's better one) and one of ``lo`` (None: it diverges)."""
    if win is None and lose is None:
        return "untested (both diverge)"
    if win is None:
        return f"fails ({w} diverges)"
    if lose is None:
        return f"holds ({lo} diverges)"
    a, b = win[1]["itae"], lose[1]["itae"]
    if a < b:
        return f"holds ({w} {fmt(a, 3)} < {lo} {fmt(b, 3)})"
    return f"fails ({lo} {fmt(b, 3)} {'<' if b < a else '='} {w} {fmt(a, 3)})"


#: a printed design whose ITAE is at least this share of y ≡ 0's is said to barely track
NEAR_TRIVIAL = 0.5


def claim_text(rep: Reproduction, scenario: int) -> str:
    """Whether the paper's claim (its structure with the lower ITAE tracks better) holds in
    this run: with the printed parameter sets, and between the best design of each
    structure (:func:`best_design`).

    A printed design that wins with an ITAE of at least :data:`NEAR_TRIVIAL` times that of
    y ≡ 0 (the controller that never moves the output) is said so.
    """
    wl = paper_winner(scenario)
    if wl is None:
        return "—"
    w, lo = wl
    recs = rep.records_by_preset()
    printed = {
        r.case.structure: (r, recs[r.case.preset])
        for r in rep.scenario_runs(scenario)
        if r.case.source == "printed"
    }

    def alive(structure: str) -> Pick | None:
        p = printed.get(structure)
        return p if p is not None and not p[1]["failed"] else None

    parts = []
    if w in printed and lo in printed:
        text = "printed sets: " + _compare(alive(w), alive(lo), w, lo)
        won = alive(w)
        triv = rep.trivial.get(scenario)
        if text.startswith("printed sets: holds") and won is not None and triv:
            share = won[1]["itae"] / triv
            if share >= NEAR_TRIVIAL:
                text = text[:-1] + f"; {w}'s ITAE is {100 * share:.0f} % of y ≡ 0's)"
        parts.append(text)
    best = _compare(best_design(rep, scenario, w), best_design(rep, scenario, lo), w, lo)
    parts.append(f"best of each structure: {best}")
    return "; ".join(parts)


def _pick_text(pick: Pick | None, *, robust: bool = False) -> str:
    if pick is None:
        return "none" if robust else "every design diverges"
    run, rec = pick
    rob = rec.get("robustness")
    if robust:
        return f"{run.case.preset}: ITAE 95 % {fmt(rob['itae']['q95'], 3)}"  # type: ignore[index]
    text = f"{run.case.preset}: ITAE {fmt(rec['itae'], 3)}, ISU {fmt(rec['isu'], 4)}"
    if rob:
        text += f"; stable on {rob['draws'] - rob['failed']}/{rob['draws']} draws"
    return text


def summary_header(rep: Reproduction) -> list[str]:
    """Columns of :func:`summary_rows`."""
    header = [
        "Scenario",
        "The paper's answer (lower ITAE)",
        "The paper's printed parameters, run here",
        "Best design (lowest ITAE)",
    ]
    if rep.robustness is not None:
        header.append("Most robust (lowest ITAE 95 %)")
    return [*header, "The paper's claim, as measured"]


def summary_rows(rep: Reproduction) -> list[list[str]]:
    """One row per scenario (see :func:`summary_header`)."""
    rows = []
    for s in sorted({r.case.scenario for r in rep.runs}):
        info = SCENARIOS[s]
        wl = paper_winner(s)
        table = PAPER_TABLES.get(s, {})
        paper = (
            f"{wl[0]}: {fmt(table[wl[0]]['itae'], 4)} < {wl[1]} {fmt(table[wl[1]]['itae'], 4)} "
            f"(Table {info.table})"
            if wl
            else "—"
        )
        row = [
            f"{s}: {info.title}",
            paper,
            _printed(rep, s),
            _pick_text(best_design(rep, s)),
        ]
        if rep.robustness is not None:
            row.append(_pick_text(most_robust(rep, s), robust=True))
        rows.append([*row, claim_text(rep, s)])
    return rows


def structure_header(rep: Reproduction) -> list[str]:
    """Columns of :func:`structure_rows`: the structure, then one per scenario."""
    return ["Best design of each structure"] + [
        f"Scenario {s}" for s in sorted({r.case.scenario for r in rep.runs})
    ]


def structure_rows(rep: Reproduction) -> list[list[str]]:
    """Per structure, per scenario: its design with the lowest nominal ITAE that does not
    diverge (``preset ITAE``), or why there is none."""
    scenarios = sorted({r.case.scenario for r in rep.runs})
    structures = list(dict.fromkeys(r.case.structure for r in rep.runs))
    rows = []
    for st in structures:
        runs = [r for r in rep.runs if r.case.structure == st]
        model = controller_access(runs[0].case.config) is not None
        cells = [st + (" (model-based)" if model else "")]
        for s in scenarios:
            pick = best_design(rep, s, st)
            if pick is not None:
                cells.append(f"{pick[0].case.preset}: {fmt(pick[1]['itae'], 3)}")
            else:
                has = any(r.case.scenario == s for r in runs)
                cells.append("every design diverges" if has else "—")
        rows.append(cells)
    return rows


def summary_intro(rep: Reproduction) -> str:
    """The question, the paper's answer and the criteria, in two sentences."""
    winners = {s: wl[0] for s in SCENARIOS if (wl := paper_winner(s))}
    if winners and len(set(winners.values())) == 1:
        (w,) = set(winners.values())
        (lo,) = {st for s in winners for st in PAPER_TABLES[s] if st != w}
        told = f"its Tables I–III give {w} the lower ITAE than {lo} in every scenario"
    else:
        told = "its Tables I–III give the lower ITAE to " + ", ".join(
            f"{w} in scenario {s}" for s, w in winners.items()
        )
    draws = (
        f"; most robust: {ROBUST_CRITERION} ({rep.robustness.draws} draws, seed "
        f"{rep.robustness.seed})"
        if rep.robustness is not None
        else ""
    )
    return (
        "The paper asks which ESO makes its AIOFL controller track better, and "
        f"{told}. Best design here: {CRITERION}{draws}. ITAE in {_itae_unit(rep)}; "
        "every design's number is a value of metrics.json (y ≡ 0: the tables' context row)."
    )


def _itae_unit(rep: Reproduction) -> str:
    unit = metric_units(rep.runs[0].case.config.plant)["itae"] if rep.runs else ""
    return unit or "the plant's units"


@dataclass
class SummarySection(Section):
    """The one-screen summary that leads the report: :func:`summary_intro`, the scenarios'
    rows (:func:`summary_rows`) and the structures' (:func:`structure_rows`)."""

    rep: Reproduction
    title = "Summary"

    def markdown(self) -> str:
        """A level-1 heading, the sentence, two tables."""
        rep = self.rep
        out = [f"# {self.title}", "", summary_intro(rep), ""]
        out += [md_table(summary_header(rep), summary_rows(rep)), ""]
        out += [md_table(structure_header(rep), structure_rows(rep)), ""]
        return "\n".join(out)

    def html(self) -> list[str]:
        """A boxed ``<section>``: the sentence, two tables, where to read on."""
        rep = self.rep
        return [
            f'<section class="summary"><h2 id="summary">{escape(self.title)}</h2>',
            f"<p>{escape(summary_intro(rep))}</p>",
            html_table(summary_header(rep), summary_rows(rep), cls="summary"),
            html_table(structure_header(rep), structure_rows(rep), cls="summary"),
            '<p class="muted">Below: Tables I–III, robustness, Pareto fronts and the '
            "linearisation; the notes on each case, Figures 3–5 and the long explanations are "
            "folded (click a ▸ line to open it).</p></section>",
        ]
