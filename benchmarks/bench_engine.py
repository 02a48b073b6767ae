"""Engine speed: scipy vs engine, one 20-s run, a batch of 64 on all cores, compile time.

Run ``python benchmarks/bench_engine.py`` (or ``make bench``).  Prints one table per part:

(a) the same closed loop through scipy's ``solve_ivp`` (RK45, the plain-Python right-hand
    side of :mod:`aiofl.engine.reference`) and through the engine (RK4, dt = 1e-4): seconds
    of wall time per simulated second, and the ratio.  scipy runs a short horizon only
    (``--scipy-horizon``, default 0.5 s); the per-simulated-second figure extrapolates it.
(b) one 20-s simulation at dt = 1e-4 after warm-up, for the paper presets (best of
    ``--repeat``).
(c) a batch of 64 members (a population around a paper preset) with 1 thread and with
    all threads (``numba.set_num_threads``): per-simulation time and the speed-up.
(d) compile time in a fresh subprocess: with the on-disk kernel cache disabled
    (``AIOFL_NO_CACHE=1``, a true cold start) and with it populated.

Wall-clock figures depend on what else the machine is doing; the load average at the
start is printed with the results.  No assertion is made on any figure.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable

import numpy as np


def _best(fn: Callable[[], object], repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _table(title: str, header: list[str], rows: list[list[str]]) -> None:
    widths = [max(len(str(c)) for c in col) for col in zip(header, *rows, strict=True)]
    print(f"\n{title}")
    print("  " + "  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)))
    print("  " + "  ".join("-" * w for w in widths))
    for row in rows:
        print("  " + "  ".join(str(c).ljust(w) for c, w in zip(row, widths, strict=True)))


def smooth_ladrc() -> object:
    """The smooth loop used to compare with scipy: linear ESO (ω0 = 100, binomial), linear
    prefilter (ω = 20), full-state linear SEF (ωc = 10), b0 = the SLFJM's true β."""
    from aiofl.controller import Controller

    beta = 1.61 * 0.00767 * 70.0 / (0.0059 * 0.0021 * 2.6)
    values = {"law.b0": beta, "eso.omega0": 100.0, "sef.omega_c": 10.0, "td.omega": 20.0}
    return Controller.from_structure("LADRC", n_feedback=4, values=values).with_binomial_alphas()


def part_a(horizon: float, repeat: int) -> None:
    from aiofl.config import load_config
    from aiofl.engine.reference import reference_simulate
    from aiofl.engine.simulation import simulate
    from aiofl.plants import get_plant
    from aiofl.scenario import Scenario

    plant = get_plant("slfjm")
    cases = [
        ("LADRC (smooth), RK45 rtol 1e-6", smooth_ladrc(), Scenario(t_final=20.0), 1e-6, horizon),
        ("LADRC (smooth), RK45 rtol 1e-9", smooth_ladrc(), Scenario(t_final=20.0), 1e-9, horizon),
    ]
    rc = load_config("paper-s1-inleso")
    cases.append(("paper-s1-inleso, RK45 rtol 1e-6", rc.controller, rc.scenario, 1e-6, horizon))
    rc = load_config("paper-s1-leso")
    # Han's TD switches with sign(): the adaptive solver crawls; a very short horizon
    cases.append(("paper-s1-leso (Han TD), RK45 rtol 1e-6", rc.controller, rc.scenario, 1e-6, 0.01))
    rows = []
    for label, ctrl, scen, rtol, span in cases:
        short = dataclasses.replace(scen, t_final=span)
        t0 = time.perf_counter()
        ref = reference_simulate(plant, ctrl, short, rtol=rtol, atol=rtol * 1e-3, t_eval=[span])
        t_scipy = (time.perf_counter() - t0) / span
        simulate(plant, ctrl, scen, store=False)  # warm
        t_engine = _best(lambda c=ctrl, s=scen: simulate(plant, c, s, store=False), repeat)
        res = simulate(plant, ctrl, scen, store=False)
        simulated = res.diverged_at if res.diverged else scen.t_final
        t_engine /= simulated
        rows.append(
            [
                label,
                f"{span:g} s",
                f"{ref.nfev}",
                f"{t_scipy:.3g}",
                f"{t_engine * 1e3:.3g} ms",
                f"{t_scipy / t_engine:,.0f}x",
            ]
        )
    _table(
        "(a) scipy solve_ivp (Python RHS) vs engine (RK4, dt=1e-4): wall time per simulated s",
        ["loop", "scipy horizon", "scipy nfev", "scipy s/s", "engine /s", "engine speed-up"],
        rows,
    )


