"""``aiofl identify LOG -o OUT``: from a rig's log to what a design needs.

Reads and checks the log (:func:`aiofl.identification.log.read_log`: every refusal names the
column and the row, exits 2 and writes nothing), then

* always the model-free route: the chain order ρ, b0 and the input delay with their
  standard errors and the candidates' scores
  (:func:`aiofl.identification.chain.identify_chain`), the ESO run offline over the log with
  them (:func:`aiofl.identification.offline_eso.offline_eso`) and a first LADRC design
  (:func:`aiofl.identification.first_config.first_config`);
* with ``--plant P --free a,b`` the grey-box route: the free parameters of the plant fitted to
  the log (:func:`aiofl.identification.grey_box.fit_plant`), on the log's first part and
  checked on a held-out part (``--holdout``) or a second log (``--validation``).

OUT (replaced as a whole, :mod:`aiofl.outputs`) holds ``identification.json``
(:mod:`aiofl.identification.records`), ``first.toml`` (the starting design: a run config),
``eso.png`` and ``candidates.png``; with a grey-box fit also ``fitted_plant.toml`` (a plant
file with the fitted values, for a plant given as a file), ``uncertainty.toml`` (the
``[uncertainty]`` table from the estimates ± k·σ) and ``fit.png``, and ``design.toml``: the
starting design on the fitted plant (the plant file, or a library plant with the fitted
values as ``[scenario] plant_overrides``) with that ``[uncertainty]`` table and, when the
starting design has none, a ``[tune]`` table (a robust GA over ω0 and ω_c from a tenth to
twice the starting values, CVaR_0.9 of ITAE + 0.1 ISU over 16 draws), ready for
``aiofl tune`` and ``aiofl robustness``; it is written only when it loads as a run config
with its ``[tune]`` table (else the summary says why not).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any

import typer

from aiofl.cli.bad_input import FORCE_OPTION, _check_out, bad_input_exits

__all__ = ["identify_command", "parse_bounds", "parse_free"]

#: largest held-out fraction of the log (the estimators keep at least half of it)
MAX_HOLDOUT = 0.5


def parse_free(text: str, names: tuple[str, ...]) -> list[str]:
    """``--free a,b,c``: distinct parameter names of the plant; raises ``ValueError``."""
    from aiofl.text import normal_name

    free = [normal_name(v.strip()) for v in text.split(",") if v.strip()]
    if not free:
        raise ValueError(
            f"--free = {text!r}; allowed: parameter names, commas ({', '.join(names)})"
        )
    unknown = [v for v in free if v not in names]
    if unknown:
        raise ValueError(
            f"--free: unknown parameter(s) {', '.join(unknown)}; the plant's parameters: "
            f"{', '.join(names)}"
        )
    twice = sorted({v for v in free if free.count(v) > 1})
    if twice:
        raise ValueError(f"--free names {', '.join(twice)} more than once")
    return free


def parse_bounds(items: list[str], free: list[str]) -> dict[str, tuple[float, float] | None]:
    """``--bounds a=lo:hi`` (repeatable) for free parameters; the others None (the fit's
    default range).  Raises ``ValueError`` naming the item."""
    from aiofl.text import normal_name

    bounds: dict[str, tuple[float, float] | None] = dict.fromkeys(free)
    for item in items:
        name, sep, rng = item.partition("=")
        name = normal_name(name.strip())
        lo_text, sep2, hi_text = rng.partition(":")
        if not sep or not sep2:
            raise ValueError(f"--bounds {item!r}; allowed: NAME=LOW:HIGH (e.g. J=1e-4:1e-2)")
        if name not in free:
            raise ValueError(f"--bounds {item!r}: {name!r} is not in --free ({', '.join(free)})")
        try:
            lo, hi = float(lo_text), float(hi_text)
        except ValueError:
            raise ValueError(f"--bounds {item!r}; allowed: NAME=LOW:HIGH with numbers") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ValueError(f"--bounds {item!r}; allowed: finite LOW < HIGH")
        if bounds[name] is not None:
            raise ValueError(f"--bounds gives {name!r} twice")
        bounds[name] = (lo, hi)
    return bounds


def _omega0(first_text: str) -> float:
    """The observer bandwidth of the starting design (``[controller.eso] omega0``)."""
    import tomllib

    return float(tomllib.loads(first_text)["controller"]["eso"]["omega0"])


def _design_text(first_text: str, plant_ref: str, overrides: dict[str, float], table: Any) -> str:
    """The starting design on the fitted plant, with the ``[uncertainty]`` table."""
    import tomlkit

    doc = tomlkit.parse(first_text)
    doc["plant"] = plant_ref
    if overrides:  # the true plant of the runs: the library plant with the fitted values
        scenario = doc.setdefault("scenario", tomlkit.table())
        scenario["plant_overrides"] = overrides
    doc["uncertainty"] = table
    head = (
        "# The starting design on the fitted plant, with the [uncertainty] box of the fit\n"
        "# (estimates +- k sigma): aiofl tune (robust scoring) and aiofl robustness run on it.\n"
    )
    controller = doc.get("controller", {})
    bands = {
        "eso.omega0": controller.get("eso", {}).get("omega0"),
        "sef.omega_c": controller.get("sef", {}).get("omega_c"),
    }
    if "tune" not in doc and all(isinstance(v, (int, float)) for v in bands.values()):
        # a robust search around the starting design (docs/guide/tuning.md, robust tuning)
        doc["tune"] = {
            "algorithm": "ga",
            "objective": {"itae": 1.0, "isu": 0.1},
            "robust": {"draws": 16, "aggregate": "cvar", "alpha": 0.9},
            "population": 24,
            "generations": 15,
            "seed": 0,
            "parameters": {
                name: {"lo": float(v) / 10, "hi": 2 * float(v), "log": True}
                for name, v in bands.items()
            },
        }
        head += (
            "# [tune]: a robust GA over omega0 and omega_c from a tenth to twice the starting\n"
            "# design's, scored by CVaR_0.9 of ITAE + 0.1 ISU over 16 draws of [uncertainty].\n"
        )
    return head + tomlkit.dumps(doc)


def identify_command(
    log: Annotated[Path, typer.Argument(help="The log: a CSV (header row of names) or .npz.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output directory.")],
    time: Annotated[
        str, typer.Option("--time", help="The time column (empty: none, then --ts).")
    ] = "t",
    input_: Annotated[str, typer.Option("--input", help="The input column.")] = "u",
    output: Annotated[str, typer.Option("--output", help="The output column.")] = "y",
    reference: Annotated[
        str | None,
        typer.Option("--reference", help="The reference column (a closed-loop log)."),
    ] = None,
    ts: Annotated[
        float | None,
        typer.Option("--ts", help="The rig's sample time [s] (time stamps may jitter by 10 %)."),
    ] = None,
    rho_max: Annotated[
        int, typer.Option("--rho-max", min=1, max=4, help="Highest chain order tried.")
    ] = 4,
    rho: Annotated[
        int | None, typer.Option("--rho", min=1, max=4, help="Fix the chain order.")
    ] = None,
    plant: Annotated[
        str | None,
        typer.Option("--plant", help="Fit this plant (a plant file .toml or a library name)."),
    ] = None,
    free: Annotated[
        str | None, typer.Option("--free", help="The plant parameters to fit: a,b,c.")
    ] = None,
    bounds: Annotated[
        list[str] | None,
        typer.Option("--bounds", help="A free parameter's range NAME=LOW:HIGH (repeatable)."),
    ] = None,
    delay: Annotated[
        str,
        typer.Option(
            "--delay", help="The grey-box model's input delay [s], or auto (the chain's)."
        ),
    ] = "0",
    closed_loop: Annotated[
        str | None,
        typer.Option(
            "--closed-loop",
            help="The run config whose controller closed the loop (grey-box; --reference).",
        ),
    ] = None,
    validation: Annotated[
        Path | None,
        typer.Option("--validation", help="A second log the grey-box fit is checked on."),
    ] = None,
    holdout: Annotated[
        float | None,
        typer.Option("--holdout", help="Check the grey-box fit on the log's last FRACTION."),
    ] = None,
    k: Annotated[
        float, typer.Option("--k", help="The uncertainty box: estimate ± k standard errors.")
    ] = 2.0,
    seed: Annotated[int, typer.Option("--seed", min=0, help="Seed of the global search.")] = 0,
    force: Annotated[bool, FORCE_OPTION] = False,
) -> None:
    """Identify from a logged experiment (t, u, y): rho, b0 and the delay for an ADRC
    design, and with --plant/--free a plant's parameters, with their standard errors.

    The log is checked first (monotonic, uniform or declared sampling, finite values,
    enough samples, an input that excites): a refusal names the column and row, exits 2
    and writes nothing.  OUT gets identification.json, first.toml (a starting LADRC
    design), eso.png and candidates.png; with --plant also fitted_plant.toml,
    uncertainty.toml, design.toml (ready for aiofl tune / robustness) and fit.png.  An
    existing non-empty OUT is refused unless --force."""
    from aiofl.identification.log import LogError, check_log, read_log

    with bad_input_exits():
        if not (math.isfinite(k) and k > 0):
            raise ValueError(f"--k = {k!r}; allowed: a finite number > 0")
        if rho is not None and rho > rho_max:
            raise ValueError(f"--rho = {rho} > --rho-max = {rho_max}")
        if (plant is None) != (free is None):
            raise ValueError("--plant and --free go together: the plant and what to fit of it")
        grey_only = {"--bounds": bounds, "--validation": validation, "--holdout": holdout}
        grey_only["--closed-loop"] = closed_loop
        for option, value in grey_only.items():
            if value and plant is None:
                raise ValueError(f"{option} applies to a grey-box fit (--plant, --free)")
        if validation is not None and holdout is not None:
            raise ValueError("--validation and --holdout: give one")
        if holdout is not None and not 0 < holdout <= MAX_HOLDOUT:
            raise ValueError(f"--holdout = {holdout!r}; allowed: 0 < FRACTION <= {MAX_HOLDOUT}")
        if closed_loop is not None and reference is None:
            raise ValueError("--closed-loop needs the logged reference: --reference NAME")
        if delay != "auto":
            try:
                fixed_delay = float(delay)
            except ValueError:
                raise ValueError(f"--delay = {delay!r}; allowed: seconds >= 0, or auto") from None
            if not (math.isfinite(fixed_delay) and fixed_delay >= 0):
                raise ValueError(f"--delay = {delay!r}; allowed: seconds >= 0, or auto")
        _check_out(out, force=force)
        names = {"t": time or None, "u": input_, "y": output, "r": reference}
        columns = {role: name for role, name in names.items() if name is not None}
        read = {"time": time or None, "input": input_, "output": output, "reference": reference}
        data = read_log(log, ts=ts, **read)
        estimation, val_log, val_label = data, None, None
        if validation is not None:
            val_log = read_log(validation, ts=ts, **read)
            val_label = str(validation)
        elif holdout is not None:
            cut = data.n_samples - round(holdout * data.n_samples)
            estimation, val_log = data.part(0, cut), data.part(cut, data.n_samples)
            val_label = f"rows {cut}:{data.n_samples}"
            for what, part in (("estimation part", estimation), ("held-out part", val_log)):
                try:
                    check_log(part, names=columns)
                except LogError as exc:
                    msg = f"--holdout {holdout:g}: the {what} of {log.name}: {exc}"
                    raise LogError(msg) from None
        model, free_map, cl_cfg = None, None, None
        if plant is not None:
            from aiofl.config import resolve_plant

            ref = str(Path(plant).resolve()) if plant.endswith(".toml") else plant
            model = resolve_plant(ref)
            free_names = parse_free(free or "", model.param_names)
            free_map = parse_bounds(list(bounds or []), free_names)
            if closed_loop is not None:
                from aiofl.cli.configs import load_run_config

                cl_cfg = load_run_config(closed_loop)
    settings = {
        "rho_max": rho_max,
        "rho": rho,
        "plant": plant,
        "free": free,
        "bounds": list(bounds or []),
        "delay": delay,
        "closed_loop": closed_loop,
        "validation": str(validation) if validation else None,
        "holdout": holdout,
        "k": k,
        "seed": seed,
    }
    from aiofl.identification.records import log_record

    log_rec = log_record(
        data,
        columns,
        estimation=(0, estimation.n_samples),
        validation=val_label,
    )
    # the grey-box fit simulates a held-out tail on from the fitted part's end state (the
    # whole log, scored on its tail), not from rest
    grey = (data, None, holdout) if holdout is not None else (estimation, val_log, 0.0)
    result = _run(estimation, grey, model, free_map, cl_cfg, plant, delay, k, seed, rho_max, rho)
    _write(out, result, log_rec, settings, data, estimation)
    _summary(result, data, out)


def _run(
    est: Any,
    grey: tuple[Any, Any, float],
    model: Any,
    free_map: Any,
    cl_cfg: Any,
    plant: str | None,
    delay: str,
    k: float,
    seed: int,
    rho_max: int,
    rho: int | None,
) -> dict[str, Any]:
    """Both routes over the checked log (the model-free one on its estimation part ``est``,
    the grey-box one on ``grey`` = (log, validation log, held-out fraction)); the results
    by name."""
    import time as clock

    from aiofl.identification.chain import identify_chain
    from aiofl.identification.first_config import chain_plant_file, first_config
    from aiofl.identification.offline_eso import offline_eso

    res: dict[str, Any] = {"plant": plant}
    with bad_input_exits(run=True):
        t0 = clock.perf_counter()
        est_chain = identify_chain(est, rho_max=rho_max, rho=rho)
        res["chain_seconds"] = clock.perf_counter() - t0
        res["estimate"] = est_chain
        res["first"] = first_config(est_chain, est)
        res["chain_plant"] = chain_plant_file(est_chain, est)
        res["eso"] = offline_eso(est, est_chain.rho, est_chain.b0, _omega0(res["first"]))
        if model is not None:
            from aiofl.identification.fitted_plant import uncertainty_table
            from aiofl.identification.grey_box import fit_plant

            used_delay = est_chain.delay if delay == "auto" else float(delay)
            res["delay"] = used_delay
            res["fit"] = fit_plant(
                grey[0],
                model,
                free_map,
                validation=grey[1],
                holdout=grey[2],
                delay=used_delay,
                closed_loop=cl_cfg,
                seed=seed,
            )
            res["uncertainty"] = uncertainty_table(res["fit"], k=k)
    res["k"] = k
    return res


def _write(
    out: Path,
    res: dict[str, Any],
    log_rec: dict[str, Any],
    settings: dict[str, Any],
    data: Any,
    est: Any,
) -> None:
    """OUT's files, staged and swapped in as a whole."""
    import tomlkit

    from aiofl.identification.first_config import CHAIN_PLANT_FILE
    from aiofl.identification.records import identification_record, record_json
    from aiofl.outputs import atomic_output_dir, atomic_write_bytes, atomic_write_text
    from aiofl.reporting.figures import figure_png
    from aiofl.reporting.identification_figures import candidates_figure, eso_figure, fit_figure

    name = Path(str(data.source)).name
    fit = res.get("fit")
    res["written"] = ["identification.json", "first.toml", CHAIN_PLANT_FILE]
    res["written"] += ["eso.png", "candidates.png"]
    with bad_input_exits(run=True), atomic_output_dir(out) as stage:
        extra = None
        if fit is not None:
            extra = {"plant": res["plant"], "delay": res["delay"]}
            plant = str(res["plant"])
            overrides: dict[str, float] = {}
            if plant.endswith(".toml"):
                from aiofl.identification.fitted_plant import fitted_plant_file

                text = fitted_plant_file(fit, Path(plant))
                atomic_write_text(stage / "fitted_plant.toml", text)
                plant_ref = "fitted_plant.toml"
                res["written"].append("fitted_plant.toml")
            else:  # a library plant: its fitted values as [scenario] plant_overrides
                plant_ref = plant
                overrides = {p.name: float(p.value) for p in fit.parameters}
            table = res["uncertainty"]
            unc_text = (
                f"# The [uncertainty] box of the grey-box fit: estimate +- {res['k']:g} standard "
                "errors.\n# Paste it into a run config (design.toml has it already).\n"
                + tomlkit.dumps({"uncertainty": table})
            )
            atomic_write_text(stage / "uncertainty.toml", unc_text)
            atomic_write_bytes(
                stage / "fit.png", figure_png(fit_figure(fit, est, f"{name}: grey-box fit"))
            )
            res["written"] += ["uncertainty.toml", "fit.png"]
            design = _design_text(res["first"], plant_ref, overrides, table)
            atomic_write_text(stage / "design.toml", design)
            try:
                from aiofl.cli.configs import load_run_config

                load_run_config(stage / "design.toml")  # with its [tune] table
                res["written"].append("design.toml")
            except (ValueError, OSError) as exc:  # a ConfigError is a ValueError
                (stage / "design.toml").unlink()
                res["design_note"] = f"design.toml not written: it does not load ({exc})"
        record = identification_record(
            log=log_rec,
            estimate=res["estimate"],
            eso=res["eso"],
            fit=fit,
            fit_extra=extra,
            uncertainty=res.get("uncertainty"),
            k=res["k"] if fit is not None else None,
            settings=settings,
        )
        atomic_write_text(stage / "identification.json", record_json(record))
        atomic_write_text(stage / "first.toml", res["first"])  # its plant: the chain, beside
        atomic_write_text(stage / CHAIN_PLANT_FILE, res["chain_plant"])
        atomic_write_bytes(
            stage / "eso.png",
            figure_png(eso_figure(res["eso"], est, f"{name}: the ESO run offline over the log")),
        )
        atomic_write_bytes(
            stage / "candidates.png",
            figure_png(candidates_figure(res["estimate"], f"{name}: candidate chains")),
        )


