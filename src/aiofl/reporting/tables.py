"""Markdown tables and notes of ``aiofl reproduce``: Tables I–III, the verdicts, the settings.

Every number here is generated from the computed :class:`aiofl.reporting.cases.Reproduction`
(and the paper's values in :data:`aiofl.reporting.paper.PAPER_TABLES`).  Units are the
plant's own (:attr:`aiofl.plants.base.Plant.output_unit`, ``input_unit``).  The HTML page
(:mod:`aiofl.reporting.html`) renders the same rows.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from aiofl.components.metrics import opi
from aiofl.plants.base import Plant
from aiofl.reporting.behaviour import analysis_numbers, reconcile, simulation_text
from aiofl.reporting.cases import (
    CaseRun,
    Reproduction,
    controller_access,
    itd_gain,
    model_assistance,
    observer_roots,
    output_ratio,
)
from aiofl.reporting.paper import PAPER_TABLES, SCENARIOS
from aiofl.reporting.sampling_note import sampling_paragraph, ts_max_cell

__all__ = [
    "CONTEXT_ROWS",
    "DASH",
    "VERDICT_HEADER",
    "case_label",
    "fmt",
    "metric_units",
    "open_settings",
    "scenario_notes",
    "table_header",
    "table_rows",
    "tables_markdown",
    "verdict_rows",
]

DASH = "—"


# ------------------------------------------------------------------------ formatting
def fmt(x: float | None, digits: int = 6) -> str:
    """A number with ``digits`` significant digits, a dash for None, ∞ for infinity."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return DASH
    if isinstance(x, float) and math.isinf(x):
        return "∞" if x > 0 else "−∞"
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


