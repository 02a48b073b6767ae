"""``aiofl tune`` on bad input: bounded budgets, damaged checkpoints, an unreachable
scheduler, and a history without NaN when a whole generation diverges."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from aiofl import layout as L
from aiofl.cli.app import app
from aiofl.config import ConfigError, parse_config
from aiofl.limits import MAX_EVALUATIONS, MAX_POPULATION
from aiofl.outputs import MARKER, ensure_output_dir
from aiofl.tuning.checkpoint import CHECKPOINT, load_checkpoint, save_checkpoint
from aiofl.tuning.evaluate import EvalSpec, PopulationResult
from aiofl.tuning.results import _history_csv
from aiofl.tuning.search import prepare, tune
from aiofl.tuning.space import parse_tune_settings, to_toml
from test_tuning import FAST

runner = CliRunner()


def _settings(**changes: Any) -> dict[str, Any]:
    return {**FAST["tune"], **changes}


@pytest.mark.parametrize(
    ("changes", "needles"),
    [
        ({"population": 1_000_000}, ["tune.population", f"{MAX_POPULATION}"]),
        (
            {"population": 5_000, "generations": 1_000},
            ["5000 x 1000 = 5000000 evaluations", f"at most {MAX_EVALUATIONS}"],
        ),
        ({"population": 64.0}, ["tune.population", "valid integer"]),
        ({"population": True}, ["tune.population", "valid integer"]),
        ({"t_final": "6"}, ["tune.t_final", "valid number"]),
        ({"divergence_penalty": float("inf")}, ["tune.divergence_penalty", "finite"]),
    ],
)
def test_tune_settings_are_strict_and_bounded(changes, needles) -> None:
    with pytest.raises(ConfigError) as err:
        parse_tune_settings(_settings(**changes))
    for needle in needles:
        assert needle in str(err.value), (needle, str(err.value))


def test_the_largest_budget_is_accepted() -> None:
    st = parse_tune_settings(
        _settings(population=MAX_POPULATION, generations=MAX_EVALUATIONS // MAX_POPULATION)
    )
    assert st.population * st.generations == MAX_EVALUATIONS


@pytest.mark.parametrize(
    ("changes", "needles"),
    [
        ({"dt": 1e-9}, ["tune.t_final / tune.dt", "6e+08 steps", "2e+07"]),
        ({"t_final": 0.6005}, ["tune.t_final = 0.6005", "simulation.dt = 0.001"]),
    ],
)
def test_the_tuning_horizon_is_bounded_like_a_run(changes, needles) -> None:
    data = {**FAST, "tune": _settings(**changes)}
    with pytest.raises(ConfigError) as err:
        prepare(parse_config(data, "fast"))
    for needle in needles:
        assert needle in str(err.value), (needle, str(err.value))


def _write_config(tmp_path: Path) -> Path:
    path = tmp_path / "fast.toml"
    path.write_text(to_toml(FAST))
    return path


@pytest.mark.parametrize("content", [b"", b"not a zip file at all", b"PK\x03\x04broken"])
def test_an_empty_or_corrupt_checkpoint_exits_2_naming_the_file(
    tmp_path: Path, content: bytes
) -> None:
    cfg = _write_config(tmp_path)
    out = ensure_output_dir(tmp_path / "out")  # as a killed tune run leaves it
    (out / CHECKPOINT).write_bytes(content)
    res = runner.invoke(app, ["tune", str(cfg), "--out", str(out), "--resume", "--quiet"])
    assert res.exit_code == 2, res.output
    assert str(out / CHECKPOINT) in res.stderr and "Traceback" not in res.output
    assert sorted(p.name for p in out.iterdir()) == sorted([MARKER, CHECKPOINT])  # as it was
    assert (out / CHECKPOINT).read_bytes() == content


def test_a_checkpoint_with_arrays_of_the_wrong_shape_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "out" / CHECKPOINT
    gen = {
        "s": np.zeros((4, 3)),
        "metrics": np.zeros((4, 2)),  # 2 metrics instead of 5
        "failed": np.zeros(4, dtype=bool),
        "stopped_at": np.zeros(4),
        "seconds": 1.0,
    }
    save_checkpoint(path, "fp", [gen])
    with pytest.raises(ConfigError, match="wrong shape"):
        load_checkpoint(path, "fp")
    gen["metrics"] = np.zeros((4, 5))
    save_checkpoint(path, "fp", [gen])
    assert load_checkpoint(path, "fp")[0]["metrics"].shape == (4, 5)


@pytest.mark.slow
def test_an_unreachable_scheduler_exits_2_with_a_message(tmp_path: Path) -> None:
    cfg = _write_config(tmp_path)
    out = tmp_path / "out"
    args = ["tune", str(cfg), "--out", str(out), "--quiet", "--scheduler", "tcp://127.0.0.1:1"]
    res = runner.invoke(app, args)
    assert res.exit_code == 2, res.output
    assert "cannot connect to the Dask scheduler 'tcp://127.0.0.1:1'" in res.stderr
    assert "Traceback" not in res.output
    assert not out.exists()


class AllDiverge:
    """Stands in for the engine: every member diverges at t = 0.3 s."""

    description = "all-diverge"

    def __call__(self, spec: EvalSpec, values: np.ndarray) -> PopulationResult:
        b = values.shape[0]
        return PopulationResult(
            np.full((b, L.N_METRIC), np.nan), np.ones(b, dtype=bool), np.full(b, 0.3)
        )

    def close(self) -> None:
        pass


def test_history_has_no_nan_when_every_member_diverges() -> None:
    cfg = parse_config(dict(FAST), "fast")
    res = tune(cfg, progress=False, evaluator=AllDiverge(), generations=2)
    assert all(h["failed"] == h["evaluations"] for h in res.history)
    lines = _history_csv(res).splitlines()
    header = lines[0].split(",")
    assert "nan" not in "\n".join(lines).lower()
    for line in lines[1:]:
        row = dict(zip(header, line.split(","), strict=True))
        assert row["mean"] == row["median"] == ""  # no stable member: an empty field
        # a diverged member scores P (2 - t_d/t_f) = 1e6 (2 - 0.3/0.6)
        assert float(row["best"]) == pytest.approx(1.5e6)