def _pm(value: float, std: float, unit: str = "") -> str:
    u = f" {unit}" if unit else ""
    return f"{value:.5g} ± {std:.2g}{u}"


def _summary(res: dict[str, Any], data: Any, out: Path) -> None:
    """The human summary: what was estimated, how well, and what was written."""
    from rich import box
    from rich.console import Console
    from rich.table import Table

    from aiofl.text import terminal_text

    e = res["estimate"]
    units = data.units
    typer.echo(
        f"log: {terminal_text(data.source)}, {data.n_samples} samples at Ts = {data.ts:.6g} s "
        f"({data.duration:.6g} s)"
    )
    typer.echo(
        f"model-free ({e.criterion}; {res['chain_seconds']:.2f} s): rho = {e.rho}, "
        f"b0 = {_pm(e.b0, e.b0_std)}, delay = {_pm(e.delay, e.delay_std, 's')} (± 1 std), "
        f"output noise std {e.noise_std:.3g} {terminal_text(units.get('y', ''))}, "
        f"fit {e.fit_percent:.2f} %"
    )
    table = Table(box=box.SIMPLE_HEAD, padding=(0, 1), collapse_padding=True)
    for col in ("rho", "delay [s]", "b0", "b0 std", "score", "fit %"):
        table.add_column(col, justify="right", no_wrap=True)
    for c in e.candidates:
        mark = " *" if c.rho == e.rho and c.delay == e.delay else ""
        table.add_row(
            f"{c.rho}{mark}",
            f"{c.delay:.4g}",
            f"{c.b0:.5g}",
            f"{c.b0_std:.2g}",
            f"{c.score:.6g}",
            f"{c.fit_percent:.2f}",
        )
    console = Console()
    Console(width=max(console.width, 90)).print(table)
    eso = res["eso"]
    typer.echo(
        f"offline ESO (omega0 = {eso.omega0:.4g} rad/s): total disturbance rms {eso.rms:.3g}, "
        f"roughness {eso.roughness:.3g}: {eso.verdict}"
    )
    fit = res.get("fit")
    if fit is not None:
        typer.echo(
            f"grey-box ({terminal_text(str(res['plant']))}, delay {res['delay']:.4g} s; "
            f"{fit.evaluations} simulations in {fit.seconds:.1f} s):"
        )
        for p in fit.parameters:
            typer.echo(
                f"  {terminal_text(p.name)} = {_pm(p.value, p.std)}  "
                f"(range {p.low:.4g}..{p.high:.4g})"
            )
        val = fit.validation_fit_percent
        r = fit.residuals
        typer.echo(
            f"  fit {fit.fit_percent:.2f} %"
            + ("" if val is None else f", on the validation data {val:.2f} %")
            + f"; residual white: {'yes' if r.white else 'no'}, independent of u: "
            + ("yes" if r.independent else "no")
            + f" (99 % band ± {r.band:.3g})"
        )
        typer.echo(f"  [uncertainty]: estimates ± {res['k']:g} standard errors")
    if res.get("design_note"):
        typer.echo(f"aiofl: note: {terminal_text(res['design_note'])}", err=True)
    typer.echo(f"wrote {out}/{', '.join(res['written'])}")
