"""Evaluating a population: one batched engine call locally, or chunks on a Dask cluster.

The unit of work is :func:`evaluate_chunk`: given an :class:`EvalSpec` (small, picklable:
the config as a plain dict, the tuned parameter names, horizon and integrator) and a
(B, d) array of parameter values, it runs **one** :func:`aiofl.engine.simulation.simulate_batch`
call and returns the metrics of the B members (B x (K+1) x R engine members with K
robust draws and R noise realisations, all in the one call).  The spec carries the plant by *name*:
a worker rebuilds the plant, controller and scenario from the dict on first use and
keeps them (so the plant's kernel is compiled once per worker process), never receiving
jitted functions over the wire.

Members are independent (the engine integrates each one alone), so how a population is
split into chunks does not change any member's numbers: the Dask path returns exactly
the local path's results.
"""

from __future__ import annotations

import hashlib
import json
import threading
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L

__all__ = [
    "CONNECT_TIMEOUT",
    "DaskEvaluator",
    "EvalSpec",
    "LocalEvaluator",
    "PopulationResult",
    "evaluate_chunk",
]

#: seconds to wait for a Dask scheduler before giving up (``--scheduler``)
CONNECT_TIMEOUT = 5.0


@dataclass(frozen=True)
class EvalSpec:
    """Everything a worker needs to evaluate members, as plain data.

    Attributes
    ----------
    config
        The run config as a dict (as loaded from TOML); the plant is named in it.
    names
        Tuned engine columns, in the order of the value arrays' columns.
    t_final
        Tuning horizon [s] (replaces the scenario's).
    dt, method, divergence_threshold
        Integrator settings.
    draws
        Robust tuning: K dicts of scenario fields (e.g. ``{"plant_scale": {"J_l": 1.1}}``,
        and ``"ts"``, a drawn sample time) that make the K perturbed scenarios; each
        candidate is simulated on the nominal scenario and on every draw (K + 1
        members).  Empty: the nominal scenario only.
    noise_realisations
        R >= 1 noise sequences per scenario (realisation r seeded
        :func:`aiofl.scenario.realisation_seed` (its noise seed, r), the same for every
        candidate); a member's metrics are their mean over the R (diverged if any is).
    expected_candidates
        Candidates the whole run evaluates (population × generations; 0: unknown), each
        (K + 1) R members: declared to the engine's lane choice
        (:func:`aiofl.engine.build.lane_choice.expect`), so a run worth the plant's lane instance
        compiles it at its first generation.  Not part of :meth:`key`.
    """

    config: Mapping[str, Any]
    names: tuple[str, ...]
    t_final: float
    dt: float
    method: str
    divergence_threshold: float
    draws: tuple[Mapping[str, Any], ...] = ()
    noise_realisations: int = 1
    expected_candidates: int = 0

    def key(self) -> str:
        """A digest identifying the spec (used to cache the built objects on a worker)."""
        blob = json.dumps(
            [
                self.config,
                self.names,
                self.t_final,
                self.dt,
                self.method,
                self.divergence_threshold,
                list(self.draws),
                *([self.noise_realisations] if self.noise_realisations > 1 else []),
            ],
            sort_keys=True,
            default=repr,
        )
        return hashlib.sha256(blob.encode()).hexdigest()


@dataclass(frozen=True)
class PopulationResult:
    """Engine results of a population: ``metrics`` (B, :data:`aiofl.layout.N_SCORE`),
    the integrals then the response figures (:data:`aiofl.layout.SCORE_NAMES`), ``failed``
    (lost or diverged) and ``stopped_at`` (B,).

    In a robust run (K draws) the shapes are (B, K+1, N_SCORE) and (B, K+1), column 0
    being the nominal plant.
    """

    metrics: NDArray[np.float64]
    failed: NDArray[np.bool_]
    stopped_at: NDArray[np.float64]

    @staticmethod
    def concatenate(parts: list[PopulationResult]) -> PopulationResult:
        """Join chunk results in order."""
        return PopulationResult(
            np.concatenate([p.metrics for p in parts]),
            np.concatenate([p.failed for p in parts]),
            np.concatenate([p.stopped_at for p in parts]),
        )


