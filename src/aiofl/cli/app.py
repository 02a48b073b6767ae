"""The ``aiofl`` command line (typer + rich).

Commands
--------
``aiofl presets``
    List the shipped presets.
``aiofl show NAME``
    Print a preset's TOML verbatim (copy it, edit it, pass the file to ``simulate``).
``aiofl simulate CONFIG.toml|PRESET --out DIR`` (or ``--check``: validate only)
    One run: ``DIR/metrics.json``, ``DIR/trajectory.csv`` (a header of column names, then a
    ``# name [unit],...`` line with the plant's units, then the data) and ``DIR/figure.png``
    (output vs reference, tracking error, control; axes in the plant's units).
``aiofl reproduce --out DIR``
    The paper's Tables I–III and Figures 3–5, and a self-contained HTML report.
``aiofl tune CONFIG --out DIR`` (or ``--check``)
    Tuning (GA, DE, CMA-ES, or NSGA-II for a Pareto front) from the config's ``[tune]``
    table (:mod:`aiofl.cli.tune_command`).
``aiofl analyze PLANT|CONFIG [--closed-loop]``
    Symbolic plant analysis or closed-loop linearisation (:mod:`aiofl.cli.analyze_command`).

Bad input (a malformed or invalid config, an unknown preset, a missing file) prints one
clear message to stderr and exits with status 2 (:mod:`aiofl.cli.bad_input`); nothing is
written to ``DIR``.  Heavy modules (numba, matplotlib) are imported inside the commands so
``aiofl --help`` is fast.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any, Literal

import typer
from typer.core import TyperCommand, TyperGroup

from aiofl.cli.bad_input import (
    FORCE_OPTION,
    RIG_OPTION,
    SENSOR_OPTION,
    _check_out,
    _out_or_check,
    bad_input_exits,
)

__all__ = ["EXAMPLES", "app", "main"]


def _flags_without_type(params: list[Any]) -> list[Any]:
    """Show on/off flags as ``--force``, not ``--force <bool>`` (typer's rich help prints a
    type for every option; an empty metavar leaves it out)."""
    for param in params:
        if getattr(param, "is_flag", False) and param.metavar is None:
            param.metavar = ""
    return params


def _reflow(text: str) -> str:
    """Help text with every paragraph on one line (a docstring's line breaks are not
    sentence breaks; the terminal wraps).  A paragraph starting with ``\\b`` (click's
    "keep my lines") is kept as it is."""
    import inspect

    paragraphs = inspect.cleandoc(text).split("\n\n")
    return "\n\n".join(
        p if p.startswith("\b") else " ".join(line.strip() for line in p.splitlines())
        for p in paragraphs
    )


def _shown_help(text: str) -> str:
    """What rich's help must be given to print ``text`` as written: reflowed, and with rich
    markup escaped, so ``[uncertainty]``, ``[s]`` or ``[controller.discrete]`` are printed
    instead of being taken as style tags and dropped."""
    from rich.markup import escape

    return escape(_reflow(text))


_HELP_ATTRS = ("help", "short_help", "epilog")


@contextmanager
def _help_as_written(command: Any, ctx: Any) -> Iterator[None]:
    """While ``command``'s help is printed by typer's rich formatter, give it (and its
    parameters, and a group's commands) help text that rich prints verbatim
    (:func:`_shown_help`); restored afterwards.  Plain click help (``TYPER_USE_RICH=0``)
    prints the text as it is and needs nothing."""
    import typer.core

    if not typer.core.HAS_RICH or getattr(command, "rich_markup_mode", None) != "rich":
        yield
        return
    objects = [command, *command.get_params(ctx)]
    if isinstance(command, TyperGroup):
        subs = (command.get_command(ctx, name) for name in command.list_commands(ctx))
        objects += [sub for sub in subs if sub is not None]
    saved = [
        (obj, key, getattr(obj, key))
        for obj in objects
        for key in _HELP_ATTRS
        if isinstance(getattr(obj, key, None), str)
    ]
    try:
        for obj, key, text in saved:
            setattr(obj, key, _shown_help(text))
        yield
    finally:
        for obj, key, text in saved:
            setattr(obj, key, text)


class _Command(TyperCommand):
    """Every ``aiofl`` command: flags shown without a type (see :func:`_flags_without_type`),
    help text printed as written (see :func:`_help_as_written`)."""

    def get_params(self, ctx: Any) -> list[Any]:
        return _flags_without_type(super().get_params(ctx))

    def format_help(self, ctx: Any, formatter: Any) -> None:
        with _help_as_written(self, ctx):
            super().format_help(ctx, formatter)


class _Group(TyperGroup):
    """The ``aiofl`` group: flags shown without a type (``--version``, ``-h/--help``), its
    commands' help printed as written."""

    def get_params(self, ctx: Any) -> list[Any]:
        return _flags_without_type(super().get_params(ctx))

    def format_help(self, ctx: Any, formatter: Any) -> None:
        with _help_as_written(self, ctx):
            super().format_help(ctx, formatter)


app = typer.Typer(
    name="aiofl",
    help="ESO-based active input-output feedback linearization (ADRC): simulate, "
    "reproduce the paper, tune, analyse.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    cls=_Group,
    context_settings={"help_option_names": ["-h", "--help"]},
)

EXAMPLES: dict[str, tuple[str, ...]] = {
    "presets": ("aiofl presets",),
    "show": ("aiofl show assisted-s1-ladrc > my-run.toml",),
    "simulate": (
        "aiofl simulate paper-s1-inleso --out runs/s1",
        "aiofl simulate my-run.toml -o runs/mine --dt 5e-5 --method euler --force",
    ),
    "reproduce": ("aiofl reproduce --out results", "aiofl reproduce -o quick --draws 0"),
    "tune": (
        "aiofl tune retuned-s1-ladrc --out tuned --generations 5 --population 16",
        "aiofl tune my-run.toml -o tuned --resume --dask-workers 2",
    ),
    "analyze": (
        "aiofl analyze slfjm --latex",
        "aiofl analyze retuned-s1-ladrc --closed-loop --json",
        "aiofl analyze retuned-s1-leso --sampling --out sampling",
    ),
    "export": (
        "aiofl export retuned-s1-leso --ts 1e-3 --out firmware",
        "aiofl export my-run.toml --ts 5e-4 --precision float -o firmware",
    ),
    "robustness": (
        "aiofl robustness my-run.toml --out robust",
        "aiofl robustness my-run.toml -o robust --draws 1000 --seed 1 --dask-workers 2",
    ),
    "trim": ("aiofl trim my-run.toml", "aiofl trim maglev.toml --y 0.01 --x0 0.01,0,0.7"),
    "design": (
        "aiofl design maglev.toml --y 0.01 --x0 0.01,0,0.7 -o first.toml",
        "aiofl design tank --y 1.0 --ts 0.01 --sensor encoder-12bit -o tank.toml",
    ),
    "report": ("aiofl report my-run.toml --out report", "aiofl report first.toml -o r --force"),
    "excite": (
        "aiofl excite --kind prbs --amplitude 0.5 --band 20 --duration 10 --ts 1e-3 -o u.csv",
        "aiofl excite --kind chirp --amplitude 1 --f0 0.5 --f1 50 --duration 20 --ts 1e-3 "
        "-o chirp.csv --c-array chirp.h --c-name u_chirp",
    ),
    "identify": (
        "aiofl identify log.csv -o id",
        "aiofl identify rig.csv --input volt --output angle --ts 1e-3 --plant arm.toml "
        "--free J,b --bounds J=1e-4:1e-2 --holdout 0.3 -o id --force",
    ),
}
"""Example invocations shown at the end of each command's ``--help``."""


def _print_version(value: bool) -> None:
    if value:
        from importlib.metadata import PackageNotFoundError, version

        try:
            v = version("aiofl")
        except PackageNotFoundError:  # pragma: no cover - running from a source tree
            from aiofl import __version__ as v
        typer.echo(f"aiofl {v}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option(
            "--version",
            "-V",
            callback=_print_version,
            is_eager=True,
            help="Print the version and exit.",
        ),
    ] = False,
) -> None:
    """ESO-based active input-output feedback linearization (ADRC)."""


