"""The report's orbit verdicts, timed per preset, without running ``aiofl reproduce`` (issue 37).

Each preset's :func:`aiofl.reporting.orbit_pool.closed_loop_verdict` (the linearisation and
the reconciled orbit verdict with the report's quick settings, what a worker of
``aiofl reproduce`` computes for a case) runs in this one process, one after the other,
after one untimed warm-up preset; the table gives its wall and CPU seconds, the orbit
analysis' own seconds, the short verdict and the largest Floquet multiplier.  ``--scipy``
integrates with scipy's BDF instead of the compiled Radau IIA
(:attr:`aiofl.analysis.orbit_loop.OrbitLoop.compiled_integrator`), for a before/after
table on one checkout; ``--full`` uses ``aiofl analyze``'s settings instead of the
report's::

    PYTHONPATH=src python benchmarks/bench_orbit_verdicts.py [--scipy] [--full] [PRESET ...]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings

from aiofl.config import load_config, preset_sets


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("presets", nargs="*", help="presets (default: every shipped one)")
    parser.add_argument("--scipy", action="store_true", help="scipy's BDF (the old path)")
    parser.add_argument("--full", action="store_true", help="aiofl analyze's settings")
    parser.add_argument("--json", action="store_true", help="one JSON line per preset")
    args = parser.parse_args()
    from aiofl.analysis.linearize import closed_loop_verdict
    from aiofl.analysis.orbit import orbit_analysis
    from aiofl.analysis.orbit_loop import OrbitLoop

    OrbitLoop.compiled_integrator = not args.scipy
    names = args.presets or sorted(n for ns in preset_sets().values() for n in ns)
    warnings.simplefilter("ignore", RuntimeWarning)

    def verdict(name: str) -> tuple[dict, dict]:
        cfg = load_config(name)
        lin = closed_loop_verdict(cfg)
        unit = cfg.plant.output_unit
        return lin, orbit_analysis(cfg, lin, unit=unit, quick=not args.full)

    verdict(names[0])  # warm: the compiled kernels loaded, the BLAS started
    if not args.json:
        print(f"{'preset':22s} {'wall s':>7s} {'cpu s':>6s} {'orbit s':>7s}  verdict")
    total_wall = total_cpu = 0.0
    for name in names:
        w0, c0 = time.perf_counter(), time.process_time()
        try:
            _lin, info = verdict(name)
        except Exception as exc:  # a preset whose analysis fails: said, not hidden
            print(f"{name:22s} failed: {type(exc).__name__}: {exc}"[:160], flush=True)
            continue
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        total_wall += wall
        total_cpu += cpu
        fl = info.get("floquet") or {}
        if args.json:
            row = {"preset": name, "wall": round(wall, 3), "cpu": round(cpu, 3)}
            row.update(orbit_s=round(info["seconds"], 3), short=info["short"])
            row.update(largest=fl.get("largest"), closing=fl.get("closing"))
            print(json.dumps(row), flush=True)
        else:
            print(
                f"{name:22s} {wall:7.2f} {cpu:6.2f} {info['seconds']:7.2f}  {info['short']}",
                flush=True,
            )
    print(f"total: {total_wall:.1f} s wall, {total_cpu:.1f} s CPU ({len(names)} presets)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
