r"""One reconciled stability verdict per design: equilibrium, limit cycle, tracking orbit.

The linearisation (:mod:`aiofl.analysis.linearize`) judges the equilibrium with the
reference held at :math:`r^*` and the non-smooth elements replaced by secant gains.  A
design can be unstable there and still track: the equilibrium of frontier-s1-leso is
unstable under its fal slopes at zero error and the loop, with r held, settles on a small
limit cycle, while the orbit it follows when tracking the sine is stable.  This module
answers the three questions separately and writes one sentence from them
(:func:`orbit_analysis`):

1. **Equilibrium**: the linearisation's verdict (``closed_loop_verdict``).
2. **Limit cycle** (only when the equilibrium is unstable): simulate the exact loop
   (:class:`aiofl.analysis.orbit_loop.OrbitLoop`) with r held at :math:`r^*`, from the
   equilibrium displaced along the unstable mode (to the describing-function amplitude
   below when there is one, else by :data:`START`), in chunks of 10 cycles until the
   amplitude settles; the peak amplitudes of y and u and the dominant frequency of y over
   the last chunk (:func:`aiofl.analysis.variational.measure_oscillation`).  Cross-check:
   the harmonic balance of the describing functions of fal / g(e) / the INLSEF terms
   (:func:`aiofl.analysis.variational.harmonic_balance`, the loop's Jacobian at the
   equilibrium with each nonlinearity replaced by its gain N(A)).
3. **Tracking orbit**: for a sine reference, the periodic steady state's Floquet
   multipliers over one period :math:`T = 2\pi/\omega` (the variational equation;
   :func:`aiofl.analysis.variational.periodic_orbit`), started at the sine's crest from the
   equilibrium there; for a step or samples, the largest finite-time Lyapunov exponent
   over the horizon from the initial state.  Measurement noise is 0; the disturbance is
   at its final value for the periodic orbit, a step at its time for the exponent.  An
   orbit that does not close and whose largest multiplier crosses 1 over the periods
   analysed is "not determined" (:func:`floquet_word`): it has not reached a periodic
   steady state, and its multipliers decide nothing.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl.analysis.budget import BudgetExceeded, time_budget
from aiofl.analysis.orbit_loop import OrbitLoop
from aiofl.analysis.variational import (
    OrbitDiverges,
    describing_gain,
    finite_time_lyapunov,
    harmonic_balance,
    measure_oscillation,
    periodic_orbit,
    trajectory,
)

__all__ = [
    "NOT_DETERMINED",
    "START",
    "equilibrium_limit_cycle",
    "floquet_word",
    "format_orbit_text",
    "limit_cycle_describing",
    "orbit_analysis",
    "reconciled_text",
    "tracking_floquet",
    "tracking_ftle",
]

START = 1e-4
"""Displacement of the limit-cycle simulation's start along the unstable mode, relative to
the equilibrium's magnitudes."""
CLOSES = 1e-3
"""A tracking orbit whose plant states return within this share of their size after one
period is periodic; above it the sentence says how far it is from closing."""
MAX_CHUNKS = 8
"""At most this many chunks of the held-reference simulation."""
BOUND = 1e6
"""A held-reference simulation whose scaled state exceeds this has left the equilibrium
(diverges)."""


def _loop(cfg: Any) -> OrbitLoop:
    return OrbitLoop(cfg.plant, cfg.controller, cfg.scenario, dt=float(cfg.dt))


def _outputs(loop: OrbitLoop, zs: NDArray[np.float64]) -> tuple[NDArray[Any], NDArray[Any]]:
    return loop.compiled.outputs(zs)


def _output_row(loop: OrbitLoop, z: NDArray[np.float64]) -> NDArray[np.float64]:
    """∂y/∂z at z (compiled, exact)."""
    return loop.output_row(z)


