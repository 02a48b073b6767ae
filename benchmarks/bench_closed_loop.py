"""Time the closed-loop analyses per shipped preset, in one process, warm.

For each preset: the linearisation verdict with its margins
(:func:`aiofl.analysis.linearize.closed_loop_verdict`) and the reconciled orbit verdict
(:func:`aiofl.analysis.orbit.orbit_analysis`), with the report's quick settings
(``--quick``, what ``aiofl reproduce`` runs in its orbit workers) or the full ones (what
``aiofl analyze --closed-loop`` runs).  Prints the wall and CPU seconds of each part and
their totals, and with ``--json FILE`` writes every record (to compare two trees: run it
with ``PYTHONPATH`` on each).  Each preset is analysed once before the timed run, so
compiling (numba, the plant's jets) is not counted.

    .venv/bin/python benchmarks/bench_closed_loop.py --quick
    PYTHONPATH=/path/to/other/src .venv/bin/python benchmarks/bench_closed_loop.py --quick
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path
from typing import Any


def _timed(fn: Any) -> tuple[Any, float, float]:
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w, time.process_time() - c


def main() -> None:
    """Run the benchmark (module docstring)."""
    import aiofl
    from aiofl.analysis.linearize import closed_loop_verdict
    from aiofl.analysis.orbit import orbit_analysis
    from aiofl.blas_threads import one_blas_thread
    from aiofl.config import load_config

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("presets", nargs="*", help="presets (default: every shipped one)")
    ap.add_argument("--quick", action="store_true", help="the report's quick orbit settings")
    ap.add_argument("--no-warm-up", action="store_true", help="time the first run too")
    ap.add_argument("--json", help="write the records to this file")
    args = ap.parse_args()
    shipped = sorted(p.stem for p in (Path(aiofl.__file__).parent / "presets").glob("*.toml"))
    names = args.presets or shipped
    one_blas_thread()
    print(f"load average {os.getloadavg()[0]:.2f}; quick = {args.quick}")
    records: dict[str, Any] = {}
    total = [0.0, 0.0, 0.0, 0.0]
    for name in names:
        cfg = load_config(name)

        def run(cfg: Any = cfg) -> tuple[Any, Any, float, float, float, float]:
            try:
                v, wl, cl = _timed(lambda: closed_loop_verdict(cfg))
            except Exception as exc:
                return {"error": f"{type(exc).__name__}: {exc}"}, None, 0.0, 0.0, 0.0, 0.0
            o, wo, co = _timed(lambda: orbit_analysis(cfg, v, quick=args.quick))
            return v, o, wl, cl, wo, co

        if not args.no_warm_up:
            run()
        v, o, wl, cl, wo, co = run()
        for i, x in enumerate((wl, cl, wo, co)):
            total[i] += x
        short = (o or {}).get("short", v.get("error", ""))
        print(
            f"{name:22s} linearise {wl:6.2f} s ({cl:6.2f} CPU-s)  orbit {wo:6.2f} s "
            f"({co:6.2f} CPU-s)  {short}",
            flush=True,
        )
        records[name] = {"linearisation": v, "orbit": o}
    print(
        f"{'total':22s} linearise {total[0]:6.2f} s ({total[1]:6.2f} CPU-s)  orbit "
        f"{total[2]:6.2f} s ({total[3]:6.2f} CPU-s)"
    )
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(records, fh, indent=1, default=str)


if __name__ == "__main__":
    main()
