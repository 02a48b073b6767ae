"""How far the lane engine's metrics are from the scalar engine's, preset by preset.

Usage::

    .venv/bin/python benchmarks/lanes_vs_scalar.py

For every shipped preset (its scenario, dt, method and divergence threshold), one run with
``engine="lanes"`` and one with ``engine="scalar"``: the largest relative difference of the
five metrics (ITAE, IAE, ISE, ISU, IAU), or both divergence times.  Where the difference is
above 1e-10, also what a one-ulp change of ω0, b0, k1 or k2 does to the scalar engine's own
result (the loop's sensitivity to rounding, which bounds how well any two roundings of it
can agree).  ``tests/test_lanes.py`` asserts the same bound; this prints the figures.
"""

from __future__ import annotations

import numpy as np

from aiofl.config import load_config
from aiofl.engine.simulation import simulate_batch

NUDGED = ("eso.omega0", "law.b0", "sef.k1", "sef.k2")


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)))


def main() -> None:
    from aiofl.config import list_presets

    presets = list_presets()
    print(f"{'preset':22s} {'lanes vs scalar':>16s}  one-ulp sensitivity of the scalar engine")
    for name in presets:
        rc = load_config(name)
        kw = {"dt": rc.dt, "method": rc.method, "divergence_threshold": rc.divergence_threshold}
        lanes = simulate_batch(rc.plant, rc.controller, rc.scenario, engine="lanes", **kw)
        scalar = simulate_batch(rc.plant, rc.controller, rc.scenario, engine="scalar", **kw)
        if lanes.diverged[0] or scalar.diverged[0]:
            print(
                f"{name:22s} diverged: lanes at {lanes.diverged_at[0]:.6g} s, "
                f"scalar at {scalar.diverged_at[0]:.6g} s"
            )
            continue
        diff = _rel(lanes.metrics[0], scalar.metrics[0])
        note = ""
        if diff > 1e-10:
            c = rc.controller
            parts = []
            for key in NUDGED:
                nudged = c.with_values(**{key: c.values[key] * (1 + 2**-52)})
                other = simulate_batch(rc.plant, nudged, rc.scenario, engine="scalar", **kw)
                parts.append(f"{key} {_rel(other.metrics[0], scalar.metrics[0]):.1e}")
            note = ", ".join(parts)
        print(f"{name:22s} {diff:16.2e}  {note}", flush=True)


if __name__ == "__main__":
    main()
