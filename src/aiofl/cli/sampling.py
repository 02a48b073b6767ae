"""``aiofl analyze CONFIG --sampling [--json] [--out DIR]``: the largest usable sample time.

Runs :func:`aiofl.analysis.sampling.sampling_limits` (batched engine runs over a ladder of
sample times) and prints ``ts_max`` (stable and within the ITAE tolerance of the continuous
design) and ``ts_stable``; ``--json`` prints ``{"ts_max": ..., "ts_stable": ..., ...}``;
``--out DIR`` also writes ``DIR/sampling.json`` and ``DIR/sampling.png`` (ITAE against Ts).
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

from aiofl.cli.errors import _check_out, bad_input_exits

__all__ = ["run_sampling"]


def _fmt(x: float | None, unit: str = " s") -> str:
    return "—" if x is None else f"{x:.4g}{unit}"


def run_sampling(target: str, *, as_json: bool, out: Path | None, tolerance: float) -> None:
    """The body of ``aiofl analyze CONFIG --sampling``."""
    from aiofl.analysis.sampling import sampling_figure, sampling_limits
    from aiofl.config import load_config
    from aiofl.outputs import atomic_output_dir, atomic_write_bytes, atomic_write_text

    with bad_input_exits():
        if not tolerance > 0:
            raise ValueError(f"--tolerance = {tolerance}; allowed: > 0")
        if out is not None:
            _check_out(out)
        cfg = load_config(target)
    with bad_input_exits(run=True):
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
        f"  continuous ITAE: {_fmt(lim.itae_continuous, '')}"
        + ("  (the continuous loop diverges)" if lim.continuous_diverged else ""),
        f"  ts_max    = {_fmt(lim.ts_max)}  (stable and ITAE within "
        f"{100 * tolerance:g} % of continuous; first failure at {_fmt(lim.ts_max_bracket[1])})",
        f"  ts_stable = {_fmt(lim.ts_stable)}  (no divergence; first divergence at "
        f"{_fmt(lim.ts_stable_bracket[1])})",
        f"  {len(lim.points)} sampled runs in {lim.engine_calls} engine calls, "
        f"{lim.seconds:.1f} s; Ts tried up to {lim.ts_upper:g} s",
    ]
    if lim.ts_max is None and not lim.continuous_diverged:
        lines.append(f"  the design fails already at Ts = dt = {cfg.dt:g} s (try a smaller dt)")
    if out is not None:
        lines.append(f"wrote {out}/sampling.json, sampling.png")
    typer.echo("\n".join(lines))