def equilibrium_limit_cycle(
    loop: OrbitLoop,
    z_op: NDArray[np.float64],
    a_lin: NDArray[np.float64],
    max_chunks: int = MAX_CHUNKS,
    start_amplitude: float | None = None,
) -> dict[str, Any]:
    """Simulate the loop with r held at :math:`r^*` from the equilibrium displaced along
    its unstable mode (module docstring, step 2).

    Returns
    -------
    dict
        ``{"bounded": bool, "settled": bool, "amplitude_y", "amplitude_u", "frequency"
        [rad/s], "centre_y", "simulated_s"}`` (no amplitudes when it diverges; "settled":
        the amplitude changed by at most 2 % over the last chunk of 10 cycles).  Started
        at ``start_amplitude`` of y along the unstable mode (the describing-function
        estimate, which saves the slow growth from a tiny start) or at :data:`START`.

    Parameters
    ----------
    loop
        The closed loop (:class:`~aiofl.analysis.orbit_loop.OrbitLoop`).
    z_op, a_lin
        The equilibrium and the linearisation's matrix there (its unstable mode is used).
    max_chunks
        The most chunks simulated (default :data:`MAX_CHUNKS`).
    start_amplitude
        The start's amplitude of y (None: :data:`START`).
    """
    lam, vec = np.linalg.eig(a_lin)
    i = int(np.argmax(lam.real))
    v = np.real(vec[:, i] if lam[i].imag == 0 else vec[:, i] + vec[:, i].conj())
    scale = np.maximum(np.abs(z_op), 1e-3 * max(float(np.max(np.abs(z_op[: loop.n]))), 1.0))
    v = v / max(float(np.max(np.abs(v) / scale)), 1e-300)
    cy = _output_row(loop, z_op)
    if start_amplitude is not None and abs(cy @ v) > 0:  # start on the predicted cycle
        z = z_op + start_amplitude * v / abs(cy @ v)
    else:
        z = z_op + START * v
    # absolute tolerance well below the start: the growth from it must be integrated
    tol_scale = 1e-3 * START * scale
    f, jac = loop.field(hold=True, d=loop.d_op)
    growth = max(float(lam[i].real), 1e-3)
    omega = abs(float(lam[i].imag)) or growth
    chunk = 10 * 2 * math.pi / omega
    if start_amplitude is None:
        chunk = max(chunk, 3.0 / growth)
    t, prev, osc_y, settled = 0.0, None, None, False
    for _ in range(max_chunks):
        try:
            with np.errstate(all="ignore"):
                sol = trajectory(f, jac, z, t, t + chunk, scale=tol_scale, rtol=1e-6)
        except (ArithmeticError, ValueError):
            return {"bounded": False, "simulated_s": t}
        if not np.all(np.isfinite(sol.y)) or np.max(np.abs(sol.y) / scale[:, None]) > BOUND:
            return {"bounded": False, "simulated_s": t + chunk}
        step = min(chunk / 4096, 2 * math.pi / omega / 32)
        ts = np.arange(t, t + chunk, step)
        zs = sol.sol(ts)
        y, u = _outputs(loop, zs)
        osc_y, osc_u = measure_oscillation(ts, y), measure_oscillation(ts, u)
        t += chunk
        z = sol.y[:, -1]
        if prev is not None and abs(osc_y.amplitude - prev) <= 0.02 * max(prev, 1e-300):
            settled = True
            break
        prev = osc_y.amplitude
    assert osc_y is not None
    return {
        "bounded": True,
        "settled": settled,
        "amplitude_y": osc_y.amplitude,
        "amplitude_u": osc_u.amplitude,
        "frequency": osc_y.frequency,
        "centre_y": osc_y.centre,
        "simulated_s": t,
    }


