"""Writing a tuning run's outputs: best config, history, evaluations, plot and summary.

:func:`write_outputs` writes, all or nothing (:func:`aiofl.outputs.atomic_output_dir`),

``best.toml``
    The input config with the best parameters, loadable by ``aiofl simulate`` from any
    working folder; its comments, layout and ``[tune]`` table are kept (so re-tuning from
    it is a warm start), and a plant file is referred to relative to the output folder
    (:func:`best_toml`).
``history.csv``
    Per generation: evaluations, best, mean, median, best so far, diverged count, time.
    ``mean`` and ``median`` are over the members that did not diverge; the field is
    empty when every member of the generation diverged (never ``nan``).
``evaluations.csv``
    Every evaluated member: generation, member, parameter values, objective, diverged.
``convergence.png``
    Best so far, generation best and median vs generation (:func:`convergence_png`).
``summary.json``
    Settings, budget, best values, and the best config's metrics over the tuning horizon
    and over the config's own horizon (:func:`full_horizon_record`).
``front.csv``, ``front.png`` (``algorithm = "nsga2"`` only)
    The Pareto front and its figure (:mod:`aiofl.tuning.front`); ``best.toml`` is then the
    design chosen by ``[tune] choose``.  The figure marks the paper's printed designs
    (the ``paper-s{N}-{leso,inleso}`` presets whose plant and scenario tables equal the
    config's, simulated over the tuning horizon), the exact-tracking ISU floor
    (:func:`aiofl.analysis.exact_tracking.exact_tracking_cost`) and the y ≡ 0 controller
    (:func:`reference_markers`).
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from aiofl import layout as L

if TYPE_CHECKING:  # pragma: no cover
    from aiofl.tuning.search import TuneResult

__all__ = [
    "best_toml",
    "convergence_png",
    "full_horizon_record",
    "reference_markers",
    "write_outputs",
]


def _history_csv(result: TuneResult) -> str:
    buf = io.StringIO()
    cols = list(result.history[0]) if result.history else []
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n")
    w.writeheader()
    for row in result.history:
        # a statistic of no members (every member diverged) is an empty field, not nan
        w.writerow({k: _csv_float(v) if isinstance(v, float) else v for k, v in row.items()})
    return buf.getvalue()


def _csv_float(v: float) -> str:
    return repr(v) if np.isfinite(v) else ""


def _evaluations_csv(result: TuneResult) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["generation", "member", *result.names, "objective", "diverged"])
    member = 0
    last = 0
    for i in range(result.n_evaluations):
        g = int(result.generation[i])
        member = member + 1 if g == last else 0
        last = g
        w.writerow(
            [
                g,
                member,
                *(_csv_float(float(v)) for v in result.values[i]),
                _csv_float(float(result.objective[i])),
                int(result.diverged[i]),
            ]
        )
    return buf.getvalue()


def convergence_png(result: TuneResult) -> bytes:
    """The convergence plot: best-so-far, generation best and median vs generation."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    h = result.history
    gen = [r["generation"] for r in h]
    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=110)
    ax.plot(gen, [r["best_so_far"] for r in h], lw=2, label="best so far")
    ax.plot(gen, [r["best"] for r in h], ".", ms=4, label="generation best")
    ax.plot(gen, [r["median"] for r in h], lw=1, alpha=0.7, label="generation median (stable)")
    vals = [v for r in h for v in (r["best"], r["median"]) if np.isfinite(v)]
    if vals and min(vals) > 0:
        ax.set_yscale("log")
    st = result.settings
    obj = st.objective if isinstance(st.objective, str) else "weighted sum"
    ax.set_xlabel("generation")
    ax.set_ylabel(f"objective ({obj}, t_f = {st.t_final:g} s)")
    ax.set_title(f"{result.source}: {st.budget()}", fontsize=9)
    ax.grid(True, alpha=0.3)
    ax2 = ax.twinx()
    ax2.bar(gen, [r["diverged"] for r in h], alpha=0.15, color="red", label="diverged")
    ax2.set_ylabel("diverged members")
    ax.set_zorder(ax2.get_zorder() + 1)  # lines over the bars
    ax.patch.set_visible(False)
    from matplotlib.ticker import MaxNLocator

    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    lines = ax.get_legend_handles_labels()
    bars = ax2.get_legend_handles_labels()
    ax.legend(lines[0] + bars[0], lines[1] + bars[1], fontsize=8, loc="upper right")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return buf.getvalue()


