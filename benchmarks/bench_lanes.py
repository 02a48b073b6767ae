"""Batch throughput: the lane engine against the scalar engine, in one run.

Usage::

    .venv/bin/python benchmarks/bench_lanes.py                 # the full table
    .venv/bin/python benchmarks/bench_lanes.py --horizon 2     # a shorter scenario
    .venv/bin/python benchmarks/bench_lanes.py --batches 1 64 --json out.json
    .venv/bin/python benchmarks/bench_lanes.py --sampled 1e-3     # sampled-data members

For each structure (LESO: ``retuned-s1-leso``; INLESO: ``paper-s1-inleso``; LADRC:
``retuned-s1-ladrc``; all on the paper's scenario 1, RK4, dt = 1e-4, metrics only, every
member stable) and batch size (1, 8, 64, 256, 1024 copies of the design), the time of one
``simulate_batch`` call with ``engine="scalar"`` (one member at a time: the time loop of
:mod:`aiofl.engine.kernel.loop` at width 1 with libm and fast-math) and ``engine="lanes"`` (groups
of 32 members in SIMD lanes, or alone for batches under 16), on
``numba.get_num_threads()`` threads, after a warm-up call (compilation excluded), best of
``--repeat``.  Printed as member-steps per second (members
× RK4 steps / wall time) and the ratio.  The load average at the start is printed: the
figures are wall-clock and the machine may be shared.

``--sampled TS`` runs the members as sampled-data controllers (``Sampling(TS)``, the
default ZOH/fhan discretisations): the sampled instances of the same loop, scalar against
lanes.
LADRC then uses ``frontier-s1-ladrc`` (``retuned-s1-ladrc``'s ω0 = 1583 is too fast for a
1 ms sample).
"""

from __future__ import annotations

import argparse
import json
import os
import time

CASES = {"LESO": "retuned-s1-leso", "INLESO": "paper-s1-inleso", "LADRC": "retuned-s1-ladrc"}
SAMPLED_CASES = {**CASES, "LADRC": "frontier-s1-ladrc"}


def measure(
    name: str, engine: str, batch: int, horizon: float, repeat: int, ts: float = 0.0
) -> float:
    """Member-steps per second of one batched call (best of ``repeat``); sampled at ``ts``
    if > 0."""
    from dataclasses import replace

    from aiofl.config import load_config
    from aiofl.engine.discrete_rows import Sampling
    from aiofl.engine.simulation import simulate_batch

    rc = load_config(name)
    scenario = replace(rc.scenario, t_final=horizon) if horizon else rc.scenario
    kw = {"dt": rc.dt, "method": rc.method, "engine": engine}
    kw["sampling"] = Sampling(ts) if ts > 0 else None
    ctrls = [rc.controller] * batch
    simulate_batch(rc.plant, ctrls, scenario, **kw)  # warm-up (compile or load)
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        res = simulate_batch(rc.plant, ctrls, scenario, **kw)
        best = min(best, time.perf_counter() - t0)
    if res.diverged.any():
        raise RuntimeError(f"{name}: a member diverged; the figure would be meaningless")
    steps = round(scenario.t_final / rc.dt)
    return batch * steps / best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--batches", type=int, nargs="+", default=[1, 8, 64, 256, 1024])
    ap.add_argument("--horizon", type=float, default=0.0, help="t_final [s] (0: 20 s)")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--json", help="also write the table to this file")
    ap.add_argument("--sampled", type=float, default=0.0, metavar="TS", help="sample time [s]")
    args = ap.parse_args()
    import numba

    print(f"threads: {numba.get_num_threads()}, load average: {os.getloadavg()}")
    if args.sampled:
        print(f"sampled-data members, Ts = {args.sampled} s")
    print(f"{'structure':9s} {'batch':>6s} {'scalar':>14s} {'lanes':>14s} {'ratio':>6s}")
    print(f"{'':9s} {'':>6s} {'Msteps/s':>14s} {'Msteps/s':>14s}")
    rows = []
    cases = SAMPLED_CASES if args.sampled else CASES
    for structure, name in cases.items():
        for batch in args.batches:
            old = measure(name, "scalar", batch, args.horizon, args.repeat, args.sampled)
            new = measure(name, "lanes", batch, args.horizon, args.repeat, args.sampled)
            rows.append({"structure": structure, "batch": batch, "scalar": old, "lanes": new})
            print(
                f"{structure:9s} {batch:6d} {old / 1e6:14.2f} {new / 1e6:14.2f} {new / old:6.2f}",
                flush=True,
            )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"load": os.getloadavg(), "rows": rows}, fh, indent=1)


if __name__ == "__main__":
    main()