def _stderr_console() -> Any:
    from rich.console import Console

    return Console(stderr=True)


# ---------------------------------------------------------------------------- presets
@app.command("presets")
def presets_command() -> None:
    """List the shipped presets by set: designs that hold on a rig, the paper's designs,
    and the ideal-world limits (name and description)."""
    import tomllib

    from rich.console import Console
    from rich.table import Table

    from aiofl.config import PRESET_SETS, preset_sets, preset_text

    console = Console()
    sets = preset_sets()
    for key, _, title in PRESET_SETS:
        if not sets[key]:
            continue
        table = Table(title=title, show_lines=False, title_justify="left")
        table.add_column("name", style="bold cyan", no_wrap=True)
        table.add_column("description")
        for name in sets[key]:
            try:
                desc = str(tomllib.loads(preset_text(name)).get("description", ""))
            except tomllib.TOMLDecodeError:
                desc = "(malformed TOML)"
            table.add_row(name, desc)
        console.print(table)


@app.command("show")
def show_command(
    name: Annotated[str, typer.Argument(help="Preset name, e.g. paper-s1-leso.")],
) -> None:
    """Print a preset's TOML verbatim, to copy and edit."""
    from aiofl.config import preset_text

    with bad_input_exits():
        text = preset_text(name)
    sys.stdout.write(text if text.endswith("\n") else text + "\n")


