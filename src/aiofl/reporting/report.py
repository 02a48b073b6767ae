"""Tables (Markdown) and the self-contained HTML report of ``aiofl reproduce``.

Every number and every finding on these pages is generated from the computed
:class:`aiofl.reporting.cases.Reproduction` (and the paper's values in
:data:`aiofl.reporting.paper.PAPER_TABLES`); nothing here states a result that was not computed
in the same run.  Extra cases (re-tuned presets, the IOFL baseline) appear as extra rows.
"""

from __future__ import annotations

import base64
import datetime as _dt
import html
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from aiofl.components.metrics import opi
from aiofl.reporting.cases import (
    CaseRun,
    Reproduction,
    itd_gain,
    observer_roots,
    output_ratio,
)
from aiofl.reporting.paper import PAPER_TABLES, SCENARIOS
from aiofl.reporting.sampling_note import sampling_paragraph, ts_max_cell

__all__ = [
    "findings",
    "html_report",
    "open_settings",
    "scenario_notes",
    "table_rows",
    "tables_markdown",
]

DASH = "—"


# ------------------------------------------------------------------------ formatting
def fmt(x: float | None, digits: int = 6) -> str:
    """A number with ``digits`` significant digits, or a dash for None."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return DASH
    if x == 0:
        return "0"
    return f"{x:.{digits}g}"


def _pct(new: float, ref: float) -> str:
    return f"{100.0 * (new - ref) / ref:+.1f} %"


def _root(z: complex) -> str:
    if abs(z.imag) < 1e-9 * max(1.0, abs(z.real)):
        return f"{z.real:.4g}"
    return f"{z.real:.4g} {'+' if z.imag >= 0 else '−'} {abs(z.imag):.4g}j"


def _cluster_roots(roots: np.ndarray, rtol: float = 1e-2) -> list[tuple[complex, int]]:
    """Group numerically split repeated roots: (mean, multiplicity), largest real part first.

    A root of multiplicity k computed by ``np.roots`` is split by about ε^(1/k) relative
    (e.g. -44.72 ± 0.049j for a 5-fold root at -44.7); roots within ``rtol`` of a group's
    first member, relative to its magnitude, are one group.
    """
    groups: list[list[complex]] = []
    for z in sorted(roots, key=lambda z: (-z.real, -z.imag)):
        for g in groups:
            if abs(z - g[0]) <= rtol * max(abs(g[0]), 1e-300):
                g.append(z)
                break
        else:
            groups.append([z])
    return [(complex(np.mean(g)), len(g)) for g in groups]


def _roots_text(roots: np.ndarray) -> str:
    parts = []
    for z, k in _cluster_roots(roots):
        if z.imag < -1e-9 * max(1.0, abs(z.real)):
            continue  # the conjugate of a pair already shown
        text = (
            _root(z)
            if abs(z.imag) < 1e-9 * max(1.0, abs(z.real))
            else _root(z).replace(" + ", " ± ")
        )
        parts.append(text + (f" (×{k})" if k > 1 else ""))
    return ", ".join(parts)


# ---------------------------------------------------------------------------- tables
TABLE_HEADER = (
    "Structure",
    "Preset",
    "ITAE paper",
    "ITAE computed",
    "ISU paper",
    "ISU computed",
    "IAU computed",
    "OPI computed",
    "ts_max [ms]",
)

CONTEXT_ROWS = (
    "y ≡ 0 (no control, for context)",
    "y ≡ r exactly (least ISU: model inversion from x*(0), for context)",
)
"""Labels of the rows that end every table (references, not results)."""


def table_rows(rep: Reproduction, scenario: int) -> list[list[str]]:
    """Rows of Table I/II/III (scenario 1/2/3): paper vs computed, plus y ≡ 0 for context."""
    rows = []
    for run in rep.scenario_runs(scenario):
        rec = run.record
        paper = (
            PAPER_TABLES[scenario].get(run.case.structure, {})
            if run.case.source == "printed"
            else {}
        )
        itae = (
            f"diverged at t = {rec['diverged_at']:.2f} s" if rec["diverged"] else fmt(rec["itae"])
        )
        rows.append(
            [
                run.case.label,
                run.case.preset,
                fmt(paper.get("itae"), 9),
                itae,
                fmt(paper.get("isu"), 9),
                fmt(rec["isu"]),
                fmt(rec["iau"]),
                fmt(rec["opi"]),
                ts_max_cell(rep.sampling.get(run.case.preset)),
            ]
        )
    triv = rep.trivial[scenario]
    w = rep.scenario_runs(scenario)[0].case.config.weights
    rows.append(
        [
            CONTEXT_ROWS[0],
            DASH,
            DASH,
            fmt(triv),
            DASH,
            "0",
            "0",
            fmt(opi(triv, 0.0, 0.0, w)),
            DASH,
        ]
    )
    # the least ISU any controller needs to keep y = r (helper C, aiofl.analysis.exact_tracking)
    from aiofl.analysis.exact_tracking import exact_tracking_cost

    ex = exact_tracking_cost(rep.scenario_runs(scenario)[0].case.config)
    rows.append(
        [
            CONTEXT_ROWS[1],
            DASH,
            DASH,
            "0",
            DASH,
            fmt(ex["isu"]),
            fmt(ex["iau"]),
            fmt(opi(0.0, ex["isu"], ex["iau"], w)),
            DASH,
        ]
    )
    return rows


def scenario_notes(rep: Reproduction, scenario: int) -> list[str]:
    """Short notes under a table, generated from the numbers in it."""
    notes = []
    triv = rep.trivial[scenario]
    paper = PAPER_TABLES[scenario]
    for run in rep.scenario_runs(scenario):
        rec = run.record
        name = f"{run.case.label} [{run.case.preset}]"
        p = paper.get(run.case.structure) if run.case.source == "printed" else None
        if rec["diverged"]:
            tail = f" The paper reports ITAE {fmt(p['itae'])}." if p else ""
            notes.append(f"{name}: the loop diverges at t = {rec['diverged_at']:.2f} s.{tail}")
            continue
        parts = [f"{name}: ITAE {fmt(rec['itae'], 5)}"]
        if p:
            parts.append(
                f"vs the paper's {fmt(p['itae'], 5)} ({_pct(rec['itae'], p['itae'])}); "
                f"ISU {fmt(rec['isu'], 4)} vs {fmt(p['isu'], 5)}"
            )
        ratio = output_ratio(run)
        rel = (rec["itae"] - triv) / triv
        if ratio is not None and ratio < 0.1:
            parts.append(
                f"the output barely moves (peak |y| over the last 5 s is {100 * ratio:.2g} % "
                "of the reference's), so its ITAE is essentially that of y ≡ 0"
            )
        elif rel >= 0:
            parts.append(f"worse than y ≡ 0 ({_pct(rec['itae'], triv)} in ITAE)")
        notes.append("; ".join(parts) + ".")
    rel = ", ".join(f"{k} {_pct(v['itae'], triv)}" for k, v in paper.items())
    msg = (
        f"y ≡ 0 scores ITAE {fmt(triv, 5)} (∫ t|r| dt over {_horizon(rep, scenario)} s); "
        f"the paper's own ITAE values relative to it: {rel}."
    )
    notes.append(msg)
    # how the re-tuned rows were tuned (budget, seed, objective), from their [tune] tables;
    # rows tuned with the same recipe share one note
    from aiofl.tuning.search import describe_tuning

    recipes: dict[str, list[str]] = {}
    for run in rep.scenario_runs(scenario):
        how = describe_tuning(run.case.config) if run.case.source == "retuned" else None
        if how:
            recipes.setdefault(how, []).append(f"{run.case.label} [{run.case.preset}]")
    for how, rows in recipes.items():
        verb = "was" if len(rows) == 1 else "were"
        notes.append(f"{_join(rows)} {verb} re-tuned with {how}.")
    return notes


def _join(items: Sequence[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def _horizon(rep: Reproduction, scenario: int) -> str:
    return fmt(rep.scenario_runs(scenario)[0].case.config.scenario.t_final, 4)


def _md_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(c.replace("|", "\\|") for c in row) + " |" for row in rows]
    return "\n".join(lines)


def tables_markdown(rep: Reproduction) -> str:
    """``tables.md``: Tables I–III, paper vs computed, with notes."""
    out = [
        "# Tables I–III: paper vs this code",
        "",
        "ITAE = ∫ t|y − r| dt and ISU = ∫ u² dt over the horizon (eq. 22); IAU = ∫ |u| dt and "
        "OPI (eq. 22, printed weights) are computed here only (the paper gives none). "
        "'paper' columns are the printed Tables I–III; 'computed' columns come from "
        "simulating the paper's printed parameters (presets `paper-s*-*`). Metrics of a run "
        "that diverged are not defined; the divergence time is given instead. The row "
        "y ≡ 0 is the trivial controller that never moves the output, for context.",
        "",
    ]
    for s, info in SCENARIOS.items():
        out += [f"## Table {info.table}: scenario {s}, {info.title}", ""]
        out += [_md_table(TABLE_HEADER, table_rows(rep, s)), ""]
        out += [f"- {n}" for n in scenario_notes(rep, s)]
        out += [""]
    para = _sampling_paragraph(rep)
    if para:
        out += ["## What the sample-time limits mean", "", " ".join(para), ""]
    return "\n".join(out)


def _sampling_paragraph(rep: Reproduction) -> list[str]:
    rows = [(r.case.label, r.case.preset, r.case.source, r.case.scenario) for r in rep.runs]
    return sampling_paragraph(rows, rep.sampling)


# -------------------------------------------------------------------------- settings
def open_settings(rep: Reproduction) -> list[tuple[str, str, str]]:
    """(setting, what the paper says, the choice made) for everything the paper leaves open.

    Values are read from the configs of this run where they are data.
    """
    s1 = rep.config("paper-s1-leso")
    s1i = rep.config("paper-s1-inleso")
    s2 = rep.config("paper-s2-leso")
    s3 = rep.config("paper-s3-leso")
    s3i = rep.config("paper-s3-inleso")
    ref = s1.scenario.reference
    sc2, sc3 = s2.scenario, s3.scenario
    w = s1.weights
    c1 = s1.controller

    def same_td_sef(a: Any, b: Any) -> bool:
        keys = [k for k in set(a.values) | set(b.values) if k.startswith(("td.", "sef."))]
        return all(a.value(k) == b.value(k) for k in keys)

    kept = all(same_td_sef(a.controller, b.controller) for a, b in ((s1, s3), (s1i, s3i)))
    x0 = "zero" if not s1.scenario.x0 else str(list(s1.scenario.x0))
    scale = ", ".join(f"{k} × {v:g}" for k, v in sc2.plant_scale.items()) or "none"
    return [
        (
            "Reference",
            "“a sinusoidal signal with frequency 2 rad/sec and amplitude of 45”",
            f"r = {math.degrees(ref.amplitude):.4g}° = {ref.amplitude:.6g} rad · "
            f"sin({ref.omega:g} t): the 45 read as degrees, in rad because y is an angle",
        ),
        (
            "Horizons",
            "20 s simulations; GA tuning with t_f = 6 s",
            f"simulation horizon {fmt(s1.scenario.t_final, 4)} s; tuning horizon 6 s "
            "(`aiofl tune`)",
        ),
        (
            "Initial state",
            "not stated",
            f"plant state {x0}; observer and differentiator states zero",
        ),
        (
            "Scenario 2 disturbance",
            "“step at t = 10 sec with amplitude 0.5 N.m and an increase 40 % in the load inertia”",
            f"τ_d = {sc2.disturbance_amplitude:g} N·m from t = {sc2.disturbance_time:g} s "
            f"through b_d of eq. (15); {scale} in the true plant only (the controller is not "
            f"told) from t = {sc2.parameter_change_time:g} s",
        ),
        (
            "Scenario 3 noise",
            "Gaussian, mean 0, variance 0.0001, at the output",
            f"variance {sc3.noise_variance:g}, held constant over {1e3 * sc3.noise_hold:g} ms, "
            f"seed {sc3.noise_seed} (numpy default_rng); only the ESO's input is noisy; "
            "metrics use the true output",
        ),
        (
            "Scenario 3 TD and SEF",
            "only the re-tuned ESO parameters are printed",
            "TD and SEF keep the scenario-1 values"
            + (" (checked: identical in the presets)" if kept else " (NOT identical: see presets)"),
        ),
        (
            "Solver",
            "MATLAB ode45 (adaptive)",
            f"fixed-step {s1.method.upper()}, dt = {s1.dt:g} s, compiled: an adaptive solver "
            "on a loop with sign() and |e|^α (α < 1) chatters and crawls "
            "(benchmarks/bench_engine.py times scipy's RK45 against the engine on these "
            "loops); rerun a preset with "
            "`aiofl simulate NAME --dt 5e-5` to check convergence in dt",
        ),
        (
            "OPI weights",
            "w = (0.6, 0.2, 0.6) (sum 1.4, although the text requires 1), N = (10, 2, 2.7)",
            f"as printed: w = ({w.w_itae:g}, {w.w_isu:g}, {w.w_iau:g}), "
            f"N = ({w.n_itae:g}, {w.n_isu:g}, {w.n_iau:g}); configurable in [metrics]",
        ),
        (
            "fal (17)",
            "inner branch e/δ^(α−1), discontinuous at |e| = δ",
            "erratum corrected: e/δ^(1−α), continuous",
        ),
        (
            "Han's TD (18)",
            "switching term r2|r2|/(2r)",
            "erratum corrected: r2|r2|/(2R)",
        ),
        (
            "NLSEF gains",
            "v = fal(e1, α1, δ1) + fal(e2, α2, δ2)",
            f"unit gains k = ({c1.value('sef.k1'):g}, {c1.value('sef.k2'):g}); "
            f"{c1.n_feedback} estimated states fed back, as in the text",
        ),
        (
            "ITAE error signal",
            "ITAE = ∫ t|y − r| dt",
            "raw reference r, not the differentiator's profile r1; true output y",
        ),
    ]


# -------------------------------------------------------------------------- findings
def findings(rep: Reproduction) -> list[str]:
    """The 'What we found' bullets, generated from the computed numbers."""
    out: list[str] = []
    printed = [r for r in rep.runs if r.case.source == "printed"]
    div = [r for r in printed if r.diverged]
    if div:
        out.append(
            f"With the printed parameters {len(div)} of {len(printed)} paper cases diverge: "
            + "; ".join(f"{r.case.preset} at t = {r.result.diverged_at:.2f} s" for r in div)
            + "."
        )
    else:
        out.append(f"None of the {len(printed)} paper cases diverges with the printed parameters.")

    # the improved TD's steady-state gain, once per distinct (a, b)
    by_ab: dict[tuple[float, float], list[CaseRun]] = {}
    for r in printed:
        if itd_gain(r.case.config) is not None:
            c = r.case.config.controller
            by_ab.setdefault((c.value("td.a"), c.value("td.b")), []).append(r)
    for (a, b), group in by_ab.items():
        gain = itd_gain(group[0].case.config) or 0.0
        seen = []
        for r in group:
            ratio = output_ratio(r)
            seen.append(
                f"{r.case.preset} {100 * ratio:.2g} %"
                if ratio is not None
                else f"{r.case.preset} diverged"
            )
        out.append(
            f"The improved TD (21) with the printed a = {a:g}, b = {b:g} settles at "
            f"(1 − a) r / b = {gain:.4f} r, so the INLESO loop is asked to track "
            f"{100 * gain:.2g} % of the reference. Measured peak |y| over the last 5 s as a "
            f"share of the reference's: {', '.join(seen)}."
        )

    # observer error polynomial (only where the ESO is in the loop: the AIOFL law)
    in_loop = [r for r in rep.runs if r.case.config.controller.law == "aiofl"]
    groups: dict[tuple[Any, ...], tuple[np.ndarray, bool, list[str]]] = {}
    for r in in_loop:
        roots = observer_roots(r.case.config)
        eso = r.case.config.controller.eso
        key = (eso, *np.round(np.sort_complex(roots), 9).view(float))
        groups.setdefault(key, (roots, eso == "linear", []))[2].append(r.case.preset)
    for roots, linear, presets in groups.values():
        names = ", ".join(presets)
        n_rhp = int(np.sum(roots.real > 0))
        what = (
            "linear-ESO error polynomial s⁵ + β1 s⁴ + … + β5 (eq. 9)"
            if linear
            else "β-polynomial of the INLESO with unit injection gain (its g(e) is "
            "nonlinear, so this is indicative only)"
        )
        verdict = (
            f"{n_rhp} root(s) in the right half-plane: the observer error is unstable on its own"
            if n_rhp and linear
            else f"{n_rhp} root(s) in the right half-plane"
            if n_rhp
            else f"all roots in the left half-plane (slowest time constant "
            f"{1.0 / max(-roots.real.max(), 1e-300):.3g} s)"
        )
        out.append(f"{names}: roots of the {what}: {_roots_text(roots)}; {verdict}.")

    # the paper's own numbers and the trivial controller
    for s, info in SCENARIOS.items():
        triv = rep.trivial[s]
        paper = PAPER_TABLES[s]
        bits = [
            f"{k} {fmt(v['itae'], 5)} ({_pct(v['itae'], triv)} vs y ≡ 0)" for k, v in paper.items()
        ]
        line = f"Table {info.table}: y ≡ 0 scores ITAE {fmt(triv, 5)}; the paper reports " + (
            ", ".join(bits)
        )
        if {"LESO", "INLESO"} <= set(paper):
            lo, inl = paper["LESO"], paper["INLESO"]
            line += (
                f"; its INLESO-vs-LESO change is {_pct(inl['itae'], lo['itae'])} in ITAE and "
                f"{_pct(inl['isu'], lo['isu'])} in ISU"
            )
        comp = {
            r.case.structure: r.record for r in rep.scenario_runs(s) if r.case.source == "printed"
        }
        if {"LESO", "INLESO"} <= set(comp):
            lo, inl = comp["LESO"], comp["INLESO"]
            if lo["diverged"] or inl["diverged"]:
                line += "; computed: not comparable (a run diverged)"
            else:
                line += (
                    f"; computed: {_pct(inl['itae'], lo['itae'])} in ITAE, "
                    f"{_pct(inl['isu'], lo['isu'])} in ISU"
                )
        out.append(line + ".")

    # extra cases
    for r in rep.runs:
        if r.case.source == "printed":
            continue
        rec = r.record
        triv = rep.trivial[r.case.scenario]
        if rec["diverged"]:
            out.append(f"{r.case.preset}: diverges at t = {rec['diverged_at']:.2f} s.")
        else:
            ratio = output_ratio(r)
            out.append(
                f"{r.case.preset} ({r.case.label}, scenario {r.case.scenario}): ITAE "
                f"{fmt(rec['itae'], 5)} ({_pct(rec['itae'], triv)} vs y ≡ 0), ISU "
                f"{fmt(rec['isu'], 4)}"
                + (f", peak |y|/|r| over the last 5 s = {ratio:.3g}" if ratio is not None else "")
                + "."
            )

    # closed-loop analysis (aiofl.analysis.linearize), grouped by verdict
    by_verdict: dict[str, list[str]] = {}
    for preset, v in rep.verdicts.items():
        mr = _max_real(v)
        tail = f" (max Re λ = {mr:.3g} 1/s)" if mr is not None else ""
        by_verdict.setdefault(str(v.get("verdict", DASH)), []).append(preset + tail)
    if by_verdict:  # empty only when there are no cases
        out.append(
            "Closed loop linearised about its operating point (aiofl.analysis.linearize): "
            + "; ".join(f"{k}: {', '.join(v)}" for k, v in by_verdict.items())
            + "."
        )
    return out


# ------------------------------------------------------------------------------ HTML
CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;max-width:1180px;
margin:2em auto;padding:0 1em;color:#1b1f24;line-height:1.45}
h1{font-size:1.6em;margin-bottom:.2em}h2{margin-top:1.8em;border-bottom:1px solid #ddd}
table{border-collapse:collapse;margin:.8em 0;font-size:.92em}
th,td{border:1px solid #ccd;padding:.3em .6em;text-align:right;vertical-align:top}
th{background:#eef2f7}td:first-child,td:nth-child(2),th:first-child{text-align:left}
tr.context td{color:#555;font-style:italic;background:#fafafa}
td.div{color:#b00020;font-weight:600}
.settings td{text-align:left}.muted{color:#666;font-size:.9em}
img{max-width:100%;border:1px solid #eee;margin:.5em 0}
ul.notes li,ul.findings li{margin:.3em 0}code{background:#f3f3f3;padding:0 .2em}
"""


