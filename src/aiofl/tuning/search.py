r"""Tuning controllers with a genetic algorithm (pymoo) on the paper's OPI, locally or on Dask.

The paper tuned each controller with a GA on its objective performance index (22) over
:math:`t_f = 6` s.  :func:`tune` does the same for any config: the ``[tune]`` table
(:mod:`aiofl.tuning.space`) names the parameters, their bounds and the objective
(:mod:`aiofl.tuning.objective`); :func:`aiofl.tuning.prepared.prepare` validates it before
anything is run or written; the search is pymoo's: its algorithm (GA, DE, CMA-ES or
NSGA-II) asks the named :class:`aiofl.tuning.problem.TuningProblem` to score each
generation in **one** batched engine call (:mod:`aiofl.tuning.evaluate`), or in chunks on a
dask.distributed cluster, with identical numbers either way, and the
:class:`aiofl.tuning.problem.RunLog` callback records it (history, checkpoint, progress
bar).  :func:`tune` returns a :class:`TuneResult`.  The checkpoint written after every
generation and its replay on resume are in :mod:`aiofl.tuning.checkpoint`, the output
files in :mod:`aiofl.tuning.results`.

Notes
-----
The algorithm's random stream is seeded (``seed``); pymoo 0.6.2 keeps it in the algorithm
(``np.random.default_rng(seed)``), the initial Latin-hypercube sample is drawn from its own
seeded generator, and CMA-ES is seeded with ``seed + 1`` (cma treats 0 as "use the
clock").  The same seed therefore gives the same run bit for bit, and a resumed run ends
with exactly the result of an uninterrupted one.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.tuning.checkpoint import CHECKPOINT, load_checkpoint
from aiofl.tuning.prepared import Prepared, prepare
from aiofl.tuning.progress import TuneProgress
from aiofl.tuning.space import TuneSettings, config_with_values, parse_tune_settings, to_toml

if TYPE_CHECKING:  # pragma: no cover
    from aiofl.config import RunConfig

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


def _make_evaluator(scheduler: Any, n_workers: int | None, chunks: int | None) -> Any:
    from aiofl.tuning.evaluate import DaskEvaluator, LocalEvaluator

    if scheduler is None and not n_workers:
        return LocalEvaluator()
    return DaskEvaluator(scheduler, n_workers if scheduler is None else None, chunks=chunks)


def tune(
    run_config: Prepared | RunConfig | str | Path,
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
        A prepared run (:func:`aiofl.tuning.prepared.prepare`, as ``aiofl tune`` passes
        it), or the config to prepare (:class:`~aiofl.config.RunConfig`, TOML path or
        preset name): plant, scenario (its horizon is replaced by ``t_final``), controller
        (untuned parameters keep its values), integrator and OPI weights.
    tune_settings
        ``[tune]`` settings (a :class:`TuneSettings` or a dict); default: the config's
        ``[tune]`` table.  Not with a prepared run.
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
        Settings fields to replace (``seed``, ``generations``, ``population`` ...), and
        ``draws`` (:func:`aiofl.tuning.prepared.prepare`).  Not with a prepared run.

    Returns
    -------
    TuneResult
    """
    from aiofl.tuning.problem import RunLog, TuningProblem

    if isinstance(run_config, Prepared):
        given = [k for k, v in overrides.items() if v is not None]
        if tune_settings is not None or given:
            raise TypeError(f"tune: a prepared run takes no settings or overrides (got {given})")
        prep = run_config
    else:
        prep = prepare(run_config, tune_settings, **overrides)
    st = prep.settings
    ckpt = Path(checkpoint_dir) / CHECKPOINT if checkpoint_dir is not None else None
    replay: list[dict[str, Any]] = []
    if resume and ckpt is not None and ckpt.exists():
        replay = load_checkpoint(ckpt, prep.fingerprint)
    own = evaluator is None
    ev = evaluator or _make_evaluator(scheduler, n_workers, st.chunks)
    problem = TuningProblem(prep, ev, replay)
    first = prep.objective.objectives[0].text() if prep.objective.objectives else None
    bar = TuneProgress(st, ev, enabled=progress, first_objective=first)
    log = RunLog(prep, ckpt, bar)
    try:
        algo = _algorithm(st, prep.initial)
        algo.setup(
            problem,
            termination=("n_gen", st.generations),
            seed=st.seed,
            verbose=False,
            callback=log,
        )
        if st.algorithm == "cmaes":
            # cma seeds numpy's global generator from this; 0 would mean "from the clock"
            algo.options["seed"] = st.seed + 1
        with bar:
            while algo.has_next() and len(problem.generations) < st.generations:
                algo.next()  # one population: asked, scored by the problem, told, logged
            log.record(problem.generations)  # a no-op unless pymoo skipped its callback
    finally:
        if own:
            ev.close()
    return _result(prep, problem.generations, log, getattr(ev, "description", type(ev).__name__))


def _result(prep: Prepared, gens: list[Any], log: Any, evaluator: str) -> TuneResult:
    """The :class:`TuneResult` of a finished run: its generations and their record."""
    space = prep.space
    s_all = np.concatenate([g.s for g in gens])
    obj_all = np.concatenate([g.scores.objective for g in gens])
    div_all = np.concatenate([g.scores.diverged for g in gens])  # any member
    met_all = np.concatenate([g.metrics for g in gens])
    if met_all.ndim == 3:  # robust: best_metrics are the nominal plant's
        met_all = met_all[:, 0, :]
    gen_idx = np.concatenate([np.full(g.s.shape[0], i + 1) for i, g in enumerate(gens)])
    values = space.decode(s_all)
    front = None
    if prep.objective.objectives:
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
        settings=prep.settings,
        names=space.names,
        best_values=best_values,
        best_objective=float(obj_all[ib]),
        best_metrics=best_metrics,
        values=values,
        objective=obj_all,
        generation=gen_idx.astype(np.int64),
        failed=div_all,
        history=log.history,
        config=config,
        source=prep.source,
        evaluator=evaluator,
        live_evaluations=int(log.live_evaluations),
        live_seconds=float(log.live_seconds),
        front=front,
    )