def limit_cycle_describing(
    loop: OrbitLoop, z_op: NDArray[np.float64], a_lin: NDArray[np.float64], points: int = 103
) -> dict[str, Any] | None:
    r"""The describing-function (harmonic-balance) estimate of the limit cycle: amplitude of
    y and frequency (module docstring, step 2); None without non-smooth elements or
    without a stable balance.  Each :math:`N_i(A)` is tabulated on a log grid of A by
    :func:`aiofl.analysis.variational.describing_gain` and interpolated (log-log).

    Parameters
    ----------
    loop, z_op, a_lin
        As for :func:`equilibrium_limit_cycle`.
    points
        Grid points of each tabulated gain, A from 1e-14 to 1e3.

    Returns
    -------
    dict or None
    """
    nls = loop.nonlinearities()
    if not nls:
        return None
    grid = np.geomspace(1e-14, 1e3, points)
    tables = []
    for nl in nls:
        vals = np.array([describing_gain(nl.phi, a, nl.kinks) for a in grid])
        tables.append(np.log(np.maximum(np.abs(vals), 1e-300)) * 1.0)
        tables[-1] = (tables[-1], np.sign(vals))

    def gain(j: int) -> Any:
        logs, signs = tables[j]
        lg = np.log(grid)

        def n_of(a: float) -> float:
            x = math.log(min(max(a, grid[0]), grid[-1]))
            return float(np.interp(x, lg, signs) * math.exp(np.interp(x, lg, logs)))

        return n_of

    def quasi_linear(gains: Any) -> NDArray[np.float64]:
        loop.describing = tuple(gains)
        try:
            return loop.jacobian_at(z_op)
        finally:
            loop.describing = None

    rows = loop.error_rows(z_op)
    cy = _output_row(loop, z_op)
    lam, vec = np.linalg.eig(a_lin)
    mode0 = vec[:, int(np.argmax(lam.real))]
    bal = harmonic_balance(
        quasi_linear, rows, cy, [gain(j) for j in range(len(nls))], mode0, a_range=(1e-12, 1e1)
    )
    if bal is None:
        return None
    return {
        "amplitude_y": bal.amplitude,
        "frequency": bal.frequency,
        "inputs": {nl.name: a for nl, a in zip(nls, bal.input_amplitudes, strict=True)},
    }


def tracking_floquet(
    loop: OrbitLoop, passes: int = 3, settle: int = 3, rtol: float = 1e-6
) -> dict[str, Any]:
    """Floquet multipliers of the tracking orbit of a sine reference (module docstring,
    step 3): ``{"multipliers": [[re, im], ...], "largest", "period", "closing", "range",
    "passes"}`` (multipliers of the last of ``passes`` periods after ``settle``; "range" the
    largest abs(μ) over the passes, "closing" how well the last one closed).

    Parameters
    ----------
    loop
        The closed loop; its scenario's reference must be a sine.
    passes, settle
        Periods measured, after ``settle`` periods to settle.
    rtol
        The integration's relative tolerance.

    Returns
    -------
    dict
    """
    ref = loop.scenario.reference
    period = 2 * math.pi / ref.omega
    t0 = (0.5 * math.pi - ref.phase) / ref.omega  # the crest: r' = 0
    if loop.controller.td == "han":
        loop.han_signal(0.0, t0 + (settle + passes + 1) * period)
    loop.r_op = float(ref.evaluate(t0))
    z = loop.operating_point()
    f, jac = loop.field(d=loop.d_op)
    po = periodic_orbit(
        f,
        jac,
        z,
        period,
        t0=t0,
        settle=settle,
        max_newton=passes,
        close_on=range(loop.n),
        rtol=rtol,
    )
    return {
        "multipliers": [[float(m.real), float(m.imag)] for m in po.multipliers],
        "largest": po.largest,
        "period": period,
        "closing": po.closing,
        "range": list(po.largest_range),
        "passes": po.newton_steps,
    }


def tracking_ftle(loop: OrbitLoop, renorm: float = 0.5) -> dict[str, Any]:
    """Largest finite-time Lyapunov exponent [1/s] along the run from its initial state
    (plant at x0, observer at (h(x0), 0, ...), TD at rest at r(0)) over the horizon."""
    sc = loop.scenario
    if loop.controller.td == "han":
        loop.han_signal(0.0, sc.t_final)
    z = np.zeros(loop.n_z)
    z[: loop.n] = np.asarray(sc.x0 or np.zeros(loop.n), dtype=np.float64)
    if loop.n_td:
        z[loop.o_td] = float(sc.reference.evaluate(0.0))
    z[loop.o_eso] = loop.compiled.evaluate(z)[0][loop.n_z]
    f, jac = loop.field()
    exps = finite_time_lyapunov(f, jac, z, 0.0, sc.t_final, renorm=renorm)
    return {"largest": float(exps[0]), "exponents": [float(x) for x in exps], "horizon": sc.t_final}


def _g(x: float, d: int = 2) -> str:
    return f"{x:.{d}g}"


NOT_DETERMINED = "not determined"
"""The tracking orbit's verdict when the analysis decides nothing (:func:`floquet_word`)."""


