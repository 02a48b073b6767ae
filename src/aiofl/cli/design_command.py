"""``aiofl design``: a first LADRC for a plant, checked, written as a run config.

The rules and the check are :func:`aiofl.analysis.first_design.first_design`.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from aiofl.cli.bad_input import FORCE_OPTION, SENSOR_OPTION, bad_input_exits, parse_numbers

__all__ = ["design_command"]


def design_command(
    plant: Annotated[
        str, typer.Argument(help="A plant file (.toml) or a registered plant's name.")
    ],
    y: Annotated[float, typer.Option("--y", help="The output to hold (the operating point).")],
    out: Annotated[Path, typer.Option("--out", "-o", help="The run config to write (.toml).")],
    x0: Annotated[
        str | None,
        typer.Option("--x0", help="Where the operating point's search starts: n numbers, commas."),
    ] = None,
    rho: Annotated[
        int | None, typer.Option("--rho", help="The chain order (default: the relative degree).")
    ] = None,
    sensor: Annotated[str | None, SENSOR_OPTION] = None,
    ts: Annotated[
        float | None, typer.Option("--ts", help="The controller's sample time [s].")
    ] = None,
    omega_c: Annotated[
        float | None,
        typer.Option("--omega-c", help="Force the closed-loop bandwidth [rad/s]."),
    ] = None,
    u_max: Annotated[
        float | None, typer.Option("--u-max", help="The actuator's limit (|u| <= u_max).")
    ] = None,
    force: Annotated[bool, FORCE_OPTION] = False,
) -> None:
    """Propose a first LADRC from the plant's operating point, sensor and sample time,
    check it in closed loop (a step about the operating point) and write it to OUT.

    b0 is beta at the operating point, omega_c at least twice the fastest unstable pole,
    omega0 four times omega_c, limited to 0.3/Ts when sampled.  What the check measured is
    printed; edit OUT and go on with aiofl simulate, analyze, tune."""
    import tomlkit

    from aiofl.analysis.first_design import first_design
    from aiofl.config import resolve_plant
    from aiofl.outputs import atomic_write_text

    with bad_input_exits():
        if out.suffix != ".toml":
            raise ValueError(f"--out = {str(out)!r}; allowed: a .toml file")
        if out.exists() and not force:
            raise ValueError(f"--out = {str(out)!r} exists; give --force to replace it")
        guess = parse_numbers("--x0", x0)
        for name, v in (("--y", y), ("--ts", ts), ("--omega-c", omega_c), ("--u-max", u_max)):
            if v is not None and not math.isfinite(v):
                raise ValueError(f"{name} = {v!r}; allowed: a finite number")
        for name, v in (("--ts", ts), ("--omega-c", omega_c), ("--u-max", u_max)):
            if v is not None and not v > 0:
                raise ValueError(f"{name} = {v!r}; allowed: a number > 0")
        if rho is not None and not 1 <= rho <= 4:
            raise ValueError(f"--rho = {rho}; allowed: 1 <= rho <= 4")
        ref = plant
        if plant.endswith(".toml"):
            ref = str(Path(plant).resolve())
        model = resolve_plant(ref)
        if guess is not None and len(guess) != model.n_states:
            raise ValueError(
                f"--x0 has {len(guess)} entries; plant {model.name!r} has {model.n_states} states"
            )
        prop = first_design(
            ref,
            model,
            y=y,
            x_guess=guess,
            rho=rho,
            sensor=sensor,
            ts=ts,
            omega_c=omega_c,
            u_max=u_max,
        )
    typer.echo(prop.point.text(model.output_unit, model.input_unit))
    typer.echo(
        f"design: LADRC, rho = {prop.rho}, b0 = {prop.b0:.6g}, omega_c = {prop.omega_c:.4g} "
        f"rad/s, omega0 = {prop.omega0:.4g} rad/s"
    )
    for note in prop.notes:
        typer.echo(f"  {note}")
    r = prop.response
    check = f"check (a step about the operating point): {prop.status}"
    if prop.status == "ok" and r:
        check += (
            f"; overshoot {r['overshoot']:.3g} %, settling "
            + ("not settled" if math.isnan(r["settling_time"]) else f"{r['settling_time']:.3g} s")
            + f", peak |u| {r['u_peak']:.4g}, noise in u {r['u_noise']:.3g}"
        )
    typer.echo(check + (f" (after {prop.rounds} rounds)" if prop.rounds > 1 else ""))
    header = (
        "# A first design proposed by aiofl design: edit, then aiofl simulate / analyze / tune.\n"
    )
    with bad_input_exits(run=True):
        atomic_write_text(out, header + tomlkit.dumps(prop.config))
    typer.echo(f"wrote {out}")
    if prop.status != "ok":
        typer.echo(
            f"aiofl: warning: the proposed design is {prop.status} in its check; see the notes",
            err=True,
        )