def full_horizon_record(result: TuneResult) -> dict[str, Any]:
    """The best config simulated over its own horizon (e.g. 20 s): itae, isu, iau, opi."""
    cfg = result.run_config()
    sim = cfg.simulate(store=False)
    rec: dict[str, Any] = {
        "t_final": cfg.scenario.t_final,
        "diverged": sim.diverged,
        "diverged_at": sim.diverged_at,
    }
    rec.update(sim.metrics or dict.fromkeys(L.METRIC_NAMES))
    rec["opi"] = sim.opi(cfg.weights)
    return rec


def _source_text(source: str) -> str | None:
    """The TOML text a tuning run started from: its config file, or a shipped preset."""
    from aiofl.config import ConfigError, preset_text

    path = Path(source)
    if source.endswith(".toml") or path.exists():
        try:
            return path.read_text(encoding="utf-8") if path.is_file() else None
        except (OSError, UnicodeDecodeError):
            return None
    try:
        return preset_text(source)
    except ConfigError:
        return None


def best_toml(result: TuneResult, out: str | Path, header: str = "") -> str:
    """``best.toml``'s text: the input config with the tuned values, to be written in ``out``.

    The user's file (or preset) is edited with tomlkit (:func:`aiofl.tuning.space.update_toml`),
    so its comments and layout stay and only the tuned values change.  A plant file is
    referred to relative to ``out`` (``aiofl simulate out/best.toml`` resolves it against
    the config's folder, from any working folder).  If the source cannot be read again, or
    no longer matches the tuned config (edited during the run), the config is written
    afresh (:func:`aiofl.tuning.space.to_toml`).  ``header`` (default: the run's
    provenance) is prepended as comments.
    """
    import os
    import tomllib

    from aiofl.tuning.space import to_toml, update_toml

    config = dict(result.config)
    plant = config.get("plant")
    if isinstance(plant, str) and plant.endswith(".toml") and Path(plant).is_absolute():
        try:
            rel = os.path.relpath(plant, Path(out).resolve())
            config["plant"] = Path(rel).as_posix()
        except ValueError:  # pragma: no cover - another drive (Windows): keep it absolute
            pass
    header = header or result.describe()
    source = _source_text(result.source) if result.source else None
    if source is not None:
        try:
            text = update_toml(source, config, result.names, header)
            if tomllib.loads(text) == config:
                return text
        except (ValueError, KeyError, TypeError):  # tomlkit/tomllib on a changed file
            pass
    return to_toml(config, header)


def reference_markers(
    result: TuneResult,
) -> tuple[list[tuple[str, float, float]], float | None, list[str]]:
    r"""Reference points for the front figure: (markers, ISU floor, notes).

    Markers are (label, objective 2, objective 1) on the **nominal** plant over the tuning
    horizon: the y ≡ 0 controller (:math:`e = r`: ITAE :math:`=\int_0^{t_f} t|r|\,dt`,
    IAE, ISE likewise, ISU = IAU = 0, by the trapezoidal rule on the tuning step) and the
    paper's printed designs whose presets share the config's plant and scenario tables.
    Objectives that are not plain metrics (``stable_fraction``) get no markers.
    """
    from dataclasses import replace

    from aiofl.config import load_config
    from aiofl.engine.simulation import simulate_batch

    front = result.front
    cfg = result.run_config()
    st = result.settings
    tf, dt = st.t_final, st.dt or cfg.dt
    metric = [q.split(":")[0] for q in front.objectives[:2]]
    notes: list[str] = []
    if not all(m in L.METRIC_NAMES for m in metric):
        return [], None, ["no reference markers: an objective is not an engine metric"]
    if any(":" in q for q in front.objectives) or st.robust is not None:
        notes.append("markers on the nominal plant")
    t = np.linspace(0.0, tf, max(2, round(tf / dt) + 1))
    r = np.asarray(cfg.scenario.reference.evaluate(t), dtype=np.float64)
    zero = {
        "itae": np.trapezoid(t * np.abs(r), t),
        "iae": np.trapezoid(np.abs(r), t),
        "ise": np.trapezoid(r * r, t),
        "isu": 0.0,
        "iau": 0.0,
    }
    markers = [("y ≡ 0 (u = 0)", float(zero[metric[1]]), float(zero[metric[0]]))]
    found = False
    for n in (1, 2, 3):
        for structure in ("leso", "inleso"):
            name = f"paper-s{n}-{structure}"
            paper = load_config(name)
            if paper.raw.get("plant") != cfg.raw.get("plant") or paper.raw.get(
                "scenario"
            ) != cfg.raw.get("scenario"):
                continue
            found = True
            res = simulate_batch(
                paper.plant,
                paper.controller,
                replace(paper.scenario, t_final=tf),
                dt=dt,
                method=st.method or cfg.method,
                sampling=paper.sampling,
            )
            if res.diverged[0]:
                notes.append(f"{name} diverged over {tf:g} s")
                continue
            m = dict(zip(L.METRIC_NAMES, res.metrics[0], strict=True))
            markers.append((name, float(m[metric[1]]), float(m[metric[0]])))
    if not found:
        notes.append("paper designs not shown: no paper preset has this plant and scenario")
    floor = None
    if "isu" in metric:
        from aiofl.analysis.exact_tracking import exact_tracking_cost

        floor = float(exact_tracking_cost(replace(cfg, dt=dt), t_final=tf)["isu"])
    return markers, floor, notes