def part_b(repeat: int) -> None:
    from aiofl.config import load_config

    rows = []
    for name in ("paper-s1-leso", "paper-s3-leso", "paper-s1-inleso", "paper-s2-inleso"):
        rc = load_config(name)
        rc.simulate(store=False)
        best = _best(lambda rc=rc: rc.simulate(store=False), repeat)
        res = rc.simulate(store=False)
        span = res.diverged_at if res.diverged else rc.scenario.t_final
        note = f"diverges at {span:.2f} s" if res.diverged else ""
        rows.append(
            [name, f"{span:.2f}", f"{best * 1e3:.1f}", f"{best / span * 20.0 * 1e3:.1f}", note]
        )
    _table(
        f"(b) one paper simulation, dt=1e-4, warm (best of {repeat})",
        ["preset", "simulated [s]", "wall [ms]", "per 20 s [ms]", "note"],
        rows,
    )


def part_c(repeat: int, size: int) -> None:
    import numba

    from aiofl.config import load_config
    from aiofl.controller import controller_batch
    from aiofl.engine.simulation import simulate_batch

    rows = []
    max_threads = numba.config.NUMBA_NUM_THREADS
    for name in ("paper-s3-leso", "paper-s1-inleso"):
        rc = load_config(name)
        w0 = rc.controller.value("eso.omega0")
        batch = controller_batch(rc.controller, {"eso.omega0": w0 * np.linspace(0.98, 1.02, size)})
        # engine="lanes": the lane instance, whatever the cache holds
        # (aiofl.engine.build.lane_choice)
        simulate_batch(rc.plant, batch, rc.scenario, engine="lanes")  # warm
        times = {}
        for threads in sorted({1, max_threads}):
            numba.set_num_threads(threads)
            times[threads] = _best(
                lambda rc=rc, batch=batch: simulate_batch(
                    rc.plant, batch, rc.scenario, engine="lanes"
                ),
                repeat,
            )
        numba.set_num_threads(max_threads)
        res = simulate_batch(rc.plant, batch, rc.scenario, engine="lanes")
        for threads, t in times.items():
            rows.append(
                [
                    name,
                    str(size),
                    str(threads),
                    f"{t:.2f}",
                    f"{t / size * 1e3:.1f}",
                    f"{times[1] / t:.2f}x",
                    str(int(res.diverged.sum())),
                ]
            )
    _table(
        f"(c) a batch of {size} (eso.omega0 ±2 % around the preset), 20 s each",
        ["preset", "members", "threads", "wall [s]", "per member [ms]", "speed-up", "diverged"],
        rows,
    )


_COLD = textwrap.dedent(
    """
    import time
    t0 = time.perf_counter()
    from aiofl.config import load_config
    from aiofl.engine import simulation
    from aiofl.engine.build import instances
    rc = load_config("paper-s1-leso")
    t1 = time.perf_counter()
    import dataclasses
    simulation.simulate(rc.plant, rc.controller, dataclasses.replace(rc.scenario, t_final=0.01))
    t2 = time.perf_counter()
    print(f"{t1 - t0:.3f} {t2 - t1:.3f} {int(instances.instance_for(rc.plant, 1).cached)}")
    """
)


def part_d() -> None:
    rows = []
    runs = [
        ("no kernel cache (AIOFL_NO_CACHE=1)", {"AIOFL_NO_CACHE": "1"}),
        ("kernel cache (first process may populate it)", {}),
        ("kernel cache, populated", {}),
    ]
    for label, env in runs:
        full_env = {k: v for k, v in os.environ.items() if k != "AIOFL_NO_CACHE"}
        full_env.update(env)
        t0 = time.perf_counter()
        out = subprocess.run(
            [sys.executable, "-c", _COLD], env=full_env, capture_output=True, text=True, check=True
        ).stdout.split()
        total = time.perf_counter() - t0
        rows.append([label, f"{float(out[0]):.2f}", f"{float(out[1]):.2f}", f"{total:.2f}"])
    _table(
        "(d) fresh process: import + first simulation (compile or load the slfjm kernel)",
        ["case", "import+config [s]", "first simulate [s]", "process total [s]"],
        rows,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--scipy-horizon", type=float, default=0.5)
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--skip", default="", help="parts to skip, e.g. 'ad'")
    args = parser.parse_args()

    import numba

    print("aiofl engine benchmark")
    print(
        f"  python {platform.python_version()}, numba {numba.__version__}, "
        f"{os.cpu_count()} CPUs ({platform.processor() or platform.machine()}), "
        f"numba threads {numba.config.NUMBA_NUM_THREADS}, "
        f"load average {', '.join(f'{v:.2f}' for v in os.getloadavg())}"
    )
    if "d" not in args.skip:
        part_d()
    if "a" not in args.skip:
        part_a(args.scipy_horizon, args.repeat)
    if "b" not in args.skip:
        part_b(args.repeat)
    if "c" not in args.skip:
        part_c(max(1, args.repeat // 2), args.batch)
    print(f"\n  load average at the end: {', '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
