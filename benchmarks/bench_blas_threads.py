"""What a multi-threaded BLAS costs aiofl's small matrices.

Run ``python benchmarks/bench_blas_threads.py``.  In one process that has run the engine
(as ``aiofl reproduce`` has by then), it times, alternately with the BLAS's default threads
and with one (:func:`aiofl.blas_threads.one_blas_thread`), ``--rounds`` times each:

* ``scipy.linalg.expm`` of a 9 × 9 matrix (the ZOH of :mod:`aiofl.analysis.sampled_loop`),
  microseconds per call (best of 3 × 200 calls);
* the sampled loop's spectral radius at five sample times and its delay margin at 1 ms for
  ``--presets`` (:class:`aiofl.analysis.sampled_loop.SampledLoop`, as the report's sampling
  limits compute them), seconds.

The effect depends on what else the cores are doing: on an idle machine the two agree;
with both cores busy (the report's engine threads and orbit workers, or another job) a
two-thread OpenBLAS waits for its second thread at each call and single calls took
0.7–7.8 ms on the 2-core development machine.  Run it beside a busy job to see that.  No
assertion is made on any figure.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from scipy.linalg import expm
from threadpoolctl import threadpool_info

from aiofl.blas_threads import one_blas_thread
from aiofl.config import load_config


def _expm_us(a: np.ndarray) -> float:
    best = float("inf")
    for _ in range(3):
        t = time.perf_counter()
        for _ in range(200):
            expm(a)
        best = min(best, (time.perf_counter() - t) / 200)
    return 1e6 * best


def _sampled_s(presets: list[str]) -> float:
    from aiofl.analysis.sampled_loop import SampledLoop

    t = time.perf_counter()
    for name in presets:
        loop = SampledLoop(load_config(name))
        for ts in (1e-4, 5e-4, 1e-3, 2e-3, 5e-3):
            loop.spectral_radius(ts)
        loop.delay_margin(1e-3)
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument(
        "--presets", nargs="+", default=["retuned-s1-leso", "retuned-s1-ladrc", "retuned-s2-leso"]
    )
    args = ap.parse_args()
    load_config(args.presets[0]).simulate()  # the engine's threads exist, as in a report
    a = np.random.default_rng(0).standard_normal((9, 9))
    _sampled_s(args.presets)  # warm-up: imports, kernels
    blas = ", ".join(f"{i['internal_api']} {i['num_threads']} threads" for i in threadpool_info())
    print(f"BLAS: {blas}; load average {os.getloadavg()[0]:.2f}")
    print(f"{'round':>5} {'expm default':>13} {'expm one':>9} {'sampled default':>16} {'one':>6}")
    for k in range(args.rounds):
        e_def, s_def = _expm_us(a), _sampled_s(args.presets)
        with one_blas_thread():
            e_one, s_one = _expm_us(a), _sampled_s(args.presets)
        print(f"{k:>5} {e_def:11.1f}us {e_one:7.1f}us {s_def:15.2f}s {s_one:5.2f}s")


if __name__ == "__main__":
    main()
