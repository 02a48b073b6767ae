"""``aiofl robustness CONFIG [--draws N] [--seed S] [--scheduler ...] --out DIR``.

Runs the design of CONFIG over the draws of its ``[uncertainty]`` table and, in the same
batched engine call, the corners of its box; then a local worst-case search from the worst
corner or draw and the β/b0 stability range
(:func:`aiofl.analysis.corners.run_box_robustness`; ``--no-corners`` runs the draws alone)
and writes ``DIR/robustness.json`` (stable fraction, ITAE/ISU quantiles, the worst draw,
the nominal run, ``corners`` with ``corners_stable``, ``worst_case``, ``beta_range``) and
``DIR/robustness.png`` (ECDFs of ITAE and ISU, the envelope of y - r, ITAE against the
two most influential parameters, ISU against ITAE), all or nothing.  A config without
``[uncertainty]``, a bad table or option exits with status 2 and writes nothing.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer

from aiofl.cli.bad_input import FORCE_OPTION, RIG_OPTION, SENSOR_OPTION, _check_out, bad_input_exits

__all__ = ["robustness_command"]


def _client(scheduler: str | None, dask_workers: int | None) -> tuple[Any, list[Any]]:
    """A ``distributed.Client`` (and what to close), or (None, []) for a local run."""
    if scheduler is None and dask_workers is None:
        return None, []
    from distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            client = Client(scheduler, timeout="5s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise ConnectionError(
                f"--scheduler {scheduler!r}: cannot connect within 5 s: {exc}"
            ) from None
        return client, [client]
    cluster = LocalCluster(
        n_workers=dask_workers, threads_per_worker=1, processes=True, dashboard_address=None
    )
    client = Client(cluster)
    return client, [client, cluster]


def _fmt(x: float | None) -> str:
    return "lost or diverged" if x is None else f"{x:.4g}"


def _point(p: dict[str, float]) -> str:
    from aiofl.uncertainty import ABSOLUTE

    return ", ".join(
        f"{k} x {v:.4g}" if k not in ABSOLUTE else f"{k} = {v:.4g}" for k, v in p.items()
    )


def _box_text(info: dict[str, Any]) -> str:
    """The corners, worst case and β/b0 lines of the summary ("" without them)."""
    c = info.get("corners")
    if c is None:
        return ""
    out = [
        f"corners_stable {c['corners_stable']:.4g} ({c['stable']} of {c['count']}; {c['design']})"
    ]
    for d in c["failed"][:8]:
        how = d.get("status", "failed")
        out.append(f"  corner {d['corner']} {how} at t = {d['t']:.3g} s: {_point(d['point'])}")
    if len(c["failed"]) > 8:
        out.append(f"  ... {len(c['failed']) - 8} more failed corners in robustness.json")
    w = info.get("worst_case")
    if w is not None:
        what = (
            f"{w.get('status', 'failed')} at t = {w['stopped_at']:.3g} s"
            if w["itae"] is None
            else f"ITAE {w['itae']:.4g}"
        )
        out.append(
            f"worst case (search from {w['start']}, {w['evaluations']} evaluation(s)): {what} "
            f"at {_point(w['point'])}"
        )
    b = info.get("beta_range")
    if b is not None:
        if b["beta_over_b0"] is not None:
            lo, hi = b["beta_over_b0"]
            caps = b["capped"]
            out.append(
                f"beta/b0 stability range: {'<= ' if caps[0] else ''}{lo:.3g} .. "
                f"{'>= ' if caps[1] else ''}{hi:.3g} (nominal {b['beta_over_b0_nominal']:.3g}; "
                f"beta scaled by s via {b['scaling']})"
            )
        elif b["s"] is not None:
            out.append(f"beta factor stability range s: {b['s'][0]:.3g} .. {b['s'][1]:.3g}")
        else:
            out.append(f"beta/b0 range: not computed ({b['reason']})")
    return "\n".join(out) + "\n"


def robustness_command(
    config: Annotated[
        str, typer.Argument(help="A TOML config file or preset, with an [uncertainty] table.")
    ],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output directory.")],
    draws: Annotated[
        int | None, typer.Option("--draws", help="Override uncertainty.draws.")
    ] = None,
    seed: Annotated[int | None, typer.Option("--seed", help="Override uncertainty.seed.")] = None,
    scheduler: Annotated[
        str | None,
        typer.Option("--scheduler", help="Dask scheduler address tcp://HOST:PORT."),
    ] = None,
    dask_workers: Annotated[
        int | None,
        typer.Option("--dask-workers", help="Start a local Dask cluster with N workers."),
    ] = None,
    sensor: Annotated[str | None, SENSOR_OPTION] = None,
    rig: Annotated[str | None, RIG_OPTION] = None,
    corners: Annotated[
        bool,
        typer.Option(
            "--corners/--no-corners",
            help="Also check the box corners, search the worst case and the beta/b0 range.",
        ),
    ] = True,
    force: Annotated[bool, FORCE_OPTION] = False,
) -> None:
    """Measure a design's robustness over the draws of its [uncertainty] table.

    Every draw has its own measurement-noise realisation (seeded from the draw); --sensor
    measures with a sensor preset.  An existing non-empty OUT is refused unless --force."""
    from aiofl.analysis.corners import run_box_robustness
    from aiofl.analysis.robustness_draws import robustness_figure, run_robustness
    from aiofl.cli.configs import load_run_config
    from aiofl.outputs import atomic_output_dir, atomic_write_bytes, atomic_write_text
    from aiofl.uncertainty import MAX_DRAWS, sample_draws

    with bad_input_exits():
        if scheduler is not None and dask_workers is not None:
            raise ValueError("give --scheduler or --dask-workers, not both")
        if dask_workers is not None and not 1 <= dask_workers <= 64:
            raise ValueError(f"--dask-workers = {dask_workers}; allowed: 1 <= N <= 64")
        if draws is not None and not 1 <= draws <= MAX_DRAWS:
            raise ValueError(f"--draws = {draws}; allowed: 1 <= N <= {MAX_DRAWS}")
        if seed is not None and not 0 <= seed < 2**63:
            raise ValueError(f"--seed = {seed}; allowed: 0 <= S < 2**63")
        _check_out(out, force=force)
        cfg = load_run_config(config)
        if sensor:
            cfg = cfg.with_sensor(sensor, source=f"{config} with --sensor {sensor}")
        if rig:
            from aiofl.analysis.rig_check import rig_config

            cfg = rig_config(cfg, rig)
        if cfg.uncertainty is None:
            raise ValueError(
                f"{config}: no [uncertainty] table; add one, e.g.\n  [uncertainty]\n"
                "  draws = 64\n  [uncertainty.parameters]\n  J_l = { uniform = 0.2 }"
            )
        # a scenario the draws cannot be applied to (its own plant change at t > 0)
        sample_draws(cfg.uncertainty, draws=1, dt=cfg.dt).scenarios(cfg.scenario)
        client, owned = _client(scheduler, dask_workers)
    try:
        with bad_input_exits(run=True):
            if corners:
                res = run_box_robustness(cfg, draws=draws, seed=seed, client=client)
            else:
                res = run_robustness(cfg, draws=draws, seed=seed, client=client)
            info = res.to_dict()
            import io

            with atomic_output_dir(out) as stage:
                text = json.dumps(info, indent=2, allow_nan=False) + "\n"
                atomic_write_text(stage / "robustness.json", text)
                buf = io.BytesIO()
                robustness_figure(res).savefig(buf, format="png", dpi=100)
                atomic_write_bytes(stage / "robustness.png", buf.getvalue())
    finally:
        for obj in owned:
            obj.close()
    itae = info["itae"]
    typer.echo(
        f"{res.name}: {len(res.itae)} draws (seed {res.draws.seed}), stable "
        f"{100 * res.stable_fraction:.1f} %, ITAE q05/q50/q95/max = "
        f"{_fmt(itae['q05'])} / {_fmt(itae['q50'])} / {_fmt(itae['q95'])} / "
        f"{_fmt(itae['max'])} (nominal {_fmt(info['nominal']['itae'])}); "
        f"{res.engine_calls} engine call(s), {res.seconds:.1f} s\n"
        f"{_box_text(info)}"
        f"sensor: {cfg.sensor.describe()}\n"
        f"wrote {out}/robustness.json, robustness.png"
    )
