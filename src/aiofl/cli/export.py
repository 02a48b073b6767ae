"""``aiofl export CONFIG [--ts TS] [--precision double|float] --out DIR``: the controller as C99.

Writes ``DIR/aiofl_controller.h`` and ``DIR/aiofl_controller.c`` (:mod:`aiofl.export`), the
discrete controller the engine simulates with ``--ts`` / ``[controller.discrete]``.  A
controller the C code cannot express (the IOFL law, which needs the plant model; a
model-assisted controller of a plant without symbolic expressions, whose nominal model is
generated as C from them), a missing sample time or a bad option exits with status 2 and the
reason; nothing is written then.
The config's name, description and path go into the files' comment block only, made inert
by :func:`aiofl.export.c_text.comment_text` inside :func:`aiofl.export.export_c`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import typer

from aiofl.cli.errors import _check_out, bad_input_exits

__all__ = ["export_command"]


def export_command(
    config: Annotated[str, typer.Argument(help="A TOML config file or a preset name.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output directory.")],
    ts: Annotated[
        float | None,
        typer.Option("--ts", help="Sample time [s] (default: the config's [controller.discrete])."),
    ] = None,
    precision: Annotated[
        Literal["double", "float"],
        typer.Option("--precision", help="Arithmetic of the C code (C double or float)."),
    ] = "double",
) -> None:
    """Export the config's controller, sampled at Ts, as C99 (aiofl_controller.h/.c in OUT)."""
    from aiofl.config import load_config
    from aiofl.export import ExportError, export_c
    from aiofl.outputs import atomic_output_dir, atomic_write_text

    with bad_input_exits():
        _check_out(out)
        cfg = load_config(config)
        if ts is not None:
            if not 0 < ts <= 1.0:  # the range of [controller.discrete] ts
                raise ValueError(f"--ts = {ts}; allowed: 0 < ts <= 1 [s]")
            from dataclasses import replace

            from aiofl.engine.discrete import Sampling

            base = cfg.sampling or Sampling(ts)
            sampling = replace(base, ts=ts)
        else:
            sampling = cfg.sampling
        try:
            files = export_c(
                cfg.controller,
                sampling,
                precision=precision,
                title=cfg.name,
                notes=[f"Config: {config}", *([cfg.description] if cfg.description else [])],
                plant=cfg.plant,  # a model-assisted controller's nominal model
                plant_source=str(cfg.raw.get("plant", cfg.plant.name)),
                x0=cfg.scenario.x0,
            )
        except ExportError as exc:
            raise ValueError(f"cannot export {cfg.name!r}: {exc}") from None
    with bad_input_exits(run=True), atomic_output_dir(out) as stage:
        for name, text in files.items():
            atomic_write_text(stage / name, text)
    typer.echo(f"wrote {out}/{', '.join(files)} (Ts = {sampling.ts:g} s, {precision})")
