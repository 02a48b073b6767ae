"""``aiofl trim``: the operating point of a plant (or of a config's plant at its reference).

Prints the equilibrium :math:`(x_e, u_e)` holding the output, β there, the open-loop
poles and whether the plant is open-loop unstable (:func:`aiofl.plants.operating_point.trim`);
``--json FILE`` also writes them.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from aiofl.cli.bad_input import FORCE_OPTION, bad_input_exits, parse_numbers

__all__ = ["trim_command"]


def trim_command(
    target: Annotated[
        str,
        typer.Argument(
            help="A run config or preset (trimmed at its reference's start, from its x0), or a "
            "plant: a plant file or a registered plant's name (give --y)."
        ),
    ],
    y: Annotated[
        float | None, typer.Option("--y", help="The output to hold (default: the config's r(0)).")
    ] = None,
    x0: Annotated[
        str | None,
        typer.Option("--x0", help="Where the search starts: n comma-separated numbers."),
    ] = None,
    json_out: Annotated[
        Path | None, typer.Option("--json", help="Also write the operating point as JSON.")
    ] = None,
    force: Annotated[bool, FORCE_OPTION] = False,
) -> None:
    """Solve for the equilibrium that holds the output: state, holding input, beta there,
    open-loop poles and stability.

    The holding input is what `[scenario] u_ref = "trim"` measures ISU and IAU about."""
    import json

    from aiofl.config import load_config, resolve_plant
    from aiofl.outputs import atomic_write_text
    from aiofl.plants.operating_point import trim

    with bad_input_exits():
        guess = parse_numbers("--x0", x0)
        if json_out is not None and json_out.exists() and not force:
            raise ValueError(f"--json = {str(json_out)!r} exists; give --force to replace it")
        if y is not None and not math.isfinite(y):
            raise ValueError(f"--y = {y!r}; allowed: a finite number")
        is_config = False
        if target.endswith(".toml") and Path(target).is_file():
            import tomllib

            with Path(target).open("rb") as fh:
                is_config = "f" not in tomllib.load(fh)
        else:
            from aiofl.config import list_presets

            is_config = target in list_presets()
        if is_config:
            cfg = load_config(target)
            plant = cfg.plant
            y_hold = y if y is not None else cfg.scenario.initial_value()
            guess = guess if guess is not None else (list(cfg.scenario.x0) or None)
        else:
            plant = resolve_plant(target)
            if y is None:
                raise ValueError(f"--y: missing; {target} is a plant, give the output to hold")
            y_hold = y
        if guess is not None and len(guess) != plant.n_states:
            raise ValueError(
                f"--x0 has {len(guess)} entries; plant {plant.name!r} has {plant.n_states} states"
            )
        point = trim(plant, float(y_hold), x_guess=guess)
    typer.echo(point.text(plant.output_unit, plant.input_unit))
    if json_out is not None:
        with bad_input_exits(run=True):
            atomic_write_text(json_out, json.dumps(point.to_dict(), indent=2) + "\n")
        typer.echo(f"wrote {json_out}")
