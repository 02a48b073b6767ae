r"""What a user gets: every shipped design with the ideal measurement and with real encoders.

Every case of the report is run three times, all in one batched engine call per group of
designs that share the plant, the horizon, the step and the method
(:func:`~aiofl.engine.simulation.simulate_batch`):

* **ideal sensor** — the preset with ``[sensor] preset = "ideal"`` (``aiofl simulate PRESET
  --sensor ideal``): the continuous controller, no quantum, the *ideal-sensor limit* of
  every design, also of those shipped sampled and quantised (the ``assisted-*`` presets);
  scenario 3's output noise is part of the scenario and stays in every column;
* **16-bit encoder** and **12-bit encoder** — the preset with ``[sensor] preset =
  "encoder-16bit"`` / ``"encoder-12bit"`` (:mod:`aiofl.sensor`): the controller sampled at
  1 ms, the output quantised to 2π/65536 or 2π/4096 rad.

A diverged run is shown as "diverged at t = …".  The verdict of a design is the best
sensor it survives (:func:`survives`: stable, ITAE and ISU close to the ideal sensor's):
"survives a 12-bit encoder", "needs a 16-bit encoder", "ideal-sensor only" or "diverges
even with the ideal sensor".
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aiofl import layout as L
from aiofl.reporting.cases import Case, Reproduction
from aiofl.reporting.section import TableSection
from aiofl.reporting.tables import DASH, fmt

__all__ = [
    "SENSOR_COLUMNS",
    "SENSOR_HEADER",
    "SENSOR_TITLE",
    "SensorSection",
    "SensorTable",
    "compute_sensor_table",
    "sensor_notes",
    "sensor_rows",
    "survives",
    "verdict",
    "with_sensors",
]

#: the columns: (key, sensor preset, label)
SENSOR_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("ideal", "ideal", "ideal sensor"),
    ("encoder-16bit", "encoder-16bit", "16-bit, 1 ms"),
    ("encoder-12bit", "encoder-12bit", "12-bit, 1 ms"),
)

SENSOR_HEADER = (
    "Scenario",
    "Design",
    "Preset",
    *(f"{m} {label}" for _, _, label in SENSOR_COLUMNS for m in ("ITAE", "ISU")),
    "Verdict",
)
"""Columns of the sensor table."""


@dataclass(frozen=True)
class SensorTable:
    """Every case with each sensor of :data:`SENSOR_COLUMNS`.

    Attributes
    ----------
    results
        By preset, by column key: ``{"itae", "isu", "diverged", "stopped_at", "sensor"}``
        (``itae``/``isu`` None when diverged; ``sensor`` the one-line description).
    skipped
        By preset and column, why a case could not run with that sensor.
    engine_calls, seconds
        Engine calls made and their wall time.
    """

    results: dict[str, dict[str, dict[str, Any]]] = field(default_factory=dict)
    skipped: dict[str, dict[str, str]] = field(default_factory=dict)
    engine_calls: int = 0
    seconds: float = 0.0


def _configs(case: Case) -> tuple[dict[str, Any], dict[str, str]]:
    """The case's config per column, and why a column cannot run."""
    from aiofl.config import ConfigError

    out: dict[str, Any] = {}
    why: dict[str, str] = {}
    for key, preset, _ in SENSOR_COLUMNS:
        try:
            out[key] = case.config.with_sensor(preset)
        except ConfigError as exc:
            why[key] = str(exc).split("\n")[-1].strip()
    return out, why


def _is_ideal(cfg: Any) -> bool:
    """Whether a config's measurement is the ideal sensor's (continuous, no quantum; its
    noise is the scenario's), so its own run is its ideal-sensor run."""
    return cfg.sampling is None and cfg.sensor.ts is None and cfg.sensor.quantum == 0


def _key(cfg: Any) -> tuple[Any, ...]:
    return (id(cfg.plant), cfg.scenario.t_final, cfg.dt, cfg.method, cfg.divergence_threshold)


def _entry(itae: Any, isu: Any, status: str, at: Any, sensor: str) -> dict[str, Any]:
    failed = status != "ok"
    return {
        "itae": None if failed else float(itae),
        "isu": None if failed else float(isu),
        "status": status,
        "failed": failed,
        "stopped_at": float(at) if failed else None,
        "sensor": sensor,
    }


