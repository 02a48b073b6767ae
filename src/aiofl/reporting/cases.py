r"""The cases of ``aiofl reproduce``: found among the presets, simulated batched, summarised.

The paper (Abdul-Adheem & Ibraheem, arXiv 1805.00222, Section V) reports two AIOFL
structures on the SLFJM of eq. (15):

* **LESO**: linear ESO (16) + NLSEF with fal (17) + Han's TD (18), law (14);
* **INLESO**: improved nonlinear ESO (19) + INLSEF (20) + improved TD (21), law (14);

in three scenarios (nominal tracking; a 0.5 N·m step load at 10 s with :math:`J_l\times1.4`;
output noise of variance 1e-4) and scores them with ITAE and ISU (eq. 22).

:func:`compute` runs the shipped presets ``paper-s{1,2,3}-{leso,inleso}`` (the printed
parameters) in as few batched engine calls as possible and returns a
:class:`Reproduction` that the tables, figures and report read; the printed numbers
themselves are in :mod:`aiofl.reporting.paper`.  Extra presets are picked up automatically
when they exist, and appear as extra rows and panels everywhere without special cases:

* ``retuned-s{N}-{leso,inleso,ladrc}``: parameters re-tuned by ``aiofl tune``
  (records with ``"source": "retuned"``);
* ``frontier-s{N}-{leso,inleso,ladrc}``: designs at the Pareto frontier, tuned for
  tracking, energy and robustness (records with ``"source": "robust"``);
* ``assisted-s{N}-ladrc``: the model-assisted ESO (``eso.model = "nominal"``: the
  observer and the law carry the plant's nominal α, β; records with
  ``"source": "assisted"``), tuned with the measurement a rig has (a 12-bit encoder
  sampled at 1 ms, or scenario 3's noise);
* ``iofl-s{N}``: the classical model-based IOFL baseline (``"structure": "IOFL"``,
  ``"source": "model"``).
"""

from __future__ import annotations

import math
import platform
import re
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl.components.differentiators import itd_steady_state
from aiofl.components.metrics import itae
from aiofl.components.observers import eso_gains
from aiofl.config import RunConfig, list_presets, load_config
from aiofl.engine.simulation import SimulationResult, simulate_batch
from aiofl.reporting.behaviour import TOLERANCE, Behaviour, analysis_numbers, measure_result
from aiofl.reporting.orbit_pool import case_verdicts, closed_loop_verdict
from aiofl.reporting.paper import PAPER_PRESETS, PAPER_TABLES, SCENARIOS

__all__ = [
    "EXTRA_PRESETS",
    "PAPER_TABLES",
    "SCENARIOS",
    "Case",
    "CaseRun",
    "Reproduction",
    "compute",
    "computed_record",
    "controller_access",
    "discover_cases",
    "model_assistance",
    "orbit_cost_rank",
    "paper_records",
    "run_cases",
    "trivial_itae",
]

EXTRA_PRESETS: tuple[tuple[str, str], ...] = (
    (r"retuned-s(?P<s>\d+)-(?:leso|inleso|ladrc)", "retuned"),
    (r"frontier-s(?P<s>\d+)-(?:leso|inleso|ladrc)", "robust"),
    (r"assisted-s(?P<s>\d+)-(?:leso|inleso|ladrc)", "assisted"),
    (r"iofl-s(?P<s>\d+)", "model"),
)
"""Optional presets (regex on the name, source label) included when they are shipped."""

SOURCE_ORDER = ("paper", "printed", "retuned", "robust", "assisted", "model")
STRUCTURE_ORDER = ("LESO", "INLESO", "LADRC", "IOFL")
_SCENARIO_IN_NAME = re.compile(r"(?:^|-)s(\d+)(?:-|$)")


# ----------------------------------------------------------------------------- cases
@dataclass(frozen=True)
class Case:
    """One simulated case: a preset, the paper scenario it belongs to, and its labels."""

    preset: str
    scenario: int
    structure: str
    source: str
    config: RunConfig = field(repr=False, compare=False)

    @property
    def label(self) -> str:
        """Row label: ``"LESO"`` for the printed sets, ``"LESO (retuned)"`` otherwise."""
        return self.structure if self.source == "printed" else f"{self.structure} ({self.source})"


