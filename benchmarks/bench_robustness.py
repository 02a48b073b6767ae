"""Robustness analysis speed, and the robustness table of the shipped designs.

Run ``python benchmarks/bench_robustness.py`` (``--draws 1000``, ``--table-draws 64 1000``,
``--dask-workers N`` to time the Dask path too, ``--skip-table``).  Prints:

(a) ``aiofl robustness`` on scenario 1 of ``retuned-s1-leso`` (20 s, RK4, dt = 1e-4) with
    ``--draws`` draws of J_l, K_s, R_m, J_h each uniform within ±20 %: wall time of
    :func:`aiofl.analysis.robustness_draws.run_robustness` after a warm-up (kernel compiled),
    locally (numba, all cores) and, if asked, on a local Dask cluster.  Goal: 1000 draws
    under 30 s on 2 cores.
(b) for each design (retuned-s1-inleso, -leso, -ladrc, iofl-s1, and a hand LADRC with exact
    reference derivatives, b0 = β of the nominal plant, ω0 = 1600, ω_c = 40): the nominal
    ITAE, the number of diverged draws, and ITAE median and 95 % (empirical quantiles over
    all draws, a diverged draw counting as +inf, printed "diverged"), for each
    ``--table-draws``.  The draws are common random numbers (seed 0): every design sees the
    same plants.

Wall-clock figures depend on what else the machine is doing; the load average at the start
is printed.  No assertion is made on any figure.
"""

from __future__ import annotations

import argparse
import os
import time
import tomllib
from typing import Any

import numpy as np

FOUR = ("J_l", "K_s", "R_m", "J_h")
DESIGNS = ("retuned-s1-inleso", "retuned-s1-leso", "retuned-s1-ladrc", "iofl-s1", "hand")


def _uncertainty(draws: int) -> dict[str, Any]:
    return {"draws": draws, "seed": 0, "parameters": {k: {"uniform": 0.2} for k in FOUR}}


def design(name: str, draws: int) -> Any:
    """The config of a table row with ``draws`` draws of ±20 % on J_l, K_s, R_m, J_h."""
    from aiofl.config import parse_config, preset_text
    from aiofl.plants.registry import get_plant

    if name != "hand":
        data = tomllib.loads(preset_text(name))
    else:  # LADRC, exact reference derivatives, b0 = beta, omega0 = 1600, omega_c = 40
        plant = get_plant("slfjm")
        beta = float(plant.normal_form(np.zeros(plant.n_states), plant.param_vector())[-1])
        data = tomllib.loads(preset_text("retuned-s1-ladrc"))
        data["name"] = "hand-ladrc-exact"
        data["controller"] = {
            "structure": "LADRC",
            "td_kind": "exact",
            "rho": 4,
            "n_feedback": 4,
            "eso": {"omega0": 1600.0, "alpha": "binomial"},
            "sef": {"omega_c": 40.0},
            "law": {"b0": beta},
        }
    data.pop("tune", None)
    data["uncertainty"] = _uncertainty(draws)
    return parse_config(data, name)


def _fmt(x: float | None) -> str:
    return "diverged" if x is None else f"{x:.4g}"


def main() -> None:
    from aiofl.analysis.robustness_draws import run_robustness

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=1000)
    ap.add_argument("--table-draws", type=int, nargs="*", default=[64, 1000])
    ap.add_argument("--dask-workers", type=int, default=0)
    ap.add_argument("--skip-table", action="store_true")
    args = ap.parse_args()
    print(f"load average at start: {os.getloadavg()}, cores: {os.cpu_count()}")

    cfg = design("retuned-s1-leso", args.draws)
    run_robustness(cfg, draws=2)  # warm-up: the kernel compiles (or loads from the cache)
    t0 = time.perf_counter()
    res = run_robustness(cfg)
    wall = time.perf_counter() - t0
    print(
        f"\n(a) retuned-s1-leso, {args.draws} draws x 20 s (RK4, dt = 1e-4), local: "
        f"{wall:.1f} s wall ({res.engine_calls} engine call(s)), stable "
        f"{100 * res.stable_fraction:.1f} %; load average now {os.getloadavg()}"
    )
    if args.dask_workers:
        from distributed import Client, LocalCluster

        with (
            LocalCluster(
                n_workers=args.dask_workers, threads_per_worker=1, dashboard_address=None
            ) as cluster,
            Client(cluster) as client,
        ):
            run_robustness(cfg, draws=2 * args.dask_workers, client=client)  # warm-up
            t0 = time.perf_counter()
            remote = run_robustness(cfg, client=client)
            wall = time.perf_counter() - t0
        same = remote.to_dict() == res.to_dict()
        print(
            f"    on a local Dask cluster of {args.dask_workers} workers: {wall:.1f} s "
            f"(results identical to the local run: {same})"
        )
    if args.skip_table:
        return
    print("\n(b) scenario 1, J_l, K_s, R_m, J_h each uniform within ±20 %, seed 0")
    header = "| design | nominal ITAE | draws | diverged | ITAE median | ITAE 95 % | seconds |"
    print(header)
    print("|---|---|---|---|---|---|---|")
    for name in DESIGNS:
        for k in args.table_draws:
            cfg = design(name, k)
            t0 = time.perf_counter()
            r = run_robustness(cfg)
            sec = time.perf_counter() - t0
            info = r.to_dict()
            print(
                f"| {cfg.name} | {_fmt(info['nominal']['itae'])} | {k} | "
                f"{len(info['diverged'])}/{k} | {_fmt(info['itae']['q50'])} | "
                f"{_fmt(info['itae']['q95'])} | {sec:.1f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
