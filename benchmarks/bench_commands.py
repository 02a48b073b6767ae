"""What a user waits for: wall time of whole ``aiofl`` commands, each in a fresh process.

Run ``python benchmarks/bench_commands.py`` (``--reproduce`` adds ``aiofl reproduce``, about
a minute or two more).  Every row runs in its own subprocess with ``AIOFL_CACHE_DIR`` set to
a new temporary folder shared by the rows of one case, so "cold" means a cache that has
never seen the plant (numba still finds the component functions it caches beside the
sources) and "warm" the same command again in a new process:

* ``simulate`` of a config on a plant file (a 2-state Duffing oscillator, 5-s step, LADRC,
  dt = 1e-3): cold, then warm (the plant module and its kernel are loaded from the cache);
  then once more after editing a parameter value in the plant file (a new plant module,
  sympy runs again, the kernel is the same: :mod:`aiofl.engine.build.code_fingerprint`); then a
  plant file of another model, never seen, in the same cache (sympy and its table entries;
  the width-1 loop of 2-state plants is cached: :mod:`aiofl.engine.build.plant_table`);
* ``simulate frontier-s1-ladrc`` (a built-in plant): cold, then warm;
* ``robustness`` of the plant-file config over 100 draws of ±20 % k and ±50 % c
  (``--no-corners``): 100 members of one kind, which run in lanes once the plant's lane
  instance is at hand or worth its compile (:mod:`aiofl.engine.build.lane_choice`), alone before;
* with ``--reproduce``: ``aiofl reproduce`` cold, then warm.

The targets of issue 19 (2-core machine, quiet): plant file cold <= 15 s, warm <= 3 s;
built-in preset warm <= 2 s; reproduce warm <= 25 s.  The load average is printed: the
figures mean little on a busy machine.  Each row also gives the CPU seconds of each run
(cold / warm ...: user + system time of the command and of the processes it started):
a command's wall time on N cores is at least its CPU seconds over N.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PLANT = """\
name = "duffing"
description = "mass-spring-damper with a hardening spring"
states = ["x", "v"]
f = ["v", "(-k*x - 0.5*k*x**3 - c*v)/m"]
g = ["0", "1/m"]
h = "x"
[params]
k = 4.0
c = 0.3
m = 1.0
"""

OTHER_PLANT = """\
name = "vdp"
description = "Van der Pol oscillator, forced"
states = ["x", "v"]
f = ["v", "mu*(1 - x**2)*v - x"]
g = ["0", "1"]
h = "x"
[params]
mu = 0.5
"""

CONFIG = """\
plant = "duffing.toml"
[scenario]
t_final = 5.0
[scenario.reference]
kind = "step"
amplitude = 1.0
[controller]
structure = "LADRC"
[controller.eso]
omega0 = 40.0
[controller.sef]
omega_c = 5.0
[controller.td]
omega = 10.0
[controller.law]
b0 = 1.0
[simulation]
dt = 1e-3
"""

UNCERTAINTY = """\
[uncertainty]
draws = 100
seed = 1
[uncertainty.parameters]
k = { uniform = 0.2 }
c = { uniform = 0.5 }
"""


def _aiofl() -> list[str]:
    exe = Path(sys.executable).with_name("aiofl")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "aiofl"]


CPU_SECONDS: list[float] = []
"""CPU seconds (user + system, the command and every process it started and waited for)
of each :func:`timed` run, in order."""


def _children_cpu() -> float:
    use = resource.getrusage(resource.RUSAGE_CHILDREN)
    return use.ru_utime + use.ru_stime


def timed(args: list[str], cache: Path, out: Path) -> tuple[float, int]:
    """Wall time and exit status of ``aiofl ARGS --out OUT`` with the cache folder ``cache``
    (its CPU seconds appended to :data:`CPU_SECONDS`)."""
    env = {k: v for k, v in os.environ.items() if k != "AIOFL_NO_CACHE"}
    env["AIOFL_CACHE_DIR"] = str(cache)
    shutil.rmtree(out, ignore_errors=True)
    cpu0 = _children_cpu()
    t0 = time.perf_counter()
    proc = subprocess.run(
        [*_aiofl(), *args, "--out", str(out)], env=env, capture_output=True, check=False
    )
    wall = time.perf_counter() - t0
    CPU_SECONDS.append(_children_cpu() - cpu0)
    return wall, proc.returncode


def _row(label: str, seconds: float, rc: int) -> None:
    note = "" if rc == 0 else f"  (exit {rc})"
    print(f"{label:36s} {'':9s} {seconds:18.2f}  [{CPU_SECONDS[-1]:.0f} CPU-s]{note}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reproduce", action="store_true", help="also time aiofl reproduce")
    parser.add_argument("--warm-runs", type=int, default=2, help="warm invocations per case")
    opts = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="aiofl-bench-commands-"))
    try:
        (work / "duffing.toml").write_text(PLANT)
        (work / "sim.toml").write_text(CONFIG)
        (work / "robust.toml").write_text(CONFIG + UNCERTAINTY)
        robust = ["robustness", str(work / "robust.toml"), "--no-corners"]
        cases = [
            ("simulate CONFIG on a plant file", ["simulate", str(work / "sim.toml")]),
            ("simulate frontier-s1-ladrc", ["simulate", "frontier-s1-ladrc"]),
            ("robustness, plant file, 100 draws", robust),
        ]
        if opts.reproduce:
            cases.append(("reproduce", ["reproduce"]))
        load = ", ".join(f"{v:.2f}" for v in os.getloadavg())
        print(f"aiofl commands, fresh process each; load average {load}, {os.cpu_count()} CPUs")
        print(f"{'command':36s} {'cold [s]':>9s} {'warm [s]':>18s}")
        for i, (label, args) in enumerate(cases):
            cache = work / f"cache{i}"
            first = len(CPU_SECONDS)
            cold, rc = timed(args, cache, work / "out")
            warm = [timed(args, cache, work / "out") for _ in range(opts.warm_runs)]
            codes = {rc, *(c for _, c in warm)}
            note = "" if codes == {0} else f"  (exit {sorted(codes)})"
            warm_text = " / ".join(f"{w:.2f}" for w, _ in warm)
            cpu = " / ".join(f"{c:.0f}" for c in CPU_SECONDS[first:])
            print(f"{label:36s} {cold:9.2f} {warm_text:>18s}  [{cpu} CPU-s]{note}")
            if i == 0:  # a parameter value of the plant file edited, then another model
                (work / "duffing.toml").write_text(PLANT.replace("k = 4.0", "k = 5.0"))
                edited, rc = timed(args, cache, work / "out")
                _row("  the same, k edited in the plant file", edited, rc)
                (work / "vdp.toml").write_text(OTHER_PLANT)
                (work / "vdp.sim.toml").write_text(CONFIG.replace("duffing.toml", "vdp.toml"))
                other = ["simulate", str(work / "vdp.sim.toml")]
                first, rc = timed(other, cache, work / "out")
                _row("  another 2-state plant file, 1st run", first, rc)
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