def floquet_word(floquet: dict[str, Any]) -> str:
    """The tracking orbit's verdict from a :func:`tracking_floquet` record: ``"stable"``
    (largest multiplier < 1), ``"unstable"``, or :data:`NOT_DETERMINED` when the orbit did
    not close (by more than :data:`CLOSES`) and the largest multiplier moved from below 1
    to 1 or above over the periods analysed: the multipliers of an orbit that has not
    settled describe no periodic orbit, and the last period's (retuned-s1-inleso: 0.9, with
    0.9–3.8 over two periods) moved with the last bit of the Jacobian."""
    mu = float(floquet["largest"])
    lo, hi = floquet.get("range") or (mu, mu)
    if floquet.get("closing", 0.0) > CLOSES and lo < 1.0 <= hi:
        return NOT_DETERMINED
    return "stable" if mu < 1 else "unstable"


def reconciled_text(info: dict[str, Any], unit: str = "") -> tuple[str, str]:
    """``(sentence, short)`` from an :func:`orbit_analysis` record: the equilibrium, the limit
    cycle it settles on, and the tracking orbit, e.g. "equilibrium unstable (max Re λ =
    10 1/s); with r held it settles on a limit cycle of 1e-05 rad at 72 rad/s; tracking
    orbit stable (largest Floquet multiplier 0.69)"."""
    u = f" {unit}" if unit and unit != "-" else ""
    eq = info.get("equilibrium", "not analysed")
    mr = info.get("max_real")
    parts = [f"equilibrium {eq}" + (f" (max Re λ = {_g(mr, 3)} 1/s)" if mr is not None else "")]
    short = []
    lc = info.get("limit_cycle")
    if lc is not None:
        if lc.get("estimate"):
            parts.append(
                f"with r held the describing functions predict a limit cycle of "
                f"{_g(lc['amplitude_y'])}{u} at {_g(lc['frequency'], 3)} rad/s"
            )
            short.append(
                f"limit cycle ≈ {_g(lc['amplitude_y'])}{u} at {_g(lc['frequency'], 3)} rad/s"
            )
        elif lc.get("bounded"):
            df = lc.get("describing")
            dtext = (
                f"; describing function: {_g(df['amplitude_y'])}{u} at "
                f"{_g(df['frequency'], 3)} rad/s"
                if df
                else ""
            )
            how = "settles on" if lc.get("settled", True) else "oscillates (not settled) in"
            parts.append(
                f"with r held it {how} a limit cycle of {_g(lc['amplitude_y'])}{u} at "
                f"{_g(lc['frequency'], 3)} rad/s (u ± {_g(lc['amplitude_u'])}{dtext})"
            )
            short.append(
                f"limit cycle {_g(lc['amplitude_y'])}{u} at {_g(lc['frequency'], 3)} rad/s"
            )
        else:
            parts.append("with r held it leaves the equilibrium (diverges)")
            short.append("equilibrium diverges")
    elif eq in ("stable", "unstable", "marginal"):
        short.append(f"equilibrium {eq}")
    if info.get("step_final") is not None:  # a step's tracking orbit is that equilibrium
        parts.append(
            f"a step reference's tracking orbit is the equilibrium at its final value r = "
            f"{_g(info['step_final'], 6)}{u}, the one above: {eq}"
        )
    fl, ft = info.get("floquet"), info.get("ftle")
    if fl is not None:
        mu = fl["largest"]
        word = floquet_word(fl)
        lo, hi = fl.get("range") or (mu, mu)
        caveat = ""
        if fl.get("closing", 0.0) > CLOSES:
            caveat = (
                f"; the orbit closes only to {_g(100 * fl['closing'])} % and its largest "
                f"multiplier ranges {_g(lo)}–{_g(hi)} over {fl['passes']} periods"
            )
        mu_text = _g(mu, 2) if mu >= 1e-12 else "< 1e-12"
        if word == NOT_DETERMINED:
            parts.append(
                f"tracking orbit {word}: its largest Floquet multiplier ranges {_g(lo)}–"
                f"{_g(hi)} over {fl['passes']} periods, on both sides of 1, and the orbit "
                f"closes only to {_g(100 * fl['closing'])} % (last period: {mu_text})"
            )
            short.insert(0, f"tracking {word} (μ {_g(lo)}–{_g(hi)})")
        else:
            parts.append(f"tracking orbit {word} (largest Floquet multiplier {mu_text}{caveat})")
            short.insert(0, f"tracking {word} (μ {'' if mu < 1e-12 else '= '}{mu_text})")
    elif ft is not None:
        lam = ft["largest"]
        word = "perturbations decay" if lam < 0 else "perturbations grow"
        parts.append(
            f"along the run {word} (largest finite-time Lyapunov exponent {_g(lam, 3)} 1/s "
            f"over {_g(ft['horizon'], 3)} s)"
        )
        short.insert(0, f"run: FTLE {_g(lam, 3)} 1/s")
    elif info.get("orbit_diverges"):
        parts.append(f"the tracking run diverges ({info['orbit_diverges']})")
        short.insert(0, "tracking diverges")
    elif info.get("orbit_error") and info.get("step_final") is not None:
        parts.append(
            "the run from the initial state was not followed to a finite-time Lyapunov "
            f"exponent (its states or Jacobian became non-finite: {info['orbit_error']}; the "
            "transient leaves the region where the loop is defined: see aiofl simulate)"
        )
    elif info.get("orbit_error"):
        parts.append(f"tracking orbit not analysed ({info['orbit_error']})")
    gave_up = info.get("gave_up")
    if gave_up:
        what = " and ".join(gave_up["parts"])
        parts.append(
            f"{what} not determined: gave up after {_g(gave_up['seconds'], 3)} s (the time "
            "budget, aiofl analyze --budget)"
        )
        short.append(f"gave up after {_g(gave_up['seconds'], 3)} s")
    return "; ".join(parts), "; ".join(short)


