r"""Tuning controllers with a genetic algorithm (pymoo) on the paper's OPI, locally or on Dask.

The paper tuned each controller with a GA on its objective performance index (22) over
:math:`t_f = 6` s.  :func:`tune` does the same for any config: the ``[tune]`` table
(:mod:`aiofl.tuning.space`) names the parameters, their bounds and the objective; each
generation is evaluated by **one** batched engine call (:mod:`aiofl.tuning.evaluate`), or in
chunks on a dask.distributed cluster, with identical numbers either way.  :func:`prepare`
validates a config and its settings before anything is run or written; :func:`tune` returns
a :class:`TuneResult`.  The checkpoint written after every generation and its replay on
resume are in :mod:`aiofl.tuning.checkpoint`, the output files in :mod:`aiofl.tuning.results`.

Notes
-----
The algorithm's random stream is seeded (``seed``); pymoo 0.6.2 keeps it in the algorithm
(``np.random.default_rng(seed)``), the initial Latin-hypercube sample is drawn from its own
seeded generator, and CMA-ES is seeded with ``seed + 1`` (cma treats 0 as "use the
clock").  The same seed therefore gives the same run bit for bit, and a resumed run ends
with exactly the result of an uninterrupted one.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.tuning.ceiling import clip_to_ceiling
from aiofl.tuning.checkpoint import (
    CHECKPOINT,
    CHECKPOINT_FORMAT,
    check_replay,
    load_checkpoint,
    save_checkpoint,
)
from aiofl.tuning.progress import TuneProgress
from aiofl.tuning.space import (
    MAX_POPULATION,
    SearchSpace,
    TuneSettings,
    config_with_values,
    objective_coefficients,
    objective_values,
    parse_tune_settings,
    to_toml,
    used_parameters,
)

if TYPE_CHECKING:  # pragma: no cover
    from aiofl.config import RunConfig
    from aiofl.tuning.evaluate import EvalSpec, PopulationResult

__all__ = [
    "TuneResult",
    "TuneSettings",
    "describe_tuning",
    "parse_tune_settings",
    "prepare",
    "tune",
]


# ------------------------------------------------------------------------ results
@dataclass(frozen=True)
class TuneResult:
    """Outcome of :func:`tune`.

    Attributes
    ----------
    settings
        The validated ``[tune]`` settings used.
    names
        Tuned parameters (engine column names).
    best_values
        Best parameter values found (lowest objective; earliest on ties).
    best_objective
        Its objective over the tuning horizon.
    best_metrics
        Its ``itae, iae, ise, isu, iau`` over the tuning horizon (None if it diverged).
    values, objective, generation, diverged
        Every evaluated member, in evaluation order: parameter values (N, d), objective
        (N,), generation index from 1 (N,), divergence flag (N,).
    history
        One dict per generation (see ``history.csv``).
    config
        The input config dict with the best values written in (``best.toml``'s data).
    source
        Where the input config came from (file or preset name).
    evaluator
        ``"local"`` or a description of the Dask cluster.
    live_evaluations, live_seconds
        Candidates simulated in this call (not replayed from a checkpoint) and the time
        spent (a robust candidate is K + 1 simulations).
    front
        ``algorithm = "nsga2"``: the Pareto front and its chosen design
        (:class:`aiofl.tuning.front.Front`; ``best_values`` is the chosen design).
    """

    settings: TuneSettings
    names: tuple[str, ...]
    best_values: dict[str, float]
    best_objective: float
    best_metrics: dict[str, float] | None
    values: NDArray[np.float64]
    objective: NDArray[np.float64]
    generation: NDArray[np.int64]
    failed: NDArray[np.bool_]
    history: list[dict[str, float]]
    config: dict[str, Any]
    source: str = ""
    evaluator: str = "local"
    live_evaluations: int = 0
    live_seconds: float = 0.0
    front: Any = None  # nsga2: the Pareto front (aiofl.tuning.front.Front)

    @property
    def n_evaluations(self) -> int:
        """Members evaluated in the whole run (including replayed generations)."""
        return int(self.objective.size)

    @property
    def evals_per_second(self) -> float:
        """Simulated members per wall-clock second in this call (NaN if none were live)."""
        if self.live_evaluations == 0 or self.live_seconds <= 0:
            return float("nan")
        return self.live_evaluations / self.live_seconds

    def run_config(self) -> RunConfig:
        """The best config, validated and built (its own horizon, e.g. the 20-s scenario)."""
        from aiofl.config import parse_config

        return parse_config(self.config, "tuned config")

    def toml(self, header: str = "") -> str:
        """``best.toml``'s text (the config with the best values), with an optional header."""
        return to_toml(self.config, header or self.describe())

    def describe(self) -> str:
        """Provenance lines for the TOML header."""
        s = self.settings
        obj = s.objective if isinstance(s.objective, str) else json.dumps(s.objective)
        rob = ""
        if s.robust is not None:
            r = s.robust
            agg = f"cvar alpha = {r.alpha:g}" if r.aggregate == "cvar" else r.aggregate
            rob = f", robust over the nominal plant + {r.draws} [uncertainty] draws ({agg})"
            if r.corners:
                rob = rob[:-1] + "; and the box corners)"
        if s.noise_realisations > 1:
            rob += f", mean over {s.noise_realisations} noise realisations"
        if self.front is not None:
            f = self.front
            cons = f" under {', '.join(f.constraints)}" if f.constraints else ""
            chosen = ", ".join(
                f"{q} {v:.6g}" for q, v in zip(f.objectives, f.F[f.chosen], strict=True)
            )
            return (
                f"Tuned by `aiofl tune` from {self.source or 'a config'}: {s.budget()}, "
                f"objectives {', '.join(f.objectives)}{cons} over t_f = {s.t_final:g} s{rob}.\n"
                f"Chosen from the {f.F.shape[0]}-design Pareto front by {f.rule}: {chosen} "
                f"({self.n_evaluations} evaluations, {int(self.failed.sum())} lost or diverged)."
            )
        return (
            f"Tuned by `aiofl tune` from {self.source or 'a config'}: {s.budget()}, "
            f"objective {obj} over t_f = {s.t_final:g} s{rob}.\n"
            f"Best objective {self.best_objective:.6g} after {self.n_evaluations} evaluations "
            f"({int(self.failed.sum())} lost or diverged)."
        )


def describe_tuning(run_config: RunConfig) -> str | None:
    """One line stating how a config was tuned (budget, seed, objective, horizon), read from
    its ``[tune]`` table, or None if it has none (e.g. for the report's re-tuned rows)."""
    data = run_config.raw.get("tune")
    if not data:
        return None
    st = parse_tune_settings(data)
    obj = st.objective
    if isinstance(obj, str):
        obj_text = obj.upper()
    else:
        obj_text = " + ".join(("" if w == 1 else f"{w:g}·") + k.upper() for k, w in obj.items())
    if st.objectives:
        obj_text = "objectives " + ", ".join(q.upper() for q in st.objectives)
        obj_text += f" under {', '.join(st.constraints)}" if st.constraints else ""
        obj_text += f", chosen by {st.choose}"
    else:
        obj_text = f"objective {obj_text}"
    if st.robust is not None:
        corners = " + the box corners" if st.robust.corners else ""
        obj_text += (
            f", robust ({st.robust.aggregate} over nominal + {st.robust.draws} draws{corners})"
        )
    horizon = st.t_final or run_config.scenario.t_final  # None: the scenario's
    return f"{st.budget()}, {obj_text} over {horizon:g} s (aiofl tune)"


# ---------------------------------------------------------------------- preparing
@dataclass(frozen=True)
class _Prepared:
    config: RunConfig
    settings: TuneSettings
    space: SearchSpace
    spec: EvalSpec
    coefficients: NDArray[np.float64]
    initial: NDArray[np.float64]  # initial population in the unit cube
    fingerprint: str
    source: str
    objectives: tuple[Any, ...] = ()  # nsga2: parsed Quantity objects
    constraints: tuple[Any, ...] = ()  # nsga2: parsed Constraint objects
    notes: tuple[str, ...] = ()  # what preparing changed (tune.omega0_ceiling)


def _check_parameters(cfg: RunConfig, settings: TuneSettings) -> None:
    from aiofl.config import ConfigError, parse_config

    used = used_parameters(cfg.controller)
    c = cfg.controller
    for name, b in settings.parameters.items():
        if name not in used:
            raise ConfigError(
                f"tune.parameters.{name!r}: has no effect on this controller (structure "
                f"{c.structure}: eso={c.eso!r}, td={c.td!r}, sef={c.sef!r}, law={c.law!r}, "
                f"rho={c.rho}, n_feedback={c.n_feedback}); allowed: {', '.join(sorted(used))}"
            )
        for which, val in (("lo", b.lo), ("hi", b.hi)):
            try:
                parse_config(config_with_values(cfg.raw, c, {name: val}), "tune bounds")
            except ConfigError as exc:
                detail = str(exc).split("\n", 1)[-1].strip()
                raise ConfigError(
                    f"tune.parameters.{name!r}.{which} = {val}: outside the range the config "
                    f"allows for this parameter: {detail}"
                ) from None


def _initial_population(space: SearchSpace, cfg: RunConfig, settings: TuneSettings) -> Any:
    from scipy.stats import qmc

    rng = np.random.default_rng([settings.seed, 0x5EED])
    pop = qmc.LatinHypercube(d=space.n_var, rng=rng).random(settings.population)
    if settings.include_initial:
        current = np.array([cfg.controller.value(n) for n in space.names])
        pop[0] = space.encode(current[None, :])[0]
    return pop


def prepare(
    run_config: RunConfig | str | Path,
    settings: TuneSettings | Mapping[str, Any] | None = None,
    *,
    draws: Sequence[Mapping[str, Any]] | None = None,
    **overrides: Any,
) -> _Prepared:
    """Validate a config and its tune settings before anything is run or written.

    ``run_config`` is a :class:`~aiofl.config.RunConfig`, a TOML path or a preset name;
    ``settings`` defaults to the config's ``[tune]`` table; ``overrides`` (e.g.
    ``seed=3``) replace settings fields.  ``draws`` (robust runs only) gives the K
    scenario changes explicitly (dicts of :class:`~aiofl.scenario.Scenario` fields, e.g.
    ``{"plant_scale": {"J_l": 1.2}}``) instead of drawing them from the config's
    ``[uncertainty]`` table.  Raises :class:`aiofl.config.ConfigError`.
    """
    from aiofl.config import ConfigError, load_config
    from aiofl.limits import check_run_size
    from aiofl.tuning.evaluate import EvalSpec

    cfg = load_config(run_config) if isinstance(run_config, (str, Path)) else run_config
    source = str(run_config) if cfg is not run_config else cfg.name
    st = parse_tune_settings(settings if settings is not None else cfg.raw.get("tune"))
    overrides = {k: v for k, v in overrides.items() if v is not None}
    st = parse_tune_settings({**st.model_dump(exclude_none=True), **overrides})
    st = st.with_horizon(cfg.scenario.t_final, source)  # t_final: the scenario's by default
    st, notes = clip_to_ceiling(cfg, st, source)  # tune.omega0_ceiling: eso.omega0's hi
    _check_parameters(cfg, st)
    try:  # the tuning horizon's size, before any member is allocated
        check_run_size(
            st.t_final, st.dt or cfg.dt, noise_hold=cfg.scenario.noise_hold, what="[tune]"
        )
    except ValueError as exc:
        msg = str(exc).replace("scenario.t_final", "tune.t_final")
        if st.dt is not None:
            msg = msg.replace("simulation.dt", "tune.dt")
        raise ConfigError(f"invalid [tune] of {source or cfg.name}: {msg}") from None
    if st.dt:  # a sampled controller's Ts must be a multiple of the tuning step too
        replace(cfg, dt=st.dt).check_sampling()
    space = SearchSpace(st.parameters)
    raw = {k: v for k, v in cfg.raw.items() if k != "tune"}
    robust_draws: tuple[Mapping[str, Any], ...] = ()
    if st.robust is not None:
        from aiofl.tuning.robust import draw_fields

        if draws is None:
            robust_draws = draw_fields(cfg, st.robust.draws, st.dt or cfg.dt)
        else:
            robust_draws = tuple(dict(d) for d in draws)
        if len(robust_draws) != st.robust.draws:
            raise ConfigError(
                f"tune.robust.draws = {st.robust.draws} but {len(robust_draws)} draws given"
            )
        if st.robust.corners:  # the box corners after the draws (given or drawn)
            robust_draws += draw_fields(cfg, 0, st.dt or cfg.dt, corners=True)
            k1 = (1 + len(robust_draws)) * st.noise_realisations
            if st.population * k1 > MAX_POPULATION:
                raise ConfigError(
                    f"invalid [tune] of {source}: population x (robust.draws + corners + 1) "
                    f"x noise_realisations = {st.population} x {k1} = {st.population * k1} "
                    f"members per generation; allowed: at most {MAX_POPULATION} (one "
                    "batched engine call)"
                )
    elif draws is not None:
        raise ConfigError("draws given but the [tune] table has no robust = {...} setting")
    from aiofl.tuning.robust import parse_constraint, parse_quantity

    objectives = tuple(parse_quantity(q) for q in st.objectives or ())
    constraints = tuple(parse_constraint(c) for c in st.constraints)
    spec = EvalSpec(
        config=raw,
        names=space.names,
        t_final=st.t_final,
        dt=st.dt or cfg.dt,
        method=st.method or cfg.method,
        divergence_threshold=cfg.divergence_threshold,
        draws=robust_draws,
        noise_realisations=st.noise_realisations,
        expected_candidates=st.population * st.generations,
    )
    if st.noise_realisations > 1 and not _noisy(cfg):
        raise ConfigError(
            f"tune.noise_realisations = {st.noise_realisations} but the measurement of "
            f"{source} has no noise; set [sensor] noise_variance (or [uncertainty] "
            "noise_variance), or noise_realisations = 1"
        )
    coeffs = objective_coefficients(st, cfg)
    initial = _initial_population(space, cfg, st)
    fp_settings = st.model_dump(exclude={"generations", "chunks"}, mode="json")
    if fp_settings.get("robust") and not fp_settings["robust"]["corners"]:
        del fp_settings["robust"]["corners"]  # checkpoints from before the option resume
    fp_data = {
        "format": CHECKPOINT_FORMAT,
        "spec": spec.key(),
        "settings": fp_settings,
        "initial": hashlib.sha256(initial.tobytes()).hexdigest(),
        "coefficients": coeffs.tolist(),
    }
    fingerprint = hashlib.sha256(json.dumps(fp_data, sort_keys=True).encode()).hexdigest()
    return _Prepared(
        cfg, st, space, spec, coeffs, initial, fingerprint, source, objectives, constraints, notes
    )


def _noisy(cfg: RunConfig) -> bool:
    """Whether the config's measurement has noise (its own or a drawn variance)."""
    unc = cfg.uncertainty
    drawn = unc is not None and unc.noise_variance is not None and unc.noise_variance[1] > 0
    return cfg.scenario.noise_variance > 0 or drawn


# -------------------------------------------------------------------------- runner
def _algorithm(st: TuneSettings, initial: NDArray[np.float64]) -> Any:
    if st.algorithm == "ga":
        from pymoo.algorithms.soo.nonconvex.ga import GA

        return GA(pop_size=st.population, sampling=initial, eliminate_duplicates=True)
    if st.algorithm == "nsga2":
        from pymoo.algorithms.moo.nsga2 import NSGA2

        return NSGA2(pop_size=st.population, sampling=initial, eliminate_duplicates=True)
    if st.algorithm == "de":
        from pymoo.algorithms.soo.nonconvex.de import DE

        return DE(pop_size=st.population, sampling=initial, variant="DE/rand/1/bin", CR=0.7)
    from pymoo.algorithms.soo.nonconvex.cmaes import CMAES

    # the initial sample is evaluated as generation 1; CMA-ES starts from its best member
    return CMAES(x0=initial, pop_size=st.population, sigma=0.2)


def _problem(
    n_var: int,
    fn: Callable[[NDArray[np.float64]], Any],
    n_obj: int = 1,
    n_constr: int = 0,
) -> Any:
    from pymoo.core.problem import Problem

    class TuningProblem(Problem):
        """Vectorized problem in the unit cube: a whole population per call."""

        def __init__(self) -> None:
            super().__init__(
                n_var=n_var, n_obj=n_obj, n_ieq_constr=n_constr, xl=0.0, xu=1.0, vtype=float
            )

        def _evaluate(self, x: Any, out: dict[str, Any], *args: Any, **kwargs: Any) -> None:
            r = fn(np.asarray(x, dtype=np.float64))
            if n_obj == 1:
                out["F"] = r[:, None]
            else:
                out["F"], out["G"] = r

    return TuningProblem()


def _generation_row(
    gen: int,
    obj: NDArray[np.float64],
    div: NDArray[np.bool_],
    total: int,
    best_so_far: float,
    seconds: float,
) -> dict[str, float]:
    ok = obj[~div]
    return {
        "generation": gen,
        "evaluations": int(obj.size),
        "total_evaluations": total,
        "best": float(obj.min()) if obj.size else float("nan"),
        "mean": float(ok.mean()) if ok.size else float("nan"),
        "median": float(np.median(ok)) if ok.size else float("nan"),
        "best_so_far": best_so_far,
        "failed": int(div.sum()),
        "seconds": seconds,
    }


def _make_evaluator(scheduler: Any, n_workers: int | None, chunks: int | None) -> Any:
    from aiofl.tuning.evaluate import DaskEvaluator, LocalEvaluator

    if scheduler is None and not n_workers:
        return LocalEvaluator()
    return DaskEvaluator(scheduler, n_workers if scheduler is None else None, chunks=chunks)


def tune(
    run_config: RunConfig | str | Path,
    tune_settings: TuneSettings | Mapping[str, Any] | None = None,
    *,
    progress: bool = True,
    checkpoint_dir: str | Path | None = None,
    resume: bool = False,
    scheduler: Any = None,
    n_workers: int | None = None,
    evaluator: Any = None,
    **overrides: Any,
) -> TuneResult:
    """Tune a controller with pymoo on the engine (the paper's GA procedure, Section V).

    Parameters
    ----------
    run_config
        The config (:class:`~aiofl.config.RunConfig`, TOML path or preset name): plant,
        scenario (its horizon is replaced by ``t_final``), controller (untuned parameters
        keep its values), integrator and OPI weights.
    tune_settings
        ``[tune]`` settings (a :class:`TuneSettings` or a dict); default: the config's
        ``[tune]`` table.
    progress
        Show a rich progress bar (generation, best objective, evaluations per second).
    checkpoint_dir
        Write ``checkpoint.npz`` there (atomically) after every generation.
    resume
        Continue from ``checkpoint_dir``'s checkpoint (replayed bit for bit, see
        :mod:`aiofl.tuning.checkpoint`); without one, start from scratch.
    scheduler
        A Dask scheduler address ``tcp://HOST:PORT`` (or a ``distributed.Client``): evaluate
        each generation in chunks on that cluster.
    n_workers
        Start a local Dask cluster with this many worker processes instead.
    evaluator
        A ready evaluator (``callable(spec, values) -> PopulationResult``), e.g. a
        :class:`~aiofl.tuning.evaluate.DaskEvaluator`; overrides ``scheduler``/``n_workers``.
    **overrides
        Settings fields to replace (``seed``, ``generations``, ``population`` ...).

    Returns
    -------
    TuneResult
    """
    prep = prepare(run_config, tune_settings, **overrides)
    st, space, spec = prep.settings, prep.space, prep.spec
    ckpt = Path(checkpoint_dir) / CHECKPOINT if checkpoint_dir is not None else None
    cached: list[dict[str, Any]] = []
    if resume and ckpt is not None and ckpt.exists():
        cached = load_checkpoint(ckpt, prep.fingerprint)
    own = evaluator is None
    ev = evaluator or _make_evaluator(scheduler, n_workers, st.chunks)
    gens: list[dict[str, Any]] = []
    history: list[dict[str, float]] = []
    state = {"best": np.inf, "lowest": np.inf, "total": 0, "live_n": 0, "live_s": 0.0}
    first = prep.objectives[0].text() if prep.objectives else None
    bar = TuneProgress(st, ev, enabled=progress, first_objective=first)

    def evaluate(s: NDArray[np.float64]) -> NDArray[np.float64]:
        g = len(gens)
        t0 = time.perf_counter()
        if g < len(cached):
            c = cached[g]
            check_replay(c, s, g + 1)
            res_m, res_d, res_t, secs = c["metrics"], c["failed"], c["stopped_at"], c["seconds"]
            live = False
        else:
            res: PopulationResult = ev(spec, space.decode(s))
            res_m, res_d, res_t = res.metrics, res.failed, res.stopped_at
            secs = time.perf_counter() - t0
            live = True
        scores = _scores(prep, res_m, res_d, res_t, space.decode(s))
        obj, cand_div = scores["objective"], scores["candidate_diverged"]
        gens.append(
            {
                "s": s.copy(),
                "metrics": res_m,
                "failed": res_d,
                "stopped_at": res_t,
                "seconds": secs,
                **scores,
            }
        )
        state["total"] += obj.size
        state["best"] = min(state["best"], float(obj.min()))
        if prep.objectives:  # the lowest first objective of a feasible design: the front's
            ok = (scores["G"] <= 0).all(axis=1) & np.isfinite(scores["F"]).all(axis=1)
            if ok.any():
                state["lowest"] = min(state["lowest"], float(scores["F"][ok, 0].min()))
        history.append(
            _generation_row(len(gens), obj, cand_div, state["total"], state["best"], secs)
        )
        if live:
            state["live_n"] += obj.size
            state["live_s"] += secs
            if ckpt is not None:
                save_checkpoint(ckpt, prep.fingerprint, gens)
        # the first objective as itself (a maximised margin is minimised as its negative)
        shown = state["lowest"] * prep.objectives[0].sign if prep.objectives else state["best"]
        bar.update(len(gens), shown, int(state["live_n"]), float(state["live_s"]))
        return (scores["F"], scores["G"]) if prep.objectives else obj

    try:
        n_con = 1 + len(prep.constraints) if prep.objectives else 0
        problem = _problem(space.n_var, evaluate, max(1, len(prep.objectives)), n_con)
        algo = _algorithm(st, prep.initial)
        algo.setup(problem, termination=("n_gen", st.generations), seed=st.seed, verbose=False)
        if st.algorithm == "cmaes":
            # cma seeds numpy's global generator from this; 0 would mean "from the clock"
            algo.options["seed"] = st.seed + 1
        with bar:
            while algo.has_next() and len(gens) < st.generations:
                algo.next()
    finally:
        if own:
            ev.close()

    s_all = np.concatenate([g["s"] for g in gens])
    obj_all = np.concatenate([g["objective"] for g in gens])
    div_all = np.concatenate([g["candidate_diverged"] for g in gens])  # any member
    met_all = np.concatenate([g["metrics"] for g in gens])
    if met_all.ndim == 3:  # robust: best_metrics are the nominal plant's
        met_all = met_all[:, 0, :]
    gen_idx = np.concatenate([np.full(g["s"].shape[0], i + 1) for i, g in enumerate(gens)])
    values = space.decode(s_all)
    front = None
    if prep.objectives:
        from aiofl.tuning.front import front_index, front_of_run

        front = front_of_run(prep, gens, values)
        ib = front_index(front, values)
    else:
        ib = int(np.argmin(obj_all))
    best_values = {n: float(values[ib, j]) for j, n in enumerate(space.names)}
    best = met_all[ib][: L.N_METRIC]  # the integrals (a custom evaluator gives only them)
    best_metrics = None if div_all[ib] else dict(zip(L.METRIC_NAMES, best.tolist(), strict=True))
    config = config_with_values(prep.config.raw, prep.config.controller, best_values)
    return TuneResult(
        settings=st,
        names=space.names,
        best_values=best_values,
        best_objective=float(obj_all[ib]),
        best_metrics=best_metrics,
        values=values,
        objective=obj_all,
        generation=gen_idx.astype(np.int64),
        failed=div_all,
        history=history,
        config=config,
        source=prep.source,
        evaluator=getattr(ev, "description", type(ev).__name__),
        live_evaluations=int(state["live_n"]),
        live_seconds=float(state["live_s"]),
        front=front,
    )


def _scores(
    prep: _Prepared,
    metrics: NDArray[np.float64],
    failed: NDArray[np.bool_],
    stopped_at: NDArray[np.float64],
    values: NDArray[np.float64] | None = None,
) -> dict[str, NDArray[Any]]:
    """Per-candidate objective (and for NSGA-II ``F``, ``G``, constraint values).

    ``values`` (B, d) are the candidates' parameter values, needed when an objective or
    constraint names a margin (:func:`aiofl.tuning.margins.candidate_margins`, computed
    then only; a candidate diverged on the nominal plant is not linearised)."""
    from aiofl.tuning.robust import objective_matrix, robust_objective

    st = prep.settings
    cand_div = failed.any(axis=1) if failed.ndim == 2 else failed
    kind, alpha = (st.robust.aggregate, st.robust.alpha) if st.robust else ("nominal", 0.9)
    if prep.objectives:
        cap = 2.0 * st.divergence_penalty
        margins = None
        named = [*prep.objectives, *(c.quantity for c in prep.constraints)]
        if values is not None and any(q.is_margin for q in named):
            from aiofl.tuning.margins import candidate_margins

            nominal_div = failed[:, 0] if failed.ndim == 2 else failed
            margins = candidate_margins(prep.config, prep.space.names, values, nominal_div)
        F, G, raw = objective_matrix(
            prep.objectives, prep.constraints, metrics, failed, kind, alpha, cap, margins
        )
        feasible = (G <= 0).all(axis=1)
        obj = np.where(feasible, F[:, 0], cap)  # history: the first objective when feasible
        return {"objective": obj, "candidate_diverged": cand_div, "F": F, "G": G, "raw": raw}
    if st.robust is None:
        obj = objective_values(
            metrics, failed, stopped_at, prep.coefficients, st.divergence_penalty, st.t_final
        )
    else:
        obj = robust_objective(
            metrics,
            failed,
            stopped_at,
            prep.coefficients,
            st.divergence_penalty,
            st.t_final,
            kind,
            alpha,
        )
    return {"objective": obj, "candidate_diverged": cand_div}
