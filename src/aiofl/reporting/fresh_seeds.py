r"""Scenario 3's shipped designs on noise seeds they were not tuned on.

Every shipped design of scenario 3 (output noise) was tuned and is reported with noise
seed 0.  :func:`compute_fresh_seeds` runs each of them on :data:`FRESH_SEEDS` (32 seeds,
1000–1031) with its own measurement (its sample time and quantum, as shipped), all in one
batched engine call per group of designs that share the plant, horizon, step and method
(:func:`~aiofl.engine.simulation.simulate_batch`): the ITAE median and maximum and the ISU
maximum over the fresh seeds stand beside the seed-0 figures of the report's own run.  A
seed's entry equals ``aiofl simulate PRESET`` with ``noise_seed`` set to that seed.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from aiofl import layout as L
from aiofl.reporting.cases import Case, Reproduction
from aiofl.reporting.section import TableSection
from aiofl.reporting.tables import DASH, fmt

__all__ = [
    "FRESH_HEADER",
    "FRESH_SCENARIO",
    "FRESH_SEEDS",
    "FRESH_TITLE",
    "FreshSeeds",
    "FreshSeedsSection",
    "compute_fresh_seeds",
    "fresh_notes",
    "fresh_rows",
    "seed_config",
]

FRESH_SCENARIO = 3
#: the noise seeds the designs were not tuned on
FRESH_SEEDS: tuple[int, ...] = tuple(range(1000, 1032))
FRESH_TITLE = "Scenario 3's designs on noise seeds they were not tuned on"


@dataclass(frozen=True)
class FreshSeeds:
    """Every scenario-3 design over :attr:`seeds`.

    Attributes
    ----------
    seeds
        The noise seeds.
    results
        By preset: ``itae``, ``isu`` (arrays over the seeds, NaN where diverged),
        ``diverged`` (bool array), ``sensor`` (the measurement, one line).
    engine_calls, seconds
        Engine calls made and their wall time.
    """

    seeds: tuple[int, ...]
    results: dict[str, dict[str, Any]] = field(default_factory=dict)
    engine_calls: int = 0
    seconds: float = 0.0


def seed_config(cfg: Any, seed: int) -> Any:
    """``cfg`` (a :class:`~aiofl.config.RunConfig`) with the output noise's seed ``seed``:
    the config's raw data with ``noise_seed`` in ``[sensor]`` (when the noise is the
    sensor's) or ``[scenario]``, parsed again."""
    import copy

    from aiofl.config import parse_config

    data = copy.deepcopy(cfg.raw)
    sensor = data.get("sensor")
    if isinstance(sensor, dict) and "noise_variance" in sensor:
        sensor["noise_seed"] = int(seed)
    else:
        data.setdefault("scenario", {})["noise_seed"] = int(seed)
    return parse_config(data, f"{cfg.name} with noise seed {seed}")


def compute_fresh_seeds(
    cases: Sequence[Case],
    *,
    seeds: Sequence[int] = FRESH_SEEDS,
    on_stage: Callable[[str], None] | None = None,
) -> FreshSeeds:
    """Run every scenario-3 case (with noise) on every seed of ``seeds`` with its own
    measurement: one :func:`~aiofl.engine.simulation.simulate_batch` call per group of
    designs sharing the plant, horizon, step, method and divergence threshold.

    Parameters
    ----------
    cases
        The report's cases (only scenario 3's with noise run).
    seeds
        The noise seeds (default :data:`FRESH_SEEDS`).
    on_stage
        Called with a description first (None: silent).

    Returns
    -------
    FreshSeeds
    """
    from aiofl.engine.simulation import simulate_batch

    chosen = [
        c for c in cases if c.scenario == FRESH_SCENARIO and c.config.scenario.noise_variance > 0
    ]
    (on_stage or (lambda _m: None))(
        f"fresh noise seeds: {len(chosen)} scenario-3 designs × {len(seeds)} seeds"
    )
    groups: dict[tuple[Any, ...], list[Case]] = {}
    for c in chosen:
        cfg = c.config
        key = (id(cfg.plant), cfg.scenario.t_final, cfg.dt, cfg.method, cfg.divergence_threshold)
        groups.setdefault(key, []).append(c)
    results: dict[str, dict[str, Any]] = {}
    t0 = time.perf_counter()
    i_itae, i_isu = L.METRIC_NAMES.index("itae"), L.METRIC_NAMES.index("isu")
    for members in groups.values():
        base = members[0].config
        ctrl, scen, samp = [], [], []
        for c in members:
            for s in seeds:
                ctrl.append(c.config.controller)
                scen.append(replace(c.config.scenario, noise_seed=int(s)))
                samp.append(c.config.sampling)
        res = simulate_batch(
            base.plant,
            ctrl,
            scen,
            dt=base.dt,
            method=base.method,
            divergence_threshold=base.divergence_threshold,
            sampling=samp if any(s is not None for s in samp) else None,
        )
        k = len(seeds)
        for j, c in enumerate(members):
            sl = slice(j * k, (j + 1) * k)
            div = np.asarray(res.failed[sl], dtype=bool)
            m = np.asarray(res.metrics[sl], dtype=np.float64)
            results[c.preset] = {
                "itae": np.where(div, np.nan, m[:, i_itae]),
                "isu": np.where(div, np.nan, m[:, i_isu]),
                "failed": div,
                "sensor": c.config.sensor.describe(),
            }
    return FreshSeeds(
        seeds=tuple(int(s) for s in seeds),
        results={c.preset: results[c.preset] for c in chosen},
        engine_calls=len(groups),
        seconds=time.perf_counter() - t0,
    )