def compute_sensor_table(
    cases: Sequence[Case],
    *,
    ideal: Mapping[str, Mapping[str, Any]] | None = None,
    on_stage: Callable[[str], None] | None = None,
) -> SensorTable:
    """Run every case with every sensor of :data:`SENSOR_COLUMNS` (module docstring): one
    :func:`~aiofl.engine.simulation.simulate_batch` call per group of members sharing the
    plant, horizon, step, method and divergence threshold (one call for the SLFJM cases).

    ``ideal`` (by preset: ``itae``, ``isu``, ``diverged``, ``stopped_at``) gives runs
    already made (the report's own runs of the presets, the numbers of ``aiofl
    simulate``): they fill the ideal column of the presets whose shipped measurement *is*
    the ideal one (continuous, no quantum), so those are not run twice; a sampled preset's
    ideal column is always run.

    Parameters
    ----------
    cases
        The report's cases.
    ideal
        Runs already made, by preset (``itae``, ``isu``, ``diverged``, ``stopped_at``); None:
        none.
    on_stage
        Called with a description before each call (None: silent).

    Returns
    -------
    SensorTable
    """
    from aiofl.engine.simulation import simulate_batch

    ideal = ideal or {}
    members: list[tuple[str, str, Any]] = []
    skipped: dict[str, dict[str, str]] = {}
    results: dict[str, dict[str, dict[str, Any]]] = {}
    for case in cases:
        cfgs, why = _configs(case)
        if why:
            skipped[case.preset] = why
        known = ideal.get(case.preset)
        if known is not None and "ideal" in cfgs and _is_ideal(case.config):
            results.setdefault(case.preset, {})["ideal"] = _entry(
                known["itae"],
                known["isu"],
                known.get("status", "diverged" if known["failed"] else "ok"),
                known["stopped_at"],
                cfgs["ideal"].sensor.describe(),
            )
            cfgs.pop("ideal")
        members += [(case.preset, key, cfg) for key, cfg in cfgs.items()]
    stage = on_stage or (lambda _msg: None)
    stage(
        f"sensors: {len(cases)} designs × {len(SENSOR_COLUMNS)} measurements (ideal, "
        "16-bit and 12-bit encoder at 1 ms)"
    )
    groups: dict[tuple[Any, ...], list[int]] = {}
    for i, (_, _, cfg) in enumerate(members):
        groups.setdefault(_key(cfg), []).append(i)
    t0 = time.perf_counter()
    for idx in groups.values():
        base = members[idx[0]][2]
        cfgs = [members[i][2] for i in idx]
        samplings = [c.sampling for c in cfgs]
        res = simulate_batch(
            base.plant,
            [c.controller for c in cfgs],
            [c.scenario for c in cfgs],
            dt=base.dt,
            method=base.method,
            divergence_threshold=base.divergence_threshold,
            sampling=samplings if any(s is not None for s in samplings) else None,
        )
        for j, i in enumerate(idx):
            preset, key, cfg = members[i]
            m = res.metrics[j]
            results.setdefault(preset, {})[key] = _entry(
                m[L.METRIC_NAMES.index("itae")],
                m[L.METRIC_NAMES.index("isu")],
                L.STATUS_NAMES[int(res.status[j])],
                res.stopped_at[j],
                cfg.sensor.describe(),
            )
    order = [k for k, _, _ in SENSOR_COLUMNS]
    return SensorTable(
        results={
            c.preset: {k: results[c.preset][k] for k in order if k in results[c.preset]}
            for c in cases
            if c.preset in results
        },
        skipped=skipped,
        engine_calls=len(groups),
        seconds=time.perf_counter() - t0,
    )


#: a design survives a sensor when it stays stable, its ITAE is at most
#: max(ITAE_FACTOR × ideal, ideal + ITAE_SLACK) and its ISU at most ISU_FACTOR × ideal
ITAE_FACTOR = 2.0
ITAE_SLACK = 0.05
ISU_FACTOR = 2.0


def survives(got: dict[str, Any] | None, ideal: dict[str, Any] | None) -> bool:
    """Whether a run with a real sensor (``got``) keeps the ideal-sensor run's performance:
    stable, ITAE <= max(:data:`ITAE_FACTOR` × ideal, ideal + :data:`ITAE_SLACK`), ISU <=
    :data:`ISU_FACTOR` × ideal (a loop that stops tracking or saturates the actuator
    with quantisation chatter does not count as surviving)."""
    if got is None or ideal is None or got["failed"] or ideal["failed"]:
        return False
    itae, isu = got["itae"], got["isu"]
    if not (np.isfinite(itae) and np.isfinite(isu)):
        return False
    i0, u0 = ideal["itae"], ideal["isu"]
    return bool(itae <= max(ITAE_FACTOR * i0, i0 + ITAE_SLACK) and isu <= ISU_FACTOR * u0)


