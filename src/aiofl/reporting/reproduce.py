"""Reproduce the paper's Tables I–III and Figures 3–5 (``aiofl reproduce``).

:func:`reproduce` computes every case (:func:`aiofl.reporting.cases.compute`) and writes
``metrics.json``, ``tables.md``, ``fig3.png``–``fig5.png`` and a self-contained
``report.html`` into an output directory, all-or-nothing.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterable
from dataclasses import replace
from pathlib import Path

from aiofl.outputs import atomic_output_dir, atomic_write_bytes, atomic_write_text
from aiofl.reporting.cases import Reproduction, compute
from aiofl.reporting.figures import figure_png, scenario_figure
from aiofl.reporting.html import html_report
from aiofl.reporting.paper import SCENARIOS
from aiofl.reporting.tables import tables_markdown

__all__ = ["reproduce"]


def reproduce(
    out: str | Path,
    *,
    available: Iterable[str] | None = None,
    on_stage: Callable[[str], None] | None = None,
    ts: float | None = None,
) -> Reproduction:
    """Run every case and write the reproduction into ``out`` (all-or-nothing).

    Writes ``metrics.json``, ``sampling.json`` (the sample-time limits of every case),
    ``tables.md``, ``fig3.png``, ``fig4.png``, ``fig5.png`` and ``report.html``.

    Parameters
    ----------
    out
        Output directory (created; files of the same name are replaced).
    available
        Preset names to draw the cases from (default: all shipped presets).
    on_stage
        Progress callback, called with a short description of each stage.
    ts
        Run every design as a sampled controller at this sample time [s] (default:
        continuous, or as the presets say).

    Returns
    -------
    Reproduction
    """
    stage = on_stage or (lambda _msg: None)
    rep = compute(available=available, on_stage=stage, ts=ts)
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
        t1 = time.perf_counter()
        rep = replace(rep, timings={**rep.timings, "figures": t1 - t0})
        stage("writing tables and report")
        atomic_write_text(stage_dir / "tables.md", tables_markdown(rep))
        atomic_write_text(stage_dir / "report.html", html_report(rep, figures))
    return rep
