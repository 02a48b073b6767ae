"""CPU seconds of the report's engine stages, each run alone and warm.

Run ``python benchmarks/bench_reproduce_stages.py``.  Times, with ``time.process_time``
(every thread of this process), the stages of ``aiofl reproduce`` that run in the compiled
lanes: the robustness draws of every shipped design (the report's 100 draws and 16
corners), the β/b0 stability ranges and the sampling limits.  Each is run once first so
that its kernels are compiled or loaded (the lane choice may rent on that first run and
compile on the next: :mod:`aiofl.engine.build.lane_choice`), then timed.  On N cores a stage's
wall time is at least its CPU seconds over N, which bounds what any warm
``aiofl reproduce`` can take (``docs/benchmarks.md``).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable

from aiofl.blas_threads import one_blas_thread


def _timed(label: str, fn: Callable[[], object], warm_runs: int = 2) -> None:
    for _ in range(warm_runs):
        fn()
    cpu0, wall0 = time.process_time(), time.perf_counter()
    fn()
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    print(f"{label:44s} wall {wall:6.1f} s   CPU {cpu:6.1f} s", flush=True)


def main() -> None:
    from aiofl.analysis.corners import beta_ranges
    from aiofl.reporting.cases import discover_cases
    from aiofl.reporting.robust_rows import DEFAULT_DRAWS, compute_robustness
    from aiofl.reporting.sampling_note import case_limits

    one_blas_thread()
    cases = discover_cases()
    configs = [c.config for c in cases]
    load = ", ".join(f"{v:.2f}" for v in os.getloadavg())
    print(f"{len(cases)} designs; load average {load}, {os.cpu_count()} CPUs")
    _timed(
        f"robustness draws ({DEFAULT_DRAWS} + corners per design)",
        lambda: compute_robustness(cases, draws=DEFAULT_DRAWS, beta=False),
    )
    _timed("β/b0 stability ranges", lambda: beta_ranges(configs))
    _timed("sampling limits", lambda: case_limits({c.preset: c.config for c in cases}))


if __name__ == "__main__":
    main()