def _join(items: Sequence[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def _pow(unit: str, k: int) -> str:
    """``unit`` to the power k (parenthesised when compound): V² , (m^3/s)²."""
    if k == 1:
        return unit
    base = f"({unit})" if any(c in unit for c in "/·^ *") else unit
    return base + {2: "²", 3: "³"}.get(k, f"^{k}")


def metric_units(plant: Plant) -> dict[str, str]:
    """Units of the metrics of eq. (22) for a plant: ITAE = ∫ t|e| dt in [y]·s², ISU = ∫ u² dt
    in [u]²·s, IAU = ∫ |u| dt in [u]·s (empty where the plant declares no unit)."""
    y, u = plant.output_unit, plant.input_unit
    known = {"y": bool(y and y != "-"), "u": bool(u and u != "-")}
    return {
        "itae": f"{y}·s²" if known["y"] else "",
        "isu": f"{_pow(u, 2)}·s" if known["u"] else "",
        "iau": f"{u}·s" if known["u"] else "",
    }


def _with_unit(text: str, unit: str) -> str:
    return f"{text} [{unit}]" if unit else text


def case_label(run: CaseRun) -> str:
    """Row label; an IOFL or model-assisted row says what its law is given."""
    given = controller_access(run.case.config) or model_assistance(run.case.config)
    return run.case.label + (f"; {given}" if given else "")


# ---------------------------------------------------------------------------- tables
CONTEXT_ROWS = (
    "y ≡ 0 (no control, for context)",
    "y ≡ r exactly (least ISU: model inversion from x*(0), for context)",
)
"""Labels of the rows that end every table (references, not results)."""


def table_header(rep: Reproduction, scenario: int) -> list[str]:
    """Columns of Table I/II/III, with the metrics' units from the scenario's plant."""
    units = metric_units(rep.scenario_runs(scenario)[0].case.config.plant)
    return [
        "Structure",
        "Preset",
        _with_unit("ITAE paper", units["itae"]),
        _with_unit("ITAE computed", units["itae"]),
        _with_unit("ISU paper", units["isu"]),
        _with_unit("ISU computed", units["isu"]),
        _with_unit("IAU computed", units["iau"]),
        "OPI computed",
        "ts_max [ms]",
    ]


def table_rows(rep: Reproduction, scenario: int) -> list[list[str]]:
    """Rows of Table I/II/III (scenario 1/2/3): paper vs computed, plus context rows."""
    rows = []
    for run in rep.scenario_runs(scenario):
        rec = run.record
        paper = (
            PAPER_TABLES[scenario].get(run.case.structure, {})
            if run.case.source == "printed"
            else {}
        )
        itae = (
            f"{rec['status']} at t = {rec['stopped_at']:.2f} s"
            if rec["failed"]
            else fmt(rec["itae"])
        )
        rows.append(
            [
                case_label(run),
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
        [CONTEXT_ROWS[0], DASH, DASH, fmt(triv), DASH, "0", "0", fmt(opi(triv, 0, 0, w)), DASH]
    )
    # the least ISU any controller needs to keep y = r (aiofl.analysis.exact_tracking)
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


def _observer_note(run: CaseRun) -> str | None:
    """The ESO's error polynomial (eq. 9) of a printed case, or of any case with a root in
    the right half-plane."""
    cfg = run.case.config
    if cfg.controller.law != "aiofl":
        return None
    roots = observer_roots(cfg)
    n_rhp = int(np.sum(roots.real > 0))
    if run.case.source != "printed" and not n_rhp:
        return None
    linear = cfg.controller.eso == "linear"
    what = (
        "linear-ESO error polynomial s^(ρ+1) + β1 s^ρ + … + β(ρ+1) (eq. 9)"
        if linear
        else "INLESO β-polynomial with unit injection gain (g(e) is nonlinear: indicative only)"
    )
    verdict = (
        f"{n_rhp} root(s) in the right half-plane"
        + (": the observer error is unstable on its own" if linear else "")
        if n_rhp
        else "all roots in the left half-plane"
    )
    return f"roots of its {what}: {_roots_text(roots)}; {verdict}"


def _itd_note(run: CaseRun) -> str | None:
    gain = itd_gain(run.case.config)
    if gain is None or abs(gain - 1.0) < 1e-3:
        return None
    c = run.case.config.controller
    return (
        f"its improved TD (21) with a = {c.value('td.a'):g}, b = {c.value('td.b'):g} settles "
        f"at (1 − a) r / b = {gain:.4f} r, so the loop is asked to track {100 * gain:.2g} % "
        "of the reference"
    )


def scenario_notes(rep: Reproduction, scenario: int) -> list[str]:
    """Short notes under a table, generated from the numbers in it."""
    notes = []
    triv = rep.trivial[scenario]
    paper = PAPER_TABLES[scenario]
    for run in rep.scenario_runs(scenario):
        rec = run.record
        name = f"{run.case.label} [{run.case.preset}]"
        p = paper.get(run.case.structure) if run.case.source == "printed" else None
        extra = [n for n in (_itd_note(run), _observer_note(run)) if n]
        if rec["failed"]:
            tail = f" The paper reports ITAE {fmt(p['itae'])}." if p else ""
            more = "".join(f" {n[0].upper()}{n[1:]}." for n in extra)
            at = f"{rec['stopped_at']:.2f}"
            what = "the plant is lost" if rec["status"] == "lost" else "the loop diverges"
            notes.append(f"{name}: {what} at t = {at} s.{tail}{more}")
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
        parts.append(simulation_text(run.behaviour, run.unit))
        parts += extra
        notes.append("; ".join(parts) + ".")
    rel_paper = ", ".join(f"{k} {_pct(v['itae'], triv)}" for k, v in paper.items())
    notes.append(
        f"y ≡ 0 scores ITAE {fmt(triv, 5)} (∫ t|r| dt over {_horizon(rep, scenario)} s); "
        f"the paper's own ITAE values relative to it: {rel_paper}."
    )
    # how the re-tuned rows were tuned, from their [tune] tables; one note per recipe
    from aiofl.tuning.search import describe_tuning

    recipes: dict[tuple[str, str], list[str]] = {}
    for run in rep.scenario_runs(scenario):
        tuned = run.case.source in ("retuned", "robust")
        how = describe_tuning(run.case.config) if tuned else None
        if how:
            what = "re-tuned" if run.case.source == "retuned" else "tuned"
            recipes.setdefault((how, what), []).append(f"{run.case.label} [{run.case.preset}]")
    for (how, what), rows in recipes.items():
        verb = "was" if len(rows) == 1 else "were"
        notes.append(f"{_join(rows)} {verb} {what} with {how}.")
    return notes


def _horizon(rep: Reproduction, scenario: int) -> str:
    return fmt(rep.scenario_runs(scenario)[0].case.config.scenario.t_final, 4)


# ----------------------------------------------------------------- verdict vs run
VERDICT_HEADER = (
    "Case",
    "Verdict (tracking orbit; equilibrium)",
    "max Re λ [1/s]",
    "min ζ",
    "GM [dB]",
    "PM [°]",
    "DM [s]",
    "Ms",
    "Reconciled verdict beside the simulation (measured from the trajectory)",
)


def verdict_rows(rep: Reproduction) -> list[list[str]]:
    """One row per case: the closed-loop verdict, damping and margins (a dash where the
    analysis gives none), and the sentence reconciling it with the simulation."""
    rows = []
    for run in rep.runs:
        v = rep.verdicts.get(run.case.preset, {})
        n = analysis_numbers(v)
        verdict = n["verdict"] if n["verdict"] in ("stable", "unstable", "marginal") else "—"
        short = (v.get("orbit") or {}).get("short")
        if short and verdict != "—":
            verdict = f"{short} (equilibrium {verdict})" if "equilibrium" not in short else short
        elif short:
            verdict = short
        given = controller_access(run.case.config)
        rows.append(
            [
                run.case.preset + (f" ({given})" if given else ""),
                verdict,
                fmt(n["max_real"], 4),
                fmt(n["min_damping"], 3),
                fmt(_raw(v, "gain_margin_db"), 3),
                fmt(_raw(v, "phase_margin_deg"), 3),
                fmt(_raw(v, "delay_margin_s"), 3),
                fmt(_raw(v, "ms"), 3),
                reconcile(v, run.behaviour, run.unit),
            ]
        )
    return rows


def _raw(v: Mapping[str, Any], key: str) -> float | None:
    """A margin as the analysis gave it (infinity kept, shown as ∞)."""
    val = v.get(key)
    return None if val is None else float(val)


def verdict_notes(rep: Reproduction) -> list[tuple[str, str]]:
    """(case, how the non-smooth elements were linearised and the ε sweep) per case."""
    out = []
    for preset, v in rep.verdicts.items():
        notes = [str(x) for x in v.get("notes") or []]
        sweep = v.get("verdicts_by_amplitude") or {}
        if sweep:
            notes.append("by amplitude ε: " + ", ".join(f"{k}: {w}" for k, w in sweep.items()))
        if notes:
            out.append((preset, "; ".join(notes)))
    return out


# ------------------------------------------------------------------------ Markdown
def _md_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(c.replace("|", "\\|") for c in row) + " |" for row in rows]
    return "\n".join(lines)


def tables_markdown(rep: Reproduction) -> str:
    """``tables.md``: Tables I–III, paper vs computed, with notes; verdicts beside runs."""
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
        out += [_md_table(table_header(rep, s), table_rows(rep, s)), ""]
        out += [f"- {n}" for n in scenario_notes(rep, s)]
        out += [""]
    para = sampling_text(rep)
    if para:
        out += ["## What the sample-time limits mean", "", para, ""]
    out += ["## Closed-loop linearisation beside the simulation", "", VERDICT_INTRO, ""]
    out += [_md_table(VERDICT_HEADER, verdict_rows(rep)), ""]
    return "\n".join(out)


def sampling_text(rep: Reproduction) -> str:
    """The paragraph on the designs' sample-time limits (empty when none were computed)."""
    rows = [(r.case.label, r.case.preset, r.case.source, r.case.scenario) for r in rep.runs]
    return " ".join(sampling_paragraph(rows, rep.sampling))


VERDICT_INTRO = (
    "One reconciled verdict per design (aiofl.analysis.orbit): the tracking orbit's largest "
    "Floquet multiplier μ over one reference period (variational equation along the periodic "
    "steady state; stable when |μ| < 1), and the equilibrium with the reference held: stable, "
    "or unstable and then the limit cycle it settles on (amplitude of y and frequency from a "
    "simulation, cross-checked by the describing functions of its nonlinearities). "
    "The equilibrium's verdict is that of the whole closed loop linearised at its operating "
    "point (the "
    "reference held constant, the disturbance at its final value; aiofl.analysis.linearize); "
    "min ζ is the least damping ratio −Re λ/|λ| of its eigenvalues; GM, PM, DM (gain, phase "
    "and delay margins, loop broken at the plant input) and Ms (sensitivity peak) are shown "
    "where the analysis provides them. The last column states what the simulation did, "
    "measured from its trajectory over its last seconds (e = y − r, in the plant's output "
    "unit), and whether the two agree."
)


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
    y_unit, d_unit = s1.plant.output_unit, s1.plant.disturbance_unit

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
            f"r = {math.degrees(ref.amplitude):.4g}° = {ref.amplitude:.6g} {y_unit} · "
            f"sin({ref.omega:g} t): the 45 read as degrees, in {y_unit} because y is an angle",
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
            f"τ_d = {sc2.disturbance_amplitude:g} {d_unit} from t = {sc2.disturbance_time:g} s "
            f"through b_d of eq. (15); {scale} in the true plant only (the controller is not "
            f"told) from t = {sc2.parameter_change_time:g} s",
        ),
        (
            "Scenario 3 noise",
            "Gaussian, mean 0, variance 0.0001, at the output",
            f"variance {sc3.noise_variance:g} {y_unit}², held constant over "
            f"{1e3 * sc3.noise_hold:g} ms, seed {sc3.noise_seed} (numpy default_rng); only the "
            "ESO's input is noisy; metrics use the true output",
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
