"""Writing a tuning run's outputs: best config, history, evaluations, plot and summary.

:func:`write_outputs` writes the run's results first, all or nothing
(:func:`aiofl.outputs.atomic_output_dir`): ``best.toml``, ``history.csv``,
``evaluations.csv``, ``front.csv`` and ``summary.json`` are the search's own data and
nothing is simulated or drawn before they are on disk.  Then it adds what is computed from
them (the full-horizon record, ``convergence.png``, the front figure's reference markers
and ``front.png``), each on its own: one that fails is left out with a note (in
``summary.json``'s ``notes``, printed by ``aiofl tune``; a marker's note also under the
front figure's title), so nothing after the search can lose the search.  The chosen
design's ``warnings`` (a parameter within 1 % of a search bound, PM < 30°, Ms > 2.5;
:mod:`aiofl.tuning.margins`) and its ``chosen_margins`` are computed the same way and
printed by ``aiofl tune`` as warnings.

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
    and over the config's own horizon (:func:`full_horizon_record`; ``null`` if it could
    not be computed); ``notes``: what was left out and why, and the front figure's notes;
    ``files``: the files written.
``front.csv``, ``front.png`` (``algorithm = "nsga2"`` only)
    The Pareto front and its figure (:mod:`aiofl.tuning.front`); ``best.toml`` is then the
    design chosen by ``[tune] choose``.  The figure marks the paper's printed designs
    (the ``paper-s{N}-{leso,inleso}`` presets whose plant and scenario tables equal the
    config's, simulated over the tuning horizon), the exact-tracking ISU floor
    (:func:`aiofl.analysis.exact_tracking.exact_tracking_cost`) and the y ≡ 0 controller
    (:func:`reference_markers`); a marker that cannot be computed (the floor of a step
    reference, which no input tracks exactly) is left out with a note.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from aiofl import layout as L

if TYPE_CHECKING:  # pragma: no cover
    from aiofl.tuning.search import TuneResult

__all__ = [
    "best_toml",
    "convergence_figure",
    "convergence_png",
    "full_horizon_record",
    "reference_markers",
    "write_outputs",
]

_T = TypeVar("_T")


def _optional(notes: list[str], what: str, compute: Callable[[], _T]) -> _T | None:
    """``compute()``, or None and a note ``"{what}: {error}"`` if it raises.

    For outputs that are derived from a finished search and may be left out (a figure, a
    reference marker, a re-simulation): their failure must not lose the search.
    """
    try:
        return compute()
    except Exception as exc:  # an optional output: left out with a note, never fatal
        notes.append(f"{what}: {type(exc).__name__}: {exc}")
        return None


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
    w.writerow(["generation", "member", *result.names, "objective", "failed"])
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
                int(result.failed[i]),
            ]
        )
    return buf.getvalue()


def convergence_figure(result: TuneResult) -> Any:
    """The convergence plot (a matplotlib ``Figure``): best-so-far, generation best and
    median vs generation, and the diverged members per generation as bars on a second axis
    from 0.  When no member diverged there is no such axis (an empty one would run from
    −0.04 to 0.04); the legend says "no member diverged" instead.  The title (the config's
    path) is plain text, never mathtext."""
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.ticker import MaxNLocator

    h = result.history
    gen = [r["generation"] for r in h]
    fig = Figure(figsize=(7, 4.2), dpi=110)
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(gen, [r["best_so_far"] for r in h], lw=2, label="best so far")
    ax.plot(gen, [r["best"] for r in h], ".", ms=4, label="generation best")
    ax.plot(gen, [r["median"] for r in h], lw=1, alpha=0.7, label="generation median (stable)")
    vals = [v for r in h for v in (r["best"], r["median"]) if np.isfinite(v)]
    if vals and min(vals) > 0:
        ax.set_yscale("log")
    st = result.settings
    obj = st.objective if isinstance(st.objective, str) else "weighted sum"
    ax.set_xlabel("generation")
    tf = "the scenario's horizon" if st.t_final is None else f"{st.t_final:g} s"
    ax.set_ylabel(f"objective ({obj}, t_f = {tf})")
    ax.set_title(f"{result.source}: {st.budget()}", fontsize=9, parse_math=False)  # a path
    ax.grid(True, alpha=0.3)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    handles, labels = ax.get_legend_handles_labels()
    diverged = [r["failed"] for r in h]
    if any(diverged):
        ax2 = ax.twinx()
        ax2.bar(gen, diverged, alpha=0.15, color="red", label="lost or diverged")
        ax2.set_ylabel("diverged members")
        ax2.set_ylim(0, max(diverged) * 1.1)
        ax2.yaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_zorder(ax2.get_zorder() + 1)  # lines over the bars
        ax.patch.set_visible(False)
        bars = ax2.get_legend_handles_labels()
        handles, labels = handles + bars[0], labels + bars[1]
    else:
        handles.append(Line2D([], [], lw=0))
        labels.append("no member diverged")
    ax.legend(handles, labels, fontsize=8, loc="upper right")
    fig.tight_layout()
    return fig


def convergence_png(result: TuneResult) -> bytes:
    """``convergence.png``: :func:`convergence_figure` rendered to PNG bytes (Agg)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = convergence_figure(result)
    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def full_horizon_record(result: TuneResult) -> dict[str, Any]:
    """The best config simulated over its own horizon (e.g. 20 s): itae, isu, iau, opi."""
    cfg = result.run_config()
    sim = cfg.simulate(store=False)
    rec: dict[str, Any] = {
        "t_final": cfg.scenario.t_final,
        "status": sim.status,
        "failed": sim.failed,
        "stopped_at": sim.stopped_at,
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

    Parameters
    ----------
    result
        The tuning run's result.
    out
        The output folder ``best.toml`` is written in.
    header
        Comment lines to prepend (default: the run's provenance).

    Returns
    -------
    str
    """
    import os
    import tomllib

    from aiofl.config.objects import is_python_plant
    from aiofl.plants.registry import python_plant_hint
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
    if isinstance(plant, str) and is_python_plant(plant):  # the CLI cannot load it: say so
        header += "\nNote: " + python_plant_hint(plant)
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
    Objectives that are not plain metrics (``stable_fraction``) get no markers.  Every
    marker and the floor are optional: one that cannot be computed (the exact-tracking
    floor of a reference that is not smooth, e.g. a step) is left out and a note says which
    and why; this function does not raise for them.
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

    def y_zero() -> tuple[str, float, float]:
        t = np.linspace(0.0, tf, max(2, round(tf / dt) + 1))
        r = np.asarray(cfg.scenario.reference.evaluate(t), dtype=np.float64)
        zero = {
            "itae": np.trapezoid(t * np.abs(r), t),
            "iae": np.trapezoid(np.abs(r), t),
            "ise": np.trapezoid(r * r, t),
            "isu": 0.0,
            "iau": 0.0,
        }
        return ("y ≡ 0 (u = 0)", float(zero[metric[1]]), float(zero[metric[0]]))

    markers: list[tuple[str, float, float]] = []
    zero_marker = _optional(notes, "y ≡ 0 marker not shown", y_zero)
    if zero_marker is not None:
        markers.append(zero_marker)
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
            res = _optional(
                notes,
                f"{name} not shown",
                lambda paper=paper: simulate_batch(
                    paper.plant,
                    paper.controller,
                    replace(paper.scenario, t_final=tf),
                    dt=dt,
                    method=st.method or cfg.method,
                    sampling=paper.sampling,
                ),
            )
            if res is None:
                continue
            if res.failed[0]:
                notes.append(f"{name} failed (lost or diverged) over {tf:g} s")
                continue
            m = dict(zip(L.METRIC_NAMES, res.metrics[0], strict=True))
            markers.append((name, float(m[metric[1]]), float(m[metric[0]])))
    if not found:
        notes.append("paper designs not shown: no paper preset has this plant and scenario")
    floor = None
    if "isu" in metric:
        from aiofl.analysis.exact_tracking import exact_tracking_cost

        floor = _optional(
            notes,
            "exact-tracking ISU floor not shown",
            lambda: float(exact_tracking_cost(replace(cfg, dt=dt), t_final=tf)["isu"]),
        )
    return markers, floor, notes


def write_outputs(result: TuneResult, out: str | Path, *, header: str = "") -> dict[str, Any]:
    """Write a run's outputs to ``out``: its results first, then what is computed from them.

    1. The results (``best.toml``, ``history.csv``, ``evaluations.csv``, ``front.csv``
       with NSGA-II, ``summary.json``): the search's own data, nothing simulated or
       drawn.  ``out`` is replaced by them as a whole
       (:func:`aiofl.outputs.atomic_output_dir`); the checkpoint written there during the
       run is carried over.
    2. Each on its own, atomically, into ``out``: the full-horizon record (a simulation),
       ``convergence.png``, the front figure's reference markers and ``front.png``; then
       ``summary.json`` again, with them.  One that fails is left out and a note in the
       summary's ``notes`` says what and why; a reference marker that cannot be computed
       is also noted under the front figure's title.

    So a failure after the search (a figure, a marker, the re-simulation, even a crash)
    never loses the search's results.

    Parameters
    ----------
    result
        A finished run (:func:`aiofl.tuning.search.tune`).
    out
        The output directory (new, empty, or written by aiofl).
    header
        Comment lines for ``best.toml`` (default: the run's provenance).

    Returns
    -------
    dict
        The summary (as in ``summary.json``): ``full_horizon`` is None if it could not be
        computed; ``notes`` lists what was left out and the front figure's notes;
        ``files`` the files written.
    """
    from aiofl.outputs import atomic_output_dir, atomic_write_bytes, atomic_write_text
    from aiofl.tuning.checkpoint import CHECKPOINT

    notes: list[str] = []
    summary: dict[str, Any] = {
        "source": result.source,
        "budget": result.settings.budget(),
        "settings": result.settings.model_dump(mode="json"),
        "best_values": result.best_values,
        "best_objective": result.best_objective,
        "tuning_horizon_metrics": result.best_metrics,
        "full_horizon": None,  # step 2
        "evaluations": result.n_evaluations,
        "failed": int(result.failed.sum()),
        "live_evaluations": result.live_evaluations,
        "live_seconds": result.live_seconds,
        "evals_per_second": result.evals_per_second,
        "evaluator": result.evaluator,
        "notes": notes,
    }
    results: dict[str, str] = {
        "best.toml": best_toml(result, out, header),
        "history.csv": _history_csv(result),
        "evaluations.csv": _evaluations_csv(result),
    }
    front = result.front
    if front is not None:
        from aiofl.tuning.front import front_csv

        results["front.csv"] = front_csv(front)
        summary["front"] = {
            "designs": int(front.F.shape[0]),
            "choose": front.rule,
            "objectives": list(front.objectives),
            "constraints": list(front.constraints),
            "chosen_objectives": front.F[front.chosen].tolist(),
            "exact_tracking_isu_floor": None,  # step 2
            "markers": [],
            "notes": [],
        }
    files = [*results, "summary.json"]
    summary["files"] = files

    def summary_json() -> str:
        return json.dumps(summary, indent=2, default=_json_default) + "\n"

    # 1. the results
    with atomic_output_dir(out, keep=(CHECKPOINT,)) as stage:
        for name, text in results.items():
            atomic_write_text(stage / name, text)
        atomic_write_text(stage / "summary.json", summary_json())

    # 2. what is computed from them; each may be left out with a note
    out = Path(out)

    def figure(name: str, draw: Callable[[], bytes]) -> None:
        data = _optional(notes, f"{name} not written", draw)
        if data is not None:
            atomic_write_bytes(out / name, data)
            files.append(name)

    summary["full_horizon"] = _optional(
        notes, "full-horizon record not computed", lambda: full_horizon_record(result)
    )
    summary["warnings"], summary["chosen_margins"] = [], None
    found_w = _optional(notes, "design warnings not computed", lambda: chosen_warnings(result))
    if found_w is not None:
        summary["warnings"], summary["chosen_margins"] = found_w
    figure("convergence.png", lambda: convergence_png(result))
    if front is not None:
        from aiofl.tuning.front import front_png

        marker_notes: list[str] = []
        found = _optional(
            marker_notes, "reference markers not shown", lambda: reference_markers(result)
        )
        markers, floor, figure_notes = found if found is not None else ([], None, [])
        figure_notes = [*figure_notes, *marker_notes]
        summary["front"].update(
            exact_tracking_isu_floor=floor,
            markers=[{"label": a, "x": x, "y": y} for a, x, y in markers],
            notes=figure_notes,
        )
        notes.extend(f"front.png: {n}" for n in figure_notes)
        tf = result.settings.t_final
        when = "the scenario's horizon" if tf is None else f"{tf:g} s"
        title = f"{result.source}: {result.settings.budget()}, t_f = {when}"
        figure("front.png", lambda: front_png(front, title, markers, floor, figure_notes))
    atomic_write_text(out / "summary.json", summary_json())
    return summary


def chosen_warnings(result: TuneResult) -> tuple[list[str], dict[str, float | None] | None]:
    """Warnings on the chosen design (:func:`aiofl.tuning.margins.design_warnings`: a
    parameter within 1 % of a search bound, PM < 30°, Ms > 2.5) and its margins
    (``pm`` [deg], ``gm`` [dB], ``dm`` [s], ``ms``; None where infinite)."""
    from aiofl.config import parse_config
    from aiofl.tuning.margins import design_warnings

    cfg = parse_config(result.config)
    warn, margins = design_warnings(cfg, result.settings.parameters, result.best_values)
    shown = (
        None
        if margins is None
        else {k: (float(v) if math.isfinite(v) else None) for k, v in margins.items()}
    )
    return warn, shown


def _json_default(o: Any) -> Any:
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.bool_):
        return bool(o)
    raise TypeError(type(o).__name__)
