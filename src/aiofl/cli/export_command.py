"""``aiofl export CONFIG --ts TS [--precision P] [--prefix NAME] [--params-only] --out DIR``.

Writes the sampled controller as C99 (:mod:`aiofl.export`): ``NAME_controller.h``,
``NAME_controller.c``, ``NAME_params.c`` (and ``NAME_model.h`` for a model-assisted
controller); with ``--params-only`` only ``NAME_<params-name>.h/.c``, another parameter
instance for a controller exported with the same prefix, precision, ρ, Ts and options.

Bad input exits with status 2 and one message naming the option, nothing written (the files
are staged in a temporary folder and renamed into place): ``--prefix`` that is not a C
identifier prefix (:func:`aiofl.export.c_text.c_prefix`), ``--ts`` ≤ 0 or not a multiple
of the config's dt, an unknown ``--format`` (:data:`FORMATS`, the one place the formats are
listed), an ``--out`` that is a file, a controller the C cannot express (the IOFL law; a
model-assisted controller of a plant without symbolic expressions), and a design whose
closed loop diverges in its own simulation (the config as it is).

Warnings (stderr, exit 0): the design sampled at Ts (without the converters' quanta, which
are not part of the code) diverges, its sampled loop linearised
at the operating point is unstable (:class:`aiofl.analysis.sampled_loop.SampledLoop`), or
its ITAE exceeds by more than ``--tolerance`` (the criterion of ``aiofl analyze
--sampling``) the design's as it was made: the continuous design's, or for a design made
sampled its own at its Ts (each warning names what it compares); with ``--precision
float``, float does not hold (:func:`aiofl.export.c_check.float_holds`, which needs a C
compiler).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, Literal

import typer

from aiofl import layout as L
from aiofl.cli.bad_input import FORCE_OPTION, _check_out, bad_input_exits

__all__ = ["FORMATS", "export_command"]


def _c_files(cfg: Any, sampling: Any, config: str, opts: dict[str, Any]) -> dict[str, str | bytes]:
    from aiofl.export import export_c

    return dict(
        export_c(
            cfg.controller,
            sampling,
            precision=opts.get("precision", "double"),
            prefix=opts.get("prefix", "aiofl"),
            title=cfg.name,
            notes=[f"Config: {config}", *([cfg.description] if cfg.description else [])],
            plant=cfg.plant,  # a model-assisted controller's nominal model
            plant_source=cfg.plant_source,
            x0=cfg.scenario.x0,
            params_only=opts.get("params_only"),
        )
    )


def _fmu_files(
    cfg: Any, sampling: Any, config: str, opts: dict[str, Any]
) -> dict[str, str | bytes]:
    """``NAME.fmu``: the C above as an FMI 2.0 co-simulation FMU (:mod:`aiofl.export.fmu`)."""
    from aiofl.export.fmu import export_fmu_for_config

    if opts.get("params_only"):
        raise ValueError("--params-only: writes C parameter files; allowed with --format c")
    precision, prefix = opts.get("precision", "double"), opts.get("prefix", "aiofl")
    name, data = export_fmu_for_config(
        cfg, sampling, precision=precision, config=config, prefix=prefix
    )
    return {name: data}


FORMATS: dict[str, Callable[[Any, Any, str, dict[str, Any]], dict[str, str | bytes]]] = {
    "c": _c_files,
    "fmu": _fmu_files,
}
"""``--format`` -> the function giving its files ``(cfg, sampling, config, options) ->
{name: text or bytes}`` (options: precision, prefix, params_only)."""


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
    prefix: Annotated[
        str, typer.Option("--prefix", help="Start of every C name (NAME_step, NAME_UP_RHO).")
    ] = "aiofl",
    fmt: Annotated[  # the choices are FORMATS' keys (a test checks they agree)
        Literal["c", "fmu"],
        typer.Option("--format", help="c: C99 sources; fmu: an FMI 2.0 co-simulation FMU."),
    ] = "c",
    params_only: Annotated[
        bool,
        typer.Option("--params-only", help="Write only another parameter instance (.h/.c)."),
    ] = False,
    params_name: Annotated[
        str | None,
        typer.Option("--params-name", help="Its name (default: the config's name)."),
    ] = None,
    tolerance: Annotated[
        float,
        typer.Option(
            help="ITAE allowance of the export (sampled at Ts) over the design as made "
            "(continuous, or sampled at its own Ts)."
        ),
    ] = 0.1,
    force: Annotated[bool, FORCE_OPTION] = False,
) -> None:
    """Export the config's controller, sampled at Ts, as C99 (NAME_controller.h/.c in OUT).

    An existing non-empty OUT is refused unless --force (then it is replaced as a whole).
    --params-only adds NAME_<params-name>.h/.c to OUT instead, typically the folder of an
    earlier export, keeping its other files; only files of the same name need --force.
    """
    from aiofl.cli.configs import load_run_config
    from aiofl.export import PRECISIONS, ExportError
    from aiofl.export.c_code import MAX_INSTANCE
    from aiofl.export.c_text import c_prefix
    from aiofl.outputs import (
        add_files,
        atomic_output_dir,
        atomic_write_bytes,
        atomic_write_text,
    )

    with bad_input_exits():
        if fmt not in FORMATS:
            raise ValueError(f"--format = {fmt!r}; allowed: {', '.join(FORMATS)}")
        if precision not in PRECISIONS:
            raise ValueError(f"--precision = {precision!r}; allowed: {', '.join(PRECISIONS)}")
        c_prefix(prefix)
        if not tolerance > 0:
            raise ValueError(f"--tolerance = {tolerance}; allowed: > 0")
        if params_name is not None and not params_only:
            raise ValueError("--params-name applies only with --params-only")
        if not params_only:  # --params-only adds to OUT: checked per file below
            _check_out(out, force=force)
        own = load_run_config(config)
        cfg, sampling = _sampling(own, ts)
        opts: dict[str, Any] = {"precision": precision, "prefix": prefix}
        if params_only:
            name = params_name
            if name is None:  # the config's name as an identifier
                name = re.sub(r"[^A-Za-z0-9]+", "_", cfg.name).strip("_").lower()
                name = name if re.match(r"[a-z]", name) else "design_" + name
                name = name[:MAX_INSTANCE].rstrip("_")
            opts["params_only"] = name  # checked by export_c
        try:
            files = FORMATS[fmt](cfg, sampling, config, opts)
        except ExportError as exc:
            raise ValueError(f"cannot export {cfg.name!r}: {exc}") from None
        if params_only:  # the folder and the instance's own files, before any simulation
            _check_added(out, files, force=force)
        warnings = _loop_checks(own, cfg, sampling, config, tolerance)
    if precision == "float" and not params_only:
        warnings += _float_check(cfg, sampling, config)
    if params_only:
        with bad_input_exits(run=True):
            add_files(out, files, force=force)
        if not (out / f"{prefix}_controller.h").is_file():
            warnings.append(
                f"{out} holds no {prefix}_controller.h: the parameter instance needs the "
                f"controller exported with --prefix {prefix} (same precision, rho, Ts, options)"
            )
    else:
        with bad_input_exits(run=True), atomic_output_dir(out) as stage:
            for name, data in files.items():
                if isinstance(data, bytes):
                    atomic_write_bytes(stage / name, data)
                else:
                    atomic_write_text(stage / name, data)
    typer.echo(f"wrote {out}/{', '.join(files)} (Ts = {sampling.ts:g} s, {precision})")
    for w in warnings:
        typer.echo(f"aiofl: warning: {w}", err=True)


def _check_added(out: Path, files: dict[str, str | bytes], *, force: bool) -> None:
    """Refuse an ``--out`` that ``--params-only`` cannot add ``files`` to: a file, a non-empty
    folder aiofl did not write, or (without ``force``) one that holds a file of the same
    name (:func:`aiofl.outputs.add_files` checks the same when it writes)."""
    from aiofl.outputs import check_addable, remove_stale

    check_addable(out, files, force=force)
    remove_stale(out)


def _sampling(cfg: Any, ts: float | None) -> tuple[Any, Any]:
    """The config the export is written from and its sampling: the config's own, or the
    config sampled at ``--ts`` (checked; Kalman gains from the measurement are designed for
    it, as ``aiofl simulate --ts`` does)."""
    from aiofl.config import ConfigError

    if ts is None:
        if cfg.sampling is None:
            raise ValueError(
                "no sample time: give --ts or a [controller.discrete] table with ts in the config"
            )
        return cfg, cfg.sampling
    if not (math.isfinite(ts) and 0 < ts <= 1.0):  # the range of [controller.discrete] ts
        raise ValueError(f"--ts = {ts}; allowed: 0 < ts <= 1 [s]")
    try:  # a positive integer multiple of dt, the horizon long enough
        sampled = cfg.with_sample_time(ts)
    except ConfigError as exc:
        raise ValueError(f"--ts = {ts:g}: {exc}") from None
    return sampled, sampled.sampling


def _loop_checks(own_cfg: Any, cfg: Any, sampling: Any, config: str, tolerance: float) -> list[str]:
    """Refuse (ValueError) a design that diverges in its own simulation (``own_cfg``, the
    config as it is); the warnings on the design sampled at the exported Ts (``cfg``)."""
    from dataclasses import replace

    from aiofl.engine.simulation import simulate_batch
    from aiofl.plants.base import PlantError

    # the discretisation alone: the converters' quanta are not part of the code; compared
    # with the design as it was made: continuous, or sampled at its own Ts (a design made
    # sampled is compared with its own sampled self, not with a continuous version)
    ideal = replace(sampling, y_quantum=0.0, u_quantum=0.0)
    made = own_cfg.sampling
    base = None if made is None else replace(made, y_quantum=0.0, u_quantum=0.0)
    what = (
        "the continuous design (the config as it is)"
        if made is None
        else f"the design at its own Ts = {made.ts:g} s (both without the converters' quanta)"
    )
    try:
        own = own_cfg.simulate(store=False)
        res = simulate_batch(
            cfg.plant,
            [own_cfg.controller, cfg.controller],
            cfg.scenario,
            dt=cfg.dt,
            method=cfg.method,
            divergence_threshold=cfg.divergence_threshold,
            sampling=[base, ideal],
        )
    except (PlantError, ValueError) as exc:
        return [f"{config}: could not simulate the design before export ({exc})"]
    if own.failed:
        how = f"sampled at Ts = {own_cfg.sampling.ts:g} s" if own_cfg.sampling else "continuous"
        raise ValueError(
            f"{config} is {own.status} at {own.stopped_at:.3g} s in its own simulation ({how}, "
            f"{own_cfg.scenario.t_final:g}-s scenario): a controller that loses its plant or "
            "diverges is not exported"
        )
    out = []
    itae = res.metric("itae")
    at = f"at Ts = {sampling.ts:g} s"
    if res.failed[1]:
        out.append(
            f"{config} sampled {at} is {L.STATUS_NAMES[int(res.status[1])]} at "
            f"{res.stopped_at[1]:.3g} s "
            "(aiofl simulate --ts): choose a shorter Ts or re-tune"
        )
    elif not res.failed[0] and itae[1] > (1.0 + tolerance) * itae[0]:
        out.append(
            f"{config} sampled {at} has ITAE {itae[1]:.4g} against {itae[0]:.4g} of {what}, "
            f"more than the {100 * tolerance:g} % allowance (aiofl analyze --sampling)"
        )
    try:
        from aiofl.analysis.sampled_loop import SampledLoop

        radius = SampledLoop(cfg).spectral_radius(sampling.ts) if not res.failed[1] else None
    except (ValueError, ArithmeticError, NotImplementedError):
        radius = None
    if radius is not None and radius > 1.0:
        out.append(
            f"{config} sampled {at}: the loop linearised at its operating point is unstable "
            f"(spectral radius {radius:.4g} > 1)"
        )
    return out


def _float_check(cfg: Any, sampling: Any, config: str) -> list[str]:
    """A warning when the float build does not hold (or cannot be checked)."""
    from aiofl.export.c_check import float_holds

    try:
        files = {p: _c_files(cfg, sampling, config, {"precision": p}) for p in ("double", "float")}
        why = float_holds(cfg, sampling, files)
    except RuntimeError as exc:
        return [f"float precision not checked ({exc})"]
    if why is None:
        return []
    return [f"float does not hold for {config} {why}: export with --precision double"]
