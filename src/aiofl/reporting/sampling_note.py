"""The sampling limits in the reproduce report: a ts_max column and what it means.

:func:`case_limits` runs :func:`aiofl.analysis.sampling_limits.sampling_limits_many` on every case
of a reproduction (batched per plant); :func:`ts_max_cell` formats one case's limit for the
tables and :func:`sampling_paragraph` writes the paragraph on what the limits mean for the
paper's printed designs, from the computed numbers only, with the definition of "stable"
of :mod:`aiofl.analysis.sampling_limits` (linearised sampled loop inside the unit circle, bounded
simulation, no more than 5 % extra time at the saturation).  Kept in its own module so that the
tables and the HTML page only add one column and one section.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

__all__ = ["case_limits", "sampling_paragraph", "ts_max_cell"]

TS_MAX_HEADER = "ts_max [ms]"


def case_limits(configs: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """Sampling limits of each preset's config, by preset (``SamplingLimits.to_dict()``)."""
    from aiofl.analysis.sampling_limits import sampling_limits_many

    names = list(configs)
    lims = sampling_limits_many([configs[n] for n in names])
    return {n: lim.to_dict() for n, lim in zip(names, lims, strict=True)}


def _ms(x: float) -> str:
    return f"{1e3 * x:.3g}"


def ts_max_cell(lim: Mapping[str, Any] | None) -> str:
    """One table cell: ts_max in ms; '≥ X' when nothing up to the largest Ts tried failed,
    '< dt' when the design fails already at Ts = dt, '—' when the continuous loop is not
    stable (it diverges or its linearisation is unstable; or no limits were computed)."""
    if lim is None or lim["continuous_diverged"]:
        return "—"
    if lim["ts_max"] is None:
        return f"< {_ms(lim['dt'])}"
    if lim["ts_max_bracket"][1] is None:
        return f"≥ {_ms(lim['ts_max'])}"
    return _ms(lim["ts_max"])


def _describe(label: str, lim: Mapping[str, Any]) -> str:
    stable = lim["ts_stable"]
    w0 = lim.get("omega0")

    def with_w0(ts: float) -> str:
        return f" (ω0·Ts = {w0 * ts:.3g})" if w0 else ""

    st = (
        "is not stable already at Ts = dt"
        if stable is None
        else (
            f"stays stable up to {_ms(stable)} ms{with_w0(stable)}"
            if lim["ts_stable_bracket"][1] is not None
            else f"stays stable at every Ts tried (up to {_ms(stable)} ms{with_w0(stable)})"
        )
    )
    if lim["continuous_diverged"]:
        how = (
            "its linearisation at the operating point is unstable"
            if lim.get("continuous_linear_stable") is False
            else "it diverges"
        )
        return (
            f"{label} is not stable in continuous time already ({how}), so no processor can run it"
        )
    if lim["ts_max"] is None:
        return (
            f"{label} loses more than {100 * lim['tolerance']:g} % of its continuous ITAE "
            f"({lim['itae_continuous']:.4g}) already at Ts = dt = {_ms(lim['dt'])} ms and {st}"
        )
    rate = 1.0 / lim["ts_max"]
    hz = f"{rate / 1e3:.3g} kHz" if rate >= 1e3 else f"{rate:.3g} Hz"
    bound = "at least " if lim["ts_max_bracket"][1] is None else ""
    return (
        f"{label} keeps its ITAE within {100 * lim['tolerance']:g} % up to Ts = "
        f"{bound}{_ms(lim['ts_max'])} ms{with_w0(lim['ts_max'])} (a controller rate of {hz} "
        f"or more) and {st}"
    )


