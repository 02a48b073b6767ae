"""``aiofl tune CONFIG --out DIR``: tune a controller from the config's ``[tune]`` table.

A thin command over :mod:`aiofl.tuning`: it validates the input (exit status 2 and one
message on bad input, :mod:`aiofl.cli.errors`), runs :func:`aiofl.tuning.search.tune` with
a progress bar, a checkpoint in ``DIR`` and optional Dask evaluation, then writes the
outputs (:func:`aiofl.tuning.results.write_outputs`: the results first, then the figures;
what was left out is printed as a note) and prints a summary.  numpy, pymoo
and the engine are imported inside the command, so registering it keeps ``aiofl --help``
fast.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from aiofl.cli.errors import _check_out, bad_input_exits

__all__ = ["tune_command"]


def tune_command(
    config: Annotated[str, typer.Argument(help="A TOML config (or preset) with a tune table.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output directory.")],
    resume: Annotated[
        bool, typer.Option("--resume", help="Continue from OUT/checkpoint.npz (same result).")
    ] = False,
    scheduler: Annotated[
        str | None,
        typer.Option(
            "--scheduler",
            help="Dask scheduler address tcp://HOST:PORT (exit 2 if unreachable within 5 s).",
        ),
    ] = None,
    dask_workers: Annotated[
        int | None,
        typer.Option("--dask-workers", help="Start a local Dask cluster with N workers."),
    ] = None,
    seed: Annotated[int | None, typer.Option("--seed", help="Override tune.seed.")] = None,
    generations: Annotated[
        int | None, typer.Option("--generations", help="Override tune.generations.")
    ] = None,
    population: Annotated[
        int | None, typer.Option("--population", help="Override tune.population.")
    ] = None,
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bar.")] = False,
    ts: Annotated[
        float | None,
        typer.Option(
            "--ts", help="Tune the controller sampled at Ts [s] (an integer multiple of dt)."
        ),
    ] = None,
) -> None:
    """Tune a controller with a GA (pymoo) on the OPI of eq. (22), per the config's tune table.

    Writes OUT/best.toml (runs with `aiofl simulate`), history.csv, evaluations.csv,
    convergence.png and summary.json (with algorithm = "nsga2" also the Pareto front,
    front.csv and front.png, best.toml being the design picked by `choose`);
    OUT/checkpoint.npz is updated after every generation so `--resume` continues a killed
    run with the same final result.  The results are written before the figures; a figure
    or marker that cannot be made is left out with a note.
    """
    from aiofl.tuning.checkpoint import CHECKPOINT, load_checkpoint
    from aiofl.tuning.results import write_outputs
    from aiofl.tuning.search import prepare, tune

    with bad_input_exits():
        if scheduler is not None and dask_workers is not None:
            raise ValueError("give --scheduler or --dask-workers, not both")
        if dask_workers is not None and dask_workers < 1:
            raise ValueError(f"--dask-workers = {dask_workers}; allowed: >= 1")
        _check_out(out)
        target = config
        if ts is not None:  # the sampled controller is tuned (and written to best.toml)
            from aiofl.config import load_config

            target = load_config(config).with_sample_time(ts)
        prep = prepare(target, None, seed=seed, generations=generations, population=population)
        if resume and (out / CHECKPOINT).exists():
            load_checkpoint(out / CHECKPOINT, prep.fingerprint)  # a damaged one: exit 2 now
        elif resume:
            typer.echo(f"aiofl: no checkpoint in {out}; starting from scratch", err=True)
    with bad_input_exits(run=True):
        try:
            result = tune(
                target,
                progress=not quiet,
                checkpoint_dir=out,
                resume=resume,
                scheduler=scheduler,
                n_workers=dask_workers,
                seed=seed,
                generations=generations,
                population=population,
            )
        except KeyboardInterrupt:
            typer.echo(
                f"aiofl: interrupted; the checkpoint in {out} keeps the finished generations "
                "(continue with --resume)",
                err=True,
            )
            raise typer.Exit(130) from None
        summary = write_outputs(result, out)
    full = summary["full_horizon"]
    if full is None:
        status = "not computed (see the note)"
    elif full["diverged"]:
        status = f"diverged at {full['diverged_at']:.3g} s"
    else:
        status = (
            f"ITAE {full['itae']:.4g}, ISU {full['isu']:.4g}, IAU {full['iau']:.4g}, "
            f"OPI {full['opi']:.4g}"
        )
    horizon = f"{full['t_final']:g} s" if full is not None else "its own horizon"
    for note in summary["notes"]:
        typer.echo(f"aiofl: note: {note}", err=True)
    typer.echo(
        f"best objective {result.best_objective:.6g} ({result.n_evaluations} evaluations, "
        f"{int(result.diverged.sum())} diverged, {result.evals_per_second:.1f} eval/s)\n"
        f"best config over {horizon}: {status}\n"
        f"wrote {out}/{', '.join(summary['files'])}"
    )
