r"""A first LADRC for a user's plant, from its operating point, its sensor and its sample time.

:func:`first_design` proposes the parameters of a linear ADRC (linear ESO of order ρ+1 with
Gao's bandwidth gains, linear state feedback with all poles at :math:`-\omega_c`, the law
:math:`u = v - \hat\xi_{\rho+1}/b_0` of eq. 14) and checks the closed loop it gives.  The
rules, each from the literature:

- **b0** is :math:`\beta(x_e)`, the coefficient of u in :math:`y^{(\rho)} = \alpha + \beta u`
  at the operating point (:func:`aiofl.plants.operating_point.trim`): the ESO then has the
  least total disturbance to estimate (Gao, "Scaling and bandwidth-parameterization based
  controller tuning", ACC 2003, where b0 is "the best estimate of the plant's gain").
- **ω_c**, the closed-loop bandwidth: at least :data:`UNSTABLE_FACTOR` times the fastest
  unstable open-loop pole (a loop must be faster than the instability it holds: Stein,
  "Respect the unstable", IEEE CSM 2003, puts the crossover above the unstable pole), at
  least :data:`REFERENCE_FACTOR` times a sine reference's frequency, and at least 1 rad/s.
- **ω0**, the observer bandwidth, :data:`OBSERVER_RATIO` times ω_c (Gao 2003: 3–10; the
  ESO must be faster than the loop it linearises).
- **Sampling**: the discrete ESO's poles :math:`e^{-\omega_0 T_s}` (Miklosovic, Radke & Gao,
  ACC 2006) need :math:`\omega_0 T_s \le` :data:`MAX_OMEGA0_TS`; a faster ω0 is lowered to
  it (and ω_c with it, keeping the ratio), and when ω_c then falls below what the plant
  needs the proposal says that the sample time is too slow for it.
- **Noise**: the check runs with the sensor (quantum, noise) and reports how much of it
  reaches u (``u_noise``, :mod:`aiofl.engine.response`).

The check: the design is simulated on a step of :data:`STEP_FRACTION` of the operating
output about it, starting at rest at the operating point.  When the plant is lost there,
ω_c (and ω0 with it) is raised by :data:`RAISE_FACTOR` and the check repeated, at most
:data:`MAX_ROUNDS` times; the proposal says how many rounds it took and what it measured.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from aiofl.plants.operating_point import OperatingPoint, trim

__all__ = ["Proposal", "first_design"]

UNSTABLE_FACTOR = 2.0
REFERENCE_FACTOR = 10.0
OBSERVER_RATIO = 4.0
MAX_OMEGA0_TS = 0.3
STEP_FRACTION = 0.1
RAISE_FACTOR = 1.5
MAX_ROUNDS = 6


@dataclass(frozen=True)
class Proposal:
    """What :func:`first_design` proposes and what its check measured.

    Attributes
    ----------
    config
        The run config as a dict (the TOML a user edits next).
    point
        The operating point.
    omega_c, omega0, b0, rho
        The design's numbers.
    status, response
        The check's verdict and figures (:mod:`aiofl.engine.response`).
    rounds
        How many checks it took (1: the first proposal held the plant).
    notes
        Why each number is what it is, and any warning.
    """

    config: dict[str, Any]
    point: OperatingPoint
    omega_c: float
    omega0: float
    b0: float
    rho: int
    status: str
    response: dict[str, float]
    rounds: int
    notes: list[str] = field(default_factory=list)


def _nice_step(limit: float) -> float:
    """The largest of 1, 2, 5 x 10^k not above ``limit``."""
    k = math.floor(math.log10(limit))
    for m in (5.0, 2.0, 1.0):
        if m * 10.0**k <= limit:
            return m * 10.0**k
    return 10.0 ** (k - 1) * 5.0


def _nice_up(x: float) -> float:
    """The smallest of 1, 2, 5 x 10^k not below ``x``."""
    k = math.floor(math.log10(x))
    for m in (1.0, 2.0, 5.0, 10.0):
        if m * 10.0**k >= x * (1.0 - 1e-12):
            return m * 10.0**k
    return 10.0 ** (k + 1)


def _dt_for(omega0: float, ts: float | None) -> float:
    """An RK4 step resolving the observer (ω0 dt <= 0.05) that divides ``ts``."""
    dt = _nice_step(min(1e-3, 0.05 / omega0))
    if ts is not None:
        n = max(1, math.ceil(ts / dt - 1e-9))
        dt = ts / n
    return dt


def first_design(
    plant_ref: str,
    plant: Any,
    *,
    y: float,
    x_guess: Any = None,
    rho: int | None = None,
    sensor: str | None = None,
    ts: float | None = None,
    omega_c: float | None = None,
    reference_omega: float = 0.0,
    u_max: float | None = None,
    base_dir: Any = None,
) -> Proposal:
    """Propose and check a first LADRC for ``plant`` held at output ``y`` (module notes).

    Parameters
    ----------
    plant_ref
        How a config names the plant (a registered name or a plant file's path).
    plant
        The plant (:class:`aiofl.plants.base.Plant`).
    y, x_guess
        The operating output, and where :func:`~aiofl.plants.operating_point.trim` starts.
    rho
        The chain order (default: the plant's relative degree).
    sensor, ts
        A sensor preset (``encoder-12bit``, ...) and the controller's sample time [s]
        (None: continuous, unless the sensor samples).
    omega_c
        Force the closed-loop bandwidth [rad/s] (default: the rules above).
    reference_omega
        The frequency of a sine reference to track [rad/s] (0: a step).
    u_max
        The actuator's limit (None: none).

    base_dir
        The folder a relative plant file in ``plant_ref`` is found from (None: the working
        folder).

    Returns
    -------
    Proposal
        The proposed design, its checked closed-loop step and the notes.
    """
    from aiofl.config import parse_config

    point = trim(plant, y, x_guess=x_guess)
    r = rho or plant.relative_degree
    if not r:
        raise ValueError(f"plant {plant.name!r}: its relative degree is unknown; give --rho")
    if point.beta is None or point.beta == 0.0:
        raise ValueError(
            f"plant {plant.name!r}: beta at the operating point is unknown or 0 (no normal "
            "form, or the input does not act there); a plant file gives it"
        )
    notes = [
        f"b0 = beta(x_e) = {point.beta:.6g} at the operating point y = {y:g} (u_e = {point.u:.6g})"
    ]
    p_u = point.fastest_unstable or 0.0
    need = max(UNSTABLE_FACTOR * p_u, REFERENCE_FACTOR * reference_omega, 1.0)
    if p_u:
        notes.append(
            f"open-loop unstable (fastest pole {p_u:.4g} rad/s): omega_c >= "
            f"{UNSTABLE_FACTOR:g} x {p_u:.4g} = {UNSTABLE_FACTOR * p_u:.4g} rad/s"
        )
    wc = float(omega_c) if omega_c is not None else need
    w0 = OBSERVER_RATIO * wc
    sample = ts
    if sensor is not None and sample is None:
        from aiofl.sensor import SENSOR_PRESETS

        sample = SENSOR_PRESETS.get(sensor, {}).get("ts")
    if sample is not None and w0 * sample > MAX_OMEGA0_TS:
        w0 = MAX_OMEGA0_TS / sample
        wc = w0 / OBSERVER_RATIO
        notes.append(
            f"sampled at Ts = {sample:g} s: omega0 lowered to {MAX_OMEGA0_TS:g}/Ts = {w0:.4g} "
            f"rad/s (discrete ESO poles e^(-omega0 Ts) >= {math.exp(-MAX_OMEGA0_TS):.2f})"
        )
        if wc < need:
            notes.append(
                f"WARNING: omega_c = {wc:.4g} rad/s is below the {need:.4g} rad/s the plant "
                f"needs: Ts = {sample:g} s is too slow for it (try Ts <= "
                f"{MAX_OMEGA0_TS / (OBSERVER_RATIO * need):.2g} s)"
            )
    notes.append(f"omega0 = {OBSERVER_RATIO:g} x omega_c (Gao's bandwidth parameterisation)")
    span = abs(y) * STEP_FRACTION if y != 0.0 else 1.0
    status, response, rounds, data = "lost", {}, 0, {}
    for rounds in range(1, MAX_ROUNDS + 1):
        data = _config(plant_ref, point, r, wc, w0, y, span, sample, sensor, u_max)
        cfg = parse_config(data, "first design", base_dir=base_dir)
        res = cfg.simulate(store=False)
        status, response = res.status, dict(res.response)
        if status == "ok" or omega_c is not None:
            break
        if sample is not None and OBSERVER_RATIO * wc * RAISE_FACTOR * sample > MAX_OMEGA0_TS:
            notes.append("the check lost the plant and Ts leaves no faster design to try")
            break
        notes.append(f"round {rounds}: {status} with omega_c = {wc:.4g}; raised x{RAISE_FACTOR:g}")
        wc *= RAISE_FACTOR
        w0 *= RAISE_FACTOR
    return Proposal(
        config=data,
        point=point,
        omega_c=wc,
        omega0=w0,
        b0=float(point.beta),
        rho=int(r),
        status=status,
        response=response,
        rounds=rounds,
        notes=notes,
    )


def _config(
    plant_ref: str,
    point: OperatingPoint,
    rho: int,
    wc: float,
    w0: float,
    y: float,
    span: float,
    ts: float | None,
    sensor: str | None,
    u_max: float | None,
) -> dict[str, Any]:
    """The run config of a proposal: the LADRC, a step of ``span`` about ``y`` from rest at
    the operating point, horizon and step from the bandwidth."""
    t_step = round(10.0 / wc, 6) or 1e-3  # after the start (u from 0) has settled
    dt = _dt_for(w0, ts)
    t_final = _nice_up(t_step + 40.0 / wc)
    t_final = dt * math.ceil(t_final / dt - 1e-9)
    law: dict[str, Any] = {"b0": float(point.beta)}
    if u_max is not None:
        law["u_max"] = float(u_max)
    data: dict[str, Any] = {
        "name": "first-design",
        "description": (
            f"first LADRC from aiofl design: omega_c {wc:.4g}, omega0 {w0:.4g}, b0 "
            f"{point.beta:.4g} at y = {y:g}"
        ),
        "plant": plant_ref,
        "controller": {
            "structure": "LADRC",
            "rho": int(rho),
            "n_feedback": int(rho),
            "eso": {"omega0": float(w0), "init": "bumpless"},
            "td": {"omega": float(wc)},
            "sef": {"omega_c": float(wc)},
            "law": law,
        },
        "scenario": {
            "name": "step about the operating point",
            "t_final": float(t_final),
            "x0": [float(v) for v in point.x],
            "u_ref": "trim",
            "reference": {
                "kind": "step",
                "offset": float(y),
                "amplitude": float(span),
                "t_step": float(t_step),
            },
        },
        "simulation": {"dt": float(dt)},
    }
    if sensor is not None:  # the sensor samples (at ts, when given)
        data["sensor"] = {"preset": sensor, **({"ts": float(ts)} if ts is not None else {})}
    elif ts is not None:
        data["controller"]["discrete"] = {"ts": float(ts)}
    return data
