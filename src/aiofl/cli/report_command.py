"""``aiofl report``: the HTML report of any design (:mod:`aiofl.reporting.design_report`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from aiofl.cli.bad_input import FORCE_OPTION, _check_out, bad_input_exits

__all__ = ["report_command"]


def report_command(
    config: Annotated[str, typer.Argument(help="A TOML config file or a preset name.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output directory.")],
    draws: Annotated[
        int | None,
        typer.Option("--draws", help="Override uncertainty.draws (with an [uncertainty] table)."),
    ] = None,
    force: Annotated[bool, FORCE_OPTION] = False,
) -> None:
    """Report one design: report.html, report.md, report.json and figure.png in OUT.

    What the plant did (ok, lost or diverged), the step metrics and the command's noise,
    the operating point, the margins of the continuous and (sampled) the sampled loop,
    the design on its own and ideal sensors and, with an [uncertainty] table, over its
    draws and box corners."""
    import json

    from aiofl.cli.configs import load_run_config
    from aiofl.outputs import atomic_output_dir, atomic_write_bytes, atomic_write_text
    from aiofl.uncertainty import MAX_DRAWS

    with bad_input_exits():
        _check_out(out, force=force)
        if draws is not None and not 1 <= draws <= MAX_DRAWS:
            raise ValueError(f"--draws = {draws}; allowed: 1 <= draws <= {MAX_DRAWS}")
        cfg = load_run_config(config)
    from aiofl.reporting.design_report import design_html, design_markdown, design_report

    with bad_input_exits(run=True), atomic_output_dir(out) as stage:
        rep = design_report(cfg, config, draws=draws)
        atomic_write_text(stage / "report.json", json.dumps(rep.to_dict(), indent=2) + "\n")
        atomic_write_bytes(stage / "figure.png", rep.figure)
        atomic_write_text(stage / "report.html", design_html(rep, cfg.description))
        atomic_write_text(stage / "report.md", design_markdown(rep, cfg.description))
    typer.echo(f"{config}: {rep.verdict}")
    for line in rep.lines:
        typer.echo(line)
    typer.echo(f"wrote {out}/report.html, report.md, report.json, figure.png")
