"""``aiofl tune CONFIG --out DIR``: tune a controller from the config's ``[tune]`` table.

A thin command over :mod:`aiofl.tuning`: it validates the input (exit status 2 and one
message on bad input, :mod:`aiofl.cli.bad_input`), prepares the run once
(:func:`aiofl.tuning.prepared.prepare`) and runs it with :func:`aiofl.tuning.search.tune` with
a progress bar, a checkpoint in ``DIR`` and optional Dask evaluation, then writes the
outputs (:func:`aiofl.tuning.results.write_outputs`: the results first, then the figures;
what was left out is printed as a note) and prints a summary.  numpy, pymoo
and the engine are imported inside the command, so registering it keeps ``aiofl --help``
fast.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from aiofl.cli.bad_input import (
    FORCE_OPTION,
    RIG_OPTION,
    SENSOR_OPTION,
    _check_out,
    _out_or_check,
    bad_input_exits,
)

__all__ = ["tune_command"]


def tune_command(
    config: Annotated[
        str, typer.Argument(help="A TOML config file (or preset) with a [tune] table.")
    ],
    out: Annotated[
        Path | None,
        typer.Option("--out", "-o", help="Output directory (required unless --check)."),
    ] = None,
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
    check: Annotated[
        bool,
        typer.Option(
            "--check",
            help="Only validate CONFIG, its [tune] table, the overrides and OUT (if given) "
            "and print the search; run and write nothing.",
        ),
    ] = False,
    ts: Annotated[
        float | None,
        typer.Option(
            "--ts", help="Tune the controller sampled at Ts [s] (an integer multiple of dt)."
        ),
    ] = None,
    sensor: Annotated[str | None, SENSOR_OPTION] = None,
    rig: Annotated[str | None, RIG_OPTION] = None,
    omega0_ceiling: Annotated[
        bool,
        typer.Option(
            "--omega0-ceiling",
            help="Clip eso.omega0's upper search bound to the rig's observer bandwidth "
            "ceiling (sample time, loop delay, sensor noise; as tune.omega0_ceiling = true).",
        ),
    ] = False,
    force: Annotated[bool, FORCE_OPTION] = False,
) -> None:
    """Tune a controller's parameters per the config's [tune] table (pymoo: GA, DE, CMA-ES
    or NSGA-II).

    The [tune] table names the parameters and their bounds, the algorithm (ga, de, cmaes:
    one objective, by default the OPI of eq. (22); nsga2: a Pareto front over 2-3
    objectives under constraints), the budget and the horizon.  Writes OUT/best.toml (runs
    with `aiofl simulate`), history.csv, evaluations.csv, convergence.png and summary.json
    (with algorithm = "nsga2" also the Pareto front, front.csv and front.png, best.toml
    being the design picked by `choose`);
    OUT/checkpoint.npz is updated after every generation so `--resume` continues a killed
    run with the same final result.  The results are written before the figures; a figure
    or marker that cannot be made is left out with a note.  --check only validates and
    prints the search it would run.  An existing non-empty OUT is refused unless --force
    (then it is replaced as a whole) or --resume continues the checkpoint it holds.
    """
    from aiofl.tuning.checkpoint import CHECKPOINT, discard_new_checkpoint, load_checkpoint
    from aiofl.tuning.front import NoFeasibleDesign
    from aiofl.tuning.prepared import prepare
    from aiofl.tuning.results import write_outputs
    from aiofl.tuning.search import tune

    with bad_input_exits():
        if scheduler is not None and dask_workers is not None:
            raise ValueError("give --scheduler or --dask-workers, not both")
        if dask_workers is not None and dask_workers < 1:
            raise ValueError(f"--dask-workers = {dask_workers}; allowed: >= 1")
        out = _out_or_check(out, check)
        if resume and out is None:
            raise ValueError("--resume needs --out (the folder holding checkpoint.npz)")
        if out is not None:  # --resume continues the run whose checkpoint OUT holds
            _check_out(out, force=force or (resume and (out / CHECKPOINT).is_file()))
        target: Any = config
        if sensor or rig or ts is not None:  # the sampled controller is tuned (and written)
            from aiofl.config import load_config

            target = load_config(config)
            if sensor:
                target = target.with_sensor(sensor, source=f"{config} with --sensor {sensor}")
            if rig:
                from aiofl.analysis.rig_check import rig_config

                target = rig_config(target, rig)
            if ts is not None:
                target = target.with_sample_time(ts)
        ceiling = True if omega0_ceiling else None  # None: the [tune] table's setting
        prep = prepare(
            target,
            None,
            seed=seed,
            generations=generations,
            population=population,
            omega0_ceiling=ceiling,
        )
        if resume and out is not None and (out / CHECKPOINT).exists():
            load_checkpoint(out / CHECKPOINT, prep.fingerprint)  # a damaged one: exit 2 now
        elif resume:
            typer.echo(f"aiofl: no checkpoint in {out}; starting from scratch", err=True)
    if check or out is None:
        typer.echo(f"{config}: valid; {check_text(prep)}; nothing run or written")
        for note in prep.notes:  # what preparing changed (the omega0 ceiling)
            typer.echo(f"aiofl: note: {note}")
        return
    found = (out.exists(), (out / CHECKPOINT).exists())  # what this run leaves is its own
    with bad_input_exits(run=True):
        try:
            result = tune(  # the run prepared (and checked) above
                prep,
                progress=not quiet,
                checkpoint_dir=out,
                resume=resume,
                scheduler=scheduler,
                n_workers=dask_workers,
            )
        except KeyboardInterrupt:
            typer.echo(
                f"aiofl: interrupted; the checkpoint in {out} keeps the finished generations "
                "(continue with --resume)",
                err=True,
            )
            raise typer.Exit(130) from None
        except NoFeasibleDesign:  # a finished run without a result: nothing to resume
            discard_new_checkpoint(out, found)
            raise
        summary = write_outputs(result, out)
    for note in summary["notes"]:
        typer.echo(f"aiofl: note: {note}", err=True)
    for warning in summary.get("warnings", []):
        typer.echo(f"aiofl: warning: {warning}", err=True)
    typer.echo(summary_text(result, summary, out))
    for note in prep.notes:  # the search bounds it ran with (the omega0 ceiling)
        typer.echo(f"search: {note}")


def check_text(prep: Any) -> str:
    """What ``aiofl tune --check`` prints after "CONFIG: valid;": the search that would run
    (algorithm, budget, simulations, objective(s), parameters, horizon and step)."""
    st = prep.settings
    candidates = st.population * st.generations
    sims = candidates * (1 + len(prep.spec.draws))
    sims *= st.noise_realisations
    if st.objectives:
        goal = f"objectives {', '.join(st.objectives)}"
        goal += f" under {', '.join(st.constraints)}" if st.constraints else ""
        goal += f", chosen by {st.choose}"
    else:
        obj = st.objective
        if not isinstance(obj, str):  # a weighted sum, e.g. itae + 0.1·isu
            obj = " + ".join(("" if w == 1 else f"{w:g}·") + k for k, w in obj.items())
        goal = f"objective {obj}"
    if st.robust is not None:
        goal += f", robust ({st.robust.aggregate} over nominal + {st.robust.draws} draws)"
    if st.noise_realisations > 1:
        goal += f", mean over {st.noise_realisations} noise realisations"
    given = isinstance(prep.config.raw.get("tune"), dict) and "t_final" in prep.config.raw["tune"]
    horizon = "tune.t_final" if given else "the scenario's horizon"
    return (
        f"{st.budget()}: up to {candidates} candidates ({sims} simulations of "
        f"{st.t_final:g} s ({horizon}) at dt = {prep.spec.dt:g}, {prep.spec.method}); {goal}; "
        f"parameters {', '.join(prep.space.names)}"
    )


def summary_text(result: Any, summary: dict[str, Any], out: Path) -> str:
    """The lines ``aiofl tune`` prints at the end (:class:`aiofl.tuning.search.TuneResult`
    and the summary of :func:`aiofl.tuning.results.write_outputs`).

    The numbers are the progress bar's: its "best" is the best objective (with NSGA-II
    its "lowest <first objective>", printed here next to the chosen design's objectives),
    its eval/s the whole run's :attr:`~aiofl.tuning.search.TuneResult.evals_per_second`.

    Parameters
    ----------
    result
        The run's :class:`~aiofl.tuning.search.TuneResult`.
    summary
        What :func:`aiofl.tuning.results.write_outputs` returned.
    out
        The output folder.

    Returns
    -------
    str
    """
    import math

    rate = result.evals_per_second
    speed = f"{rate:.1f} eval/s" if math.isfinite(rate) else "all replayed from the checkpoint"
    failed = int(result.failed.sum())
    counts = f"({result.n_evaluations} evaluations, {failed} lost or diverged, {speed})"
    front = result.front
    if front is None:
        head = f"best objective {result.best_objective:.6g} {counts}"
    else:
        chosen = ", ".join(
            f"{q} {v:.6g}" for q, v in zip(front.objectives, front.F[front.chosen], strict=True)
        )
        first = front.objectives[0]
        best_first = (  # a margin (pm, gm, dm) objective is maximised
            ("highest", float(front.F[:, 0].max()))
            if first.split(":")[0] in ("pm", "gm", "dm")
            else ("lowest", float(front.F[:, 0].min()))
        )
        head = (
            f"chosen design ({front.rule}, from a {front.F.shape[0]}-design Pareto front): "
            f"{chosen}; {best_first[0]} {first} on the front {best_first[1]:.6g} {counts}"
        )
    full = summary["full_horizon"]
    if full is None:
        status = "not computed (see the note)"
    elif full["failed"]:
        status = f"{full.get('status', 'failed')} at {full['stopped_at']:.3g} s"
    else:
        status = (
            f"ITAE {full['itae']:.4g}, ISU {full['isu']:.4g}, IAU {full['iau']:.4g}, "
            f"OPI {full['opi']:.4g}"
        )
    horizon = f"{full['t_final']:g} s" if full is not None else "its own horizon"
    which = "best" if front is None else "chosen"
    files = ", ".join(summary["files"])
    return f"{head}\n{which} config over {horizon}: {status}\nwrote {out}/{files}"
