"""Speed of the tuner: evaluations per second, and a full GA run on the paper's 6-s OPI.

Usage::

    .venv/bin/python benchmarks/bench_tuning.py            # everything (a few minutes)
    .venv/bin/python benchmarks/bench_tuning.py --quick    # skip the 64 x 50 GA runs
    .venv/bin/python benchmarks/bench_tuning.py --json out.json

What is measured (all warm: the plant's kernel is compiled, or loaded from numba's cache,
before timing):

1. *Generation throughput*: one generation of 64 members of each structure (LESO, INLESO,
   LADRC; the paper's scenario 1 over the tuning horizon t_f = 6 s at dt = 1e-4, i.e.
   60 000 RK4 steps per member) evaluated in one batched engine call, with numba using
   1 thread and then both cores.  Reported as evaluations per second.
2. *Dask*: the same generation through a ``LocalCluster`` of 2 worker processes (chunks of
   32, one engine call each), to show the overhead of the scale-out path on one machine.
3. *GA end to end*: ``tune`` with a GA of population 64 x 50 generations on the 6-s OPI,
   the paper's budget-sized run (3 200 simulations), for LESO and LADRC.

The machine is shared: run it when nothing else is busy, and read the load average it
prints.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from typing import Any

import numpy as np

from aiofl.config import load_config, parse_config
from aiofl.tuning.evaluate import DaskEvaluator, evaluate_chunk
from aiofl.tuning.search import prepare, tune

TUNE = {
    "LESO": {
        "eso.omega0": {"lo": 50.0, "hi": 2000.0, "log": True},
        "law.b0": {"lo": 1.0, "hi": 1e5, "log": True},
        "td.R": {"lo": 10.0, "hi": 1e4, "log": True},
        "sef.delta1": {"lo": 1e-3, "hi": 100.0, "log": True},
        "sef.delta2": {"lo": 1e-3, "hi": 100.0, "log": True},
    },
    "INLESO": {
        "eso.omega0": {"lo": 50.0, "hi": 500.0, "log": True},
        "law.b0": {"lo": 1.0, "hi": 1e5, "log": True},
        "td.rho": {"lo": 1.0, "hi": 100.0, "log": True},
    },
    "LADRC": {
        "eso.omega0": {"lo": 10.0, "hi": 5000.0, "log": True},
        "sef.omega_c": {"lo": 0.5, "hi": 200.0, "log": True},
        "td.omega": {"lo": 1.0, "hi": 5000.0, "log": True},
        "law.b0": {"lo": 100.0, "hi": 1e6, "log": True},
    },
}


def config_for(structure: str, population: int = 64, generations: int = 50) -> Any:
    """Scenario 1 with the paper's parameters (LESO, INLESO) or a LADRC, plus a [tune] table."""
    if structure == "LADRC":
        raw = dict(load_config("paper-s1-leso").raw)
        raw["controller"] = {
            "structure": "LADRC",
            "rho": 4,
            "n_feedback": 4,
            "eso": {"omega0": 500.0, "alpha": "binomial"},
            "td": {"omega": 100.0},
            "sef": {"omega_c": 20.0},
            "law": {"b0": 26800.0},
        }
    else:
        raw = dict(load_config(f"paper-s1-{structure.lower()}").raw)
    raw["tune"] = {
        "objective": "opi",
        "t_final": 6.0,
        "population": population,
        "generations": generations,
        "seed": 1,
        "parameters": TUNE[structure],
    }
    return parse_config(raw, f"bench {structure}")


def generation_rate(cfg: Any, threads: int, repeats: int = 2) -> dict[str, float]:
    """Evaluations/s of one 64-member generation in one engine call with ``threads`` threads."""
    import numba

    prep = prepare(cfg)
    values = prep.space.decode(prep.initial)
    numba.set_num_threads(threads)
    evaluate_chunk(prep.spec, values[:2])  # warm (compile or load the kernel)
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        res = evaluate_chunk(prep.spec, values)
        best = min(best, time.perf_counter() - t0)
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    return {
        "members": int(values.shape[0]),
        "seconds": best,
        "evals_per_s": values.shape[0] / best,
        "diverged": int(res.diverged.sum()),
    }


