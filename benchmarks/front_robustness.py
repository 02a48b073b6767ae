"""Robust columns for a shipped Pareto front: every front design over model-error draws.

Reads ``src/aiofl/presets/fronts/s{N}-{structure}.csv`` (an NSGA-II ``front.csv`` of
``aiofl tune``) and the recipe config next to it (``s{N}-{structure}.toml``), runs each
front design with ISU at most ``--isu-max`` (default: every design; at most ``--max-rows``
of them, those of lowest ITAE, default 48) over ``--draws`` draws
(default 64) of J_l, K_s, R_m, J_h each uniform within +-20 % (seed ``--seed``, default 0;
common random numbers, :func:`aiofl.analysis.robustness_draws.simulate_designs`, one batched
engine call per chunk of designs), and writes ``s{N}-{structure}-robust.csv`` beside it:
the front's parameter columns first, then ``itae_q05, itae_q50, itae_q95, itae_max,
isu_q50, isu_q95, stable_fraction, draws``.  A quantile that falls on a diverged draw
(+inf) is an empty cell.  Rows are in the front's order (ascending ITAE); designs left out
have no row (the report matches rows by parameter values, so a missing row is NaN there).

    python benchmarks/front_robustness.py src/aiofl/presets/fronts/s1-ladrc.csv --isu-max 31
"""

from __future__ import annotations

import argparse
import csv
import io
import sys
import time
from pathlib import Path

import numpy as np

from aiofl.analysis.robustness_draws import simulate_designs
from aiofl.config import load_config, parse_config
from aiofl.tuning.space import config_with_values
from aiofl.uncertainty import UncertaintyModel, sample_draws

UNCERTAINTY = {
    "seed": 0,
    "parameters": {p: {"uniform": 0.2} for p in ("J_l", "K_s", "R_m", "J_h")},
}
STATS = (
    "itae_q05",
    "itae_q50",
    "itae_q95",
    "itae_max",
    "isu_q50",
    "isu_q95",
    "stable_fraction",
    "draws",
)


def _cell(v: float) -> str:
    return repr(float(v)) if np.isfinite(v) else ""


def robust_rows(
    front_csv: Path,
    recipe: Path,
    *,
    draws: int,
    seed: int,
    isu_max: float,
    chunk: int,
    max_rows: int,
) -> str:
    """The ``-robust.csv`` text for ``front_csv`` (see the module docstring)."""
    lines = list(csv.reader(io.StringIO(front_csv.read_text(encoding="utf-8"))))
    header, body = lines[0], [r for r in lines[1:] if r]
    cfg = load_config(recipe)
    names = list(cfg.raw["tune"]["parameters"])
    if header[: len(names)] != names:
        raise SystemExit(f"{front_csv}: parameters {header[: len(names)]} != recipe's {names}")
    i_isu = next(i for i, h in enumerate(header) if h.split(":")[0] == "isu")
    i_itae = next(i for i, h in enumerate(header) if h.split(":")[0] == "itae")
    rows = [r for r in body if float(r[i_isu]) <= isu_max]
    keep = sorted(range(len(rows)), key=lambda i: float(rows[i][i_itae]))[:max_rows]
    rows = [rows[i] for i in sorted(keep)]
    raw = {k: v for k, v in cfg.raw.items() if k not in ("tune", "uncertainty")}
    cfgs = [
        parse_config(
            config_with_values(raw, cfg.controller, {n: float(r[j]) for j, n in enumerate(names)}),
            f"{front_csv.name} row",
        )
        for r in rows
    ]
    spec = UncertaintyModel.model_validate({**UNCERTAINTY, "draws": draws, "seed": seed})
    dr = sample_draws(spec, dt=cfg.dt)
    results = []
    for a in range(0, len(cfgs), chunk):
        results += simulate_designs(cfgs[a : a + chunk], dr)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([*names, *STATS])
    for r, res in zip(rows, results, strict=True):
        q = lambda v, p: float(np.quantile(v, p, method="inverted_cdf"))  # noqa: E731
        w.writerow(
            [
                *r[: len(names)],
                _cell(q(res.itae, 0.05)),
                _cell(q(res.itae, 0.5)),
                _cell(q(res.itae, 0.95)),
                _cell(float(np.max(res.itae))),
                _cell(q(res.isu, 0.5)),
                _cell(q(res.isu, 0.95)),
                repr(res.stable_fraction),
                str(draws),
            ]
        )
    return buf.getvalue()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("front", type=Path, help="a shipped front .csv (its recipe .toml beside it)")
    ap.add_argument("--draws", type=int, default=64)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--isu-max", type=float, default=float("inf"))
    ap.add_argument("--max-rows", type=int, default=48, help="at most this many designs")
    ap.add_argument("--chunk", type=int, default=16, help="designs per engine call")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    text = robust_rows(
        a.front,
        a.front.with_suffix(".toml"),
        draws=a.draws,
        seed=a.seed,
        isu_max=a.isu_max,
        chunk=a.chunk,
        max_rows=a.max_rows,
    )
    out = a.front.with_name(a.front.stem + "-robust.csv")
    out.write_text(text, encoding="utf-8")
    n = text.count("\n") - 1
    print(f"wrote {out}: {n} designs x {a.draws} draws in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