# --------------------------------------------------------------------------- simulate
def _trajectory_columns(result: Any, cfg: Any) -> list[str]:
    """Signals written to trajectory.csv: t, r, y, y_meas, u, d, the plant state, and the
    observer / differentiator states the controller actually uses."""
    c = cfg.controller
    n_td = 2 if c.td in ("han", "improved") else c.rho
    cols = ["t", "r", "y", "y_meas", "u", "d"]
    cols += [f"x{i}" for i in range(1, cfg.plant.n_states + 1)]
    cols += [f"xi_hat{i}" for i in range(1, c.rho + 2)]
    cols += [f"r{i}" for i in range(1, n_td + 1)]
    return [col for col in cols if col == "t" or col in result.signals]


def _column_labels(cfg: Any, columns: list[str]) -> list[str]:
    """Name and unit of every trajectory.csv column, from the plant's declared units.

    t [s]; r, y, y_meas in the output unit; u in the input unit; d in the disturbance unit;
    x_i as the plant's state name and unit; the ESO's ξ̂_i and the TD's r_i estimate
    y^(i−1) (ξ̂_(ρ+1) the total disturbance, in y^(ρ)'s unit), so their unit is
    [y]/s^(i−1).  A unit the plant does not declare is left out.
    """
    from aiofl.plants.base import derivative_unit, unit_label

    plant = cfg.plant
    fixed = {
        "t": "s",
        "r": plant.output_unit,
        "y": plant.output_unit,
        "y_meas": plant.output_unit,
        "u": plant.input_unit,
        "d": plant.disturbance_unit,
    }
    labels = []
    for col in columns:
        if col in fixed:
            labels.append(unit_label(col, fixed[col]))
        elif col.startswith("xi_hat") or (col[0] == "r" and col[1:].isdigit()):
            k = int(col[6:] if col.startswith("xi_hat") else col[1:]) - 1
            labels.append(unit_label(col, derivative_unit(plant.output_unit, k)))
        else:  # x1..xn
            labels.append(plant.state_label(int(col[1:]) - 1))
    from aiofl.text import one_line

    # one line, one cell each: a newline or CR is escaped, a comma is no separator
    return [one_line(lab).replace(",", ";") for lab in labels]


def _csv_text(result: Any, columns: list[str], labels: list[str] | None = None) -> str:
    """trajectory.csv: a header of column names, then (with ``labels``) a ``#`` line giving
    each column's name and unit (``# t [s],r [rad],...``), then the data.

    The units line is a comment, so ``numpy.loadtxt(path, delimiter=",", skiprows=1)`` and
    ``pandas.read_csv(path, comment="#")`` read the numbers unchanged.
    """
    import io

    import numpy as np

    data = np.column_stack([result.t if c == "t" else result.signals[c] for c in columns])
    header = ",".join(columns) + ("\n# " + ",".join(labels) if labels else "")
    buf = io.StringIO()
    np.savetxt(buf, data, delimiter=",", header=header, comments="", fmt="%.10g")
    return buf.getvalue()


