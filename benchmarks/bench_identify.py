"""The model-free route on synthetic logs: ρ, b0, delay, their accuracy and the time taken.

Run ``python benchmarks/bench_identify.py`` (``--seconds 10``, ``--skip-simulate``).  Every
log is made by :func:`aiofl.identification.synthetic.simulate_log` (scipy's solve_ivp, not
the code being measured), 1 kHz, a ±1 random binary input switching every 20 ms at most,
and a 12-bit encoder (quantum 2π/4096 rad, no other noise).  Prints one row per plant:

(a) chains y^(ρ) = b0 u - (s+2)^ρ terms, ρ = 1..4, b0 = 5·2^ρ: the order found, b0 and its
    error, whether the 95 % interval covers the truth, the delay found (truth 0);
(b) a first-order-plus-delay plant (ρ = 1, pole -2, b0 = 10, τ = 12.3 ms): the delay error
    in samples;
(c) a double integrator with a Coulomb friction Fc tanh(ẏ/0.01), Fc = 0.15·b0 (b0 = 20),
    fitted with the automatic friction term and without it, and the same plant without
    friction: b0's error (target: within 5 %);
(d) the library's DC-motor arm (``dcmotor_arm``: n = 3, gravity, back-EMF; true b0 =
    K_t/(J L) = 500) driven by ±2 V;

each with the wall time of :func:`aiofl.identification.chain.identify_chain` (ρ = 1..4,
after a warm-up: kernels compiled; target ≤ 2 s).  Then (unless ``--skip-simulate``) the
first config :func:`~aiofl.identification.first_config.first_config` writes for (b), (c) and
(d) is simulated by ``aiofl``'s engine on the identified chain and, for (d), on the true
arm: status and step figures.  Wall-clock figures depend on what else the machine
is doing; the load average is printed.  No assertion is made on any figure.
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
import time
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

TS = 1e-3
QUANTUM = 2 * math.pi / 4096


def chain_plant(rho: int, b0: float, pole: float, friction: float = 0.0) -> Any:
    """y^(ρ) = b0 u - (coefficients of (s + pole)^ρ)·(y..y^(ρ-1)) [- Fc tanh(ẏ/0.01)]."""
    from aiofl.plants.base import Plant

    a = np.poly(np.full(rho, -pole))[1:][::-1]

    def f(x: Any, p: Any) -> tuple[float, ...]:
        acc = -sum(a[i] * x[i] for i in range(rho))
        if friction:
            acc -= friction * math.tanh(x[1] / 0.01)
        return (*[x[i + 1] for i in range(rho - 1)], acc)

    def g(x: Any, p: Any) -> tuple[float, ...]:
        return (*([0.0] * (rho - 1)), b0)

    return Plant(name=f"chain{rho}", n_states=rho, f=f, g=g, h=lambda x, p: x[0], params={"b0": b0})


def prbs(n: int, clock: int, amplitude: float = 1.0, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return amplitude * np.repeat(rng.integers(0, 2, n // clock + 2) * 2.0 - 1.0, clock)[:n]


def cases(seconds: float) -> list[dict[str, Any]]:
    from aiofl.plants.registry import get_plant

    rows: list[dict[str, Any]] = []
    for rho in (1, 2, 3, 4):
        rows.append(
            {
                "name": f"chain rho={rho}",
                "plant": chain_plant(rho, 5.0 * 2**rho, 2.0),
                "rho": rho,
                "b0": 5.0 * 2**rho,
                "delay": 0.0,
                "amp": 1.0,
            }
        )
    rows.append(
        {
            "name": "FOPDT tau=12.3ms",
            "plant": chain_plant(1, 10.0, 2.0),
            "rho": 1,
            "b0": 10.0,
            "delay": 0.0123,
            "amp": 1.0,
            "config": True,
        }
    )
    rows.append(
        {
            "name": "2-int, no friction",
            "plant": chain_plant(2, 20.0, 0.0),
            "rho": 2,
            "b0": 20.0,
            "delay": 0.0,
            "amp": 1.0,
        }
    )
    rows.append(
        {
            "name": "2-int, Coulomb 15%",
            "plant": chain_plant(2, 20.0, 0.0, 3.0),
            "rho": 2,
            "b0": 20.0,
            "delay": 0.0,
            "amp": 1.0,
            "config": True,
            "plain": True,
        }
    )
    rows.append(
        {
            "name": "dcmotor_arm",
            "plant": get_plant("dcmotor_arm"),
            "rho": 3,
            "b0": 500.0,
            "delay": 0.0,
            "amp": 2.0,
            "config": True,
            "true_plant": "dcmotor_arm",
        }
    )
    n = round(seconds / TS) + 1
    t = np.arange(n) * TS
    from aiofl.identification.synthetic import simulate_log

    for row in rows:
        t0 = time.perf_counter()
        row["log"] = simulate_log(
            row["plant"], t, prbs(n, 20, row["amp"]), delay=row["delay"], quantum=QUANTUM
        )
        row["sim_s"] = time.perf_counter() - t0
    return rows


def simulate_config(est: Any, log: Any, true_plant: str | None) -> list[str]:
    """The first config on the identified chain (and on the true plant): status, figures."""
    from aiofl.config import load_config
    from aiofl.identification.first_config import chain_plant_file, first_config

    out = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "identified-chain.toml").write_text(chain_plant_file(est, log))
        text = first_config(est, log)
        targets = [("identified chain", text)]
        if true_plant is not None:
            targets.append(
                (
                    f"true {true_plant}",
                    text.replace('plant = "identified-chain.toml"', f'plant = "{true_plant}"'),
                )
            )
        for label, body in targets:
            path = folder / "first.toml"
            path.write_text(body)
            cfg = load_config(str(path))
            res = cfg.simulate(store=False)
            r = res.response
            w0 = tomllib.loads(body)["controller"]["eso"]["omega0"]
            out.append(
                f"    first config (omega0 {w0:.4g}) on the {label}: {res.status}; overshoot "
                f"{r.get('overshoot', math.nan):.3g} %, settling "
                f"{r.get('settling_time', math.nan):.3g} s, u_noise "
                f"{r.get('u_noise', math.nan):.3g}"
            )
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--skip-simulate", action="store_true")
    args = parser.parse_args()
    from aiofl.blas_threads import one_blas_thread
    from aiofl.identification.chain import identify_chain
    from aiofl.identification.first_config import omega0_rules
    from aiofl.identification.offline_eso import offline_eso

    one_blas_thread()
    print(f"load average {os.getloadavg()[0]:.2f}; logs of {args.seconds:g} s at 1 kHz, 12-bit")
    rows = cases(args.seconds)
    identify_chain(rows[0]["log"].part(0, 2000))  # warm-up: the compiled recursion
    head = (
        f"{'plant':20s} {'rho':>7s} {'b0 true':>8s} {'b0 found':>10s} {'+-1sd':>8s} "
        f"{'err %':>7s} {'in 95%':>6s} {'delay ms':>9s} {'d err/Ts':>8s} {'Fc':>6s} "
        f"{'fit %':>6s} {'time s':>6s}"
    )
    print(head)
    print("-" * len(head))
    notes: list[str] = []
    for row in rows:
        log = row["log"]
        t0 = time.perf_counter()
        est = identify_chain(log)
        dt = time.perf_counter() - t0
        b0 = row["b0"]
        err = 100.0 * (est.b0 / b0 - 1.0)
        inside = abs(est.b0 - b0) <= 1.96 * est.b0_std
        print(
            f"{row['name']:20s} {row['rho']:>3d}->{est.rho:<3d} {b0:8.4g} {est.b0:10.5g} "
            f"{est.b0_std:8.2g} {err:7.2f} {'yes' if inside else 'no':>6s} "
            f"{1e3 * est.delay:9.3f} {(est.delay - row['delay']) / TS:8.2f} "
            f"{est.friction:6.3g} {est.fit_percent:6.2f} {dt:6.2f}"
        )
        notes.append(
            f"  {row['name']}: BIC "
            + ", ".join(f"rho {c.rho}: {c.score:.0f}" for c in est.candidates)
        )
        if row.get("plain"):
            plain = identify_chain(log, rho=row["rho"], friction=False)
            notes.append(
                f"    without the friction term: b0 {plain.b0:.5g} +- {plain.b0_std:.2g} "
                f"({100 * (plain.b0 / b0 - 1):+.1f} %)"
            )
        w0, _ = omega0_rules(est, log)
        chk = offline_eso(log, est.rho, est.b0, w0)
        bad = offline_eso(log, est.rho, 3.0 * est.b0, w0)
        notes.append(
            f"    offline ESO at omega0 {w0:.4g}: rms {chk.rms:.3g}, roughness "
            f"{chk.roughness:.3g} -> {chk.verdict}; with 3 b0: rms {bad.rms:.3g} -> {bad.verdict}"
        )
        if row.get("config") and not args.skip_simulate:
            notes.extend(simulate_config(est, log, row.get("true_plant")))
    print()
    print("\n".join(notes))
    print(f"\nlog simulation (solve_ivp) took {sum(r['sim_s'] for r in rows):.1f} s in all")


if __name__ == "__main__":
    main()
