r"""Robustness rows of ``aiofl reproduce``: every shipped design over the same model-error draws.

Every case of the report (:func:`aiofl.reporting.cases.discover_cases`: the paper's printed
designs, the ``retuned-*``, ``frontier-*`` and ``iofl-*`` presets) is run over the same
``N`` draws of the true plant: :math:`J_h, J_l, K_s, R_m` each a factor uniform on
:math:`[0.8, 1.2]` of its nominal value (:data:`ROBUST_PARAMETERS`, :data:`ROBUST_SPREAD`),
from t = 0, the controller's nominal model unchanged (an ``[uncertainty]`` table,
:mod:`aiofl.uncertainty`).  The draws depend only on the seed (common random numbers), so
the rows are paired comparisons; all designs of a scenario run in one batched engine call
(:func:`aiofl.analysis.robustness.simulate_designs`).

A row gives the stable fraction and the ITAE quantiles q05/q50/q95 over all N draws, a
diverged draw counting as :math:`+\infty` (empirical quantiles, ``inverted_cdf``; a quantile
that falls on a diverged draw is ``null`` in ``metrics.json`` and "diverged" in the tables),
exactly the statistics of ``aiofl robustness``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from aiofl.reporting.cases import Case, Reproduction, controller_access
from aiofl.reporting.tables import DASH, fmt
from aiofl.uncertainty import UncertaintyModel, sample_draws

__all__ = [
    "DEFAULT_DRAWS",
    "DEFAULT_SEED",
    "ROBUST_HEADER",
    "ROBUST_PARAMETERS",
    "ROBUST_SPREAD",
    "RobustTable",
    "compute_robustness",
    "robust_markdown",
    "robust_notes",
    "robust_rows",
    "robust_spec",
    "with_robustness",
]

#: the plant parameters drawn (SLFJM names)
ROBUST_PARAMETERS = ("J_h", "J_l", "K_s", "R_m")
#: each drawn factor is uniform on [1 - spread, 1 + spread]
ROBUST_SPREAD = 0.2
#: draws per design of ``aiofl reproduce`` (``--draws``); see :func:`compute_robustness`
DEFAULT_DRAWS = 100
#: the seed of the draws
DEFAULT_SEED = 0

ROBUST_HEADER = (
    "Scenario",
    "Design",
    "Preset",
    "ITAE nominal",
    "stable",
    "ITAE 5 %",
    "ITAE 50 %",
    "ITAE 95 %",
)
"""Columns of the robustness table."""


def robust_spec(draws: int, seed: int = DEFAULT_SEED) -> UncertaintyModel:
    """The ``[uncertainty]`` table of the report: ±20 % uniform on J_h, J_l, K_s, R_m."""
    return UncertaintyModel(
        draws=draws,
        seed=seed,
        parameters={name: {"uniform": ROBUST_SPREAD} for name in ROBUST_PARAMETERS},  # type: ignore[misc]
    )


@dataclass(frozen=True)
class RobustTable:
    """The robustness of every case over the same draws.

    Attributes
    ----------
    draws, seed
        Number of draws per design and their seed.
    uncertainty
        The ``[uncertainty]`` table as data (``draws``, ``seed``, ``parameters``).
    results
        By preset, :meth:`aiofl.analysis.robustness.DesignDraws.to_dict`: ``draws``,
        ``seed``, ``stable_fraction``, ``diverged`` (count), ``itae`` and ``isu`` quantiles
        (q05, q50, q95, max; null where the value falls on a diverged draw).
    skipped
        By preset, why a case was not run over the draws.
    engine_calls, seconds
        Engine calls made and their wall time.
    """

    draws: int
    seed: int
    uncertainty: dict[str, Any]
    results: dict[str, dict[str, Any]] = field(default_factory=dict)
    skipped: dict[str, str] = field(default_factory=dict)
    engine_calls: int = 0
    seconds: float = 0.0


def compute_robustness(
    cases: Sequence[Case],
    *,
    draws: int = DEFAULT_DRAWS,
    seed: int = DEFAULT_SEED,
    on_stage: Callable[[str], None] | None = None,
) -> RobustTable | None:
    """Run every case over the same ``draws`` draws of :func:`robust_spec` (None if 0).

    A case whose plant lacks one of :data:`ROBUST_PARAMETERS`, or whose scenario changes
    the plant at t > 0, is listed in ``skipped`` with the reason instead of failing the
    report.  The cases run scenario by scenario (designs of different scenarios never
    share an engine call), and ``on_stage`` is called with a description before each.
    """
    from aiofl.analysis.robustness import simulate_designs

    if draws == 0:
        return None
    spec = robust_spec(draws, seed)
    d = sample_draws(spec, draws=draws, seed=seed)
    run: list[Case] = []
    skipped: dict[str, str] = {}
    for case in cases:
        cfg = case.config
        try:
            spec.check(cfg.plant.param_names, discrete=cfg.sampling is not None, dt=cfg.dt)
            d.scenarios(cfg.scenario)
        except ValueError as exc:
            skipped[case.preset] = str(exc).split("\n")[0]
            continue
        run.append(case)
    stage = on_stage or (lambda _msg: None)
    scenarios = sorted({c.scenario for c in run})
    results: dict[str, dict[str, Any]] = {}
    n_calls = 0
    t0 = time.perf_counter()
    for i, s in enumerate(scenarios, 1):
        group = [c for c in run if c.scenario == s]
        stage(
            f"robustness, scenario {s} ({i} of {len(scenarios)}): {len(group)} designs × "
            f"{draws} draws of ±{100 * ROBUST_SPREAD:g} % model error"
        )
        res = simulate_designs([c.config for c in group], d)
        n_calls += sum({r.group: r.engine_calls for r in res}.values())
        results.update({c.preset: r.to_dict() for c, r in zip(group, res, strict=True)})
    seconds = time.perf_counter() - t0
    return RobustTable(
        draws=draws,
        seed=seed,
        uncertainty=spec.model_dump(exclude_none=True),
        results={c.preset: results[c.preset] for c in run},
        skipped=skipped,
        engine_calls=n_calls,
        seconds=seconds,
    )


def with_robustness(
    records: Sequence[dict[str, Any]], table: RobustTable | None
) -> list[dict[str, Any]]:
    """The records with ``"robustness"`` added to every computed one (those with a
    ``preset``): the case's :attr:`RobustTable.results` entry, or null when skipped (or
    when no table was computed, ``--draws 0``).  The paper's records are unchanged."""
    out = []
    for rec in records:
        if "preset" in rec:
            rec = {**rec, "robustness": table.results.get(rec["preset"]) if table else None}
        out.append(rec)
    return out