def simulation_record(cfg: Any, result: Any, source_name: str) -> dict[str, Any]:
    """The metrics.json record of ``aiofl simulate`` (keys as in reproduce's records).

    ``scenario`` is the paper scenario number when a shipped preset was run whose name
    encodes it (``paper-s2-leso`` -> 2), and null for a config file (its scenario may have
    been edited); ``scenario_name`` is always the config's ``[scenario] name``.
    ``source`` is ``"config"``.  ``config`` is what was run, as given (the preset's name,
    or the file's path: a preset copied to ``my.toml`` and edited is ``"my.toml"``, not the
    preset), ``name`` the config's own ``name``.

    Parameters
    ----------
    cfg
        The run config.
    result
        Its simulation result.
    source_name
        The config as given (a preset's name or a path).

    Returns
    -------
    dict
    """
    from aiofl.config import list_presets
    from aiofl.reporting.cases import computed_record, scenario_number

    number = scenario_number(source_name) if source_name in list_presets() else None
    rec = computed_record(
        result,
        scenario=number,
        structure=cfg.controller.structure,
        source="config",
        opi=result.opi(cfg.weights),
        extra=True,
    )
    rec["scenario_name"] = cfg.scenario.name
    rec["config"] = source_name
    rec["name"] = cfg.name
    rec["sample_time"] = cfg.sampling.ts if cfg.sampling is not None else None
    rec["sensor"] = cfg.sensor.describe()
    return rec


def _run_label(config: str, name: str) -> str:
    """A run's name in its figure: the config's ``name``, with the file it came from when
    that is named otherwise (a copied preset: ``"paper-s1-leso (my.toml)"``)."""
    from aiofl.config import list_presets

    if config in list_presets() or Path(config).stem == name:
        return name
    return f"{name} ({config})"


@app.command("simulate")
def simulate_command(
    config: Annotated[str, typer.Argument(help="A TOML config file or a preset name.")],
    out: Annotated[
        Path | None,
        typer.Option("--out", "-o", help="Output directory (required unless --check)."),
    ] = None,
    dt: Annotated[
        float | None, typer.Option(help="Override the fixed step [s] (0 < dt <= 0.1).")
    ] = None,
    method: Annotated[
        Literal["rk4", "euler"] | None, typer.Option(help="Override the integrator.")
    ] = None,
    t_final: Annotated[
        float | None,
        typer.Option("--t-final", help="Override the horizon [s] (0 < t_final <= 1e4)."),
    ] = None,
    force: Annotated[bool, FORCE_OPTION] = False,
    check: Annotated[
        bool,
        typer.Option(
            "--check", help="Only validate CONFIG (and OUT if given); run and write nothing."
        ),
    ] = False,
    ts: Annotated[
        float | None,
        typer.Option(
            "--ts",
            help="Run the controller sampled at Ts [s] (an integer multiple of dt; the "
            "other [controller.discrete] settings are kept).",
        ),
    ] = None,
    sensor: Annotated[str | None, SENSOR_OPTION] = None,
    rig: Annotated[str | None, RIG_OPTION] = None,
) -> None:
    """Simulate one config: metrics.json, trajectory.csv and figure.png in OUT.

    A run whose plant leaves its envelope is reported as lost, one whose numbers blow up
    as diverged, each with the time (metrics null); neither is an error.  An existing
    non-empty OUT is refused unless --force (then it is replaced as a whole).  --dt,
    --t-final and --method pass the same checks as the config's values.  With --ts (or a
    [controller.discrete] table) the controller runs sampled.  --check only validates
    CONFIG, the overrides and OUT (if given) and prints what would run.
    """
    import json

    from aiofl.cli.configs import load_run_config
    from aiofl.config import ConfigError
    from aiofl.outputs import atomic_output_dir, atomic_write_bytes, atomic_write_text

    console = _stderr_console()
    with bad_input_exits():
        out = _out_or_check(out, check)
        if out is not None:
            _check_out(out, force=force)
        cfg = load_run_config(config)
        if method is not None and method not in ("rk4", "euler"):
            raise ConfigError(f"--method = {method!r}; allowed: rk4, euler")
        given = {"--dt": dt, "--t-final": t_final, "--method": method}
        if any(v is not None for v in given.values()):
            flags = " ".join(f"{k} {v}" for k, v in given.items() if v is not None)
            cfg = cfg.with_overrides(
                t_final=t_final, dt=dt, method=method, source=f"{config} with {flags}"
            )
        cfg = cfg.with_sensor(sensor, source=f"{config} with --sensor {sensor}") if sensor else cfg
        if rig:
            from aiofl.analysis.rig_check import rig_config

            cfg = rig_config(cfg, rig)
        cfg = cfg.with_sample_time(ts) if ts is not None else cfg
        cfg.check_sampling()  # Ts must stay a multiple of an overridden dt
    if check or out is None:
        from aiofl.text import terminal_text

        steps = round(cfg.scenario.t_final / cfg.dt)
        typer.echo(
            f"{terminal_text(config)}: valid; {steps} {cfg.method} steps of {cfg.dt:g} s over "
            f"{cfg.scenario.t_final:g} s, plant {terminal_text(cfg.plant.name)}, "
            f"{cfg.controller.structure} controller, sensor {cfg.sensor.describe()}; "
            "nothing run or written"
        )
        for line in cfg.defaults:  # documented defaults the config relies on
            typer.echo(f"  default: {line}")
        return
    with bad_input_exits(run=True), atomic_output_dir(out) as stage:
        from aiofl.text import terminal_text

        # the name is user text: a "[/]" in it is no rich markup (aiofl.text)
        label = terminal_text(cfg.name, markup=True)
        with console.status(f"simulating {label} (first run compiles the kernel)"):
            result = cfg.simulate(store=True)
        record = simulation_record(cfg, result, config)
        atomic_write_text(stage / "metrics.json", json.dumps(record, indent=2) + "\n")
        columns = _trajectory_columns(result, cfg)
        atomic_write_text(
            stage / "trajectory.csv", _csv_text(result, columns, _column_labels(cfg, columns))
        )
        from aiofl.reporting.figures import config_figure, figure_png

        title = (
            f"{_run_label(config, cfg.name)}: output vs reference, tracking error and "
            "control signal"
        )
        fig = config_figure(cfg, result, title)
        atomic_write_bytes(stage / "figure.png", figure_png(fig))
    _print_records([record], title=f"aiofl simulate {config}")
    from aiofl.reporting.verdict import command_text, step_text, verdict_text

    typer.echo(f"verdict: {verdict_text(cfg, result)}")
    for line in (
        step_text(result, cfg.plant.output_unit),
        command_text(result, cfg.scenario.t_final, cfg.plant.input_unit),
    ):
        if line:
            typer.echo(line)
    typer.echo(f"sensor: {cfg.sensor.describe()}")
    typer.echo(f"wrote {out}/metrics.json, trajectory.csv, figure.png")
    note = units_note(cfg.plant)
    if note:
        typer.echo(f"aiofl: note: {note}", err=True)