_BUILT: dict[str, Any] = {}
_LOCK = threading.Lock()  # one engine call at a time per process (threaded Dask workers)


def _build(spec: EvalSpec) -> Any:
    key = spec.key()
    if key not in _BUILT:
        from aiofl.config import parse_config

        cfg = parse_config(dict(spec.config), "tuning spec")
        _BUILT.clear()  # keep only the current spec's objects
        scenario = replace(cfg.scenario, t_final=spec.t_final)
        scenarios = [scenario] + [
            replace(scenario, **{k: v for k, v in d.items() if k != "ts"}) for d in spec.draws
        ]
        sampling: Any = cfg.sampling
        if any("ts" in d for d in spec.draws):  # drawn sample times: one setting per member
            sampling = [sampling] + [
                replace(sampling, ts=d["ts"]) if "ts" in d else sampling for d in spec.draws
            ]
        r = spec.noise_realisations
        if r > 1:  # every scenario's R noise realisations, next to each other
            from aiofl.scenario import realisation_seed

            scenarios = [
                replace(s, noise_seed=realisation_seed(s.noise_seed, i))
                for s in scenarios
                for i in range(r)
            ]
            if isinstance(sampling, list):
                sampling = [x for x in sampling for _ in range(r)]
        _BUILT[key] = (cfg.plant, cfg.controller, scenarios, sampling)
    return _BUILT[key]


def _mean_over_realisations(
    metrics: NDArray[np.float64], diverged: NDArray[np.bool_], at: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64]]:
    """Collapse the realisation axis (the last of ``diverged``): metrics their mean,
    diverged if any realisation diverged, at the earliest divergence."""
    div = diverged.any(axis=-1)
    first = np.where(diverged, at, np.inf).min(axis=-1)
    return metrics.mean(axis=-2), div, np.where(div, first, at[..., 0])


def evaluate_chunk(spec: EvalSpec, values: NDArray[np.float64]) -> PopulationResult:
    """Simulate the members with parameter ``values`` (B, d) in one batched engine call.

    With K robust draws the call has B (K+1) members, candidate-major: member
    ``b (K+1) + k`` is candidate b on scenario k (0 = nominal).
    """
    from aiofl.controller import controller_batch
    from aiofl.engine.build.lane_choice import expect
    from aiofl.engine.simulation import simulate_batch

    values = np.asarray(values, dtype=np.float64)
    k1 = 1 + len(spec.draws)
    r = spec.noise_realisations
    shape = (values.shape[0], k1) if spec.draws else (values.shape[0],)
    if values.shape[0] == 0:
        empty = np.zeros((*shape, L.N_SCORE))
        return PopulationResult(empty, np.zeros(shape, dtype=bool), np.zeros(shape))
    with _LOCK:
        plant, controller, scenarios, sampling = _build(spec)
        if spec.expected_candidates:
            steps = float(spec.expected_candidates * k1 * r) * round(spec.t_final / spec.dt)
            expect(plant, sampling is not None, steps)
        members = np.repeat(values, k1 * r, axis=0)
        batch = controller_batch(
            controller, {name: members[:, j] for j, name in enumerate(spec.names)}
        )
        res = simulate_batch(
            plant,
            batch,
            scenarios * values.shape[0] if len(scenarios) > 1 else scenarios[0],
            dt=spec.dt,
            method=spec.method,
            store=False,
            divergence_threshold=spec.divergence_threshold,
            # a [controller.discrete] table tunes the sampled controller
            sampling=sampling * values.shape[0] if isinstance(sampling, list) else sampling,
        )
    # the integrals, then the response figures (aiofl.layout.SCORE_NAMES)
    scores = np.column_stack([res.metrics, *(res.response[k] for k in L.RESPONSE_NAMES)])
    if r > 1:  # (B, [K+1,] R): the mean over the realisations
        m, d, t = _mean_over_realisations(
            scores.reshape(*shape, r, L.N_SCORE),
            res.failed.reshape(*shape, r),
            res.stopped_at.reshape(*shape, r),
        )
        return PopulationResult(m, d, t)
    return PopulationResult(
        scores.reshape(*shape, L.N_SCORE).copy(),
        res.failed.reshape(shape).copy(),
        res.stopped_at.reshape(shape).copy(),
    )


