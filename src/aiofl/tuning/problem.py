r"""The tuning problem as pymoo sees it: a named ``Problem`` and the run's ``Callback``.

:class:`TuningProblem` is a prepared run (:func:`aiofl.tuning.prepared.prepare`) as a pymoo
``Problem`` in the unit cube: its ``_evaluate`` scores a whole population in **one** call
of the evaluator (local or Dask; or replays the generation a checkpoint holds,
:mod:`aiofl.tuning.checkpoint`) with the run's objective
(:class:`aiofl.tuning.objective.Objective`) and fills ``out["F"]`` (and ``out["G"]``, the
constraints of NSGA-II).  It keeps every population it scored, in order
(:class:`Generation`): the run's evaluations.

:class:`RunLog` is the ``Callback`` pymoo calls after every generation: it adds the
generation's row to the history, writes the checkpoint and moves the progress bar.

This module imports pymoo; :func:`aiofl.tuning.search.tune` imports it when a search runs.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from pymoo.core.callback import Callback
from pymoo.core.problem import Problem

from aiofl.tuning.checkpoint import check_replay, save_checkpoint
from aiofl.tuning.objective import Scores

if TYPE_CHECKING:  # pragma: no cover
    from aiofl.tuning.evaluate import EvalSpec, PopulationResult
    from aiofl.tuning.prepared import Prepared
    from aiofl.tuning.progress import TuneProgress

__all__ = ["Generation", "RunLog", "TuningProblem"]


# -------------------------------------------------------------------- the problem
@dataclass(frozen=True)
class Generation:
    """One population as :class:`TuningProblem` scored it.

    Attributes
    ----------
    s
        The candidates in the unit cube, (B, d).
    metrics, failed, stopped_at
        The evaluation's metrics (B, [K+1,] metrics), lost-or-diverged flags and times.
    seconds
        The evaluation's wall time (a replayed generation: the stored one).
    live
        Simulated in this run (False: replayed from the checkpoint).
    scores
        Its scores (:meth:`aiofl.tuning.objective.Objective.score`).
    """

    s: NDArray[np.float64]
    metrics: NDArray[np.float64]
    failed: NDArray[np.bool_]
    stopped_at: NDArray[np.float64]
    seconds: float
    live: bool
    scores: Scores

    def stored(self) -> dict[str, Any]:
        """What the checkpoint keeps of it (:func:`aiofl.tuning.checkpoint.save_checkpoint`)."""
        return {
            "s": self.s,
            "metrics": self.metrics,
            "failed": self.failed,
            "stopped_at": self.stopped_at,
            "seconds": self.seconds,
        }


class TuningProblem(Problem):  # type: ignore[misc]
    """A prepared tuning run as a pymoo problem in the unit cube: a population per call.

    Parameters
    ----------
    prepared
        The run (:func:`aiofl.tuning.prepared.prepare`).
    evaluator
        ``callable(spec, values) -> PopulationResult``: one batched engine call
        (:class:`~aiofl.tuning.evaluate.LocalEvaluator`) or chunks on Dask.
    replay
        Generations a checkpoint holds (:func:`aiofl.tuning.checkpoint.load_checkpoint`):
        the first populations asked for are checked against them and their stored
        results are used instead of simulating.
    """

    def __init__(
        self,
        prepared: Prepared,
        evaluator: Callable[[EvalSpec, NDArray[np.float64]], PopulationResult],
        replay: Sequence[Mapping[str, Any]] = (),
    ) -> None:
        o = prepared.objective
        super().__init__(
            n_var=prepared.space.n_var,
            n_obj=o.n_obj,
            n_ieq_constr=o.n_ieq_constr,
            xl=0.0,
            xu=1.0,
            vtype=float,
        )
        self.prepared = prepared
        self.evaluator = evaluator
        self.replay = tuple(replay)
        #: every population scored so far, in order
        self.generations: list[Generation] = []

    def _evaluate(self, x: Any, out: dict[str, Any], *args: Any, **kwargs: Any) -> None:
        gen = self.score(np.asarray(x, dtype=np.float64))
        self.generations.append(gen)
        out["F"] = gen.scores.F
        if self.n_ieq_constr:
            out["G"] = gen.scores.G

    def score(self, s: NDArray[np.float64]) -> Generation:
        """Evaluate and score the population ``s`` (B, d), the next one of the run.

        One evaluator call for the B candidates (each on the K + 1 plants of a robust
        run), or the stored results if the checkpoint holds this generation; the
        candidates' margins are computed only when the objective names one (a candidate
        diverged on the nominal plant is not linearised).

        Parameters
        ----------
        s
            The candidates in the unit cube.

        Returns
        -------
        Generation
        """
        prep = self.prepared
        g = len(self.generations)
        t0 = time.perf_counter()
        values = prep.space.decode(s)
        if g < len(self.replay):
            c = self.replay[g]
            check_replay(c, s, g + 1)
            metrics, failed, stopped_at = c["metrics"], c["failed"], c["stopped_at"]
            seconds, live = c["seconds"], False
        else:
            res = self.evaluator(prep.spec, values)
            metrics, failed, stopped_at = res.metrics, res.failed, res.stopped_at
            seconds, live = time.perf_counter() - t0, True
        margins = None
        if prep.objective.needs_margins:
            from aiofl.tuning.margins import candidate_margins

            nominal_failed = failed[:, 0] if failed.ndim == 2 else failed
            margins = candidate_margins(prep.config, prep.space.names, values, nominal_failed)
        scores = prep.objective.score(metrics, failed, stopped_at, margins)
        return Generation(s.copy(), metrics, failed, stopped_at, seconds, live, scores)


# ------------------------------------------------------------------- the record
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


class RunLog(Callback):  # type: ignore[misc]
    """What a run records after every generation (pymoo calls :meth:`notify`).

    For each generation the problem scored since the last call: its row of
    ``history.csv`` (:attr:`history`), the checkpoint (every generation so far, written
    after a simulated one) and the progress bar.  :attr:`best` is the lowest objective so
    far; :attr:`lowest`, with several objectives, the lowest first objective of a feasible
    design (the front's end, which the bar shows); :attr:`live_evaluations` and
    :attr:`live_seconds` count the candidates simulated in this run and their time.

    Parameters
    ----------
    prepared
        The run (:func:`aiofl.tuning.prepared.prepare`).
    checkpoint
        The checkpoint file (None: none is written).
    bar
        The progress bar.
    """

    def __init__(self, prepared: Prepared, checkpoint: Path | None, bar: TuneProgress) -> None:
        super().__init__()
        self.prepared = prepared
        self.checkpoint = checkpoint
        self.bar = bar
        self.history: list[dict[str, float]] = []
        self.best = np.inf
        self.lowest = np.inf
        self.total = 0
        self.live_evaluations = 0
        self.live_seconds = 0.0

    def notify(self, algorithm: Any) -> None:
        """Record the generations ``algorithm.problem`` scored since the last call."""
        self.record(algorithm.problem.generations)

    def record(self, generations: Sequence[Generation]) -> None:
        """Record ``generations[len(history):]`` (those not recorded yet).

        Parameters
        ----------
        generations
            Every generation of the run so far (:attr:`TuningProblem.generations`).
        """
        for i in range(len(self.history), len(generations)):
            gen, sc = generations[i], generations[i].scores
            obj = sc.objective
            self.total += obj.size
            self.best = min(self.best, float(obj.min()))
            objectives = self.prepared.objective.objectives
            if objectives:  # the lowest first objective of a feasible design: the front's
                ok = (sc.G <= 0).all(axis=1) & np.isfinite(sc.F).all(axis=1)
                if ok.any():
                    self.lowest = min(self.lowest, float(sc.F[ok, 0].min()))
            self.history.append(
                _generation_row(i + 1, obj, sc.diverged, self.total, self.best, gen.seconds)
            )
            if gen.live:
                self.live_evaluations += obj.size
                self.live_seconds += gen.seconds
                if self.checkpoint is not None:
                    stored = [g.stored() for g in generations[: i + 1]]
                    save_checkpoint(self.checkpoint, self.prepared.fingerprint, stored)
            # the first objective as itself (a maximised margin is minimised as its negative)
            shown = self.lowest * objectives[0].sign if objectives else self.best
            self.bar.update(i + 1, shown, self.live_evaluations, self.live_seconds)
