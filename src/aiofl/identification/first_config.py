r"""A first LADRC from an identified chain: a run config (and the chain's plant file).

:func:`first_config` writes the TOML of an aiofl run config for ``aiofl simulate``: a
linear ADRC of order ρ with the identified b0 (:mod:`aiofl.identification.chain`), run
sampled at the log's Ts (exact-ZOH current-observer ESO), on a plant file
:func:`chain_plant_file` writes from the same estimate — the identified chain
:math:`y^{(\rho)} + a_{\rho-1}y^{(\rho-1)} + \dots + a_0y = b_0u + c` — with the identified
input delay (``scenario.input_delay``), the log's quantisation step (``y_quantum``) and the
noise beyond it (``scenario.noise_variance``).  The config names the plant file
``plant = "<plant>"``, a path relative to the config's folder: write both files side by
side (the default name is :data:`CHAIN_PLANT_FILE`).  A Coulomb friction the fit found is
left out of the plant file (its discontinuity needs a tiny step) and named in a comment.

The bandwidths, each capped by what the log shows (the rules live in
:mod:`aiofl.analysis.observer_bandwidth`, which ``aiofl analyze`` and ``aiofl tune`` use too):

- **Sampling**: :math:`\omega_0 T_s \le` :data:`~aiofl.analysis.first_design.MAX_OMEGA0_TS`
  (the discrete ESO's poles :math:`e^{-\omega_0T_s}`, Miklosovic, Radke & Gao, ACC 2006;
  the rule ``aiofl design`` uses).
- **Delay**: :math:`\omega_0\tau \le` :data:`DELAY_PRODUCT`: the delay costs the observer
  :math:`\omega_0\tau` rad of phase at its own bandwidth (the phase of
  :math:`e^{-s\tau}`), which its model of the plant does not have.  The number is this
  project's rule of thumb, in the range the ADRC literature's delay studies work in (the
  observer kept well below :math:`1/\tau`; Zheng & Gao, "Predictive active disturbance
  rejection control for processes with time delay", ISA Trans. 53, 2014, treat longer
  delays with a predictor instead); ``benchmarks/bench_identify.py`` simulates the
  resulting design on the identified plant.
- **Noise**: the controller's gain from a measurement sample to the command it sends at
  that sample, :math:`|F L|` (L the current-observer gain, F the law's gains on
  :math:`\hat\xi`: :math:`u = (\sum k_i(r_i - \hat\xi_i) - \hat\xi_{\rho+1})/b_0`), times
  the measured noise level must stay within :data:`NOISE_FRACTION` of the input's
  half-range in the log: :math:`|FL|\,\sigma_y \le` ``NOISE_FRACTION`` ·
  :math:`(\max u - \min u)/2`.  This is the high-frequency gain of the LADRC controller
  written as a transfer function (Herbst, "Transfer function analysis and implementation
  of active disturbance rejection control", Control Theory Technol. 19, 2021), which grows
  as :math:`\omega_0^{\rho+1}`; the fraction is this project's choice.  The largest ω0
  meeting it is found by Brent's method
  (:func:`aiofl.analysis.observer_bandwidth.largest_omega0`).
- **ω_c** = ω0 / :data:`~aiofl.analysis.first_design.OBSERVER_RATIO` (Gao, "Scaling and
  bandwidth-parameterization based controller tuning", ACC 2003: ω0 = 3–10 ω_c).

The scenario steps the reference by a tenth of the log's output range from the log's first
output, at rest; the horizon and step time follow ω_c as in ``aiofl design``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from aiofl.analysis.first_design import MAX_OMEGA0_TS, OBSERVER_RATIO
from aiofl.analysis.observer_bandwidth import (
    DELAY_PRODUCT,
    delay_cap,
    largest_omega0,
    noise_gain,
    sampling_cap,
)
from aiofl.identification.chain import ChainEstimate
from aiofl.identification.log import Log

__all__ = [
    "CHAIN_PLANT_FILE",
    "DELAY_PRODUCT",
    "NOISE_FRACTION",
    "chain_plant_file",
    "first_config",
    "noise_gain",
    "omega0_rules",
]

#: the plant file's default name, beside the config
CHAIN_PLANT_FILE = "identified-chain.toml"
#: the largest command noise, as a fraction of the log's input half-range (|F L| measure)
NOISE_FRACTION = 0.05
#: the step of the check scenario, as a fraction of the log's output range
STEP_FRACTION = 0.1


def omega0_rules(estimate: ChainEstimate, log: Log) -> tuple[float, list[str]]:
    """The observer bandwidth the three caps allow (module notes) and why, one line each.

    The sampling and delay caps are :func:`aiofl.analysis.observer_bandwidth.sampling_cap`
    and :func:`~aiofl.analysis.observer_bandwidth.delay_cap`; the noise cap bounds the
    per-sample gain :func:`~aiofl.analysis.observer_bandwidth.noise_gain` (``|F L|``)
    times the log's noise level, its largest ω0 found by
    :func:`~aiofl.analysis.observer_bandwidth.largest_omega0` (Brent's method)."""
    ts = log.ts
    caps = {"sampling": sampling_cap(ts).omega0}
    notes = [f"sampling: omega0 <= {MAX_OMEGA0_TS:g}/Ts = {caps['sampling']:.4g} rad/s"]
    if estimate.delay > 0:
        caps["delay"] = delay_cap(estimate.delay).omega0
        notes.append(
            f"delay: omega0 <= {DELAY_PRODUCT:g}/tau = {DELAY_PRODUCT:g}/{estimate.delay:.4g} s "
            f"= {caps['delay']:.4g} rad/s"
        )
    half = 0.5 * float(np.ptp(log.u))
    budget = NOISE_FRACTION * half
    if estimate.noise_std > 0 and half > 0:
        rho, b0, std = estimate.rho, estimate.b0, estimate.noise_std
        caps["noise"], _ = largest_omega0(
            lambda w: noise_gain(rho, b0, w, ts) * std, budget, 1e-6 / ts, caps["sampling"]
        )
        notes.append(
            f"noise: |F L| noise_std <= {NOISE_FRACTION:g} x {half:.4g} (input half-range), "
            f"noise_std = {estimate.noise_std:.3g}: omega0 <= {caps['noise']:.4g} rad/s"
        )
    rule = min(caps, key=lambda k: caps[k])
    notes.append(f"omega0 = {caps[rule]:.4g} rad/s, set by the {rule} rule")
    return caps[rule], notes


def _nice(x: float) -> float:
    """x rounded to 3 significant digits (readable TOML)."""
    return float(f"{x:.3g}")


def chain_plant_file(estimate: ChainEstimate, log: Log, *, name: str = "identified-chain") -> str:
    """The plant file (TOML) of the identified chain (module notes).

    Parameters
    ----------
    estimate
        The chain identified by :func:`aiofl.identification.chain.identify_chain`.
    log
        The log it was identified from (named in the file's comments).
    name
        The plant's name in the file (default ``"identified-chain"``).

    Returns
    -------
    str
        The TOML text.
    """
    import tomlkit

    rho = estimate.rho
    states = ["y"] + [f"y_d{i}" for i in range(1, rho)]
    a = list(estimate.coefficients) or [0.0] * rho
    rhs = "-" + " - ".join(f"a{i}*{states[i]}" for i in range(rho)) + " + c"
    doc = tomlkit.document()
    doc.add(tomlkit.comment(f"chain of order {rho} identified from {log.source or 'a log'}"))
    doc.add(tomlkit.comment("by aiofl's model-free route (aiofl.identification.chain):"))
    doc.add(tomlkit.comment("y^(rho) + a_(rho-1) y^(rho-1) + ... + a0 y = b0 u(t - delay) + c"))
    doc.add(
        tomlkit.comment(
            f"b0 = {estimate.b0:.6g} +- {estimate.b0_std:.2g} (1 sigma), input delay "
            f"{estimate.delay:.4g} s (in the run config), fit {estimate.fit_percent:.1f} %"
        )
    )
    if estimate.friction:
        doc.add(
            tomlkit.comment(
                f"a Coulomb friction Fc sign(y') with Fc = {estimate.friction:.4g} was fitted "
                "and is left out here"
            )
        )
    doc["name"] = name
    doc["description"] = f"identified chain, rho = {rho}"
    doc["states"] = states
    doc["f"] = [*states[1:], rhs]
    doc["g"] = ["0"] * (rho - 1) + ["b0"]
    doc["h"] = "y"
    if log.units.get("y"):
        doc["output_unit"] = str(log.units["y"])
    if log.units.get("u"):
        doc["input_unit"] = str(log.units["u"])
    params = tomlkit.table()
    params["b0"] = float(estimate.b0)
    for i in range(rho):
        params[f"a{i}"] = float(a[i])
    params["c"] = float(estimate.offset)
    doc["params"] = params
    return tomlkit.dumps(doc)


def _quantum(y: np.ndarray) -> float:
    """The log's output step when every change is a whole multiple of the smallest (an
    encoder), else 0."""
    steps = np.abs(np.diff(y))
    steps = steps[steps > 0]
    if steps.size == 0:
        return 0.0
    q = float(steps.min())
    ratio = steps / q
    return q if np.all(np.abs(ratio - np.round(ratio)) < 1e-6 * np.maximum(ratio, 1.0)) else 0.0


def first_config(
    estimate: ChainEstimate,
    log: Log,
    *,
    omega0: float | None = None,
    plant: str = CHAIN_PLANT_FILE,
) -> str:
    """TOML text of a run config for ``aiofl simulate``: a sampled LADRC of order ρ with b0,
    ω0 from the sampling, delay and noise rules (or ``omega0``), ω_c = ω0/4, on the plant
    file ``plant`` (write :func:`chain_plant_file`'s text there, beside the config).

    Parameters
    ----------
    estimate, log
        The identified chain and its log (the sample time Ts is the log's).
    omega0
        The observer bandwidth [rad/s], 0 < ω0 ≤ π/Ts; None: from the rules.
    plant
        The plant file the config names (default :data:`CHAIN_PLANT_FILE`).

    Returns
    -------
    str
        The TOML text.
    """
    import tomlkit

    ts = log.ts
    notes: list[str]
    if omega0 is None:
        w0, notes = omega0_rules(estimate, log)
    else:
        if not math.isfinite(omega0) or not 0.0 < omega0 * ts <= math.pi:
            raise ValueError(
                f"omega0 = {omega0!r} rad/s; allowed: 0 < omega0 <= pi/Ts = {math.pi / ts:.4g}"
            )
        w0, notes = float(omega0), [f"omega0 = {omega0:g} rad/s, given"]
    wc = w0 / OBSERVER_RATIO
    notes.append(f"omega_c = omega0/{OBSERVER_RATIO:g} = {wc:.4g} rad/s (Gao 2003)")
    # simulation step: resolves the observer (ω0 dt <= 0.05), divides Ts
    n_sub = max(1, math.ceil(ts / min(1e-3, 0.05 / w0) - 1e-9))
    dt = ts / n_sub
    t_step = _nice(10.0 / wc)
    t_final = dt * math.ceil(min(t_step + 40.0 / wc, 1e4) / dt - 1e-9)
    y0 = float(log.y[0])
    span = float(np.ptp(log.y))
    amplitude = _nice(STEP_FRACTION * span) if span > 0 else 1.0
    scenario: dict[str, Any] = {
        "name": "step from the log's first output",
        "t_final": t_final,
        "x0": [y0] + [0.0] * (estimate.rho - 1),
        "reference": {"kind": "step", "offset": y0, "amplitude": amplitude, "t_step": t_step},
    }
    if estimate.delay > 0:
        scenario["input_delay"] = round(estimate.delay / dt) * dt
    q = _quantum(np.asarray(log.y, dtype=np.float64))
    extra = estimate.noise_std**2 - q**2 / 12.0
    if extra > 0.0 and math.sqrt(extra) > 0.1 * estimate.noise_std:
        scenario["noise_variance"] = float(extra)
        scenario["noise_hold"] = float(ts)
    discrete: dict[str, Any] = {"ts": float(ts), "eso": "zoh"}
    if q > 0:
        discrete["y_quantum"] = q
    data: dict[str, Any] = {
        "name": "identified-ladrc",
        "description": (
            f"first LADRC from the log: rho {estimate.rho}, b0 {estimate.b0:.4g}, omega0 "
            f"{w0:.4g}, omega_c {wc:.4g}"
        ),
        "plant": plant,
        "controller": {
            "structure": "LADRC",
            "rho": int(estimate.rho),
            "n_feedback": int(estimate.rho),
            "eso": {"omega0": float(w0), "init": "bumpless"},
            "td": {"omega": float(wc)},
            "sef": {"omega_c": float(wc)},
            "law": {"b0": float(estimate.b0)},
            "discrete": discrete,
        },
        "scenario": scenario,
        "simulation": {"dt": float(dt)},
    }
    header = "".join(
        f"# {line}\n"
        for line in [
            f"a first LADRC from {log.source or 'a log'} (aiofl.identification.first_config);",
            f"the plant is the identified chain in {plant} (write it beside this file)",
            *notes,
        ]
    )
    return header + tomlkit.dumps(data)