def verdict(by_column: dict[str, dict[str, Any]]) -> str:
    """The best sensor a design survives (:func:`survives`), as one phrase."""
    ideal = by_column.get("ideal")
    if ideal is None or ideal["failed"]:
        lost = ideal is not None and ideal.get("status") == "lost"
        return f"{'loses the plant' if lost else 'diverges'} even with the ideal sensor"
    if survives(by_column.get("encoder-12bit"), ideal):
        return "survives a 12-bit encoder"
    if survives(by_column.get("encoder-16bit"), ideal):
        return "needs a 16-bit encoder"
    return "ideal-sensor only"


def with_sensors(records: Sequence[dict[str, Any]], table: SensorTable | None) -> list[dict]:
    """The records with ``"sensors"`` (the case's :attr:`SensorTable.results` entry plus its
    ``verdict``) added to every computed one; the paper's records are unchanged."""
    out = []
    for rec in records:
        if "preset" in rec and table is not None:
            got = table.results.get(rec["preset"])
            rec = {**rec, "sensors": None if got is None else {**got, "verdict": verdict(got)}}
        out.append(rec)
    return out


def _cells(got: dict[str, Any] | None) -> list[str]:
    if got is None:
        return [DASH, DASH]
    if got["failed"]:
        return [f"{got.get('status', 'failed')} at t = {got['stopped_at']:.2f} s", DASH]
    return [fmt(got["itae"], 3), fmt(got["isu"], 3)]


def sensor_rows(rep: Reproduction) -> list[list[str]]:
    """One row per case: scenario, label, preset, ITAE and ISU per sensor, verdict."""
    table: SensorTable | None = getattr(rep, "sensors", None)
    if table is None:
        return []
    rows = []
    for run in rep.runs:
        got = table.results.get(run.case.preset, {})
        cells = [c for key, _, _ in SENSOR_COLUMNS for c in _cells(got.get(key))]
        rows.append([str(run.case.scenario), run.case.label, run.case.preset, *cells, verdict(got)])
    return rows


def sensor_notes(rep: Reproduction) -> list[str]:
    """What the columns are, and how many designs survive each sensor."""
    table: SensorTable | None = getattr(rep, "sensors", None)
    if table is None:
        return []
    verdicts = [verdict(table.results.get(r.case.preset, {})) for r in rep.runs]
    counts = {v: verdicts.count(v) for v in dict.fromkeys(verdicts)}
    notes = [
        "'ideal sensor' is the design with the ideal, continuous measurement (aiofl "
        "simulate PRESET --sensor ideal): the ideal-sensor limit no real controller "
        "reaches, for every design, also those shipped sampled and quantised (the "
        "assisted-* presets, whose own runs in the tables above are their 12-bit or noisy "
        "1-ms runs). '16-bit, 1 ms' and '12-bit, 1 ms' run the same design measured "
        "by an encoder (aiofl simulate PRESET --sensor encoder-16bit / encoder-12bit): the "
        "controller sampled at 1 ms, the output quantised to 2π/65536 or 2π/4096 rad. "
        "Scenario 3's output noise is part of the scenario and stays in every column. Full "
        "horizon, same step and scenario as the tables above; the ideal-sensor column reuses "
        "the run of those tables for the presets shipped continuous; the other runs are "
        f"{table.engine_calls} batched engine call(s), {table.seconds:.1f} s.",
        "A design survives a sensor when it stays stable with it, its ITAE is at most "
        f"max({ITAE_FACTOR:g} × the ideal-sensor ITAE, that + {ITAE_SLACK:g}) and its ISU "
        f"at most {ISU_FACTOR:g} × the ideal-sensor ISU (a loop that stops tracking or "
        "turns quantisation steps into control chatter does not survive). Verdicts: "
        + "; ".join(f"{v}: {n} design(s)" for v, n in counts.items())
        + ". A result counts as a user would get it: a design that is 'ideal-sensor only' "
        "does not survive a real 16-bit or 12-bit encoder (it diverges, or loses its "
        "tracking or its control energy budget).",
    ]
    if table.skipped:
        notes.append(
            "Not run with every sensor: "
            + "; ".join(
                f"{p} ({', '.join(f'{k}: {w}' for k, w in why.items())})"
                for p, why in table.skipped.items()
            )
            + "."
        )
    return notes


SENSOR_TITLE = "What a user gets: the ideal sensor beside 16-bit and 12-bit encoders"


@dataclass
class SensorSection(TableSection):
    """The sensor table of the report: :func:`sensor_rows` and :func:`sensor_notes`."""

    rep: Reproduction
    title = SENSOR_TITLE
    header = SENSOR_HEADER

    def rows(self) -> list[list[str]]:
        """:func:`sensor_rows`."""
        return sensor_rows(self.rep)

    def notes(self) -> list[str]:
        """:func:`sensor_notes`."""
        return sensor_notes(self.rep)