class LocalEvaluator:
    """Evaluate a whole population in this process: one engine call (all cores via numba)."""

    description = "local"

    def __call__(self, spec: EvalSpec, values: NDArray[np.float64]) -> PopulationResult:
        return evaluate_chunk(spec, values)

    def close(self) -> None:
        """Nothing to release."""


class DaskEvaluator:
    """Evaluate a population as chunks on a dask.distributed cluster.

    Parameters
    ----------
    scheduler
        Address ``tcp://HOST:PORT`` of a running scheduler, or a ``distributed.Client``.
    n_workers
        Start a ``LocalCluster`` with this many worker processes instead.
    chunks
        Number of chunks per generation (default: the number of workers, at least 1).
    processes
        For ``n_workers``: worker processes (default) or threads in this process.
    """

    def __init__(
        self,
        scheduler: Any = None,
        n_workers: int | None = None,
        *,
        chunks: int | None = None,
        processes: bool = True,
    ) -> None:
        from distributed import Client, LocalCluster

        self._own_client = False
        self._cluster = None
        if scheduler is not None and n_workers is not None:
            raise ValueError("give either a scheduler address or a number of workers, not both")
        if isinstance(scheduler, Client):
            self.client = scheduler
            self.description = f"dask {scheduler.scheduler.address}"
        elif scheduler is not None:
            try:
                self.client = Client(str(scheduler), timeout=f"{CONNECT_TIMEOUT}s")
            except (OSError, TimeoutError, ValueError) as exc:
                # ConnectionError (an OSError): the CLI reports it as bad input, exit 2
                raise ConnectionError(
                    f"cannot connect to the Dask scheduler {scheduler!r} within "
                    f"{CONNECT_TIMEOUT:g} s: {exc}"
                ) from None
            self._own_client = True
            self.description = f"dask {scheduler}"
        else:
            n = int(n_workers or 1)
            if n < 1:
                raise ValueError(f"dask workers = {n}; allowed: >= 1")
            self._cluster = LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=processes,
                dashboard_address=None,
            )
            self.client = Client(self._cluster)
            self._own_client = True
            self.description = f"dask LocalCluster({n} {'processes' if processes else 'threads'})"
        self.chunks = chunks
        self._spec_key: str | None = None
        self._spec_future: Any = None

    def n_chunks(self) -> int:
        """Chunks per generation: ``chunks`` if given, else the number of workers."""
        if self.chunks:
            return int(self.chunks)
        return max(1, len(self.client.scheduler_info(n_workers=-1).get("workers", {})))

    def __call__(self, spec: EvalSpec, values: NDArray[np.float64]) -> PopulationResult:
        values = np.asarray(values, dtype=np.float64)
        k = min(self.n_chunks(), max(1, values.shape[0]))
        parts = np.array_split(values, k)
        key = spec.key()
        if self._spec_key != key:  # send the spec to the workers once per tuning run
            self._spec_future = self.client.scatter(spec, broadcast=True, hash=False)
            self._spec_key = key
        futures = self.client.map(evaluate_chunk, [self._spec_future] * k, parts, pure=False)
        return PopulationResult.concatenate(self.client.gather(futures))

    def close(self) -> None:
        """Close the client and the local cluster if this evaluator created them."""
        if self._own_client:
            self.client.close()
        if self._cluster is not None:
            self._cluster.close()
