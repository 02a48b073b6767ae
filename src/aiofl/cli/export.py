"""``aiofl export CONFIG [--ts TS] [--precision double|float] --out DIR``: the controller as C99.

Writes ``DIR/aiofl_controller.h`` and ``DIR/aiofl_controller.c`` (:mod:`aiofl.export`), the
discrete controller the engine simulates with ``--ts`` / ``[controller.discrete]``.  A
controller the C code cannot express (the IOFL law, which needs the plant model; a
model-assisted controller of a plant without symbolic expressions, whose nominal model is
generated as C from them), a missing sample time or a bad option exits with status 2 and the
reason; nothing is written then.

Before writing, the design is simulated as the config describes it (sampled at the exported
Ts when that is a multiple of the config's dt): a design that diverges there is still
exported (exit 0), with a warning on stderr naming the time, so firmware is never generated
from a diverging loop without a word.
The config's name, description and path go into the files' comment block only, made inert
by :func:`aiofl.export.c_text.comment_text` inside :func:`aiofl.export.export_c`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal

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
    fmt: Annotated[
        Literal["c", "fmu"],
        typer.Option(
            "--format",
            help="c: C99 sources; fmu: an FMI 2.0 co-simulation FMU, NAME.fmu, with the C "
            "sources and a Linux x86-64 binary built by the system C compiler.",
        ),
    ] = "c",
) -> None:
    """Export the config's controller, sampled at Ts, as C99 (aiofl_controller.h/.c in OUT)."""
    from aiofl.config import load_config
    from aiofl.export import ExportError, export_c
    from aiofl.outputs import atomic_output_dir, atomic_write_bytes, atomic_write_text

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
            if fmt == "fmu":  # aiofl.export.fmu: that C, wrapped, compiled and zipped
                from aiofl.export.fmu import export_fmu_for_config

                files = dict(
                    [export_fmu_for_config(cfg, sampling, precision=precision, config=config)]
                )
        except ExportError as exc:
            raise ValueError(f"cannot export {cfg.name!r}: {exc}") from None
    warning = _divergence_warning(cfg, sampling, config)
    with bad_input_exits(run=True), atomic_output_dir(out) as stage:
        for name, text in files.items():
            if isinstance(text, bytes):  # the FMU
                atomic_write_bytes(stage / name, text)
            else:
                atomic_write_text(stage / name, text)
    typer.echo(f"wrote {out}/{', '.join(files)} (Ts = {sampling.ts:g} s, {precision})")
    if warning:
        typer.echo(f"aiofl: warning: {warning}", err=True)


def _divergence_warning(cfg: Any, sampling: Any, config: str) -> str | None:
    """Why the exported design should not go on a rig: it diverges in its own simulation
    (sampled at the exported Ts when that is a multiple of dt); None when it does not."""
    from aiofl.config import ConfigError
    from aiofl.plants.base import PlantError

    run_cfg = cfg
    if cfg.sampling is None or cfg.sampling.ts != sampling.ts:
        try:
            run_cfg = cfg.with_sample_time(sampling.ts)
        except ConfigError:  # Ts not a multiple of dt: the config's own loop
            run_cfg = cfg
    try:
        res = run_cfg.simulate(store=False)
    except (PlantError, ValueError) as exc:
        return f"{config}: could not simulate the design before export ({exc})"
    if not res.diverged:
        return None
    how = f"sampled at Ts = {run_cfg.sampling.ts:g} s" if run_cfg.sampling else "continuous"
    return (
        f"{config} diverges at {res.diverged_at:.2f} s in its own simulation ({how}, "
        f"{run_cfg.scenario.t_final:g}-s scenario); the exported controller is that design: "
        "check it with `aiofl simulate` before running it on hardware"
    )
