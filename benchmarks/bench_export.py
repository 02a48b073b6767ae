"""Cost of one ``aiofl_step`` of the exported C controller, and its agreement with the engine.

Run ``python benchmarks/bench_export.py``.  For the shipped ρ = 4 designs (re-tuned LESO,
INLESO and LADRC of scenario 1) it exports the controller sampled at ``--ts`` in double and
single precision, compiles it with the system C compiler (``cc -std=c99 -O2``, plus
``--march`` if given) together with a small timing driver, and prints the nanoseconds per
``aiofl_step`` call: the best of ``--repeat`` runs of ``--steps`` calls each on a
precomputed measurement/reference sequence, timed with ``clock_gettime(CLOCK_MONOTONIC)``
inside C (no Python in the loop).  The driver sums the commands into a volatile, so the
calls cannot be optimised away.

The third column is the float build with float signals (``-DAIOFL_SIGNAL_IS_FLOAT``): the
cost of the offset coordinates' double subtractions is the difference to the second.

With ``--agreement`` it also drives each exported controller in closed loop on the SLFJM
(:mod:`aiofl.export.c_check`, as ``tests/test_export.py`` does) for ``--agreement-time``
seconds and prints the largest difference between its commands and the engine's discrete
controller's, relative to the largest command.

Timings depend on the machine and its load (printed with the results); no assertion is
made on any figure.
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

DRIVER = r"""
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "aiofl_controller.h"

int main(int argc, char **argv)
{
    long n = argc > 1 ? atol(argv[1]) : 1000000L;
    int repeat = argc > 2 ? atoi(argv[2]) : 5;
    static aiofl_signal ys[4096], rs[4096][AIOFL_RHO + 1];
    volatile double sink = 0.0;
    double best = 1e300;
    aiofl_state s;
    int i, k, rep;
    for (i = 0; i < 4096; ++i) {
        double t = i * AIOFL_TS, w = 2.0, a = 0.785398;
        ys[i] = (aiofl_signal)(0.95 * a * sin(w * t - 0.05) + 1e-4 * cos(37.0 * t));
        for (k = 0; k <= AIOFL_RHO; ++k)
            rs[i][k] = (aiofl_signal)(a * pow(w, k) * sin(w * t + k * 1.5707963267948966));
    }
    for (rep = 0; rep < repeat; ++rep) {
        struct timespec t0, t1;
        long j;
        double acc = 0.0;
        aiofl_init(&s, &aiofl_default_params, ys[0]);
        clock_gettime(CLOCK_MONOTONIC, &t0);
        for (j = 0; j < n; ++j)
            acc += aiofl_step(&s, &aiofl_default_params, rs[j & 4095], ys[j & 4095]);
        clock_gettime(CLOCK_MONOTONIC, &t1);
        sink += acc;
        double ns = ((t1.tv_sec - t0.tv_sec) * 1e9 + (t1.tv_nsec - t0.tv_nsec)) / (double)n;
        if (ns < best) best = ns;
    }
    printf("%.3f %g\n", best, (double)sink);
    return 0;
}
"""

DESIGNS = ("retuned-s1-leso", "retuned-s1-inleso", "retuned-s1-ladrc", "frontier-s1-ladrc")
# columns: (precision, extra cc flags); float with float signals is the build without the
# offset coordinates' double subtractions (y quantised to 24 bits: float does not hold)
COLUMNS = (("double", []), ("float", []), ("float", ["-DAIOFL_SIGNAL_IS_FLOAT"]))


def _table(title: str, header: list[str], rows: list[list[str]]) -> None:
    widths = [max(len(str(c)) for c in col) for col in zip(header, *rows, strict=True)]
    print(f"\n{title}")
    print("  " + "  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)))
    print("  " + "  ".join("-" * w for w in widths))
    for row in rows:
        print("  " + "  ".join(str(c).ljust(w) for c, w in zip(row, widths, strict=True)))


def ns_per_step(
    preset: str, ts: float, precision: str, extra: list[str], args: argparse.Namespace
) -> float:
    from aiofl.config import load_config
    from aiofl.engine.discrete_rows import Sampling
    from aiofl.export import export_c

    cfg = load_config(preset)
    files = export_c(cfg.controller, Sampling(ts), precision=precision)
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        for name, text in files.items():
            (d / name).write_text(text)
        (d / "driver.c").write_text(DRIVER)
        exe = d / "bench"
        flags = ["-std=c99", "-O2", *extra, *([f"-march={args.march}"] if args.march else [])]
        srcs = sorted(str(p) for p in d.glob("*.c"))
        cmd = [args.cc, *flags, "-o", str(exe), *srcs, "-lm"]
        subprocess.run(cmd, check=True)
        out = subprocess.run(
            [str(exe), str(args.steps), str(args.repeat)],
            check=True,
            capture_output=True,
            text=True,
        )
    return float(out.stdout.split()[0])


def agreement(preset: str, ts: float, precision: str, t_final: float) -> float:
    from aiofl.config import load_config
    from aiofl.discrete_controller import DiscreteController
    from aiofl.engine.discrete_rows import Sampling
    from aiofl.export import export_c
    from aiofl.export.c_check import CController, build, loop

    cfg = load_config(preset)
    samp, c = Sampling(ts), cfg.controller
    eng = DiscreteController(c, samp)
    u_e: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        cc = CController(build(Path(tmp), export_c(c, samp, precision=precision)), precision)

        def step(r: list[float], y: float) -> float:
            if not u_e:
                cc.start(y, c.eso_init)
                eng.init(y)
            u_e.append(eng.step(r, y))
            return cc.step(r, y)

        _, _, u_c = loop(step, cfg.plant, cfg.scenario.reference, c.rho, ts, t_final)
    return float(abs(u_c - u_e).max() / abs(np.array(u_e)).max())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ts", type=float, default=1e-3)
    ap.add_argument("--steps", type=int, default=2_000_000)
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--cc", default=shutil.which("cc") or "cc")
    ap.add_argument("--march", default="", help="e.g. native (default: the compiler's)")
    ap.add_argument("--agreement", action="store_true")
    ap.add_argument("--agreement-time", type=float, default=2.0)
    args = ap.parse_args()
    print(f"machine: {platform.machine()} {platform.processor()}, load {os.getloadavg()}")
    cc_version = subprocess.run([args.cc, "--version"], capture_output=True, text=True)
    print(f"compiler: {cc_version.stdout.splitlines()[0]}, -std=c99 -O2 {args.march}")
    rows = []
    for preset in DESIGNS:
        row = [preset]
        for precision, extra in COLUMNS:
            row.append(f"{ns_per_step(preset, args.ts, precision, extra, args):.1f}")
        rows.append(row)
    _table(
        f"ns per aiofl_step (rho = 4, Ts = {args.ts:g} s, best of {args.repeat} x {args.steps})",
        ["design", "double", "float", "float, float y (no offsets)"],
        rows,
    )
    if args.agreement:
        rows = []
        for preset in DESIGNS:
            rows.append(
                [
                    preset,
                    *(
                        f"{agreement(preset, args.ts, p, args.agreement_time):.2e}"
                        for p in ("double", "float")
                    ),
                ]
            )
        _table(
            "max |u_C - u_engine| / max |u_engine| in closed loop on the SLFJM",
            ["design", "double", "float"],
            rows,
        )


if __name__ == "__main__":
    main()
