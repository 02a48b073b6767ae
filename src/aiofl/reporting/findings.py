"""The "What we found" list of the report: a handful of measured facts.

Each finding is generated from this run's records, the very records written to
``metrics.json`` (:func:`aiofl.reporting.cases.reproduction_record`), so every number in a
finding can be looked up there; nothing is hard-coded.  Explanations that need other
numbers (the improved TD's steady-state gain, the observers' roots, the margins) live in
the notes under each table and in the verdict table.

At most :data:`MAX_FINDINGS` findings, in this order:

1. divergence of the paper's printed parameters;
2. what the printed parameters give where they run, beside Tables I–III;
3. how every run ends: tracks / bounded / growing / diverged (measured over its last
   seconds, :mod:`aiofl.reporting.behaviour`);
4. where the closed-loop linearisation and the simulation disagree;
5. the least damped design among those the linearisation calls stable;
6. the IOFL baseline, and what it is given;
7. the lowest ITAE of an ESO-based design per scenario;
8. the cases the linearisation could not analyse.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from aiofl.reporting.cases import CaseRun, Reproduction, controller_access
from aiofl.reporting.page import details, item_list
from aiofl.reporting.paper import PAPER_TABLES
from aiofl.reporting.section import Section
from aiofl.reporting.tables import fmt, word_list

__all__ = ["MAX_FINDINGS", "FindingsSection", "findings"]

MAX_FINDINGS = 8


def _err(run: CaseRun, rec: dict[str, Any]) -> str:
    e = (rec.get("tracking") or {}).get("max_abs_error")
    return f"max |e| = {fmt(e, 3)}{run.unit_suffix}" if e is not None else ""


def _printed_divergence(rep: Reproduction, recs: dict[str, dict[str, Any]]) -> str | None:
    printed = [r for r in rep.runs if r.case.source == "printed"]
    if not printed:
        return None
    div = [r for r in printed if recs[r.case.preset]["failed"]]
    if not div:
        return f"None of the {len(printed)} paper cases diverges with the printed parameters."
    times = [
        f"{r.case.preset} {recs[r.case.preset]['status']} at t = "
        f"{recs[r.case.preset]['stopped_at']:.2f} s"
        for r in div
    ]
    return (
        f"With the paper's printed parameters {len(div)} of the {len(printed)} paper cases "
        f"fail (the plant lost, or the numbers diverged): {word_list(times)}."
    )


def _printed_vs_paper(rep: Reproduction, recs: dict[str, dict[str, Any]]) -> str | None:
    parts = []
    for r in rep.runs:
        rec = recs[r.case.preset]
        paper = PAPER_TABLES.get(r.case.scenario, {}).get(r.case.structure)
        if r.case.source != "printed" or rec["failed"] or not paper:
            continue
        parts.append(
            f"{r.case.preset} ITAE {fmt(rec['itae'], 5)} (paper {fmt(paper['itae'], 5)}), "
            f"ISU {fmt(rec['isu'], 5)} (paper {fmt(paper['isu'], 5)})"
        )
    if not parts:
        return None
    return "Where the printed parameters run, computed vs Tables I–III: " + "; ".join(parts) + "."


def _how_runs_end(rep: Reproduction, recs: dict[str, dict[str, Any]]) -> str | None:
    tracked = [(r, recs[r.case.preset]) for r in rep.runs if "tracking" in recs[r.case.preset]]
    if not tracked:
        return None
    groups: dict[str, list[tuple[CaseRun, dict[str, Any]]]] = {}
    for r, rec in tracked:
        groups.setdefault(rec["tracking"]["behaviour"], []).append((r, rec))
    first = tracked[0][1]["tracking"]
    windows = {rec["tracking"]["window_s"] for _, rec in tracked}
    over = f"the last {fmt(first['window_s'], 3)} s" if len(windows) == 1 else "its last seconds"
    parts = []
    if "tracks" in groups:
        g = sorted(groups["tracks"], key=lambda p: p[1]["tracking"]["max_abs_error"])
        (lo_run, lo), (hi_run, hi) = g[0], g[-1]
        lo_e, hi_e = lo["tracking"]["max_abs_error"], hi["tracking"]["max_abs_error"]
        span = (
            f"max |e| from {fmt(lo_e, 3)}{lo_run.unit_suffix} ({lo_run.case.preset}) "
            f"to {fmt(hi_e, 3)}{hi_run.unit_suffix} ({hi_run.case.preset})"
        )
        parts.append(f"{len(g)} of {len(tracked)} runs track ({span})")
    for kind, what in (
        ("bounded", "stay bounded, above that tolerance"),
        ("growing", "still grow"),
    ):
        if kind in groups:
            items = [f"{r.case.preset} ({_err(r, rec)})" for r, rec in groups[kind]]
            parts.append(f"{len(items)} {what}: {', '.join(items)}")
    if "lost" in groups:
        parts.append(f"{len(groups['lost'])} lose the plant (leave its envelope)")
    if "diverged" in groups:
        parts.append(f"{len(groups['diverged'])} diverge")
    tol = fmt(first["tolerance"], 3)
    return (
        f"Each run over {over} (tracking: max |e| ≤ {tol} × peak |r|, e = y − r): "
        + "; ".join(parts)
        + "."
    )


def _verdict_vs_simulation(rep: Reproduction, recs: dict[str, dict[str, Any]]) -> str | None:
    unstable_bounded, stable_diverged, reconciled = [], [], []
    for r in rep.runs:
        rec = recs[r.case.preset]
        lin, beh = rec.get("linearisation"), (rec.get("tracking") or {}).get("behaviour")
        if not lin or beh is None:
            continue
        mr = f"max Re λ = {fmt(lin['max_real'], 3)} 1/s" if lin["max_real"] is not None else ""
        mu = lin.get("largest_multiplier")
        if (
            lin["verdict"] == "unstable"
            and beh in ("tracks", "bounded")
            and mu is not None
            and lin.get("tracking_orbit") == "stable"
        ):
            amp = lin.get("limit_cycle_amplitude_y")
            cyc = (
                f", limit cycle {fmt(amp, 2)}{r.unit_suffix} at "
                f"{fmt(lin['limit_cycle_frequency'], 3)} rad/s"
                if amp is not None and lin.get("limit_cycle_frequency") is not None
                else ""
            )
            reconciled.append(f"{r.case.preset} (μ = {fmt(mu, 2)}{cyc})")
        elif lin["verdict"] == "unstable" and beh in ("tracks", "bounded"):
            unstable_bounded.append((r, beh, mr))
        elif lin["verdict"] == "stable" and beh in ("lost", "diverged", "growing"):
            stable_diverged.append((r, beh, mr))
    parts = []
    if reconciled:
        parts.append(
            f"{len(reconciled)} designs have an unstable equilibrium (linearisation, r held) "
            "but a stable tracking orbit (largest Floquet multiplier μ < 1); with r held they "
            f"settle on a limit cycle: {', '.join(reconciled)}"
        )
    if unstable_bounded:
        n_track = sum(1 for _, beh, _ in unstable_bounded if beh == "tracks")
        names = [f"{r.case.preset} ({mr})" for r, _, mr in unstable_bounded]
        parts.append(
            f"The closed-loop linearisation calls {len(names)} designs unstable whose "
            f"simulations stay bounded ({n_track} of them track): {', '.join(names)}; it "
            "holds only for small errors about a constant reference"
        )
    if stable_diverged:
        names = [f"{r.case.preset} ({mr})" for r, _, mr in stable_diverged]
        parts.append(
            f"it calls {len(names)} designs stable whose simulations diverge or grow: "
            + ", ".join(names)
        )
    if not parts:
        return None
    text = "; ".join(parts)
    where = " (see: Closed-loop linearisation beside the simulation)."
    return text[:1].upper() + text[1:] + where


def _least_damped(rep: Reproduction, recs: dict[str, dict[str, Any]]) -> str | None:
    stable = [
        (r, recs[r.case.preset]["linearisation"]["min_damping"])
        for r in rep.runs
        if (recs[r.case.preset].get("linearisation") or {}).get("verdict") == "stable"
        and recs[r.case.preset]["linearisation"]["min_damping"] is not None
    ]
    if not stable:
        return None
    r, z = min(stable, key=lambda p: p[1])
    return (
        f"Of the {len(stable)} designs the linearisation calls stable, the least damped is "
        f"{r.case.preset}: min ζ = {fmt(z, 3)}."
    )


def _iofl(rep: Reproduction, recs: dict[str, dict[str, Any]]) -> str | None:
    runs = [r for r in rep.runs if controller_access(r.case.config) is not None]
    if not runs:
        return None
    parts = []
    for r in runs:
        rec = recs[r.case.preset]
        if rec["failed"]:
            parts.append(f"{r.case.preset} {rec['status']} at t = {rec['stopped_at']:.2f} s")
            continue
        err = _err(r, rec)
        parts.append(f"{r.case.preset} ITAE {fmt(rec['itae'], 5)}" + (f", {err}" if err else ""))
    given = controller_access(runs[0].case.config, short=True)
    return f"The IOFL baseline ({given}, which the ESO-based designs are not): " + (
        "; ".join(parts) + "."
    )


def _best_eso(rep: Reproduction, recs: dict[str, dict[str, Any]]) -> str | None:
    parts = []
    for s in sorted({r.case.scenario for r in rep.runs}):
        cands = [
            r
            for r in rep.scenario_runs(s)
            if controller_access(r.case.config) is None and not recs[r.case.preset]["failed"]
        ]
        if cands:
            best = min(cands, key=lambda r: recs[r.case.preset]["itae"])
            parts.append(f"{best.case.preset} {fmt(recs[best.case.preset]['itae'], 5)}")
    if not parts:
        return None
    return "Lowest ITAE of an ESO-based design, per scenario: " + ", ".join(parts) + "."


def _not_analysed(rep: Reproduction, recs: dict[str, dict[str, Any]]) -> str | None:
    missing = [
        r.case.preset
        for r in rep.runs
        if (recs[r.case.preset].get("linearisation") or {}).get("verdict", "stable")
        not in ("stable", "unstable", "marginal")
    ]
    if not missing:
        return None
    return (
        f"The closed-loop linearisation gave no verdict for {word_list(missing)} (no operating "
        "point found or the analysis failed; the reason is in the verdict table)."
    )


def findings(rep: Reproduction) -> list[str]:
    """The 'What we found' list: at most :data:`MAX_FINDINGS` facts measured in this run.

    Every number in a finding is a value of the records written to ``metrics.json`` (or a
    count of them).
    """
    recs = rep.records_by_preset()
    makers: Sequence[Any] = (
        _printed_divergence,
        _printed_vs_paper,
        _how_runs_end,
        _verdict_vs_simulation,
        _least_damped,
        _iofl,
        _best_eso,
        _not_analysed,
    )
    out = [text for make in makers if (text := make(rep, recs))]
    return out[:MAX_FINDINGS]


@dataclass
class FindingsSection(Section):
    """The report's "What we found" list (:func:`findings`)."""

    rep: Reproduction
    title = "What we found"

    def markdown(self) -> str:
        """``## title`` and the findings as a list."""
        return f"## {self.title}\n\n" + "".join(f"- {f}\n" for f in findings(self.rep))

    def html(self) -> list[str]:
        """The list, folded under an ``<h2>``."""
        return [details(self.title, [item_list(findings(self.rep), "findings")], heading=True)]
