"""Simulating closed loops: the Python-facing API of the compiled, batched engine.

:func:`simulate_batch` packs a *batch* of members (one row each of controller,
plant-parameter, scenario and discrete-controller arrays: a
:class:`~aiofl.engine.batch.Batch`), plans their groups (:func:`plan`: by timing, kinds and
lane width), runs each group on the plant's compiled instance of the time loop
(:mod:`aiofl.engine.kernel.loop`, :mod:`aiofl.engine.build.instances`) in parallel, and
unpacks the outputs; :func:`simulate` is a batch of one.  The closed loop (plant, tracking
differentiator, ESO, state error feedback, linearizing law and the performance integrals,
RK4 or forward Euler) is described in :mod:`aiofl.engine.kernel.continuous` and, sampled,
:mod:`aiofl.engine.kernel.sampled`.  A member that is *lost* (its plant left the operating
envelope: the output's distance from the reference or a declared range of the output or a
state) or *diverged* (its numbers blew up: a plant state non-finite or beyond
``divergence_threshold``, a controller state non-finite) is reported as such with the time,
the others carry on; results come back as a
:class:`BatchResult` (or a :class:`SimulationResult` per member), with the step metrics,
the noise in u and the saturation time of :mod:`aiofl.engine.response`.
:func:`closed_loop_rhs` evaluates the compiled right-hand side once, for cross-checks.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.checks import check_integer, check_number
from aiofl.components.metrics import OPIWeights, opi
from aiofl.controller import Controller, ControllerBatch, controller_batch
from aiofl.engine.batch import Batch, Outputs
from aiofl.engine.build.instances import instance_for, plan_groups, run, set_plant_table
from aiofl.engine.build.lane_choice import lanes_worth_it
from aiofl.engine.discrete_rows import D_STEPS, N_DISC, Sampling, check_delays, sampling_rows
from aiofl.engine.kernel.loop import WIDTH
from aiofl.engine.kernel.plant_calls import N_TABLE
from aiofl.engine.observer_gains import model_jacobians, with_model_gains
from aiofl.engine.response import response_figures
from aiofl.limits import DT_MAX, MAX_STEPS, MAX_TRAJECTORY_BYTES, check_run_size
from aiofl.plants.base import Plant
from aiofl.scenario import Scenario, noise_sequence

__all__ = ["BatchResult", "SimulationResult", "closed_loop_rhs", "simulate", "simulate_batch"]


# ---------------------------------------------------------------------------- results
@dataclass(frozen=True)
class SimulationResult:
    """One member's result.

    Attributes
    ----------
    metrics
        ``itae, iae, ise, isu, iau`` over the horizon (None if lost or diverged).
    status
        What the run did: ``"ok"``, ``"lost"`` (the plant left its envelope) or
        ``"diverged"`` (numerical blow-up) (:data:`aiofl.layout.STATUS_NAMES`).
    stopped_at
        When it was lost or diverged [s] (None if ok).
    t, signals
        Saved time points and a dict of signals by column name (``r, y, y_meas, u, d,
        x1.., xi_hat1.., r1..``); empty if trajectories were not stored.
    response
        The figures of :data:`aiofl.engine.response.RESPONSE_NAMES` (step metrics, noise
        in u, peaks, saturation time; NaN where they do not apply).
    """

    metrics: dict[str, float] | None
    status: str
    stopped_at: float | None
    t: NDArray[np.float64]
    signals: dict[str, NDArray[np.float64]]
    response: dict[str, float] = field(default_factory=dict)

    @property
    def diverged(self) -> bool:
        """Whether the numbers blew up (status ``"diverged"``)."""
        return self.status == "diverged"

    @property
    def lost(self) -> bool:
        """Whether the plant left its envelope (status ``"lost"``)."""
        return self.status == "lost"

    @property
    def failed(self) -> bool:
        """Lost or diverged: the run has no metrics."""
        return self.status != "ok"

    @property
    def diverged_at(self) -> float | None:
        """When the run diverged [s] (None unless diverged)."""
        return self.stopped_at if self.diverged else None

    def opi(self, weights: OPIWeights | None = None) -> float | None:
        """OPI (eq. 22) of this run, or None if it diverged."""
        if self.metrics is None:
            return None
        m = self.metrics
        return float(opi(m["itae"], m["isu"], m["iau"], weights))

    def __getitem__(self, name: str) -> NDArray[np.float64]:
        return self.signals[name]


@dataclass(frozen=True)
class BatchResult:
    """Results of a batch: ``metrics`` (B, 5) by :data:`aiofl.layout.METRIC_NAMES`,
    ``status`` (B,) (:data:`aiofl.layout.STATUS_OK`, ``STATUS_LOST``, ``STATUS_DIVERGED``),
    ``stopped_at`` (B,) when a member was lost or diverged [s, NaN if ok], ``response``
    the figures of :data:`aiofl.engine.response.RESPONSE_NAMES` (each (B,)),
    ``trajectories`` (B, T, C) or None, with ``columns`` naming C."""

    metrics: NDArray[np.float64]
    status: NDArray[np.int64]
    stopped_at: NDArray[np.float64]
    trajectories: NDArray[np.float64] | None
    columns: tuple[str, ...]
    dt: float
    response: dict[str, NDArray[np.float64]] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.metrics.shape[0])

    @property
    def diverged(self) -> NDArray[np.bool_]:
        """(B,) the members whose numbers blew up."""
        return np.asarray(self.status == L.STATUS_DIVERGED)

    @property
    def lost(self) -> NDArray[np.bool_]:
        """(B,) the members whose plant left its envelope."""
        return np.asarray(self.status == L.STATUS_LOST)

    @property
    def failed(self) -> NDArray[np.bool_]:
        """(B,) lost or diverged: the members without metrics."""
        return np.asarray(self.status != L.STATUS_OK)

    @property
    def diverged_at(self) -> NDArray[np.float64]:
        """(B,) when a member diverged [s] (NaN unless diverged)."""
        return np.where(self.diverged, self.stopped_at, np.nan)

    def metric(self, name: str) -> NDArray[np.float64]:
        """One metric for every member (NaN where the member was lost or diverged)."""
        col = self.metrics[:, L.METRIC_NAMES.index(name)].copy()
        col[self.failed] = np.nan
        return col

    def opi(self, weights: OPIWeights | None = None) -> NDArray[np.float64]:
        """OPI (eq. 22) of every member (NaN where the member was lost or diverged)."""
        return np.asarray(opi(self.metric("itae"), self.metric("isu"), self.metric("iau"), weights))

    def member(self, i: int) -> SimulationResult:
        """Member ``i`` as a :class:`SimulationResult` (trajectory cut where it stopped)."""
        status = L.STATUS_NAMES[int(self.status[i])]
        ok = status == "ok"
        mets = (
            {k: float(v) for k, v in zip(L.METRIC_NAMES, self.metrics[i], strict=True)}
            if ok
            else None
        )
        stop = None if ok else float(self.stopped_at[i])
        resp = {k: float(v[i]) for k, v in self.response.items()}
        if self.trajectories is None:
            return SimulationResult(mets, status, stop, np.empty(0), {}, resp)
        tr = self.trajectories[i]
        tr = tr[~np.isnan(tr[:, 0])]
        sig = {c: tr[:, j] for j, c in enumerate(self.columns) if c != "t"}
        return SimulationResult(mets, status, stop, tr[:, 0], sig, resp)


# ------------------------------------------------------------------------------- API
def _as_list(x: Any, n: int, what: str) -> list[Any]:
    if isinstance(x, (list, tuple)):
        if len(x) not in (1, n):
            raise ValueError(f"{len(x)} {what} for a batch of {n}")
        return list(x) * (n if len(x) == 1 else 1)
    return [x] * n


def _check_settings(
    plant: Any, method: Any, dt: Any, decimation: Any, divergence_threshold: Any
) -> tuple[float, int, float]:
    """The run settings, refused as the config's ``[simulation]`` table refuses them
    (:class:`aiofl.config.schema.SimulationModel`): ``ValueError`` naming the argument."""
    if not isinstance(plant, Plant):
        raise ValueError(f"plant = {plant!r}; allowed: an aiofl.Plant (e.g. get_plant('slfjm'))")
    if not isinstance(method, str) or method not in L.METHODS:
        raise ValueError(f"simulation.method = {method!r}; allowed: {', '.join(L.METHODS)}")
    return (
        check_number("simulation.dt", dt, gt=0.0, le=DT_MAX),
        check_integer("simulation.decimation", decimation, ge=1, le=MAX_STEPS),
        # finite: an infinite threshold would switch divergence detection off
        check_number("simulation.divergence_threshold", divergence_threshold, gt=0.0, le=1e300),
    )


def _check_members(controllers: Any, scenarios: Any, sampling: Any) -> None:
    """Refuse controllers, scenarios or sampling settings of the wrong kind, or none."""
    if not isinstance(controllers, (Controller, ControllerBatch)):
        if isinstance(controllers, (str, bytes)) or not isinstance(controllers, Sequence):
            raise ValueError(
                f"controllers = {controllers!r}; allowed: a Controller, a non-empty sequence "
                "of Controllers or a ControllerBatch"
            )
        bad = [i for i, c in enumerate(controllers) if not isinstance(c, Controller)]
        if not controllers or bad:
            got = "an empty sequence" if not controllers else repr(controllers[bad[0]])
            raise ValueError(
                f"controllers: {got}"
                + (f" at index {bad[0]}" if bad else "")
                + "; allowed: a Controller, a non-empty sequence of Controllers or a "
                "ControllerBatch (e.g. Controller.from_structure('LESO'))"
            )
    elif isinstance(controllers, ControllerBatch) and len(controllers) == 0:
        raise ValueError("controllers: an empty ControllerBatch; allowed: at least one member")
    many = isinstance(scenarios, (list, tuple))
    scens = list(scenarios) if many else [scenarios]
    if not scens or not all(isinstance(s, Scenario) for s in scens):
        raise ValueError(
            f"scenarios = {scenarios!r}; allowed: a Scenario or a non-empty list of Scenarios"
        )
    samp = list(sampling) if isinstance(sampling, (list, tuple)) else [sampling]
    if not all(s is None or isinstance(s, Sampling) for s in samp):
        raise ValueError(
            f"sampling = {sampling!r}; allowed: None, a Sampling, or a list of them (one per "
            "member)"
        )


#: most bytes of a batch's stored trajectories together (members x points x columns x 8):
#: 8 x the per-member bound of :func:`aiofl.limits.check_run_size`, room for the reports'
#: batches of stored runs, refusing a batch that would exhaust the machine's memory
MAX_BATCH_TRAJECTORY_BYTES = 8 * MAX_TRAJECTORY_BYTES


def _check_size(
    plant: Plant, scens: list[Scenario], b: int, dt: float, *, store: bool, decimation: int
) -> None:
    """The run's size, bounded before anything is allocated (:func:`aiofl.limits.check_run_size`:
    a whole number of steps, at most ``MAX_STEPS``, the noise table, a stored trajectory),
    and the batch's stored trajectories together at most :data:`MAX_BATCH_TRAJECTORY_BYTES`."""
    t_final = scens[0].t_final
    if any(abs(s.t_final - t_final) > 1e-12 for s in scens):
        raise ValueError("all scenarios in one batch must share t_final")
    columns = len(L.trajectory_columns(plant.n_states))
    n = check_run_size(
        t_final,
        dt,
        noise_hold=min(s.noise_hold for s in scens),
        trajectory_columns=columns if store else None,
        decimation=decimation,
    )
    nbytes = b * (n // decimation + 1) * columns * 8
    if store and nbytes > MAX_BATCH_TRAJECTORY_BYTES:
        raise ValueError(
            f"the batch's stored trajectories need {nbytes / 2**20:.0f} MiB ({b} members x "
            f"{n // decimation + 1} points x {columns} columns x 8 bytes; simulation.decimation"
            f" = {decimation}); allowed: at most {MAX_BATCH_TRAJECTORY_BYTES // 2**20} MiB (store "
            "fewer members, or raise decimation or dt)"
        )


def simulate_batch(
    plant: Plant,
    controllers: Controller | Sequence[Controller] | ControllerBatch,
    scenarios: Scenario | Sequence[Scenario],
    *,
    dt: float = 1e-4,
    method: str = "rk4",
    store: bool = False,
    decimation: int = 10,
    divergence_threshold: float = 1e10,
    sampling: Sampling | Sequence[Sampling | None] | None = None,
    engine: str | None = None,
) -> BatchResult:
    """Simulate a batch of closed loops in one compiled, parallel call.

    Parameters
    ----------
    plant
        The plant (its kernel is compiled on first use and cached).
    controllers
        One controller, a sequence (one per member) or a packed :class:`ControllerBatch`.
    scenarios
        One scenario for all members, or one per member; all share ``t_final``.
    dt
        Fixed step [s].
    method
        ``"rk4"`` or ``"euler"``.
    store, decimation
        Store trajectories, every ``decimation``-th step.
    divergence_threshold
        A member whose state leaves ``|z| < threshold`` (or becomes NaN) is stopped and
        reported as diverged.
    sampling
        Run controllers sampled (:class:`aiofl.engine.discrete_rows.Sampling`): one setting for
        all members or one per member (None = continuous); sample times must be integer
        multiples of ``dt`` (:mod:`aiofl.engine.kernel.sampled`).  Continuous members are
        unaffected.
    engine
        ``"lanes"``: members run in groups of 32, one per SIMD lane, or alone (width 1)
        when their kind has few members (:mod:`aiofl.engine.build.instances`); ``"auto"``
        (default): as ``"lanes"``, but members run alone while the plant's lane instance
        is neither at hand (built, or in the kernel cache) nor worth its compile for the
        work so far (:mod:`aiofl.engine.build.lane_choice`): the same numbers, bit for bit;
        ``"scalar"``: every member alone, in the same time loop compiled with libm and
        the components' fast-math flags, a differently-rounded check of the lane engine.
        Default: the environment variable ``AIOFL_ENGINE``, else ``"auto"``.  Sampled
        members run the sampled instance of the same loop (the plant in lanes, the
        controller lane by lane at the samples).

    Returns
    -------
    BatchResult
    """
    engine = _engine_choice(engine)
    dt, decimation, divergence_threshold = _check_settings(
        plant, method, dt, decimation, divergence_threshold
    )
    _check_members(controllers, scenarios, sampling)
    batch = (
        controllers
        if isinstance(controllers, ControllerBatch)
        else controller_batch(
            controllers if isinstance(controllers, Controller) else list(controllers)
        )
    )
    b = len(batch)
    scens = _as_list(scenarios, b, "scenarios")
    _check_size(plant, scens, b, dt, store=store, decimation=decimation)
    if not isinstance(controllers, ControllerBatch):  # a packed batch is checked when built
        ctrls = [controllers] * b if isinstance(controllers, Controller) else list(controllers)
        pairs = {(id(c), id(s)): (c, s) for c, s in zip(ctrls, scens, strict=True)}
        for c, s in pairs.values():
            c.check_plant(plant, s.x0 or None)  # ρ, IOFL's normal form, the sign of b0
    samplings = _as_list(sampling, b, "sampling settings")
    # a model-assisted observer's gains are placed for the plant's nominal model
    jac = model_jacobians(plant, batch, [s.x0 for s in scens])
    disc = sampling_rows(batch, samplings, dt, jac) if any(samplings) else None
    batch = with_model_gains(batch, jac)
    rec, out = pack(
        plant,
        batch,
        scens,
        disc,
        dt=dt,
        method=method,
        store=store,
        decimation=decimation,
        divergence_threshold=divergence_threshold,
    )
    run_plan(plant, plan(rec, engine, plant), rec, out, engine)
    return BatchResult(
        metrics=out.metrics,
        status=out.status,
        stopped_at=out.t_stop,
        trajectories=out.traj if store else None,
        columns=L.trajectory_columns(plant.n_states),
        dt=float(dt),
        response=response_figures(
            out.stats, rec.scen, out.status, out.t_stop, float(dt), rec.n_steps * float(dt)
        ),
    )


def pack(
    plant: Plant,
    batch: ControllerBatch,
    scens: list[Scenario],
    disc: NDArray[np.float64] | None,
    *,
    dt: float,
    method: str,
    store: bool,
    decimation: int,
    divergence_threshold: float,
) -> tuple[Batch, Outputs]:
    """The batch as the time loop reads it, and its output arrays: one row per member of
    every table (the scenario tables computed once per distinct scenario), the discrete
    rows ``disc`` (zeros for continuous members) and the run's settings."""
    t_final = scens[0].t_final
    b = len(batch)
    n_steps = round(t_final / dt)
    n = plant.n_states

    # per-scenario tables (computed once per distinct scenario)
    uniq: dict[int, int] = {}
    for s in scens:
        uniq.setdefault(id(s), len(uniq))
    distinct = list({id(s): s for s in scens}.values())
    rows = np.array([uniq[id(s)] for s in scens], dtype=np.int64)
    p_nom_vec = plant.param_vector()
    p_nom = np.repeat(p_nom_vec[None, :], b, axis=0)
    p_before_d = np.stack([p_nom_vec for _ in distinct])
    p_after_d = np.stack([plant.param_vector(s.plant_overrides, s.plant_scale) for s in distinct])
    # a change at t = 0 applies from the start
    scen_d = np.stack([s.row() for s in distinct])
    x0_d = np.zeros((len(distinct), n))
    for j, s in enumerate(distinct):
        if s.x0:
            if len(s.x0) != n:
                raise ValueError(f"scenario.x0 has {len(s.x0)} entries; plant has {n} states")
            x0_d[j] = s.x0
    n_noise = max(s.noise_samples for s in distinct)
    noise_d = np.stack(
        [
            noise_sequence(s.noise_seed, n_noise) if s.noise_variance > 0 else np.zeros(n_noise)
            for s in distinct
        ]
    )
    n_ref = max([len(s.reference.samples) for s in distinct] + [2])
    ref_d = np.zeros((len(distinct), n_ref))
    for j, s in enumerate(distinct):
        if s.reference.samples:
            ref_d[j, : len(s.reference.samples)] = s.reference.samples
            ref_d[j, len(s.reference.samples) :] = s.reference.samples[-1]

    for j, s in enumerate(distinct):  # the default envelope counts y(0) = h(x0)
        if s.envelope is None:
            scen_d[j, L.S_ENVELOPE] = s.default_envelope(_output_at(plant, x0_d[j], p_before_d[j]))
    check_delays(scen_d[rows], disc, dt)  # transport delays: sampled, k·dt, bounded
    continuous = np.ones(len(batch.floats), dtype=bool) if disc is None else disc[:, D_STEPS] == 0
    if np.any(continuous & (batch.floats[:, L.F_ESO_DELAY] != 0.0)):
        raise ValueError(
            "controller.eso.delay (a known measurement delay to compensate) needs a sampled "
            "controller ([sensor] ts or aiofl simulate --ts); allowed: eso.delay = 0 for a "
            "continuous one"
        )
    n_save = n_steps // decimation + 1 if store else 0
    n_cols = len(L.trajectory_columns(n))
    rec = Batch(
        ints=batch.ints,
        floats=batch.floats,
        p_before=np.ascontiguousarray(p_before_d[rows]),
        p_after=np.ascontiguousarray(p_after_d[rows]),
        p_nom=p_nom,
        scen=np.ascontiguousarray(scen_d[rows]),
        x0=np.ascontiguousarray(x0_d[rows]),
        ref_table=ref_d,
        ref_row=rows,
        noise_table=noise_d,
        noise_row=rows,
        disc=disc if disc is not None else np.zeros((b, N_DISC)),
        bounds=np.ascontiguousarray(np.repeat(plant.bounds_array()[None], b, axis=0)),
        plant_table=np.zeros(N_TABLE, dtype=np.int64),
        dt=float(dt),
        n_steps=int(n_steps),
        method=int(L.METHODS[method]),
        decimation=int(decimation),
        store=bool(store),
        threshold=float(divergence_threshold),
    )
    out = Outputs(
        metrics=np.zeros((b, L.N_METRIC)),
        status=np.zeros(b, dtype=np.int64),
        t_stop=np.zeros(b),
        stats=np.zeros((b, L.N_STAT)),
        traj=np.empty((b, n_save, n_cols)),  # rows after a divergence are set to NaN
    )
    return rec, out


def _output_at(plant: Plant, x: NDArray[np.float64], p: NDArray[np.float64]) -> float:
    """y = h(x) on the host (0 when the plant's h cannot say: the engine will)."""
    try:
        y = float(plant.h(np.asarray(x, dtype=np.float64), np.asarray(p, dtype=np.float64)))
    except Exception:  # a plant that raises here is reported by the engine
        return 0.0
    return y if np.isfinite(y) else 0.0


def plan(
    batch: Batch, engine: str = "auto", plant: Plant | None = None
) -> dict[tuple[int, bool], NDArray[np.int64]]:
    """The groups to run, by (lane width, sampled): continuous and sampled members apart,
    grouped by kinds (:func:`aiofl.engine.build.instances.plan_groups`); with ``engine="scalar"``
    every member alone (width 1); with ``engine="auto"`` (and the ``plant``) the members
    planned for lanes run alone instead when the lanes are neither at hand nor worth
    compiling (:func:`aiofl.engine.build.lane_choice.lanes_worth_it`)."""
    steps = batch.disc[:, D_STEPS]
    sampled = steps > 0
    out: dict[tuple[int, bool], NDArray[np.int64]] = {}
    ref_kind = batch.scen[:, L.S_REF_KIND]
    for is_sampled in (False, True):
        members = np.flatnonzero(sampled == is_sampled)
        if not members.size:
            continue
        if engine == "scalar":
            out[(1, is_sampled)] = members.reshape(-1, 1)
            continue
        by_steps = steps if is_sampled else None
        planned = plan_groups(batch.ints, ref_kind, members, by_steps)
        if engine == "auto" and plant is not None and WIDTH in planned:
            in_lanes = int(np.count_nonzero(planned[WIDTH] >= 0))
            if not lanes_worth_it(plant, is_sampled, float(in_lanes) * batch.n_steps):
                planned = {1: members.reshape(-1, 1)}
        for width, groups in planned.items():
            out[(width, is_sampled)] = groups
    return out


def run_plan(
    plant: Plant,
    groups_by_instance: dict[tuple[int, bool], NDArray[np.int64]],
    batch: Batch,
    out: Outputs,
    engine: str = "auto",
) -> None:
    """Run every planned group on its instance (compiled on first use)."""
    variant = "scalar" if engine == "scalar" else "lanes"
    for (width, is_sampled), groups in groups_by_instance.items():
        run(plant, width, groups, batch, out, sampled_data=is_sampled, variant=variant)


ENGINES = ("auto", "lanes", "scalar")
"""The time loops :func:`simulate_batch` can run (``engine``)."""


def _engine_choice(engine: str | None) -> str:
    import os

    choice = engine if engine is not None else os.environ.get("AIOFL_ENGINE", "") or "auto"
    if choice not in ENGINES:
        raise ValueError(f"engine = {choice!r}; allowed: {', '.join(ENGINES)}")
    return choice


def simulate(
    plant: Plant,
    controller: Controller,
    scenario: Scenario,
    *,
    dt: float = 1e-4,
    method: str = "rk4",
    store: bool = True,
    decimation: int = 10,
    divergence_threshold: float = 1e10,
    sampling: Sampling | None = None,
) -> SimulationResult:
    """Simulate one closed loop (a batch of one). See :func:`simulate_batch`.

    Parameters
    ----------
    plant, controller, scenario, dt, method, store, decimation, divergence_threshold, sampling
        As for :func:`simulate_batch`, one controller and one scenario (``store``: True here).

    Returns
    -------
    SimulationResult
        The one member's result (member 0 of the batch's :class:`BatchResult`).
    """
    res = simulate_batch(
        plant,
        controller,
        scenario,
        dt=dt,
        method=method,
        store=store,
        decimation=decimation,
        divergence_threshold=divergence_threshold,
        sampling=sampling,
    )
    return res.member(0)


def closed_loop_rhs(
    plant: Plant,
    controller: Controller,
    scenario: Scenario,
    t: float,
    x: Sequence[float],
    td: Sequence[float] = (),
    xi: Sequence[float] = (),
    *,
    noise: float = 0.0,
    changed: bool = False,
) -> dict[str, Any]:
    """One evaluation of the engine's compiled right-hand side :math:`F(t, z)`.

    For cross-checks against an independent implementation (:mod:`aiofl.engine.reference`):
    the same compiled code the time loop runs, at a chosen state.

    Parameters
    ----------
    plant, controller, scenario
        As for :func:`simulate`.
    t
        Time [s].
    x, td, xi
        Plant state (n), differentiator state (0, 2 or ρ entries; missing ones are 0) and
        observer state ξ̂ (ρ+1 entries; missing ones are 0).
    noise
        Measurement noise added to y at this instant.
    changed
        Use the changed plant parameters (``scenario.plant_scale``/``plant_overrides``).

    Returns
    -------
    dict
        ``dx``, ``dtd``, ``dxi``, ``dmetrics`` (ITAE, IAE, ISE, ISU, IAU integrands) and the
        signals ``r``, ``y``, ``y_meas``, ``u``, ``d``.
    """
    evaluate = instance_for(plant, 1).namespace["_EVAL"]
    n = plant.n_states
    rho = controller.rho
    n_td = {"exact": 0, "han": 2, "improved": 2, "linear": rho}[controller.td]
    batch = controller_batch(controller)
    batch = with_model_gains(batch, model_jacobians(plant, batch, [scenario.x0]))
    p_nom = plant.param_vector()
    p = plant.param_vector(scenario.plant_overrides, scenario.plant_scale) if changed else p_nom
    nz = n + L.N_METRIC + 2 * L.RHO_MAX + 1
    z = np.zeros(nz)
    z[:n] = np.asarray(x, dtype=float)
    o_td = n + L.N_METRIC
    o_eso = o_td + n_td
    td_v = np.asarray(td, dtype=float)
    xi_v = np.asarray(xi, dtype=float)
    if td_v.size > n_td or xi_v.size > rho + 1:
        raise ValueError(f"td has at most {n_td} entries and xi at most {rho + 1}")
    z[o_td : o_td + td_v.size] = td_v
    z[o_eso : o_eso + xi_v.size] = xi_v
    dz = np.zeros(nz)
    sig = np.zeros(5)
    rec, _ = pack(
        plant,
        batch,
        [scenario],
        None,
        dt=scenario.t_final,
        method="rk4",
        store=False,
        decimation=1,
        divergence_threshold=1.0,
    )
    rec = rec._replace(p_after=p[None, :])  # the parameters the right-hand side sees
    set_plant_table(plant, rec)
    evaluate(rec, float(t), z, float(noise), dz, sig)
    return {
        "dx": dz[:n].copy(),
        "dmetrics": dz[n : n + L.N_METRIC].copy(),
        "dtd": dz[o_td:o_eso].copy(),
        "dxi": dz[o_eso : o_eso + rho + 1].copy(),
        **dict(zip(("r", "y", "y_meas", "u", "d"), (float(v) for v in sig), strict=True)),
    }