def _e(s: object) -> str:
    return html.escape(str(s))


def _html_table(
    header: Sequence[str], rows: Sequence[Sequence[str]], *, cls: str = "", context_rows: int = 0
) -> str:
    """An HTML table; the last ``context_rows`` rows are styled as context (not results)."""
    parts = [f'<table class="{cls}"><thead><tr>']
    parts += [f"<th>{_e(h)}</th>" for h in header]
    parts.append("</tr></thead><tbody>")
    for i, row in enumerate(rows):
        ctx = ' class="context"' if i >= len(rows) - context_rows else ""
        parts.append(f"<tr{ctx}>")
        for cell in row:
            c = ' class="div"' if cell.startswith("diverged") else ""
            parts.append(f"<td{c}>{_e(cell)}</td>")
        parts.append("</tr>")
    parts.append("</tbody></table>")
    return "".join(parts)


def _max_real(v: Mapping[str, Any]) -> float | None:
    if v.get("max_real") is not None:
        return float(v["max_real"])
    eig = v.get("eigenvalues") or []
    return max((float(e[0]) for e in eig), default=None)


def _verdict_table(rep: Reproduction) -> str:
    rows = []
    for preset, v in rep.verdicts.items():
        mr = _max_real(v)
        sweep = v.get("verdicts_by_amplitude") or {}
        notes = list(v.get("notes") or [])
        if sweep:
            notes.append("by amplitude ε: " + ", ".join(f"{k}: {w}" for k, w in sweep.items()))
        rows.append(
            [preset, str(v.get("verdict", DASH)), fmt(mr, 4), "; ".join(str(n) for n in notes)]
        )
    return _html_table(["Case", "Verdict", "max Re λ [1/s]", "Notes"], rows, cls="settings")


