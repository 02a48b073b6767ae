"""Every shipped preset's verdict and figures, one JSON line each (issue 33's re-check).

Runs each preset as it is (its own scenario, sampling and sensor) and prints its status,
the time it stopped, ITAE and ISU.  Written to run on older checkouts too (before verdicts
existed a result had only ``diverged`` / ``diverged_at``), so a before/after table can be
made by running it on two commits::

    PYTHONPATH=src python benchmarks/preset_verdicts.py > after.jsonl
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from aiofl.config import load_config


def _verdict(res: object) -> tuple[str, float | None]:
    status = getattr(res, "status", None)
    if status is None:  # before the verdicts: diverged or "stable"
        bad = bool(res.diverged)  # type: ignore[attr-defined]
        at = float(res.diverged_at) if bad else None  # type: ignore[attr-defined]
        return ("diverged" if bad else "ok"), at
    at = res.stopped_at if res.failed else None  # type: ignore[attr-defined]
    return str(status), (None if at is None else float(at))


def main() -> None:
    import aiofl

    presets = Path(aiofl.__file__).parent / "presets"
    # every preset set (presets/, paper/, limits/); older checkouts have the first only
    paths = [p for p in presets.rglob("*.toml") if p.parent.name != "fronts"]
    for path in sorted(paths, key=lambda p: p.stem):
        t0 = time.perf_counter()
        try:
            cfg = load_config(path.stem)
            res = cfg.simulate(store=False)
        except Exception as exc:  # a preset that cannot run: said
            print(json.dumps({"preset": path.stem, "error": str(exc)[:200]}), flush=True)
            continue
        status, at = _verdict(res)
        m = res.metrics or {}
        line = {
            "preset": path.stem,
            "status": status,
            "stopped_at": at,
            "itae": m.get("itae"),
            "isu": m.get("isu"),
            "seconds": round(time.perf_counter() - t0, 2),
        }
        print(json.dumps(line), flush=True)


if __name__ == "__main__":
    sys.exit(main())
