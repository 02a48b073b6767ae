"""Reproduce the paper's Tables I–III and Figures 3–5 (``aiofl reproduce``).

:func:`reproduce` computes every case (:func:`aiofl.reporting.cases.compute`), runs every
case over the same model-error draws (:mod:`aiofl.reporting.robust_rows`) and with the ideal
sensor beside 16-bit and 12-bit encoders (:mod:`aiofl.reporting.sensor_rows`), reads the
shipped Pareto fronts (:mod:`aiofl.reporting.fronts`) and writes ``metrics.json``,
``tables.md``, ``fig3.png``–``fig5.png``, ``fronts-s1.png``/``fronts-s3.png`` (when
fronts are shipped), ``noise-front-s3.png`` (scenario 3's noise fronts,
:mod:`aiofl.reporting.noise_front`; with scenario 3's designs on fresh noise seeds,
:mod:`aiofl.reporting.fresh_seeds`) and a self-contained ``report.html`` into an output directory,
all-or-nothing; ``tables.md`` and ``report.html`` are the sections of
:mod:`aiofl.reporting.reproduction_report`.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterable
from dataclasses import replace
from pathlib import Path

from aiofl.blas_threads import one_blas_thread
from aiofl.outputs import atomic_output_dir, atomic_write_bytes, atomic_write_text
from aiofl.reporting.cases import Reproduction, compute
from aiofl.reporting.figures import figure_png, scenario_figure
from aiofl.reporting.fresh_seeds import compute_fresh_seeds
from aiofl.reporting.front_files import FRONT_SCENARIOS, load_fronts
from aiofl.reporting.fronts import front_figure
from aiofl.reporting.noise_front import load_noise_fronts, noise_figure
from aiofl.reporting.paper import SCENARIOS
from aiofl.reporting.reproduction_report import html_report, report_markdown
from aiofl.reporting.rig_rows import RIG_DESIGNS, RIG_DRAWS_N, compute_rig_table, with_rig_records
from aiofl.reporting.robust_rows import (
    DEFAULT_DRAWS,
    DEFAULT_SEED,
    compute_robustness,
    with_robustness,
)
from aiofl.reporting.sensor_rows import compute_sensor_table, with_sensors
from aiofl.uncertainty import MAX_DRAWS

__all__ = ["reproduce"]


def reproduce(
    out: str | Path,
    *,
    available: Iterable[str] | None = None,
    on_stage: Callable[[str], None] | None = None,
    ts: float | None = None,
    draws: int = DEFAULT_DRAWS,
    seed: int = DEFAULT_SEED,
    fronts_dir: str | Path | None = None,
) -> Reproduction:
    """Run every case and write the reproduction into ``out`` (all-or-nothing).

    Writes ``metrics.json``, ``sampling.json`` (the sample-time limits of every case),
    ``tables.md``, ``fig3.png``, ``fig4.png``, ``fig5.png``, ``fronts-s{N}.png`` (one per
    scenario with a shipped front), ``noise-front-s3.png`` (when a noise front is shipped)
    and ``report.html``.

    Parameters
    ----------
    out
        Output directory (created; files of the same name are replaced).
    available
        Preset names to draw the cases from (default: all shipped presets).
    on_stage
        Progress callback, called with a short description of each stage as it starts
        (the robustness draws: one stage per scenario).
    ts
        Run every design as a sampled controller at this sample time [s] (default:
        continuous, or as the presets say).
    draws, seed
        Model-error draws per design for the robustness rows (0: skip them) and their seed.
    fronts_dir
        Folder of the Pareto-front files (default: the package's ``presets/fronts``).

    Returns
    -------
    Reproduction
    """
    if not 0 <= draws <= MAX_DRAWS:
        raise ValueError(f"draws = {draws}; allowed: 0 <= draws <= {MAX_DRAWS} (0 = skip)")
    with one_blas_thread():  # small matrices on busy cores (aiofl.blas_threads)
        return _reproduce(out, available, on_stage, ts, draws, seed, fronts_dir)


def _reproduce(
    out: str | Path,
    available: Iterable[str] | None,
    on_stage: Callable[[str], None] | None,
    ts: float | None,
    draws: int,
    seed: int,
    fronts_dir: str | Path | None,
) -> Reproduction:
    stage = on_stage or (lambda _msg: None)
    available = None if available is None else list(available)
    rep = compute(available=available, on_stage=stage, ts=ts)
    t0 = time.perf_counter()
    table = compute_robustness([r.case for r in rep.runs], draws=draws, seed=seed, on_stage=stage)
    t1 = time.perf_counter()
    # the report's own runs fill the ideal column of the presets run continuous
    ideal = {r.case.preset: r.record for r in rep.runs}
    sensors = compute_sensor_table([r.case for r in rep.runs], ideal=ideal, on_stage=stage)
    t2 = time.perf_counter()
    fresh = compute_fresh_seeds([r.case for r in rep.runs], on_stage=stage)
    t3 = time.perf_counter()
    rig = compute_rig_table(
        [r.case for r in rep.runs],
        own=ideal,
        draws=min(draws, RIG_DRAWS_N),
        extra=[n for n in RIG_DESIGNS if available is None or n in available],
        on_stage=stage,
    )
    t4 = time.perf_counter()
    stage("reading the shipped Pareto fronts")
    rep = replace(
        rep,
        robustness=table,
        sensors=sensors,
        records=with_rig_records(with_sensors(with_robustness(rep.records, table), sensors), rig),
        fronts=load_fronts(fronts_dir),
        noise_fronts=load_noise_fronts(fronts_dir),
        fresh=fresh,
        rig=rig,
        timings={
            **rep.timings,
            "robustness": t1 - t0,
            "sensors": t2 - t1,
            "fresh noise seeds": t3 - t2,
            "rig": t4 - t3,
        },
        engine={
            "sensors": (
                f"ideal, 16-bit and 12-bit encoder at 1 ms for every design: "
                f"{sensors.engine_calls} engine call(s)"
            ),
            "fresh noise seeds": (
                f"{len(fresh.results)} scenario-3 designs × {len(fresh.seeds)} seeds: "
                f"{fresh.engine_calls} engine call(s)"
            ),
            **rep.engine,
            "model-error draws": (
                f"{table.draws} per design, seed {table.seed}, {table.engine_calls} engine "
                "call(s) for all designs (one per scenario)"
                if table is not None
                else "skipped (--draws 0)"
            ),
        },
    )
    with atomic_output_dir(out) as stage_dir:
        atomic_write_text(stage_dir / "metrics.json", json.dumps(rep.records, indent=2) + "\n")
        sampling = json.dumps(rep.sampling, indent=2) + "\n"  # ts_max, ts_stable per preset
        atomic_write_text(stage_dir / "sampling.json", sampling)
        t0 = time.perf_counter()
        stage("drawing figures 3–5")
        figures: dict[str, bytes] = {}
        for s, info in SCENARIOS.items():
            name = f"fig{info.figure}.png"
            figures[name] = figure_png(scenario_figure(rep, s))
            atomic_write_bytes(stage_dir / name, figures[name])
        from aiofl.analysis.exact_tracking import exact_tracking_cost

        for s in FRONT_SCENARIOS:
            if not any(k[0] == s for k in rep.fronts.fronts) or not rep.scenario_runs(s):
                continue
            floor = exact_tracking_cost(rep.scenario_runs(s)[0].case.config)["isu"]
            name = f"fronts-s{s}.png"
            figures[name] = figure_png(front_figure(rep, s, floor))
            atomic_write_bytes(stage_dir / name, figures[name])
        if rep.noise_fronts.fronts:
            figures["noise-front-s3.png"] = figure_png(noise_figure(rep))
            atomic_write_bytes(stage_dir / "noise-front-s3.png", figures["noise-front-s3.png"])
        t1 = time.perf_counter()
        rep = replace(rep, timings={**rep.timings, "figures": t1 - t0})
        stage("writing tables and report")
        atomic_write_text(stage_dir / "tables.md", report_markdown(rep))
        atomic_write_text(stage_dir / "report.html", html_report(rep, figures))
    return rep
