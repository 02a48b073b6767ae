"""Messages, help and figures: what a new user reads and sees (issue 22).

The help prints bracketed table names and units as written and does not break a sentence
where the docstring's line ends; the enum-like options list their choices; ``--check``
needs no ``--out`` on simulate and exists on tune; a plant file given to
``analyze --closed-loop`` is named as such; ``dir(aiofl)`` lists the lazy names; the tune
progress bar and the summary print the same numbers; ``metrics.json`` names the file that
ran; the figures have no overlapping tick labels, no negative decades to place a zero, no
empty axis running below 0, no repeated panel letter, no matplotlib warning, and draw a
``$`` in user text as plain text.  Every test here runs in well under a second or two
(no kernel is compiled; the one simulation uses a cached shipped kernel).
"""

from __future__ import annotations

import json
import re
import tomllib
import warnings
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from aiofl.cli.app import app
from aiofl.config import preset_text

runner = CliRunner()
COMMANDS = ("presets", "show", "simulate", "reproduce", "tune", "analyze", "export", "robustness")
WIDE = {"COLUMNS": "1000"}  # nothing wraps: a line break in the output is the help's own
MATHTEXT_BREAKER = r"my $\frac$ run"  # matplotlib's mathtext raises on this


def _help(*command: str) -> str:
    res = runner.invoke(app, [*command, "--help"], env=WIDE)
    assert res.exit_code == 0, res.output
    return res.stdout


def _click_command(name: str | None) -> Any:
    import typer.main

    group = typer.main.get_command(app)
    return group if name is None else group.commands[name]


def _texts(name: str | None) -> list[str]:
    """The help texts a command's help shows: its own and its parameters' (for the group
    also each command's first paragraph)."""
    cmd = _click_command(name)
    texts = [cmd.help or ""]
    texts += [getattr(p, "help", None) or "" for p in cmd.params]
    if name is None:
        texts += [(c.help or "").split("\n\n")[0] for c in cmd.commands.values()]
    return texts


# ------------------------------------------------------------------------------ help
@pytest.mark.parametrize("name", [None, *COMMANDS])
def test_help_prints_every_bracketed_text_as_written(name: str | None) -> None:
    """Rich markup used to eat ``[uncertainty]``, ``[s]``, ``[controller.discrete]``."""
    shown = _help(*([name] if name else []))
    brackets = {b for text in _texts(name) for b in re.findall(r"\[[^\]\s]+\]", text)}
    for b in brackets:
        assert b in shown, (name, b)


def test_the_reported_help_lines_are_whole() -> None:
    assert "robustness over the draws of its [uncertainty] table" in _help()
    assert "(or a [controller.discrete] table)" in _help("simulate")
    assert "Sample time [s] (default: the config's [controller.discrete])" in _help("export")
    assert "Override the fixed step [s]" in _help("simulate")  # no stray backslash
    assert "\\[" not in _help("simulate")


@pytest.mark.parametrize("name", [None, *COMMANDS])
def test_help_paragraphs_are_not_broken_mid_sentence(name: str | None) -> None:
    """Each paragraph of a command's docstring is one line on a wide terminal (the
    docstring's own line breaks used to be kept, cutting sentences), also in the group's
    list of commands."""
    shown = [" ".join(line.split()) for line in _help(*([name] if name else [])).splitlines()]
    cmd = _click_command(name)
    # the group's list of commands shows each one's first paragraph
    docs = list(cmd.commands.values()) if name is None else [cmd]
    for c in docs:
        paragraphs = (c.help or "").split("\n\n")
        wanted = paragraphs[:1] if name is None else paragraphs
        for para in wanted:
            words = " ".join(para.split())
            if words:
                assert any(words in line for line in shown), (name, words)


def test_precision_lists_its_choices_and_refuses_others(tmp_path: Path) -> None:
    shown = _help("export")
    (line,) = [ln for ln in shown.splitlines() if "--precision" in ln and "│" in ln]
    assert "double|float" in line and "<str>" not in line
    out = tmp_path / "c"
    res = runner.invoke(
        app, ["export", "retuned-s1-leso", "--ts", "1e-3", "--precision", "long", "-o", str(out)]
    )
    assert res.exit_code == 2 and "'double'" in res.stderr and "'float'" in res.stderr
    assert list(tmp_path.iterdir()) == []