def write_outputs(result: TuneResult, out: str | Path, *, header: str = "") -> dict[str, Any]:
    """Write best.toml, history.csv, evaluations.csv, convergence.png, summary.json to ``out``.

    ``out`` is replaced as a whole (:func:`aiofl.outputs.atomic_output_dir`); the
    checkpoint written there during the run is carried over.  Returns the summary dict.
    """
    from aiofl.outputs import atomic_output_dir, atomic_write_bytes, atomic_write_text

    summary = {
        "source": result.source,
        "budget": result.settings.budget(),
        "settings": result.settings.model_dump(mode="json"),
        "best_values": result.best_values,
        "best_objective": result.best_objective,
        "tuning_horizon_metrics": result.best_metrics,
        "full_horizon": full_horizon_record(result),
        "evaluations": result.n_evaluations,
        "diverged": int(result.diverged.sum()),
        "live_evaluations": result.live_evaluations,
        "live_seconds": result.live_seconds,
        "evals_per_second": result.evals_per_second,
        "evaluator": result.evaluator,
    }
    text = best_toml(result, out, header)
    from aiofl.tuning.checkpoint import CHECKPOINT

    front_files: dict[str, str | bytes] = {}
    if result.front is not None:
        from aiofl.tuning.front import front_csv, front_png

        markers, floor, notes = reference_markers(result)
        title = f"{result.source}: {result.settings.budget()}, t_f = {result.settings.t_final:g} s"
        front_files["front.csv"] = front_csv(result.front)
        front_files["front.png"] = front_png(result.front, title, markers, floor, notes)
        summary["front"] = {
            "designs": int(result.front.F.shape[0]),
            "choose": result.front.rule,
            "objectives": list(result.front.objectives),
            "constraints": list(result.front.constraints),
            "chosen_objectives": result.front.F[result.front.chosen].tolist(),
            "exact_tracking_isu_floor": floor,
            "markers": [{"label": a, "x": x, "y": y} for a, x, y in markers],
            "notes": notes,
        }

    with atomic_output_dir(out, keep=(CHECKPOINT,)) as stage:
        atomic_write_text(stage / "best.toml", text)
        atomic_write_text(stage / "history.csv", _history_csv(result))
        atomic_write_text(stage / "evaluations.csv", _evaluations_csv(result))
        atomic_write_bytes(stage / "convergence.png", convergence_png(result))
        atomic_write_text(
            stage / "summary.json", json.dumps(summary, indent=2, default=_json_default) + "\n"
        )
        for name, data in front_files.items():
            if isinstance(data, bytes):
                atomic_write_bytes(stage / name, data)
            else:
                atomic_write_text(stage / name, data)
    return summary


def _json_default(o: Any) -> Any:
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.bool_):
        return bool(o)
    raise TypeError(type(o).__name__)
