"""Every shipped preset on a rig (issue 36): the verdict, nominal and over draws.

Each preset runs as shipped (a controller not told about the rig's delay is not told) on
the rig preset (default ``servo-1khz``), nominal and over ``--draws`` draws of its
``[uncertainty]`` box and the rig's lag and friction (:func:`aiofl.analysis.rig_check`),
one JSON line per preset, then a Markdown table::

    PYTHONPATH=src python benchmarks/rig_verdicts.py --draws 32 > rig.jsonl
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from aiofl.analysis.rig_check import rig_check
from aiofl.config import list_presets, load_config


def _cell(x: float | None, digits: int = 4) -> str:
    return "—" if x is None else f"{x:.{digits}g}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rig", default="servo-1khz")
    ap.add_argument("--draws", type=int, default=32)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--told", action="store_true", help="tell every controller the delay")
    ap.add_argument("presets", nargs="*", help="default: every shipped preset")
    args = ap.parse_args()
    rows = []
    for name in args.presets or list_presets():
        t0 = time.perf_counter()
        try:
            chk = rig_check(
                load_config(name), args.rig, draws=args.draws, seed=args.seed, told=args.told
            )
        except Exception as exc:  # a preset that cannot run on the rig: said
            print(json.dumps({"preset": name, "error": str(exc)[:300]}), flush=True)
            rows.append(f"| {name} | cannot run: {str(exc).splitlines()[-1][:80]} |||||||")
            continue
        rec = {"preset": name, **chk.to_dict(), "seconds": round(time.perf_counter() - t0, 1)}
        print(json.dumps(rec), flush=True)
        nom, own = chk.nominal, chk.own
        rows.append(
            f"| {name} | {_cell(own['itae'])} @ {_cell(own['isu'])} | "
            f"{_cell(nom['itae'])} @ {_cell(nom['isu'])} | {nom['status']} | "
            f"{100 * chk.not_lost:.0f} % | {_cell(chk.itae_q95)} | {_cell(chk.isu_q95)} | "
            f"{chk.verdict} |"
        )
    print()
    print(
        "| preset | own run ITAE @ ISU | rig nominal ITAE @ ISU | status | not lost | "
        "ITAE q95 | ISU q95 | verdict |"
    )
    print("|---|---|---|---|---|---|---|---|")
    print("\n".join(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