def dask_rate(cfg: Any, workers: int = 2) -> dict[str, float]:
    """Evaluations/s of the same generation on a LocalCluster of ``workers`` processes."""
    prep = prepare(cfg)
    values = prep.space.decode(prep.initial)
    ev = DaskEvaluator(n_workers=workers)
    try:
        t0 = time.perf_counter()
        ev(prep.spec, values[: 2 * workers])  # each worker builds (or loads) its kernel
        warm = time.perf_counter() - t0
        t0 = time.perf_counter()
        ev(prep.spec, values)
        secs = time.perf_counter() - t0
    finally:
        ev.close()
    return {
        "workers": workers,
        "warmup_s": warm,
        "seconds": secs,
        "evals_per_s": values.shape[0] / secs,
    }


def ga_run(cfg: Any) -> dict[str, Any]:
    """A GA of population 64 x 50 generations on the 6-s OPI, timed end to end."""
    prep = prepare(cfg)
    evaluate_chunk(prep.spec, prep.space.decode(prep.initial[:2]))  # warm
    t0 = time.perf_counter()
    res = tune(cfg, progress=False)
    wall = time.perf_counter() - t0
    return {
        "budget": res.settings.budget(),
        "evaluations": res.n_evaluations,
        "diverged": int(res.diverged.sum()),
        "wall_s": wall,
        "evals_per_s": res.n_evaluations / wall,
        "best_objective": res.best_objective,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="skip the 64 x 50 GA runs")
    ap.add_argument("--no-dask", action="store_true", help="skip the Dask measurement")
    ap.add_argument("--json", help="write the results to this JSON file")
    args = ap.parse_args()
    import numba

    out: dict[str, Any] = {
        "cpus": os.cpu_count(),
        "numba_threads": numba.config.NUMBA_NUM_THREADS,
        "load_average_before": os.getloadavg(),
        "horizon_s": 6.0,
        "dt": 1e-4,
        "generation": {},
    }
    cfgs = {s: config_for(s) for s in TUNE}
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cpus")
    print("one generation of 64 members, 6-s OPI horizon, dt = 1e-4 (60k RK4 steps/member)")
    for s, cfg in cfgs.items():
        row = {f"{t}_thread": generation_rate(cfg, t) for t in (1, out["numba_threads"])}
        out["generation"][s] = row
        one, two = row["1_thread"], row[f"{out['numba_threads']}_thread"]
        print(
            f"  {s:7s} 1 thread {one['evals_per_s']:6.1f} eval/s   "
            f"{out['numba_threads']} threads {two['evals_per_s']:6.1f} eval/s   "
            f"(x{two['evals_per_s'] / one['evals_per_s']:.2f})"
        )
    if not args.no_dask:
        d = dask_rate(cfgs["LESO"])
        out["dask_LESO"] = d
        print(
            f"  LESO via Dask LocalCluster(2 processes): {d['evals_per_s']:.1f} eval/s "
            f"(worker warm-up {d['warmup_s']:.1f} s)"
        )
    if not args.quick:
        out["ga"] = {}
        for s in ("LESO", "LADRC"):
            r = ga_run(cfgs[s])
            out["ga"][s] = r
            print(
                f"  GA {s}: {r['budget']}: {r['evaluations']} evaluations in {r['wall_s']:.1f} s "
                f"({r['evals_per_s']:.1f} eval/s, {r['diverged']} diverged), "
                f"best OPI {r['best_objective']:.4g}"
            )
    out["load_average_after"] = os.getloadavg()
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(out, fh, indent=2)


if __name__ == "__main__":
    main()
