"""Bad input on the command line: one clear message on stderr and exit status 2.

Every ``aiofl`` command wraps the validation of its input in :func:`bad_input_exits` (and
the work itself in ``bad_input_exits(run=True)``), so a malformed or invalid config, an
unknown preset or a missing file prints ``aiofl: error: ...`` and exits with
:data:`EXIT_BAD_INPUT`, without a traceback and before anything is written.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import typer

__all__ = ["EXIT_BAD_INPUT", "FORCE_OPTION", "SENSOR_OPTION", "bad_input_exits", "parse_numbers"]

EXIT_BAD_INPUT = 2


def _input_errors(run: bool) -> tuple[type[BaseException], ...]:
    import tomllib

    from aiofl.config import ConfigError
    from aiofl.plants.base import PlantError

    if run:  # a user plant that fails to compile or raises at run time is bad input too
        return (ConfigError, PlantError, OSError)
    return (ConfigError, PlantError, ValueError, OSError, tomllib.TOMLDecodeError)


def _check_out(out: Path, *, force: bool) -> None:
    """Reject an ``--out`` that the command could not replace, before any work.

    The one rule of every command that writes a folder (:mod:`aiofl.outputs`): a file, a
    non-empty directory aiofl did not write, without ``force`` (the command's
    :data:`FORCE_OPTION`) any non-empty directory, and a folder that cannot be created are
    refused (:func:`aiofl.outputs.check_replaceable`).  The staging and trash folders that killed
    runs left next to ``out`` are removed now (:func:`aiofl.outputs.remove_stale`), so a
    run that then fails still cleans up.
    """
    from aiofl.outputs import check_replaceable, remove_stale

    check_replaceable(out, force=force)
    remove_stale(out)  # staging / trash folders of killed runs, before the work


def _out_or_check(out: Path | None, check: bool) -> Path | None:
    """``--out``, which only ``--check`` (validate, run and write nothing) may leave out;
    raises ``ValueError`` naming ``--out`` when it is missing otherwise."""
    if out is None and not check:
        raise ValueError(
            "--out / -o: missing; give the output directory (or --check to only validate)"
        )
    return out


def parse_numbers(option: str, text: str | None) -> list[float] | None:
    """A comma-separated list of finite numbers (``--x0 0.01,0,0.7``), or None when the
    option is not given; raises ``ValueError`` naming ``option``."""
    import math

    if text is None:
        return None
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise ValueError(f"{option} = {text!r}; allowed: comma-separated numbers") from None
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"{option} = {text!r}; allowed: finite numbers")
    return values


@contextmanager
def bad_input_exits(*, run: bool = False) -> Iterator[None]:
    """Turn bad-input exceptions into one message on stderr and exit status 2.

    Wrap the validation of a command's input with it.  Around the work itself use
    ``run=True``: then only a :class:`~aiofl.config.ConfigError` (e.g. a checkpoint from
    another run), a :class:`~aiofl.plants.base.PlantError` (a user plant function that does
    not compile, or raises at run time) or an ``OSError`` (an unwritable ``--out``) is bad
    input; any other exception is a bug and propagates with its traceback.
    """
    try:
        yield
    except _input_errors(run) as exc:
        from aiofl.text import terminal_text

        # a message may quote user text (a TOML key, a path): escaped for the terminal
        msg = terminal_text(str(exc).strip() or type(exc).__name__, lines=True)
        typer.echo(f"aiofl: error: {msg}", err=True)
        raise typer.Exit(EXIT_BAD_INPUT) from None


SENSOR_OPTION = typer.Option(
    "--sensor",
    help="Measure with this sensor preset (ideal, encoder-12bit, encoder-14bit, "
    "encoder-16bit): sets the config's [sensor] preset (its noise keys kept).",
)
"""The ``--sensor PRESET`` option of simulate, robustness and tune."""

RIG_OPTION = typer.Option(
    "--rig",
    help="Put the design on this rig preset (ideal, servo-1khz: 12-bit encoder at 1 ms, "
    "1 ms measurement delay and actuator lag, 1 % Coulomb friction): replaces the config's "
    "[rig] and [sensor]; friction acts on the shipped plants' velocity state; the rig's lag "
    "and friction join the [uncertainty] draws (x U[0.5, 1.5]).  The controller is told the "
    "delay only if its [controller.eso] delay says so.",
)
"""The ``--rig PRESET`` option of simulate, robustness and tune
(:func:`aiofl.analysis.rig_check.rig_config`)."""

FORCE_OPTION = typer.Option(
    "--force",
    help="Replace an existing non-empty OUT (a folder aiofl wrote, as a whole); without it "
    "an existing non-empty OUT is refused.",
)
"""The ``--force`` option of every command that writes (one rule: :mod:`aiofl.outputs`)."""