def units_note(plant: Any) -> str | None:
    """Why figure.png and trajectory.csv carry no units, if the plant declares none of
    ``output_unit``/``input_unit``; None when it declares them."""
    missing = [k for k in ("output_unit", "input_unit") if not getattr(plant, k)]
    if not missing:
        return None
    return (
        f"plant {plant.name!r} declares no {' or '.join(missing)}, so figure.png and "
        'trajectory.csv leave those signals without units; add e.g. output_unit = "rad" '
        'and input_unit = "N·m" to its plant file (Python: Plant(..., output_unit=...))'
    )


# -------------------------------------------------------------------------- reproduce
def _short(x: float | None) -> str:
    """4 significant digits, compact exponent (1.205e5), dash for None."""
    from aiofl.reporting.tables import fmt

    return fmt(x, 4).replace("e+0", "e").replace("e-0", "e-").replace("e+", "e")


def _print_records(records: list[dict[str, Any]], title: str) -> None:
    from rich import box
    from rich.console import Console
    from rich.table import Table

    table = Table(title=title, box=box.SIMPLE_HEAD, padding=(0, 1), collapse_padding=True)
    for col in ("#", "structure", "source", "ITAE", "ISU", "IAU", "OPI", "status"):
        table.add_column(col, justify="right" if col.isupper() else "left", no_wrap=True)
    for r in records:
        status = f"[red]{r['status']} {r['stopped_at']:.2f} s[/red]" if r["failed"] else "ok"
        table.add_row(
            str(r["scenario"]) if r["scenario"] is not None else "—",
            str(r["structure"]),
            str(r["source"]),
            *(_short(r[k]) for k in ("itae", "isu", "iau", "opi")),
            status,
        )
    console = Console()
    # not a terminal (a pipe, a log): wide enough that no column is cut
    Console(width=max(console.width, 110)).print(table)


