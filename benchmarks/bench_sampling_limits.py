"""The report's sampling limits: the largest sample time of every shipped design, warm.

Run ``python benchmarks/bench_sampling_limits.py``.  It runs
:func:`aiofl.reporting.sampling_note.case_limits` on the designs ``aiofl reproduce`` reports
(the stage "sampling limits" of its timings: a ladder of sample times per design, simulated
in batched engine calls, and each sampled loop's linearisation), once to fill the kernel
cache and then ``--repeat`` times, and prints the wall time of each repeat and how many
members ran in groups of 32 lanes and alone.  A ladder's members differ in their steps per
sample; since the sampled loop gives each lane its own period they share lane groups.

No figure is asserted.  The load average is printed: the figures mean little on a busy
machine.
"""

from __future__ import annotations

import argparse
import os
import time

from aiofl.engine import simulation
from aiofl.reporting.cases import discover_cases
from aiofl.reporting.sampling_note import case_limits


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=2, help="timed runs after the warm-up")
    args = parser.parse_args()
    configs = {c.preset: c.config for c in discover_cases(None)}
    widths: dict[int, int] = {}
    real_plan = simulation.plan

    def counting_plan(*a: object) -> dict:  # members per lane width, for the printout
        out = real_plan(*a)  # type: ignore[arg-type]
        for (width, _), groups in out.items():
            widths[width] = widths.get(width, 0) + int((groups >= 0).sum())
        return out

    simulation.plan = counting_plan  # type: ignore[assignment]
    case_limits(configs)  # warm-up: kernels compiled or loaded
    load = ", ".join(f"{v:.2f}" for v in os.getloadavg())
    print(f"sampling limits of {len(configs)} designs; load average {load}, {os.cpu_count()} CPUs")
    for i in range(args.repeat):
        widths.clear()
        t0 = time.perf_counter()
        case_limits(configs)
        wall = time.perf_counter() - t0
        groups = ", ".join(f"{n} members at width {w}" for w, n in sorted(widths.items()))
        print(f"  run {i + 1}: {wall:6.2f} s  ({groups})")


if __name__ == "__main__":
    main()