def sampling_paragraph(
    cases: Sequence[tuple[str, str, str, int]], limits: Mapping[str, Mapping[str, Any]]
) -> list[str]:
    """The paragraph on what the sample-time limits mean, as sentences.

    ``cases`` are ``(label, preset, source, scenario)`` of the report's rows; ``limits`` the
    :func:`case_limits` by preset.
    """
    if not limits:
        return []
    any_lim = next(iter(limits.values()))
    out = [
        "The paper simulates its controllers in continuous time and states no sample rate. "
        "The column ts_max is the largest sample time Ts at which a design, run as a sampled "
        "controller (the command held over each sample; the linear ESO by its exact ZOH "
        "current observer, the INLESO and the ITD by forward Euler, Han's TD by fhan, the "
        "prefilter by ZOH), is stable and keeps its ITAE within "
        f"{100 * any_lim['tolerance']:g} % of the continuous value, at that and every smaller "
        f"Ts tried (multiples of dt = {_ms(any_lim['dt'])} ms, up to "
        f"{_ms(any_lim['ts_upper'])} ms; aiofl analyze CONFIG --sampling; every run is in "
        "sampling.json).",
        "Stable at a Ts means three things at once: the sampled loop linearised at its "
        "operating point (the zero-order-hold model of the plant's continuous linearisation "
        "closed with the controller's discrete update) has all eigenvalues inside the unit "
        "circle; the simulation over the horizon stays bounded; and the command sits at its "
        f"limit for at most {100 * any_lim.get('saturation_allowance', 0.05):g} % of the "
        "horizon more than the continuous design does (a loop held by a saturated command "
        "stays bounded whatever its dynamics). ts_stable is the largest Ts stable at it and "
        "every smaller Ts tried; ω0·Ts (the observer bandwidth times the sample time) is "
        "given beside each limit. A design whose continuous loop is not stable has neither "
        "limit.",
    ]
    printed = [(lbl, p, s) for lbl, p, src, s in cases if src == "printed" and p in limits]
    if printed:
        out.append(
            "For the paper's printed designs: "
            + "; ".join(_describe(f"{lbl} of scenario {s}", limits[p]) for lbl, p, s in printed)
            + "."
        )
    margins = _delay_margins(cases, limits)
    if margins:
        out.append(margins)
    others = [(lbl, p, s) for lbl, p, src, s in cases if src != "printed" and p in limits]
    fails_at_dt = [f"{lbl} of scenario {s}" for lbl, p, s in others if _fails_at_dt(limits[p])]
    if fails_at_dt:
        out.append(
            "Of the other designs, "
            + _join(fails_at_dt)
            + f" lose more than the allowance already at Ts = dt = {_ms(any_lim['dt'])} ms: "
            "their continuous ITAE is either very small or rests on observer and "
            "differentiator bandwidths that a controller sampled at that rate does not "
            "reproduce, so it is not the ITAE a processor would achieve."
        )
    return out


def _delay_margins(
    cases: Sequence[tuple[str, str, str, int]], limits: Mapping[str, Mapping[str, Any]]
) -> str:
    """The sentence on the delay margins: sampled (the discrete model with the delay) against
    continuous, per case, at the sample time they were computed for ('' if none)."""
    items, ts_set = [], set()
    for lbl, p, _src, s in cases:
        lim = limits.get(p)
        if lim is None or lim.get("delay_margin_sampled_s") is None:
            continue
        cont = lim.get("delay_margin_continuous_s")
        ts_set.add(lim["delay_ts"])
        items.append(
            f"{lbl} of scenario {s} {_ms(lim['delay_margin_sampled_s'])} ms"
            + ("" if cont is None else f" (continuous {_ms(cont)} ms)")
        )
    if not items:
        return ""
    at = f"Ts = {_ms(ts_set.pop())} ms" if len(ts_set) == 1 else "each design's Ts"
    return (
        "The largest unmodelled transport delay (actuator or sensor) each loop tolerates, "
        f"sampled at {at}, from the discrete model with the delay (shift register and "
        "fractional-delay hold) against the continuous loop's phase-margin delay: "
        + "; ".join(items)
        + ". The sampled margin is the one a processor has; the continuous one ignores the "
        "hold and the discrete observer."
    )


def _join(items: Sequence[str]) -> str:
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def _fails_at_dt(lim: Mapping[str, Any]) -> bool:
    return not lim["continuous_diverged"] and lim["ts_max"] is None