@app.command("reproduce")
def reproduce_command(
    out: Annotated[Path, typer.Option("--out", "-o", help="Output directory.")] = Path("results"),
    ts: Annotated[
        float | None,
        typer.Option("--ts", help="Run every design sampled at Ts [s] (a multiple of dt)."),
    ] = None,
    draws: Annotated[
        int,
        typer.Option(
            "--draws",
            min=0,
            max=100_000,
            help="Draws of ±20 % model error (J_l, K_s, R_m, J_h; seed 0) per design for "
            "the robustness rows; 0 skips them.",
        ),
    ] = 100,
    force: Annotated[bool, FORCE_OPTION] = False,
) -> None:
    """Reproduce the paper: Tables I–III, Figures 3–5 and report.html in OUT.

    Runs the six paper cases (3 scenarios × LESO/INLESO, printed parameters) and any
    shipped retuned-s*-* / frontier-s*-* / iofl-s* presets, batched; runs every design over
    the same --draws model-error draws (one batched call per scenario) and reads the
    shipped Pareto fronts.  Writes metrics.json, sampling.json, tables.md, fig3.png,
    fig4.png, fig5.png, fronts-s1.png / fronts-s3.png (when fronts are shipped),
    noise-front-s3.png (when scenario 3's noise fronts are shipped) and report.html.
    An existing non-empty OUT is refused unless --force (then it is replaced as a whole;
    `make run` passes it).
    """
    import time

    from aiofl.cli.stage_progress import StageProgress
    from aiofl.reporting.reproduce import reproduce

    t0 = time.perf_counter()
    with bad_input_exits():
        _check_out(out, force=force)
    # a spinner on a terminal; one line per stage (with elapsed seconds) in a log
    with bad_input_exits(run=True), StageProgress(_stderr_console()) as progress:
        rep = reproduce(out, on_stage=progress.stage, ts=ts, draws=draws)
        progress.done()
    _print_records(rep.records, title="aiofl reproduce: paper vs computed")
    fronts = "".join(f"fronts-s{s}.png, " for s in sorted({k[0] for k in rep.fronts.fronts}))
    fronts += "noise-front-s3.png, " if rep.noise_fronts.fronts else ""
    typer.echo(
        f"wrote {out}/metrics.json, sampling.json, tables.md, fig3.png, fig4.png, fig5.png, "
        f"{fronts}report.html in {time.perf_counter() - t0:.1f} s"
    )


def main() -> None:
    """Entry point of the ``aiofl`` console script (BLAS limited to one thread:
    :mod:`aiofl.blas_threads`)."""
    from aiofl.blas_threads import one_blas_thread
    from aiofl.cache import plain_cache_warnings

    one_blas_thread()
    plain_cache_warnings()
    app()


def register_feature(name: str, target: str) -> None:
    """Add feature command ``name`` from ``"module:function"`` (one line per feature below).

    The module is imported now, so it must keep its heavy imports inside the function.
    Every feature module ships with aiofl: an import error is a bug and propagates.
    """
    from importlib import import_module

    module, func = target.split(":")
    app.command(name)(getattr(import_module(module), func))


# --- feature commands ---
register_feature("tune", "aiofl.cli.tune_command:tune_command")
register_feature("analyze", "aiofl.cli.analyze_command:analyze_command")
register_feature("export", "aiofl.cli.export_command:export_command")
register_feature("robustness", "aiofl.cli.robustness_command:robustness_command")
register_feature("trim", "aiofl.cli.trim_command:trim_command")
register_feature("design", "aiofl.cli.design_command:design_command")
register_feature("report", "aiofl.cli.report_command:report_command")
register_feature("excite", "aiofl.cli.excite_command:excite_command")
register_feature("identify", "aiofl.cli.identify_command:identify_command")


def _finish_commands() -> None:
    """Give every registered command the flag display of :class:`_Command` and its
    :data:`EXAMPLES` as the help's epilog (run once, after the last command is added)."""
    for info in app.registered_commands:
        if info.cls in (None, TyperCommand):
            info.cls = _Command
        examples = EXAMPLES.get(info.name or "")
        if examples and info.epilog is None:
            info.epilog = "Examples:\n\n" + "\n\n".join(f"  $ {e}" for e in examples)


_finish_commands()