def html_report(rep: Reproduction, figures: Mapping[str, bytes]) -> str:
    """``report.html``: one self-contained page (inline CSS, figures as base64 PNG).

    Parameters
    ----------
    rep
        The reproduction.
    figures
        PNG bytes by file name (``fig3.png`` ...).
    """
    now = _dt.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z")
    body = [
        "<h1>AIOFL reproduction report</h1>",
        '<p class="muted">Abdul-Adheem &amp; Ibraheem, <em>On the Active Input-Output '
        "Feedback Linearization of Single-Link Flexible Joint Manipulator: an Extended "
        f"State Observer Approach</em> (arXiv 1805.00222). Generated by "
        f"<code>aiofl reproduce</code> on {_e(now)}.</p>",
        "<p>Each table puts the paper's printed ITAE and ISU beside what this code computes "
        "from the paper's printed parameters (presets <code>paper-s*-*</code>, shown with "
        "<code>aiofl show NAME</code>). A run that diverged has no metrics; its divergence "
        "time is shown. The row <em>y ≡ 0</em> is the trivial controller that never moves "
        "the output, for context.</p>",
        "<h2>What we found</h2>",
        '<ul class="findings">' + "".join(f"<li>{_e(f)}</li>" for f in findings(rep)) + "</ul>",
    ]
    for s, info in SCENARIOS.items():
        body.append(f"<h2>Table {info.table}: scenario {s}, {_e(info.title)}</h2>")
        body.append(_html_table(TABLE_HEADER, table_rows(rep, s), context_rows=len(CONTEXT_ROWS)))
        body.append(
            '<ul class="notes">'
            + "".join(f"<li>{_e(n)}</li>" for n in scenario_notes(rep, s))
            + "</ul>"
        )
        name = f"fig{info.figure}.png"
        if name in figures:
            data = base64.b64encode(figures[name]).decode("ascii")
            body.append(
                f'<img alt="Figure {info.figure}: scenario {s}" src="data:image/png;base64,{data}">'
            )
    para = _sampling_paragraph(rep)
    if para:
        body.append("<h2>What the sample-time limits mean</h2>")
        body.append("<p>" + _e(" ".join(para)) + "</p>")
    body.append("<h2>Closed-loop linearisation per case</h2>")
    body.append(_verdict_table(rep))
    body.append("<h2>Settings the paper leaves open and the choice made</h2>")
    body.append(
        _html_table(
            ["Setting", "The paper", "Choice made"],
            [list(t) for t in open_settings(rep)],
            cls="settings",
        )
    )
    body.append("<h2>Engine settings</h2>")
    timing = ", ".join(f"{k} {v:.2f} s" for k, v in rep.timings.items())
    eng = [*rep.engine.items(), ("wall time", timing)]
    body.append(_html_table(["Setting", "Value"], [list(r) for r in eng], cls="settings"))
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        "<title>AIOFL reproduction report</title>"
        f"<style>{CSS}</style></head><body>\n" + "\n".join(body) + "\n</body></html>\n"
    )