QUICK = {
    "passes": 2,
    "settle": 2,
    "rtol": 1e-5,
    "simulate_cycle": False,
    "points": 52,
    "orbit_when_stable": False,
}
"""The cheaper settings of ``orbit_analysis(quick=True)`` (the report): two settling and
two measured periods at rtol 1e-5; the limit cycle from the describing functions
(tabulated at 52 amplitudes) only, without the held-reference simulation (which costs
several seconds for a loop with observer poles near −2000; ``aiofl analyze --closed-loop``
runs it); the tracking orbit only where the equilibrium is not stable, i.e. where the
linearisation alone could contradict the simulation (1–9 s per design otherwise)."""


def orbit_analysis(
    cfg: Any,
    verdict: dict[str, Any] | None = None,
    *,
    unit: str = "",
    quick: bool = False,
    budget: float | None = None,
) -> dict[str, Any]:
    """The reconciled verdict of a run config (module docstring).

    Parameters
    ----------
    cfg
        A :class:`aiofl.config.RunConfig`.
    verdict
        Its :func:`aiofl.analysis.linearize.closed_loop_verdict` (computed if None).
    unit
        The plant's output unit, for the sentence.
    quick
        The cheaper settings :data:`QUICK` (for ``aiofl reproduce``).
    budget
        Seconds the analysis may take (None: no limit; :mod:`aiofl.analysis.budget`).  A
        part not finished when it is spent (the limit cycle, the tracking orbit) is left
        out, ``"gave_up"`` says so (``{"seconds", "parts"}``) and the verdict calls it not
        determined.

    Returns
    -------
    dict
        ``{"equilibrium": "stable"|"unstable"|..., "max_real", "limit_cycle":
        {"bounded", "amplitude_y", "amplitude_u", "frequency", "describing":
        {"amplitude_y", "frequency"}} or None, "floquet": {"multipliers", "largest", ...} or
        None, "ftle": {"largest", ...} or None, "verdict": sentence, "short": label,
        "seconds": wall time}``, and ``"notes"`` when a plant function's Jacobian came
        from finite differences (:class:`aiofl.analysis.derivatives.PlantDerivatives`).
    """
    from aiofl.analysis.linearize import closed_loop_verdict

    t_start = time.perf_counter()
    v = verdict if verdict is not None else closed_loop_verdict(cfg)
    out: dict[str, Any] = {
        "equilibrium": v.get("verdict", "not analysed"),
        "max_real": v.get("max_real"),
        "limit_cycle": None,
        "floquet": None,
        "ftle": None,
    }
    loops: list[OrbitLoop] = []
    gave_up: list[str] = []
    with time_budget(budget):
        _orbit_parts(cfg, v, out, loops, gave_up, QUICK if quick else {})
    if gave_up:
        out["gave_up"] = {"seconds": budget, "parts": gave_up}
    notes = list(dict.fromkeys(n for lp in loops for n in lp.derivatives.notes))
    if notes:  # a plant function differentiated by finite differences
        out["notes"] = notes
    out["verdict"], out["short"] = reconciled_text(out, unit)
    out["seconds"] = time.perf_counter() - t_start
    return out


