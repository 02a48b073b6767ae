"""Nothing after the search may lose the search.

A robust NSGA-II run on a step reference used to run every generation and then die
drawing ``front.png`` (the exact-tracking ISU floor needs a smooth reference), leaving only
``checkpoint.npz``, and ``--resume`` died the same way.  Now the result files are written
first, a marker that cannot be computed is left out with a note (printed, under the
figure's title, in ``summary.json``), and a figure or re-simulation that fails is left out
with a note without losing the results.  The run is tiny: 4 candidates x 2 generations x
(1 + 2 draws) members over 0.6 s at dt = 1e-3.
"""

from __future__ import annotations

import csv
import json
import tomllib
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from aiofl.cli.app import app
from aiofl.config import load_config, parse_config
from aiofl.tuning.search import TuneResult, tune
from aiofl.tuning.space import to_toml

STEP_NSGA2: dict[str, Any] = {
    "name": "step-nsga2",
    "plant": "slfjm",
    "scenario": {
        "name": "step",
        "t_final": 2.0,
        "reference": {"kind": "step", "amplitude": 0.5, "t_step": 0.1},
    },
    "controller": {
        "structure": "LADRC",
        "rho": 4,
        "n_feedback": 4,
        "eso": {"omega0": 300.0, "alpha": "binomial"},
        "td": {"omega": 50.0},
        "sef": {"omega_c": 10.0},
        "law": {"b0": 26800.0},
    },
    "simulation": {"dt": 1e-3},
    "uncertainty": {"seed": 1, "parameters": {"J_l": {"uniform": 0.2}}},
    "tune": {
        "algorithm": "nsga2",
        "objectives": ["itae", "isu"],
        "robust": {"draws": 2, "aggregate": "worst"},
        "t_final": 0.6,
        "population": 4,
        "generations": 2,
        "seed": 7,
        "parameters": {
            "eso.omega0": {"lo": 50.0, "hi": 600.0, "log": True},
            "sef.omega_c": {"lo": 2.0, "hi": 30.0, "log": True},
        },
    },
}
RESULTS = ("best.toml", "history.csv", "evaluations.csv", "front.csv", "summary.json")
FLOOR_NOTE = "exact-tracking ISU floor not shown: ValueError: reference.kind = 'step'"


def _chosen_row(out: Path) -> dict[str, str]:
    with (out / "front.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert rows and sum(int(r["chosen"]) for r in rows) == 1
    return next(r for r in rows if r["chosen"] == "1")


def _assert_results(out: Path) -> dict[str, Any]:
    """The result files are there and agree: best.toml is front.csv's chosen design."""
    for name in RESULTS:
        assert (out / name).stat().st_size > 0, name
    chosen = _chosen_row(out)
    best = tomllib.loads((out / "best.toml").read_text())
    assert best["controller"]["eso"]["omega0"] == float(chosen["eso.omega0"])
    assert best["controller"]["sef"]["omega_c"] == float(chosen["sef.omega_c"])
    return json.loads((out / "summary.json").read_text())


@pytest.fixture(scope="module")
def config_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("step") / "step.toml"
    path.write_text(to_toml(STEP_NSGA2))
    return path


def test_cli_robust_nsga2_on_a_step_writes_its_results_and_notes_the_floor(
    config_path: Path, tmp_path: Path
) -> None:
    out = tmp_path / "run"
    runner = CliRunner()
    res = runner.invoke(app, ["tune", str(config_path), "--out", str(out), "--quiet"])
    assert res.exit_code == 0, res.output
    summary = _assert_results(out)
    assert (out / "front.png").read_bytes()[:4] == b"\x89PNG"
    assert (out / "convergence.png").read_bytes()[:4] == b"\x89PNG"
    assert summary["full_horizon"] is not None  # the step itself simulates fine
    # the floor is left out with a note: printed, under the figure's title, in the summary
    assert summary["front"]["exact_tracking_isu_floor"] is None
    assert any(n.startswith(FLOOR_NOTE) for n in summary["front"]["notes"])
    assert any(FLOOR_NOTE in n for n in summary["notes"])
    assert f"aiofl: note: front.png: {FLOOR_NOTE}" in res.stderr
    assert "wrote" in res.stdout and "front.csv" in res.stdout
    # --resume replays the checkpoint to the same results (it used to die the same way)
    first = {name: (out / name).read_bytes() for name in ("front.csv", "best.toml")}
    res = runner.invoke(app, ["tune", str(config_path), "--out", str(out), "--quiet", "--resume"])
    assert res.exit_code == 0, res.output
    resumed = _assert_results(out)
    assert resumed["live_evaluations"] == 0  # nothing simulated again
    assert {name: (out / name).read_bytes() for name in first} == first


@pytest.fixture(scope="module")
def result(config_path: Path) -> TuneResult:
    return tune(load_config(config_path), progress=False)


def test_failing_figures_and_resimulation_do_not_lose_the_results(
    result: TuneResult, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Both figures and the full-horizon simulation raise: the results are on disk when
    the first figure is drawn, every failure is a note, nothing else is missing."""
    import aiofl.tuning.front as front_module
    import aiofl.tuning.results as results_module
    from aiofl.tuning.results import write_outputs

    out = tmp_path / "run"
    seen: dict[str, list[str]] = {}

    def broken(name: str):
        def draw(*args: Any, **kwargs: Any) -> bytes:
            seen[name] = sorted(p.name for p in out.iterdir())
            raise RuntimeError(f"{name} is broken")

        return draw

    monkeypatch.setattr(results_module, "full_horizon_record", broken("simulation"))
    monkeypatch.setattr(results_module, "convergence_png", broken("convergence"))
    monkeypatch.setattr(front_module, "front_png", broken("front"))
    summary = write_outputs(result, out)
    for name in ("simulation", "convergence", "front"):
        assert set(RESULTS) <= set(seen[name]), (name, seen[name])  # written before
    assert not (out / "front.png").exists() and not (out / "convergence.png").exists()
    on_disk = _assert_results(out)  # summary.json rewritten with the notes
    assert on_disk["notes"] == summary["notes"] and on_disk["files"] == summary["files"]
    assert on_disk["full_horizon"] is None
    assert summary["full_horizon"] is None
    assert summary["files"] == list(RESULTS)
    notes = summary["notes"]
    for note in (
        "full-horizon record not computed: RuntimeError: simulation is broken",
        "convergence.png not written: RuntimeError: convergence is broken",
        "front.png not written: RuntimeError: front is broken",
    ):
        assert note in notes
    assert any(FLOOR_NOTE in n for n in notes)
    assert summary["best_values"] == on_disk["best_values"] == result.best_values


def test_reference_markers_leave_out_what_cannot_be_computed(result: TuneResult) -> None:
    """The exact-tracking floor of a step is no number: no floor, a note; the y = 0
    marker is still there.  With a sine reference the floor is computed."""
    from dataclasses import replace

    from aiofl.tuning.results import reference_markers

    markers, floor, notes = reference_markers(result)
    assert floor is None and any(n.startswith(FLOOR_NOTE) for n in notes)
    assert [m[0] for m in markers] == ["y ≡ 0 (u = 0)"]
    sine = {**STEP_NSGA2["scenario"], "reference": {"kind": "sine", "amplitude": 0.5}}
    cfg = parse_config({**STEP_NSGA2, "scenario": sine}, "sine")
    smooth = replace(result, config=cfg.raw, source="sine")
    markers, floor, notes = reference_markers(smooth)
    assert floor is not None and floor > 0 and not any("floor" in n for n in notes)
