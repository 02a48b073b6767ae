"""A robust design tuned from a log alone, against the design tuned on the true plant.

Run ``python benchmarks/bench_identified_design.py`` (``--population``, ``--generations``,
``--draws``, ``--seed``).  Steps, all seeded:

1. The log: the library plant ``dcmotor_arm`` (a DC-motor-driven arm with armature
   inductance, ρ = 3) with J, b, K_t off their nominal values (×1.25, ×0.75, ×0.9: the
   *true* plant), driven by a ±2 V random binary input held 100 ms for 5 s at 1 kHz, made
   by the project's independent scipy simulator
   (:func:`aiofl.identification.synthetic.simulate_log`), with Gaussian output noise
   σ = 2e-3 rad and a 12-bit encoder (quantum 2π/4096 rad).
2. The grey-box fit (:func:`aiofl.identification.grey_box.fit_plant`) of J, b, K_t from
   the nominal plant file values (nominal × [0.2, 5]), 20 % of the log held out; its
   ``[uncertainty]`` table (:func:`aiofl.identification.fitted_plant.uncertainty_table`,
   the ±2σ box).
3. Three robust LADRC designs (ρ = 3, the preset ``dcmotor-arm-ladrc``'s structure and
   scenario: tracking (π/4) sin t for 10 s), each tuned by :meth:`aiofl.Design.tune` with
   the same budget (GA, ``population`` × ``generations``, objective ITAE (``--objective``;
   the default OPI's ISU weight drives every design to the smallest gain), robust mean
   over the nominal plant + ``draws`` draws of the same relative box) over ω0 ∈ [20, 400],
   ω_c ∈ [2, 40], b0 ∈ [100, 2000] (log scales): on the *fitted* plant (from the log alone), on the
   *true* plant (the best one could do knowing the truth), and on the *nominal* plant
   (the datasheet values, no identification) for context.
4. Every design evaluated on the TRUE plant: ITAE and ISU of one run (the metrics of
   ``aiofl simulate``), and the robust-tuning objective it reached on its own model.

It prints the fit (estimates, σ, truth inside the 95 % interval?), the box, and the table.
No assertion is made; the measured table is in ``docs/benchmarks.md``.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace

import numpy as np

from aiofl import Controller, Design, Reference, Scenario
from aiofl.identification.fitted_plant import uncertainty_table
from aiofl.identification.grey_box import fit_plant
from aiofl.identification.log import Log
from aiofl.identification.synthetic import measure, simulate_log
from aiofl.plants.registry import get_plant

TRUTH_SCALE = {"J": 1.25, "b": 0.75, "K_t": 0.9}
TUNED = {
    "eso.omega0": {"lo": 20.0, "hi": 400.0, "log": True},
    "sef.omega_c": {"lo": 2.0, "hi": 40.0, "log": True},
    "law.b0": {"lo": 100.0, "hi": 2000.0, "log": True},
}


def _log(seed: int) -> tuple[Log, np.ndarray]:
    plant = get_plant("dcmotor_arm")
    ts, n = 1e-3, 5001
    rng = np.random.default_rng(seed)
    u = 2.0 * np.repeat(rng.choice([-1.0, 1.0], n // 100 + 1), 100)[:n]
    truth = plant.param_vector(scale=TRUTH_SCALE)
    clean = simulate_log(plant, np.arange(n) * ts, u, params=truth)
    y = measure(clean.y, noise_std=2e-3, quantum=2 * np.pi / 4096, seed=seed)
    return Log(clean.t, clean.u, y, source="bench"), truth


def _design(plant, uncertainty: dict) -> Design:
    controller = Controller(  # the LADRC structure, exact reference derivatives (the preset's)
        eso="linear",
        td="exact",
        sef="linear",
        law="aiofl",
        rho=3,
        n_feedback=3,
        structure="LADRC",
        values={"eso.omega0": 100.0, "sef.omega_c": 15.0, "law.b0": 400.0},
    )
    scenario = Scenario(reference=Reference(amplitude=math.pi / 4, omega=1.0), t_final=10.0)
    return Design(plant, controller, scenario, dt=1e-4, uncertainty=uncertainty)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--population", type=int, default=16)
    ap.add_argument("--generations", type=int, default=8)
    ap.add_argument("--draws", type=int, default=8)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--objective", default="itae", help="the [tune] objective (default itae)")
    args = ap.parse_args()

    nominal = get_plant("dcmotor_arm")
    t0 = time.perf_counter()
    log, truth = _log(args.seed)
    print(f"scipy log: {log.n_samples} samples in {time.perf_counter() - t0:.1f} s")
    fit = fit_plant(log, nominal, dict.fromkeys(TRUTH_SCALE), holdout=0.2, seed=args.seed)
    print(
        f"grey-box fit: {fit.seconds:.1f} s, fit {fit.fit_percent:.2f} %, held-out "
        f"{fit.validation_fit_percent:.2f} %, residual white {fit.residuals.white}"
    )
    for p in fit.parameters:
        true = nominal.params[p.name] * TRUTH_SCALE[p.name]
        lo, hi = p.interval95
        print(
            f"  {p.name}: {p.value:.5g} ± {p.std:.2g} (truth {true:.5g}, nominal "
            f"{nominal.params[p.name]:.5g}; truth {'inside' if lo <= true <= hi else 'OUTSIDE'} "
            "the 95 % interval)"
        )
    box = uncertainty_table(fit, k=2.0)
    box["draws"] = args.draws
    print(f"[uncertainty] (k = 2): {box['parameters']}")

    names = dict(zip(nominal.param_names, (float(v) for v in truth), strict=True))
    plants = {
        "fitted (from the log)": replace(fit.plant, name="arm_fitted", _checked={}),
        "true plant": replace(nominal, name="arm_true", params=names, _checked={}),
        "nominal (datasheet)": replace(nominal, name="arm_nominal", _checked={}),
    }
    judge = _design(plants["true plant"], box)
    settings = {
        "population": args.population,
        "generations": args.generations,
        "seed": args.seed + 1,
        "objective": args.objective,
        "robust": {"draws": args.draws, "aggregate": "mean"},
    }
    rows = []
    for label, plant in plants.items():
        t0 = time.perf_counter()
        result = _design(plant, box).tune(TUNED, **settings)
        wall = time.perf_counter() - t0
        on_true = judge.with_values(result.best_values).simulate(store=False)
        m = on_true.metrics
        rows.append((label, result.best_values, result.best_objective, m, on_true.failed, wall))
    print(
        f"\nbudget per design: GA {args.population} x {args.generations}, objective "
        f"{args.objective}, robust mean over "
        f"nominal + {args.draws} draws of the fitted box; evaluated on the TRUE plant"
    )
    print(
        f"{'tuned on':<24}{'omega0':>9}{'omega_c':>9}{'b0':>9}{'objective':>11}"
        f"{'ITAE':>11}{'ISU':>11}{'tune s':>8}"
    )
    for label, best, obj, m, failed, wall in rows:
        itae = "diverged" if failed else f"{m['itae']:.4g}"
        isu = "" if failed else f"{m['isu']:.4g}"
        print(
            f"{label:<24}{best['eso.omega0']:>9.1f}{best['sef.omega_c']:>9.2f}"
            f"{best['law.b0']:>9.1f}{obj:>11.4g}{itae:>11}{isu:>11}{wall:>8.1f}"
        )


if __name__ == "__main__":
    main()
