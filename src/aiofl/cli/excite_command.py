"""``aiofl excite``: an input for an identification experiment (PRBS or chirp), as CSV and C.

The signals and the rule that picks a PRBS's clock from the band are
:mod:`aiofl.identification.excitation`.  Bad input (a band the sample time cannot reach, a
duration that is not a whole number of samples, a size beyond
:data:`aiofl.limits.MAX_LOG_SAMPLES`, an existing output file without ``--force``) exits 2
with one message naming the option, nothing written.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import typer

from aiofl.cli.bad_input import FORCE_OPTION, bad_input_exits

__all__ = ["excite_command"]


def excite_command(
    out: Annotated[Path, typer.Option("--out", "-o", help="The signal's CSV file (t, u).")],
    duration: Annotated[float, typer.Option("--duration", help="Length of the signal [s].")],
    ts: Annotated[float, typer.Option("--ts", help="Sample time of the rig [s].")],
    amplitude: Annotated[
        float, typer.Option("--amplitude", help="u swings over offset ± amplitude.")
    ],
    kind: Annotated[
        Literal["prbs", "chirp"],
        typer.Option("--kind", help="prbs: a pseudo-random binary sequence; chirp: a swept sine."),
    ] = "prbs",
    band: Annotated[
        float | None,
        typer.Option(
            "--band",
            help="The band to excite, 0..F [Hz] (PRBS: its clock period is 0.44/F; chirp: "
            "its end frequency).",
        ),
    ] = None,
    f0: Annotated[
        float | None,
        typer.Option("--f0", help="Chirp: start frequency [Hz] (default 1/duration)."),
    ] = None,
    f1: Annotated[
        float | None, typer.Option("--f1", help="Chirp: end frequency [Hz] (as --band).")
    ] = None,
    method: Annotated[
        Literal["linear", "logarithmic"],
        typer.Option("--method", help="Chirp: how the frequency sweeps."),
    ] = "linear",
    offset: Annotated[
        float, typer.Option("--offset", help="The level u swings about (operating point).")
    ] = 0.0,
    seed: Annotated[
        int, typer.Option("--seed", min=0, help="PRBS: the seed of its start state.")
    ] = 0,
    unit: Annotated[
        str, typer.Option("--unit", help="The input's unit, written in the CSV header.")
    ] = "",
    c_array: Annotated[
        Path | None,
        typer.Option("--c-array", help="Also write the signal as a C header (.h) for a rig."),
    ] = None,
    c_name: Annotated[
        str, typer.Option("--c-name", help="The C array's name (and its macros' prefix).")
    ] = "aiofl_excitation",
    force: Annotated[bool, FORCE_OPTION] = False,
) -> None:
    """Write an excitation signal for an identification experiment: a PRBS exciting
    0..--band Hz, or a chirp from --f0 to --f1 (or --band) Hz, sampled at --ts.

    OUT is a CSV with columns t [s] and u: play u on the rig (held over each sample), log
    t, u and the output, then run aiofl identify on the log.  --c-array also writes the
    samples as a C array (static const float NAME[NAME_N], with NAME_N and NAME_TS).  An
    existing file is refused unless --force."""
    from aiofl.identification.excitation import c_array_text, chirp, csv_text, prbs
    from aiofl.outputs import atomic_write_text, check_file_replaceable
    from aiofl.text import MAX_UNIT_CHARS, check_text

    with bad_input_exits():
        if out.suffix.lower() != ".csv":
            raise ValueError(f"--out = {str(out)!r}; allowed: a .csv file")
        check_file_replaceable(out, force=force, option="--out")
        if c_array is not None:
            if c_array.suffix.lower() != ".h":
                raise ValueError(f"--c-array = {str(c_array)!r}; allowed: a .h file")
            if c_array.resolve() == out.resolve():
                raise ValueError("--c-array and --out name the same file")
            check_file_replaceable(c_array, force=force, option="--c-array")
        check_text("--unit", unit, max_chars=MAX_UNIT_CHARS)
        if kind == "prbs":
            for name, value in (("--f0", f0), ("--f1", f1)):
                if value is not None:
                    raise ValueError(f"{name} applies to --kind chirp; a PRBS takes --band")
            if band is None:
                raise ValueError("--band: missing; a PRBS needs the band it excites, 0..F Hz")
            signal = prbs(
                amplitude=amplitude, band=band, duration=duration, ts=ts, offset=offset, seed=seed
            )
        else:
            if band is not None and f1 is not None and band != f1:
                raise ValueError(f"--band = {band:g} and --f1 = {f1:g}: give one (the same)")
            end = f1 if f1 is not None else band
            if end is None:
                raise ValueError("--f1 (or --band): missing; a chirp needs its end frequency")
            signal = chirp(
                amplitude=amplitude,
                f1=end,
                f0=f0,
                duration=duration,
                ts=ts,
                offset=offset,
                method=method,
            )
        header = c_array_text(signal, c_name) if c_array is not None else None
    with bad_input_exits(run=True):
        atomic_write_text(out, csv_text(signal, unit=unit))
        if c_array is not None and header is not None:
            atomic_write_text(c_array, header)
    typer.echo(signal.describe())
    if signal.kind == "prbs":
        typer.echo(
            f"  clock period Tc = {signal.clock_period:g} s: excites 0..0.44/Tc = "
            f"{0.44 / signal.clock_period:.4g} Hz within 3 dB (asked: 0..{signal.band:g} Hz)"
        )
    written = [str(out)] + ([str(c_array)] if c_array is not None else [])
    typer.echo(f"wrote {', '.join(written)}")