def _sort_key(case: Case) -> tuple[int, int, int, str]:
    src = SOURCE_ORDER.index(case.source) if case.source in SOURCE_ORDER else len(SOURCE_ORDER)
    st = (
        STRUCTURE_ORDER.index(case.structure)
        if case.structure in STRUCTURE_ORDER
        else len(STRUCTURE_ORDER)
    )
    return (case.scenario, src, st, case.preset)


def scenario_number(name: str) -> int | None:
    """The paper scenario encoded in a preset name (``paper-s2-leso`` -> 2), else None."""
    m = _SCENARIO_IN_NAME.search(name)
    return int(m.group(1)) if m else None


def discover_cases(available: Iterable[str] | None = None) -> list[Case]:
    """The six paper cases plus every shipped ``retuned-*`` / ``frontier-*`` / ``iofl-*``
    preset.

    Parameters
    ----------
    available
        Preset names to choose from (default: :func:`aiofl.config.list_presets`).

    Returns
    -------
    list of Case
        Sorted by scenario, then source (printed, retuned, robust, model), then structure.
    """
    names = set(list_presets() if available is None else available)
    cases = []
    for preset, s, structure in PAPER_PRESETS:
        cases.append(Case(preset, s, structure, "printed", load_config(preset)))
    for name in sorted(names):
        for pattern, source in EXTRA_PRESETS:
            m = re.fullmatch(pattern, name)
            if m and int(m.group("s")) in SCENARIOS:
                cfg = load_config(name)
                structure = "IOFL" if source == "model" else cfg.controller.structure
                cases.append(Case(name, int(m.group("s")), structure, source, cfg))
    return sorted(cases, key=_sort_key)


# ------------------------------------------------------------------------------ runs
@dataclass(frozen=True)
class CaseRun:
    """A case and what the engine computed for it."""

    case: Case
    result: SimulationResult = field(repr=False)
    opi: float | None

    @property
    def failed(self) -> bool:
        """Whether the run was lost or diverged."""
        return self.result.failed

    @property
    def record(self) -> dict[str, Any]:
        """This run's metrics record (see :func:`computed_record`)."""
        return computed_record(
            self.result,
            scenario=self.case.scenario,
            structure=self.case.structure,
            source=self.case.source,
            opi=self.opi,
        )

    @cached_property
    def behaviour(self) -> Behaviour:
        """What the run did over its last seconds (:mod:`aiofl.reporting.behaviour`)."""
        return measure_result(self.result, self.case.config.scenario.t_final)

    @property
    def unit(self) -> str:
        """The plant's output unit (``"rad"`` for the SLFJM)."""
        return self.case.config.plant.output_unit

    @property
    def unit_suffix(self) -> str:
        """``" rad"``, to write after a value of the output; empty when undeclared."""
        return f" {self.unit}" if self.unit and self.unit != "-" else ""


def _batch_key(cfg: RunConfig) -> tuple[Any, ...]:
    return (
        id(cfg.plant),
        cfg.scenario.t_final,
        cfg.dt,
        cfg.method,
        cfg.decimation,
        cfg.divergence_threshold,
    )


def run_cases(
    cases: Sequence[Case],
    *,
    store: bool = True,
    on_batch: Callable[[int, int], None] | None = None,
) -> list[CaseRun]:
    """Simulate the cases, one batched engine call per group of compatible cases.

    Cases share a call when they have the same plant, horizon, step, method, decimation
    and divergence threshold (the engine's batch requirements); the members of a call run
    in parallel.

    Parameters
    ----------
    cases
        The cases (see :func:`discover_cases`).
    store
        Keep trajectories (needed for figures).
    on_batch
        Called as ``on_batch(done_batches, n_batches)`` after each engine call.

    Returns
    -------
    list of CaseRun
        In the order of ``cases``.
    """
    groups: dict[tuple[Any, ...], list[int]] = {}
    for i, case in enumerate(cases):
        groups.setdefault(_batch_key(case.config), []).append(i)
    results: dict[int, SimulationResult] = {}
    for done, idx in enumerate(groups.values(), 1):
        first = cases[idx[0]].config
        batch = simulate_batch(
            first.plant,
            [cases[i].config.controller for i in idx],
            [cases[i].config.scenario for i in idx],
            dt=first.dt,
            method=first.method,
            sampling=[cases[i].config.sampling for i in idx],  # None: continuous
            store=store,
            decimation=first.decimation,
            divergence_threshold=first.divergence_threshold,
        )
        for j, i in enumerate(idx):
            results[i] = batch.member(j)
        if on_batch is not None:
            on_batch(done, len(groups))
    return [
        CaseRun(case, results[i], results[i].opi(case.config.weights))
        for i, case in enumerate(cases)
    ]


