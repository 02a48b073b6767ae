"""What a multi-threaded BLAS costs aiofl's small matrices on busy cores.

Run ``python benchmarks/bench_blas_threads.py``.  Times ``scipy.linalg.expm`` (the ZOH of
:mod:`aiofl.analysis.sampled_loop`), ``numpy.linalg.eigvals`` and ``numpy.linalg.solve`` of
an n × n matrix (``--n``, default 9: a ρ = 4 loop) with the BLAS's default threads and with
one (:func:`aiofl.blas_threads.one_blas_thread`), first on idle cores, then with
``--busy`` processes spinning (default: one per core, as the engine's numba threads or the
orbit workers keep them during ``aiofl reproduce``).  Prints microseconds per call (best
of ``--repeat`` runs of ``--calls`` calls); no assertion is made on any figure.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import time
from collections.abc import Callable

import numpy as np
from scipy.linalg import expm
from threadpoolctl import threadpool_info

from aiofl.blas_threads import one_blas_thread


def _spin(stop: float) -> None:
    while time.time() < stop:
        pass


def _time(fn: Callable[[], object], calls: int, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        for _ in range(calls):
            fn()
        best = min(best, (time.perf_counter() - t) / calls)
    return 1e6 * best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=9)
    ap.add_argument("--calls", type=int, default=200)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--busy", type=int, default=os.cpu_count() or 1)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    a = rng.standard_normal((args.n, args.n))
    b = rng.standard_normal(args.n)
    cases = {
        "expm": lambda: expm(a),
        "eigvals": lambda: np.linalg.eigvals(a),
        "solve": lambda: np.linalg.solve(a, b),
    }
    blas = ", ".join(f"{i['internal_api']} {i['num_threads']} threads" for i in threadpool_info())
    print(f"n = {args.n}; BLAS: {blas}; load average {os.getloadavg()[0]:.2f}")
    print(f"{'cores':>6} {'call':>8} {'default [us]':>13} {'one thread [us]':>16}")
    for label, busy in (("idle", 0), ("busy", args.busy)):
        procs = [mp.Process(target=_spin, args=(time.time() + 600,)) for _ in range(busy)]
        for p in procs:
            p.start()
        try:
            for name, fn in cases.items():
                default = _time(fn, args.calls, args.repeat)
                with one_blas_thread():
                    one = _time(fn, args.calls, args.repeat)
                print(f"{label:>6} {name:>8} {default:13.1f} {one:16.1f}")
        finally:
            for p in procs:
                p.terminate()


if __name__ == "__main__":
    main()
