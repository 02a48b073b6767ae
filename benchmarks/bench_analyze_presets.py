"""``aiofl analyze PRESET --closed-loop`` per shipped preset, warm, one at a time (issue 37).

Each preset runs once to warm the caches (``--warm 1``) and then ``--repeat`` times in a
fresh ``python -m aiofl`` process; the table gives the best wall time and the CPU time
(user + sys) of that run, with the load average before each preset, so a busy machine is
seen in the figures.  The target is at most 2 s wall per preset::

    PYTHONPATH=src python benchmarks/bench_analyze_presets.py [--repeat 2] [PRESET ...]
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import time

from aiofl.config import preset_sets


def _run(preset: str) -> tuple[float, float, int]:
    """One ``aiofl analyze PRESET --closed-loop``: (wall s, CPU s, exit status)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "aiofl", "analyze", preset, "--closed-loop"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        check=False,
    )
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if proc.returncode != 0:
        sys.stderr.write(proc.stderr.decode(errors="replace")[-500:])
    return wall, cpu, proc.returncode


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("presets", nargs="*", help="presets (default: every shipped one)")
    parser.add_argument("--repeat", type=int, default=2, help="timed runs per preset")
    parser.add_argument("--warm", type=int, default=1, help="untimed runs first")
    args = parser.parse_args()
    names = args.presets or sorted(n for ns in preset_sets().values() for n in ns)
    print(f"{'preset':26s} {'wall s':>7s} {'cpu s':>6s} {'load':>5s}  exit")
    worst = 0.0
    for name in names:
        for _ in range(args.warm):
            _run(name)
        load = os.getloadavg()[0]
        runs = [_run(name) for _ in range(args.repeat)]
        wall, cpu, code = min(runs)
        worst = max(worst, wall)
        print(f"{name:26s} {wall:7.2f} {cpu:6.2f} {load:5.2f}  {code}", flush=True)
    print(f"slowest: {worst:.2f} s wall")
    return 0


if __name__ == "__main__":
    sys.exit(main())