def _orbit_parts(
    cfg: Any,
    v: dict[str, Any],
    out: dict[str, Any],
    loops: list[OrbitLoop],
    gave_up: list[str],
    q: dict[str, Any],
) -> None:
    """The limit cycle and the tracking orbit of :func:`orbit_analysis` (with the settings
    ``q``: :data:`QUICK` or none), into ``out``; a part stopped by the time budget is named
    in ``gave_up``."""
    from aiofl.analysis.closed_loop import reference_operating_value
    from aiofl.analysis.linearize import linearize_closed_loop

    simulate_cycle = q.get("simulate_cycle", True)
    points = {k: q[k] for k in ("points",) if k in q}
    periods = {k: q[k] for k in ("passes", "settle", "rtol") if k in q}

    if out["equilibrium"] == "unstable":
        try:
            lin = linearize_closed_loop(cfg, amplitude=float(v.get("amplitude", 1e-3)))
            loop = _loop(cfg)
            loops.append(loop)
            df = limit_cycle_describing(loop, lin.z_op, lin.a, **points)
            start = df["amplitude_y"] if df else None
            if simulate_cycle:
                lc = equilibrium_limit_cycle(loop, lin.z_op, lin.a, start_amplitude=start)
                lc["describing"] = df
            elif df is not None:  # the describing-function estimate alone
                lc = {"bounded": True, "estimate": "describing function", **df, "describing": df}
            else:
                lc = None
            out["limit_cycle"] = lc
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
            out["limit_cycle_error"] = f"{type(exc).__name__}: {exc}"
        except BudgetExceeded:
            gave_up.append("limit cycle")
    if gave_up:  # the budget is spent: the tracking orbit would give up at once
        gave_up.append("tracking orbit")
        return
    skip_orbit = out["equilibrium"] == "stable" and not q.get("orbit_when_stable", True)
    try:
        loop = _loop(cfg)
        loops.append(loop)
        if skip_orbit:
            out["orbit_skipped"] = "equilibrium stable (aiofl analyze --closed-loop runs it)"
        elif cfg.scenario.reference.kind == "sine":
            out["floquet"] = tracking_floquet(loop, **periods)
        else:
            if cfg.scenario.reference.kind == "step":  # after the step r is held: its orbit
                out["step_final"] = reference_operating_value(cfg.scenario.reference)
            out["ftle"] = tracking_ftle(loop)
    except OrbitDiverges as exc:
        out["orbit_diverges"] = str(exc)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        out["orbit_error"] = f"{type(exc).__name__}: {exc}"
    except BudgetExceeded:
        gave_up.append("tracking orbit")


def format_orbit_text(info: dict[str, Any]) -> str:
    """Plain-text lines of an :func:`orbit_analysis` record (``aiofl analyze --closed-loop``)."""
    out = ["Reconciled verdict (equilibrium, limit cycle, tracking orbit)"]
    lc = info.get("limit_cycle")
    if lc and lc.get("bounded"):
        out.append(
            f"  limit cycle with r held: |y| {lc['amplitude_y']:.3g}, |u| {lc['amplitude_u']:.3g}"
            f" at {lc['frequency']:.4g} rad/s (simulated {lc['simulated_s']:.3g} s)"
        )
        df = lc.get("describing")
        if df:
            out.append(
                f"  describing function: |y| {df['amplitude_y']:.3g} at {df['frequency']:.4g} rad/s"
            )
    fl = info.get("floquet")
    if fl:
        mus = ", ".join(f"{abs(complex(*m)):.3g}" for m in fl["multipliers"][:4])
        out.append(
            f"  Floquet multipliers (|μ|, largest first): {mus}; period {fl['period']:.4g} s, "
            f"orbit closes to {fl['closing']:.2g}, largest over {fl['passes']} periods "
            f"{fl['range'][0]:.3g}–{fl['range'][1]:.3g}"
        )
    if info.get("ftle"):
        out.append(f"  largest finite-time Lyapunov exponent: {info['ftle']['largest']:.4g} 1/s")
    out.append(f"  verdict: {info['verdict']}")
    out.append(f"  ({info['seconds']:.2f} s)")
    return "\n".join(out)