FRESH_HEADER = (
    "Design",
    "Preset",
    "seed 0: ITAE",
    "seed 0: ISU",
    "fresh seeds: ITAE median",
    "ITAE max",
    "ISU max",
    "diverged",
)


def fresh_rows(rep: Reproduction) -> list[list[str]]:
    """One row per scenario-3 design: the seed-0 run of the report, then the median and
    maximum ITAE, the maximum ISU and the diverged count over the fresh seeds."""
    table: FreshSeeds | None = getattr(rep, "fresh", None)
    if table is None:
        return []
    rows = []
    for run in rep.scenario_runs(FRESH_SCENARIO):
        got = table.results.get(run.case.preset)
        if got is None:
            continue
        rec = run.record
        seed0 = (
            [f"{rec['status']} at t = {rec['stopped_at']:.2f} s", DASH]
            if rec["failed"]
            else [fmt(rec["itae"], 3), fmt(rec["isu"], 3)]
        )
        div = got["failed"]
        ok = ~div
        n = len(div)
        stats = (
            [DASH, DASH, DASH]
            if not ok.any()
            else [
                fmt(float(np.median(got["itae"][ok])), 3),
                "∞" if div.any() else fmt(float(np.max(got["itae"][ok])), 3),
                "∞" if div.any() else fmt(float(np.max(got["isu"][ok])), 3),
            ]
        )
        rows.append([run.case.label, run.case.preset, *seed0, *stats, f"{int(div.sum())} of {n}"])
    return rows


def fresh_notes(rep: Reproduction) -> list[str]:
    """How the fresh-seed rows were computed."""
    table: FreshSeeds | None = getattr(rep, "fresh", None)
    if table is None:
        return []
    return [
        "Every shipped scenario-3 design was tuned and is reported with noise seed 0. Here "
        f"each runs on {len(table.seeds)} noise seeds it was not tuned on "
        f"({table.seeds[0]}–{table.seeds[-1]}), nominal plant, full horizon, with its own "
        "measurement as shipped (continuous, or sampled at 1 ms with its quantum): "
        f"{table.engine_calls} batched engine call(s), {table.seconds:.1f} s. The median is "
        "over the seeds that did not diverge; the maxima are ∞ when any seed diverged. A "
        "seed's run equals aiofl simulate PRESET with noise_seed set to that seed."
    ]


@dataclass
class FreshSeedsSection(TableSection):
    """The fresh-seed table of the report: :func:`fresh_rows` and :func:`fresh_notes`."""

    rep: Reproduction
    title = FRESH_TITLE
    header = FRESH_HEADER
    notes_summary = "How these rows were computed"

    def rows(self) -> list[list[str]]:
        """:func:`fresh_rows`."""
        return fresh_rows(self.rep)

    def notes(self) -> list[str]:
        """:func:`fresh_notes`."""
        return fresh_notes(self.rep)