def _pct(x: float) -> str:
    return f"{100 * x:.0f} %" if x in (0.0, 1.0) else f"{100 * x:.1f} %"


def _q(value: float | None) -> str:
    return "diverged" if value is None else fmt(value, 3)


def robust_rows(rep: Reproduction) -> list[list[str]]:
    """One row per case: scenario, label, preset, nominal ITAE (this run), stable share,
    ITAE q05/q50/q95 over the draws ("diverged" where the quantile falls on a diverged
    draw)."""
    table: RobustTable | None = rep.robustness
    if table is None:
        return []
    rows = []
    for run in rep.runs:
        preset = run.case.preset
        rec = run.record
        nominal = (
            f"diverged at t = {rec['diverged_at']:.2f} s"
            if rec["diverged"]
            else (fmt(rec["itae"], 3))
        )
        got = table.results.get(preset)
        if got is None:
            why = table.skipped.get(preset, "not run")
            rows.append(
                [str(run.case.scenario), run.case.label, preset, nominal, why, DASH, DASH, DASH]
            )
            continue
        k, n_div = got["draws"], got["diverged"]
        q = got["itae"]
        rows.append(
            [
                str(run.case.scenario),
                run.case.label,
                preset,
                nominal,
                f"{_pct(got['stable_fraction'])} ({k - n_div}/{k})",
                _q(q["q05"]),
                _q(q["q50"]),
                _q(q["q95"]),
            ]
        )
    return rows


def robust_notes(rep: Reproduction) -> list[str]:
    """What the rows are (N, seed, distribution, statistics) and, per scenario, the most
    robust design by its ITAE 95 % among those stable on every draw."""
    table: RobustTable | None = rep.robustness
    if table is None:
        return [
            "Robustness over model error was not computed in this run (aiofl reproduce --draws 0)."
        ]
    names = ", ".join(ROBUST_PARAMETERS)
    notes = [
        f"{table.draws} draws (seed {table.seed}) of the true plant: {names} each multiplied "
        f"by a factor uniform on [{1 - ROBUST_SPREAD:g}, {1 + ROBUST_SPREAD:g}], from t = 0; "
        "the controllers' nominal model is unchanged (in scenario 2 the factor multiplies "
        "J_l × 1.4). Common random numbers: every design sees the same plants, so rows are "
        "paired comparisons. Same horizon, step and scenario as the tables above.",
        "A diverged draw counts as ITAE = +∞: the quantiles are empirical (numpy "
        "inverted_cdf) over all draws, and 'diverged' means the quantile falls on a diverged "
        "draw. 'ITAE nominal' is the run of the table above. The same statistics as aiofl "
        "robustness; in metrics.json each computed record carries them as 'robustness'.",
    ]
    for s in sorted({r.case.scenario for r in rep.runs}):
        cands = [
            (r, table.results[r.case.preset])
            for r in rep.scenario_runs(s)
            if r.case.preset in table.results
        ]
        full = [(r, g) for r, g in cands if g["diverged"] == 0 and g["itae"]["q95"] is not None]
        if not cands:
            continue
        text = (
            f"Scenario {s}: {len(full)} of {len(cands)} designs stayed stable on all "
            f"{table.draws} draws"
        )
        eso = [(r, g) for r, g in full if controller_access(r.case.config) is None]
        if eso:
            r, g = min(eso, key=lambda p: p[1]["itae"]["q95"])
            text += (
                f"; the lowest ITAE 95 % of an ESO-based one is {r.case.label} "
                f"[{r.case.preset}], {fmt(g['itae']['q95'], 3)} (median "
                f"{fmt(g['itae']['q50'], 3)}, nominal {fmt(r.record['itae'], 3)})"
            )
        notes.append(text + ".")
    if table.skipped:
        notes.append(
            "Not run over the draws: "
            + "; ".join(f"{p} ({why})" for p, why in table.skipped.items())
            + "."
        )
    return notes


def robust_markdown(rep: Reproduction) -> str:
    """The robustness section of ``tables.md``."""
    from aiofl.reporting.tables import _md_table

    out = ["## Robustness: every design over the same ±20 % model errors", ""]
    rows = robust_rows(rep)
    if rows:
        out += [_md_table(ROBUST_HEADER, rows), ""]
    out += [f"- {n}" for n in robust_notes(rep)]
    return "\n".join(out) + "\n"