def test_tune_help_names_every_algorithm() -> None:
    shown = _help("tune")
    for algorithm in ("GA", "DE", "CMA-ES", "NSGA-II"):
        assert algorithm in shown
    assert "with a GA" not in shown
    summary = next(ln for ln in _help().splitlines() if "│ tune" in ln)
    assert "NSGA-II" in summary


# --------------------------------------------------------------------------- --check
def test_simulate_check_needs_no_out(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(app, ["simulate", "paper-s1-leso", "--check"])
    assert res.exit_code == 0, res.output
    assert "valid" in res.stdout and "nothing run or written" in res.stdout
    assert list(tmp_path.iterdir()) == []
    missing = runner.invoke(app, ["simulate", "paper-s1-leso"])
    assert missing.exit_code == 2 and "--out" in missing.stderr
    assert "Traceback" not in missing.output


FAST_TUNE: dict[str, Any] = {
    "name": "fast",
    "plant": "slfjm",
    "scenario": {"name": "nominal", "t_final": 2.0},
    "controller": {
        "structure": "LADRC",
        "rho": 4,
        "eso": {"omega0": 300.0},
        "td": {"omega": 50.0},
        "sef": {"omega_c": 10.0},
        "law": {"b0": 26800.0},
    },
    "simulation": {"dt": 1e-3},
    "tune": {
        "t_final": 0.6,
        "population": 4,
        "generations": 2,
        "parameters": {"eso.omega0": {"lo": 50.0, "hi": 600.0, "log": True}},
    },
}


def test_tune_has_check(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from aiofl.tuning.space import to_toml

    monkeypatch.chdir(tmp_path)
    Path("fast.toml").write_text(to_toml(FAST_TUNE))
    res = runner.invoke(app, ["tune", "fast.toml", "--check", "--population", "6"])
    assert res.exit_code == 0, res.output
    assert res.stdout.startswith("fast.toml: valid; GA population 6 x 2 generations")
    assert "12 candidates" in res.stdout and "eso.omega0" in res.stdout
    assert "nothing run or written" in res.stdout
    with_out = runner.invoke(app, ["tune", "fast.toml", "--check", "-o", "out"])
    assert with_out.exit_code == 0, with_out.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fast.toml"]
    bad = {**FAST_TUNE, "tune": {**FAST_TUNE["tune"], "population": 0}}
    Path("bad.toml").write_text(to_toml(bad))
    refused = runner.invoke(app, ["tune", "bad.toml", "--check"])
    assert refused.exit_code == 2 and "population" in refused.stderr
    missing = runner.invoke(app, ["tune", "fast.toml"])
    assert missing.exit_code == 2 and "--out" in missing.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml", "fast.toml"]


# ---------------------------------------------------------------- plant file as config
PLANT_FILE = """
name = "pend"
states = ["theta", "omega"]
f = ["omega", "-g/l*sin(theta)"]
g = ["0", "1/(m*l**2)"]
h = "theta"
output_unit = "rad"
input_unit = "N m"
[params]
m = 1.0
l = 0.5
g = 9.81
"""


def test_a_plant_file_is_named_as_such(tmp_path: Path) -> None:
    plant = tmp_path / "pend.toml"
    plant.write_text(PLANT_FILE)
    res = runner.invoke(app, ["analyze", str(plant), "--closed-loop"])
    assert res.exit_code == 2
    assert "is a plant file; --closed-loop wants a run config" in res.stderr
    assert "unknown key" not in res.stderr and len(res.stderr.strip().splitlines()) == 1
    sim = runner.invoke(app, ["simulate", str(plant), "--check"])
    assert sim.exit_code == 2
    assert "this is a plant file" in sim.stderr and "unknown key" not in sim.stderr


# --------------------------------------------------------------------------- dir(aiofl)
def test_dir_lists_the_lazy_names_without_importing_them() -> None:
    import subprocess
    import sys

    code = (
        "import sys, aiofl; names = dir(aiofl); "
        "print(sorted(set(aiofl.__all__) - set(names)), 'numba' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["[]", "False"]


# ------------------------------------------------------------ tune: bar and summary agree
class _TwoGoals:
    """Stands in for the engine: ITAE and ISU are two quadratics in log10 of the values,
    with different optima (a Pareto front), nothing diverges."""

    description = "two quadratics"

    def __init__(self, n: int) -> None:
        self.a = np.linspace(2.0, 2.5, n)
        self.b = np.linspace(2.6, 2.9, n)

    def __call__(self, spec: Any, values: np.ndarray) -> Any:
        from aiofl import layout as L
        from aiofl.tuning.evaluate import PopulationResult

        m = np.zeros((values.shape[0], L.N_METRIC))
        lv = np.log10(values)
        m[:, L.METRIC_NAMES.index("itae")] = ((lv - self.a) ** 2).sum(axis=1)
        m[:, L.METRIC_NAMES.index("isu")] = ((lv - self.b) ** 2).sum(axis=1) + 0.01
        b = values.shape[0]
        return PopulationResult(m, np.zeros(b, dtype=bool), np.full(b, np.nan))

    def close(self) -> None:
        pass


def _bar_fields(err: str) -> tuple[str, str, str]:
    """(label, best, rate) of the progress bar's last line."""
    (m,) = re.findall(r"gen · (best|lowest \S+) (\S+) · (\S+) eval/s", err)[-1:]
    return m


@pytest.mark.parametrize("algorithm", ["ga", "nsga2"])
def test_progress_bar_and_summary_print_the_same_numbers(
    algorithm: str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The bar's eval/s was the last generation's (229.7) and the summary's the run's
    (12.2); NSGA-II's bar said "best 0.2027" and the summary "best objective 0.5565"."""
    from aiofl.cli.tune_command import summary_text
    from aiofl.config import parse_config
    from aiofl.tuning.search import tune

    monkeypatch.setenv("COLUMNS", "200")
    cfg = parse_config(FAST_TUNE, "fast")
    tune_table = {"population": 8, "generations": 5, "algorithm": algorithm}
    if algorithm == "nsga2":
        tune_table.update(objectives=["itae", "isu"], choose="knee")
    else:
        tune_table.update(objective="itae")
    params = {n: {"lo": 10.0, "hi": 1e4, "log": True} for n in ("eso.omega0", "sef.omega_c")}
    res = tune(cfg, progress=True, evaluator=_TwoGoals(2), parameters=params, **tune_table)
    label, best, rate = _bar_fields(capsys.readouterr().err)
    text = summary_text(res, {"full_horizon": None, "files": ["best.toml"]}, Path("out"))
    assert rate == f"{res.evals_per_second:.1f}"
    assert f"{rate} eval/s" in text
    if algorithm == "ga":
        assert (label, best) == ("best", f"{res.best_objective:.6g}")
        assert f"best objective {best} " in text
    else:
        front = res.front
        assert (label, best) == ("lowest itae", f"{front.F[:, 0].min():.6g}")
        assert f"lowest itae on the front {best} " in text
        chosen = front.F[front.chosen]
        assert f"itae {chosen[0]:.6g}, isu {chosen[1]:.6g}" in text
        assert "chosen design (knee" in text


# ------------------------------------------------------------------------ metrics.json
def test_metrics_json_of_a_copied_preset_names_the_file(tmp_path: Path) -> None:
    cfg = tmp_path / "my.toml"
    cfg.write_text(preset_text("retuned-s1-ladrc"))
    out = tmp_path / "run"
    res = runner.invoke(app, ["simulate", str(cfg), "--out", str(out), "--t-final", "0.2"])
    assert res.exit_code == 0, res.output
    rec = json.loads((out / "metrics.json").read_text())
    assert rec["config"] == str(cfg)
    assert rec["name"] == "retuned-s1-ladrc"
    assert rec["scenario"] is None


def test_a_plant_without_units_is_noted() -> None:
    from aiofl.cli.app import units_note
    from aiofl.plants.registry import get_plant

    assert units_note(get_plant("slfjm")) is None
    bare = SimpleNamespace(name="pend", output_unit="", input_unit="V")
    note = units_note(bare)
    assert note is not None and "output_unit" in note and "input_unit" not in note.split(",")[0]


def test_the_manual_s_plant_file_shows_every_key_with_the_units() -> None:
    """output_unit/input_unit were documented only in a docstring."""
    from aiofl.plants.symbolic import SymbolicPlant

    page = Path(__file__).resolve().parents[1] / "docs" / "guide" / "plants.md"
    blocks = re.findall(r"```toml\n(.*?)```", page.read_text(encoding="utf-8"), flags=re.S)
    (block,) = [b for b in blocks if re.search(r"^states = ", b, flags=re.M)]
    keys = set(re.findall(r"^#? ?(\w+) = |^\[(\w+)\]$", block, flags=re.M))
    keys = {k for pair in keys for k in pair if k}
    assert set(SymbolicPlant._KEYS) <= keys
    data = tomllib.loads(block)
    plant = SymbolicPlant.from_dict(data, "docs/guide/plants.md")
    assert (plant.output_unit, plant.input_unit) == ("rad", "N·m")


# --------------------------------------------------------------------------------- figures
def _draw(fig: Any) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return canvas.get_renderer()


def _tick_label_boxes(ax: Any, which: str, renderer: Any) -> list[Any]:
    axis = ax.xaxis if which == "x" else ax.yaxis
    lo, hi = sorted(axis.get_view_interval())
    boxes = []
    for tick in [*axis.get_major_ticks(), *axis.get_minor_ticks()]:
        label = tick.label1
        if label.get_visible() and label.get_text() and lo <= tick.get_loc() <= hi:
            boxes.append(label.get_window_extent(renderer))
    return boxes


def _assert_no_tick_labels_overlap(fig: Any) -> None:
    renderer = _draw(fig)
    for ax in fig.axes:
        for which in ("x", "y"):
            boxes = _tick_label_boxes(ax, which, renderer)
            for i, a in enumerate(boxes):
                for b in boxes[i + 1 :]:
                    overlap = a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1
                    assert not overlap, (ax.get_title(), which)


def _robustness_result(itae: np.ndarray, isu: np.ndarray, name: str = "design") -> Any:
    from aiofl.analysis.robustness_draws import RobustnessResult
    from aiofl.uncertainty import Draws

    k = itae.size
    rng = np.random.default_rng(0)
    div = ~np.isfinite(itae)
    t = np.linspace(0.0, 1.0, 50)
    factors = {"J_l": rng.uniform(0.8, 1.2, k), "K_s": rng.uniform(0.8, 1.2, k)}
    nominal = None if div.all() else float(np.min(itae[~div]))
    return RobustnessResult(
        name=name,
        draws=Draws(seed=0, factors=factors),
        nominal_params={"J_l": 1.0, "K_s": 1.0},
        itae=itae,
        isu=isu,
        failed=div,
        stopped_at=np.where(div, 0.5, np.nan),
        status=np.where(div, 1, 0),  # aiofl.layout.STATUS_DIVERGED, STATUS_OK
        nominal={"itae": nominal, "isu": None, "failed": nominal is None, "stopped_at": None},
        t=t,
        error=(0.1 * np.outer(np.ones(k), np.sin(t))).astype(np.float32),
        engine_calls=1,
        seconds=0.0,
    )


def test_robustness_figure_tick_labels_do_not_overlap_and_isu_is_plotted() -> None:
    from aiofl.analysis.robustness_draws import robustness_figure

    rng = np.random.default_rng(1)
    narrow = 0.0165 + 0.0035 * rng.random(16)  # the reported ECDF: 0.0165..0.020
    wide = 10.0 ** rng.uniform(-3, 1, 16)  # four decades
    for itae in (narrow, wide):
        res = _robustness_result(itae, 0.57 + 0.07 * rng.random(16))
        fig = robustness_figure(res)
        _assert_no_tick_labels_overlap(fig)
        (isu_ax,) = [ax for ax in fig.axes if ax.get_title().startswith("ECDF of ISU")]
        (line,) = [ln for ln in isu_ax.get_lines() if ln.get_label() == "ISU ECDF"]
        assert np.allclose(np.sort(line.get_xdata()), np.sort(res.isu))


def test_an_all_diverged_robustness_figure_raises_no_warning() -> None:
    from aiofl.analysis.robustness_draws import robustness_figure

    res = _robustness_result(np.full(8, np.inf), np.full(8, np.inf), name=MATHTEXT_BREAKER)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fig = robustness_figure(res)
        _draw(fig)
    assert fig.get_suptitle().startswith(MATHTEXT_BREAKER)


def _front(F: list[list[float]]) -> Any:
    from aiofl.tuning.front import Front

    arr = np.array(F, dtype=np.float64)
    no_constraints = np.zeros((len(F), 0))
    return Front(("eso.omega0",), ("itae", "isu"), (), arr[:, :1], arr, no_constraints, 0, "knee")


def test_front_figure_places_a_zero_isu_without_negative_decades() -> None:
    from aiofl.tuning.front import front_figure

    front = _front([[0.5, 2.0], [0.3, 5.0], [0.2, 20.0]])
    fig = front_figure(front, MATHTEXT_BREAKER, [("y ≡ 0 (u = 0)", 0.0, 3.1)])
    _draw(fig)
    ax = fig.axes[0]
    lo, hi = ax.get_xlim()
    assert lo == 0.0  # was -0.028: the symmetric-log axis reached into negative ISU
    ticks = [t.get_loc() for t in ax.xaxis.get_major_ticks() if lo <= t.get_loc() <= hi]
    assert 0.0 in ticks and min(ticks) >= 0.0
    _assert_no_tick_labels_overlap(fig)


def _tune_result(diverged: list[int]) -> Any:
    from aiofl.tuning.space import TuneSettings

    n = len(diverged)
    history = [
        {"generation": g + 1, "best": 1.0 / (g + 1), "median": 2.0 / (g + 1),
         "best_so_far": 1.0 / (g + 1), "failed": d}
        for g, d in enumerate(diverged)
    ]  # fmt: skip
    settings = TuneSettings.model_validate(
        {"generations": n, "population": 4, "parameters": {"eso.omega0": {"lo": 1, "hi": 2}}}
    )
    return SimpleNamespace(history=history, settings=settings, source=MATHTEXT_BREAKER)


def test_convergence_figure_has_no_diverged_axis_below_zero() -> None:
    from aiofl.tuning.results import convergence_figure

    none = convergence_figure(_tune_result([0, 0, 0, 0]))
    _draw(none)
    assert len(none.axes) == 1  # no empty "diverged members" axis running -0.04..0.04
    legend = [t.get_text() for t in none.axes[0].get_legend().get_texts()]
    assert "no member diverged" in legend
    some = convergence_figure(_tune_result([0, 3, 1, 0]))
    _draw(some)
    (bars,) = [ax for ax in some.axes if ax.get_ylabel() == "diverged members"]
    assert bars.get_ylim()[0] == 0.0 and bars.get_ylim()[1] >= 3


def _fake_run(t_final: float = 2.0) -> Any:
    from aiofl.engine.simulation import SimulationResult

    t = np.linspace(0.0, t_final, 101)
    r = np.sin(t)
    return SimulationResult({"itae": 1.0}, False, None, t, {"r": r, "y": r, "u": np.cos(t)})


def test_no_panel_letter_repeats_in_a_figure_of_many_runs() -> None:
    """Figures 3 and 5 have nine runs (27 panels): the 27th was "(a)" again."""
    from aiofl.reporting.figures import Panel, panel_letter, runs_figure

    assert [panel_letter(i) for i in (0, 25, 26, 27, 701, 702)] == [
        "a", "z", "aa", "ab", "zz", "aaa",
    ]  # fmt: skip
    panels = [Panel(f"run {i}", _fake_run(), "C0", 2.0) for i in range(10)]
    fig = runs_figure(panels, MATHTEXT_BREAKER)
    letters = [ax._left_title.get_text().split(")")[0] for ax in fig.axes]
    assert len(letters) == 30 and len(set(letters)) == 30


def test_user_text_in_figure_titles_is_plain_text() -> None:
    """A ``$`` in a config's name or path reached mathtext, which raised on drawing."""
    import control

    from aiofl.analysis.frequency import loop_figure, loop_margins
    from aiofl.analysis.sampling_limits import SamplingLimits, SamplingPoint, sampling_figure
    from aiofl.reporting.figures import result_figure

    points = [
        SamplingPoint(1e-4, 0.02, False, None, 0.0, 0.9, None),
        SamplingPoint(1e-3, 0.021, False, None, 0.0, 0.95, None),
        SamplingPoint(4e-3, None, True, 0.3, None, 1.2, None),
    ]
    lim = SamplingLimits(
        MATHTEXT_BREAKER, 1e-4, 0.1, 0.02, False, 1e-3, 2e-3, (1e-3, 2e-3), (2e-3, 4e-3), 1e-2,
        points,
    )  # fmt: skip
    loop = control.ss(control.tf([8.0], [1.0, 3.0, 2.0, 0.0]))
    margins = loop_margins(loop, control.feedback(loop, 1).poles())
    figures = [
        sampling_figure(lim),
        loop_figure(loop, margins, f"{MATHTEXT_BREAKER}: loop broken at the plant input"),
        result_figure(_fake_run(), MATHTEXT_BREAKER, 2.0, output_unit="$", input_unit="$x$"),
    ]
    for fig in figures:
        _draw(fig)  # raised ValueError (mathtext) before
    texts = [t.get_text() for fig in figures for ax in fig.axes for t in (ax.title, ax.yaxis.label)]
    texts += [fig.get_suptitle() for fig in figures]
    assert any(MATHTEXT_BREAKER in t for t in texts)
    assert "u [$x$]" in texts