def _num(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def computed_record(
    result: SimulationResult,
    *,
    scenario: int | None,
    structure: str,
    source: str,
    opi: float | None,
    extra: bool = False,
) -> dict[str, Any]:
    """The metrics record of one computed run (metrics null if it was lost or diverged).

    Keys: ``scenario, structure, source, itae, isu, iau, opi, status`` (``"ok"``,
    ``"lost"``, ``"diverged"``), ``failed`` (not ok), ``stopped_at`` (when it was lost or
    diverged) and the step metrics and noise in u of
    :data:`aiofl.engine.response.RESPONSE_NAMES` (null where they do not apply); with
    ``extra`` also ``iae`` and ``ise``.

    Parameters
    ----------
    result
        The run.
    scenario, structure, source
        The record's labels (scenario None: not a paper scenario).
    opi
        Its OPI (None: not computed).
    extra
        Add ``iae`` and ``ise``.

    Returns
    -------
    dict
    """
    m = result.metrics
    rec: dict[str, Any] = {
        "scenario": scenario,
        "structure": structure,
        "source": source,
        "itae": _num(m["itae"]) if m else None,
        "isu": _num(m["isu"]) if m else None,
        "iau": _num(m["iau"]) if m else None,
        "opi": _num(opi) if m else None,
        "status": result.status,
        "failed": bool(result.failed),
        "stopped_at": _num(result.stopped_at) if result.failed else None,
        **{k: _num(v) for k, v in result.response.items()},
    }
    if extra:
        rec["iae"] = _num(m["iae"]) if m else None
        rec["ise"] = _num(m["ise"]) if m else None
    return rec


def paper_records() -> list[dict[str, Any]]:
    """Records of the paper's Tables I–III (IAU and OPI null: the paper gives none)."""
    return [
        {
            "scenario": s,
            "structure": structure,
            "source": "paper",
            "itae": vals["itae"],
            "isu": vals["isu"],
            "iau": None,
            "opi": None,
            "status": "ok",
            "failed": False,
            "stopped_at": None,
        }
        for s, table in PAPER_TABLES.items()
        for structure, vals in table.items()
    ]


def reproduction_record(run: CaseRun, verdict: dict[str, Any] | None) -> dict[str, Any]:
    """The metrics.json record of a reproduced case: :func:`computed_record` plus

    * ``"preset"``: the preset that was run;
    * ``"tracking"``: what the run did over its last seconds, in the plant's output unit
      (:meth:`aiofl.reporting.behaviour.Behaviour.to_dict`, with the ``tolerance`` within
      which it counts as tracking, a share of the reference peak);
    * ``"linearisation"``: the closed-loop verdict and its numbers
      (:func:`aiofl.reporting.behaviour.analysis_numbers`), null where not provided.
    """
    rec = run.record
    rec["preset"] = run.case.preset
    rec["tracking"] = {**run.behaviour.to_dict(), "tolerance": TOLERANCE}
    rec["linearisation"] = analysis_numbers(verdict or {})
    return rec


def build_records(
    runs: Sequence[CaseRun], verdicts: dict[str, dict[str, Any]] | None = None
) -> list[dict[str, Any]]:
    """Paper records and computed records, ordered by scenario, source, structure.

    With ``verdicts`` (by preset) the computed records carry ``tracking`` and
    ``linearisation`` (:func:`reproduction_record`).
    """
    recs = paper_records() + [
        r.record if verdicts is None else reproduction_record(r, verdicts.get(r.case.preset))
        for r in runs
    ]

    def key(rec: dict[str, Any]) -> tuple[int, int, int]:
        src = rec["source"]
        st = rec["structure"]
        return (
            rec["scenario"],
            SOURCE_ORDER.index(src) if src in SOURCE_ORDER else 99,
            STRUCTURE_ORDER.index(st) if st in STRUCTURE_ORDER else 99,
        )

    return sorted(recs, key=key)  # stable: runs keep their order within a key


# ----------------------------------------------------------------------------- facts
def trivial_itae(cfg: RunConfig, dt: float = 1e-4) -> float:
    r"""ITAE of the trivial controller :math:`y \equiv 0`: :math:`\int_0^{t_f} t\,|r|\,dt`.

    Computed numerically (trapezoid on a grid of step ``dt``) from the scenario's
    reference, over the scenario's horizon.
    """
    t_f = cfg.scenario.t_final
    t = np.linspace(0.0, t_f, round(t_f / dt) + 1)
    return itae(t, np.zeros_like(t), cfg.scenario.reference.evaluate(t))


def observer_roots(cfg: RunConfig) -> NDArray[np.complex128]:
    r"""Roots of :math:`s^{\rho+1} + \beta_1 s^\rho + \dots + \beta_{\rho+1}`, eq. (9).

    For a linear ESO these are the poles of its estimation error; for the INLESO (whose
    injection g(e) is nonlinear) they are the poles with unit injection gain.
    """
    c = cfg.controller
    alphas = [c.value(f"eso.alpha{i}") for i in range(1, c.rho + 2)]
    betas = eso_gains(c.value("eso.omega0"), alphas)
    return np.roots(np.r_[1.0, betas]).astype(np.complex128)


def itd_gain(cfg: RunConfig) -> float | None:
    r"""Steady-state gain :math:`(1-a)/b` of the improved TD (21), or None for other TDs."""
    c = cfg.controller
    if c.td != "improved":
        return None
    return itd_steady_state(1.0, c.value("td.a"), c.value("td.b"))


def output_ratio(run: CaseRun, window: float = 5.0) -> float | None:
    """Peak |y| over the last ``window`` seconds divided by peak |r| there (None if diverged).

    About 1 for good tracking of a sine, near 0 when the output barely moves.
    """
    res = run.result
    if res.failed or res.t.size == 0:
        return None
    sel = res.t >= res.t[-1] - window
    r_peak = float(np.max(np.abs(res["r"][sel])))
    if r_peak == 0.0:
        return None
    return float(np.max(np.abs(res["y"][sel]))) / r_peak


def controller_access(cfg: RunConfig, *, short: bool = False) -> str | None:
    """What a model-based (IOFL) controller is given that the ESO-based ones are not.

    None for the AIOFL law, which sees only the measured output, ρ and b0.  The classical
    IOFL law (Section III, u = (−α(x) + v)/β(x)) is given the plant's model with its
    *nominal* parameters and the plant state x itself, free of measurement noise; the long
    form names what the scenario changes that IOFL is not told.
    """
    c, sc = cfg.controller, cfg.scenario
    if c.law != "iofl":
        return None
    if short:
        return "given the nominal model and the noise-free state x"
    changed = ", ".join(
        [f"{k} × {v:g}" for k, v in sc.plant_scale.items()]
        + [f"{k} = {v:g}" for k, v in sc.plant_overrides.items()]
    )
    unknown = [f"the true plant has {changed}"] if changed else []
    if sc.disturbance_amplitude != 0.0:
        unknown.append("the disturbance is not modelled")
    model = "the nominal model" + (f" ({'; '.join(unknown)})" if unknown else "")
    state = "the noise-free state x" + (
        f" (the measured output carries noise of variance {sc.noise_variance:g})"
        if sc.noise_variance > 0
        else ""
    )
    items = [model, state] + (["the exact reference derivatives"] if c.td == "exact" else [])
    return "given " + (", ".join(items[:-1]) + " and " + items[-1])


def model_assistance(cfg: RunConfig) -> str | None:
    """What a model-assisted ESO design is given besides the measured output, ρ and b0
    (None for a model-free or IOFL design), and the sensor it was designed for."""
    c = cfg.controller
    if c.law != "aiofl" or c.eso_model == "none":
        return None
    text = "given the nominal model (α, β at x̂ = Φ⁻¹(ξ̂)) and the measured output"
    sensor = getattr(cfg, "sensor", None)
    if sensor is not None and sensor.preset not in ("ideal", "custom"):
        text += f", {sensor.preset}"
    return text


# ----------------------------------------------------------------------- orchestration
@dataclass(frozen=True)
class Reproduction:
    """Everything :func:`reproduce` computed, for the tables, figures and report."""

    runs: list[CaseRun]
    records: list[dict[str, Any]]
    trivial: dict[int, float]
    verdicts: dict[str, dict[str, Any]]
    engine: dict[str, str]
    timings: dict[str, float]
    sampling: dict[str, dict[str, Any]] = field(default_factory=dict)  # limits by preset
    # robustness over model-error draws (aiofl.reporting.robust_rows.RobustTable), or None
    robustness: Any = None
    # the shipped Pareto fronts (aiofl.reporting.fronts.ShippedFronts), or None
    fronts: Any = None
    # every design with the ideal sensor and real encoders (reporting.sensor_rows), or None
    sensors: Any = None
    # scenario 3's noise fronts (reporting.noise_front.NoiseFronts), or None
    noise_fronts: Any = None
    # scenario 3's designs on fresh noise seeds (reporting.fresh_seeds.FreshSeeds), or None
    fresh: Any = None
    # every design on the servo-1khz rig (reporting.rig_rows.RigTable), or None
    rig: Any = None

    def scenario_runs(self, scenario: int) -> list[CaseRun]:
        """The runs of one scenario, in table order."""
        return [r for r in self.runs if r.case.scenario == scenario]

    def config(self, preset: str) -> RunConfig:
        """The config of a case by preset name."""
        return next(r.case.config for r in self.runs if r.case.preset == preset)

    def records_by_preset(self) -> dict[str, dict[str, Any]]:
        """The computed records by preset (those written to metrics.json); a run without a
        record (a Reproduction built without verdicts) gives its plain record."""
        by = {rec["preset"]: rec for rec in self.records if "preset" in rec}
        for run in self.runs:
            by.setdefault(run.case.preset, {**run.record, "preset": run.case.preset})
        return by


def _engine_settings(cases: Sequence[Case], n_batches: int) -> dict[str, str]:
    import numba

    def distinct(values: Iterable[Any]) -> str:
        return ", ".join(str(v) for v in dict.fromkeys(values))

    cfgs = [c.config for c in cases]
    return {
        "integrator": distinct(c.method.upper() for c in cfgs) + " (fixed step)",
        "controller": distinct(
            "continuous" if c.sampling is None else f"sampled, Ts = {c.sampling.ts:g} s"
            for c in cfgs
        ),
        "step dt [s]": distinct(c.dt for c in cfgs),
        "horizon [s]": distinct(c.scenario.t_final for c in cfgs),
        "trajectory decimation": distinct(c.decimation for c in cfgs)
        + " (every n-th step stored; metrics are integrated at every step)",
        "divergence threshold": distinct(f"{c.divergence_threshold:g}" for c in cfgs)
        + " (|state| or non-finite stops a member)",
        "cases / engine calls": f"{len(cases)} / {n_batches} (batched, members in parallel)",
        "numba threads": str(numba.config.NUMBA_NUM_THREADS),
        "versions": (
            f"aiofl {__import__('aiofl').__version__}, numpy {np.__version__}, "
            f"numba {numba.__version__}, Python {platform.python_version()}"
        ),
    }


def orbit_cost_rank(cfg: RunConfig) -> int:
    """How many of the observer, the feedback and the differentiator are nonlinear (the
    improved ESO counts twice): the orbit verdicts that take seconds have the most (the
    INLESO designs 0.4–13 s, the LESO ones 0–2.6 s, the linear ones ~0 s in a warm run),
    so they are started first."""
    c = cfg.controller
    return 2 * (c.eso == "improved") + (c.sef != "linear") + (c.td in ("han", "improved"))


def _timed_case_verdicts(presets: list[str], ts: float | None) -> tuple[dict[str, Any], float]:
    """:func:`aiofl.reporting.orbit_pool.case_verdicts` and when it ended
    (``time.perf_counter``): what :func:`compute` runs on a background thread."""
    return case_verdicts(presets, ts), time.perf_counter()


def _prepare_later_instances(cases: list[Case], *, sampled: bool) -> None:
    """Compile, in a second process, the instances of the cases' plants this run needs
    after its first simulation (:mod:`aiofl.engine.build.prepare`), in the order it needs them:
    the discrete controller's update (the sampled loop's linearisation), the sampled ones
    of width 1 and 32 for the sampling limits (a ladder of sample times per design: the
    kinds with many members run in lanes) and the sensor rows, then the width-32 one for
    the robustness draws (sampled when every design is); the first simulation compiles the
    width-1 one meanwhile."""
    from aiofl.engine.build.prepare import prepare_in_background
    from aiofl.plants.registry import available_plants

    names = {c.config.plant.name for c in cases} & set(available_plants())
    specs = list(dict.fromkeys([(1, True), (32, True), (32, sampled)]))
    for i, name in enumerate(sorted(names)):  # the plant-free controller update once
        prepare_in_background(name, specs, controller=i == 0)


def compute(
    *,
    available: Iterable[str] | None = None,
    on_stage: Callable[[str], None] | None = None,
    ts: float | None = None,
) -> Reproduction:
    """Discover and simulate all cases and derive the facts the report needs.

    The closed-loop verdicts of the runs that did not diverge (linearisation and orbit:
    :func:`aiofl.reporting.orbit_pool.case_verdicts`) are computed in worker processes,
    which load each design's preset by its name (and apply ``ts``), while this process
    computes the sampling limits.

    Parameters
    ----------
    available
        Preset names to choose from (as for :func:`discover_cases`).
    on_stage
        Called with a description before each stage (None: silent).
    ts
        Run every design sampled at this sample time [s] (None: as configured).

    Returns
    -------
    Reproduction
    """
    stage = on_stage or (lambda _msg: None)
    t0 = time.perf_counter()
    stage("loading presets")
    cases = discover_cases(available)
    if ts is not None:  # every design sampled at ts (raises ConfigError for a bad ts)
        cases = [replace(c, config=c.config.with_sample_time(ts)) for c in cases]
    n_batches = len({_batch_key(c.config) for c in cases})
    _prepare_later_instances(cases, sampled=ts is not None)
    stage(f"simulating {len(cases)} cases in {n_batches} batched call(s) (first call compiles)")
    t1 = time.perf_counter()
    runs = run_cases(cases)
    t2 = time.perf_counter()
    trivial = {s: trivial_itae(next(c for c in cases if c.scenario == s).config) for s in SCENARIOS}
    stage("closed-loop analysis")
    # each design's linearisation and orbit verdicts (Python-level variational integration)
    # in worker processes, the likely slowest first, while this process computes the
    # sampling limits (engine threads): a core an orbit worker leaves idle has work meanwhile
    configs = {c.preset: c.config for c in cases}
    live = [r.case.preset for r in runs if not r.result.failed]
    order = sorted(live, key=lambda name: -orbit_cost_rank(configs[name]))
    pool = ThreadPoolExecutor(max_workers=1)  # its workers are processes
    orbits = pool.submit(_timed_case_verdicts, order, ts)
    pool.shutdown(wait=False)
    # a run that diverged: its linearisation alone (the simulation and an unstable
    # linearisation agree, nothing to reconcile)
    verdicts = {
        r.case.preset: closed_loop_verdict(r.case.config, orbit=False)
        for r in runs
        if r.result.failed
    }
    stage("sampling limits (largest Ts per design, batched)")
    from aiofl.reporting.sampling_note import case_limits

    t3 = time.perf_counter()
    sampling = case_limits(configs)
    t4 = time.perf_counter()
    records, orbits_done = orbits.result()  # re-raises what the thread raised
    verdicts.update(records)
    # in the runs' order; a design without a worker's record: its linearisation alone
    verdicts = {
        r.case.preset: verdicts.get(r.case.preset)
        or closed_loop_verdict(r.case.config, orbit=False)
        for r in runs
    }
    return Reproduction(
        runs=runs,
        records=build_records(runs, verdicts),
        trivial=trivial,
        verdicts=verdicts,
        engine=_engine_settings(cases, n_batches),
        # analysis: linearisations and orbit verdicts, overlapping the sampling limits
        timings={
            "load": t1 - t0,
            "simulate": t2 - t1,
            "analysis": orbits_done - t2,
            "sampling": t4 - t3,
        },
        sampling=sampling,
    )
