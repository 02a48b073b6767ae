r"""``aiofl analyze CONFIG --sampling [--json] [--out DIR]``: the largest usable sample time.

Runs :func:`aiofl.analysis.sampling_limits.sampling_limits` (batched engine runs over a ladder of
sample times, each with the spectral radius of the linearised sampled loop) and prints the
definitions, ``ts_max`` (stable and within the ITAE tolerance of the continuous design) and
``ts_stable`` with :math:`\omega_0T_s`, the sampled and continuous delay margins
(:mod:`aiofl.analysis.sampling_limits`), and every run (Ts, ω0·Ts, spectral radius, time at
the saturation, ITAE, the criteria it fails); a design whose continuous loop is not stable
gets neither limit; ``--json`` prints ``{"ts_max": ..., "ts_stable": ..., ...}``;
``--out DIR`` also writes ``DIR/sampling.json`` and ``DIR/sampling.png`` (ITAE against Ts).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import typer

from aiofl.cli.bad_input import _check_out, bad_input_exits

__all__ = ["run_sampling"]


def _fmt(x: float | None, unit: str = " s") -> str:
    return "—" if x is None else f"{x:.4g}{unit}"


def _fmt_delay(x: float | None) -> str:
    if x is None:
        return "—"
    return "∞ (none up to the largest delay tried)" if x == float("inf") else f"{1e3 * x:.4g} ms"


def _w0(lim: Any, ts: float | None) -> str:
    return "" if ts is None or lim.omega0 is None else f" (ω0·Ts = {lim.omega0 * ts:.3g})"


def _criteria_lines(lim: Any) -> list[str]:
    words = lim.criteria.split(" ")
    out, line = [], "  definitions:"
    for w in words:
        if len(line) + len(w) > 92:
            out.append(line)
            line = "   "
        line += " " + w
    return [*out, line]


def _point_line(lim: Any, p: Any) -> str:
    fails = p.failures(lim.saturated_continuous or 0.0, lim.saturation_allowance)
    w0 = "—" if p.omega0_ts is None else f"{p.omega0_ts:.3g}"
    rad = "—" if p.radius is None else f"{p.radius:.6f}"
    sat = "—" if p.saturated is None else f"{100 * p.saturated:.3g} %"
    return (
        f"  {p.ts:<10.4g}  {w0:<8}  {rad:<9}  {sat:<9}  {_fmt(p.itae, ''):<10}  "
        f"{', '.join(fails) or 'stable'}"
    )


def run_sampling(
    target: str,
    *,
    as_json: bool,
    out: Path | None,
    tolerance: float,
    force: bool = False,
    budget: float | None = None,
) -> None:
    """The body of ``aiofl analyze CONFIG --sampling`` (``budget``: seconds for the refining
    rounds, :mod:`aiofl.analysis.budget`).

    Parameters
    ----------
    target
        The config (a path or a preset name).
    as_json
        Print JSON instead of text.
    out
        A folder to write the report into (None: none).
    tolerance
        The ITAE allowance (> 0) of :func:`aiofl.analysis.sampling_limits.sampling_limits`.
    force
        Replace ``out``.
    budget
        Seconds for the refining rounds (None: no limit).
    """
    from aiofl.analysis.budget import time_budget
    from aiofl.analysis.sampling_limits import sampling_figure, sampling_limits
    from aiofl.cli.configs import load_run_config
    from aiofl.outputs import atomic_output_dir, atomic_write_bytes, atomic_write_text

    with bad_input_exits():
        if not tolerance > 0:
            raise ValueError(f"--tolerance = {tolerance}; allowed: > 0")
        if out is not None:
            _check_out(out, force=force)
        cfg = load_run_config(target)
    with bad_input_exits(run=True):
        with time_budget(budget):
            lim = sampling_limits(cfg, tolerance=tolerance)
        info = lim.to_dict()
        if out is not None:
            import io

            with atomic_output_dir(out) as stage:
                atomic_write_text(stage / "sampling.json", json.dumps(info, indent=2) + "\n")
                buf = io.BytesIO()
                sampling_figure(lim).savefig(buf, format="png")
                atomic_write_bytes(stage / "sampling.png", buf.getvalue())
    if as_json:
        typer.echo(json.dumps(info, indent=2))
        return
    lines = [
        f"{cfg.name}: sampled controller, engine step dt = {cfg.dt:g} s, horizon "
        f"{cfg.scenario.t_final:g} s",
        *(f"  {ln}" for ln in lim.discretisation),
        *_criteria_lines(lim),
        f"  continuous ITAE: {_fmt(lim.itae_continuous, '')}"
        + (
            f", at the saturation {100 * lim.saturated_continuous:.3g} % of the horizon"
            if lim.saturated_continuous is not None
            else ""
        ),
    ]
    if lim.linearisation_note:
        lines.append(f"  note: {lim.linearisation_note}")
    if lim.continuous_diverged:
        lines.append(
            "  the continuous loop is not stable (it diverges, or its linearisation is "
            "unstable): there is no sample time to look for; no ts_max, no ts_stable"
        )
    else:
        fail = ", ".join(lim.first_failure) or "—"
        lines += [
            f"  ts_max    = {_fmt(lim.ts_max)}{_w0(lim, lim.ts_max)}  (stable and ITAE within "
            f"{100 * tolerance:g} % of continuous; first failure at "
            f"{_fmt(lim.ts_max_bracket[1])})",
            f"  ts_stable = {_fmt(lim.ts_stable)}{_w0(lim, lim.ts_stable)}  (first unstable Ts "
            f"{_fmt(lim.ts_stable_bracket[1])}{_w0(lim, lim.ts_stable_bracket[1])}, fails: "
            f"{fail})",
        ]
        if lim.ts_stable is not None and lim.ts_stable_bracket[1] is None:
            lines.append(
                f"  (nothing up to the largest Ts tried, {lim.ts_upper:g} s, failed: "
                "ts_stable is a lower bound)"
            )
    if lim.delay_ts is not None and not lim.continuous_diverged:
        lines.append(
            f"  delay margin at Ts = {_fmt(lim.delay_ts)}: sampled "
            f"{_fmt_delay(lim.delay_margin_sampled)} (discrete model with the delay), "
            f"continuous {_fmt_delay(lim.delay_margin_continuous)}"
        )
    lines += [
        "  Ts [s]      ω0·Ts     radius    saturated  ITAE        fails",
        *(_point_line(lim, p) for p in lim.points),
        f"  {len(lim.points)} sampled runs in {lim.engine_calls} engine calls, "
        f"{lim.seconds:.1f} s; Ts tried up to {lim.ts_upper:g} s",
    ]
    if lim.gave_up is not None:
        lines.append(
            f"  gave up refining after {lim.gave_up:g} s (the time budget, --budget): the "
            "limits are those of the coarser ladder above"
        )
    if lim.ts_max is None and not lim.continuous_diverged:
        lines.append(f"  the design fails already at Ts = dt = {cfg.dt:g} s (try a smaller dt)")
    if out is not None:
        lines.append(f"wrote {out}/sampling.json, sampling.png")
    typer.echo("\n".join(lines))
