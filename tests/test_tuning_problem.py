"""The named tuning problem (aiofl.tuning.problem): a pymoo Problem whose _evaluate scores a
population in one evaluator call, replays a checkpoint, and fills F and G; a prepared run
passed to tune; ``aiofl tune`` preparing once."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from aiofl import layout as L
from aiofl.config import ConfigError, parse_config
from aiofl.tuning.evaluate import EvalSpec, PopulationResult
from aiofl.tuning.prepared import Prepared, prepare
from aiofl.tuning.problem import TuningProblem
from aiofl.tuning.search import tune
from aiofl.tuning.space import to_toml

FAST: dict[str, Any] = {
    "name": "fast-ladrc",
    "plant": "slfjm",
    "scenario": {"name": "nominal", "t_final": 20.0},
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
    "tune": {
        "objective": "itae",
        "t_final": 0.6,
        "population": 6,
        "generations": 3,
        "seed": 7,
        "parameters": {
            "eso.omega0": {"lo": 20.0, "hi": 2000.0, "log": True},
            "sef.omega_c": {"lo": 1.0, "hi": 100.0, "log": True},
        },
    },
}


class Known:
    """Stands in for the engine: ITAE = Σ log10(v)², ISU = Σ log10(v); counts its calls."""

    description = "known"

    def __init__(self) -> None:
        self.calls = 0

    def __call__(self, spec: EvalSpec, values: np.ndarray) -> PopulationResult:
        self.calls += 1
        m = np.zeros((values.shape[0], L.N_METRIC))
        m[:, L.M_ITAE] = (np.log10(values) ** 2).sum(axis=1)
        m[:, L.M_ISU] = np.log10(values).sum(axis=1)
        b = values.shape[0]
        return PopulationResult(m, np.zeros(b, dtype=bool), np.full(b, np.nan))

    def close(self) -> None:
        pass


def _prepared(**tune: Any) -> Prepared:
    return prepare(parse_config({**FAST, "tune": {**FAST["tune"], **tune}}, "fast"))


def test_one_call_scores_a_population_and_a_checkpoint_replays_it() -> None:
    prep = _prepared()
    ev = Known()
    problem = TuningProblem(prep, ev)
    assert (problem.n_var, problem.n_obj, problem.n_ieq_constr) == (2, 1, 0)
    out = problem.evaluate(prep.initial, return_as_dictionary=True)
    values = prep.space.decode(prep.initial)
    want = (np.log10(values) ** 2).sum(axis=1)
    assert ev.calls == 1 and out["F"].shape == (6, 1)
    np.testing.assert_array_equal(out["F"][:, 0], want)
    (gen,) = problem.generations
    assert gen.live and np.array_equal(gen.s, prep.initial)
    # a checkpoint's generation is replayed: the same F, no simulation
    again = Known()
    replayed = TuningProblem(prep, again, replay=[gen.stored()])
    out2 = replayed.evaluate(prep.initial, return_as_dictionary=True)
    assert again.calls == 0 and not replayed.generations[0].live
    np.testing.assert_array_equal(out2["F"], out["F"])
    # ... but only if the algorithm asks for the stored population
    with pytest.raises(ConfigError, match="replay diverged at generation 1"):
        TuningProblem(prep, again, replay=[gen.stored()]).evaluate(prep.initial[::-1].copy())


def test_nsga2_problem_fills_objectives_and_constraints() -> None:
    prep = _prepared(
        algorithm="nsga2", objectives=["itae", "isu"], constraints=["isu <= 2"], objective="opi"
    )
    problem = TuningProblem(prep, Known())
    assert (problem.n_obj, problem.n_ieq_constr) == (2, 2)
    out = problem.evaluate(prep.initial, return_as_dictionary=True)
    logs = np.log10(prep.space.decode(prep.initial))
    np.testing.assert_array_equal(out["F"][:, 0], (logs**2).sum(axis=1))
    np.testing.assert_array_equal(out["F"][:, 1], logs.sum(axis=1))
    assert (out["G"][:, 0] == 0).all()  # no member diverged
    np.testing.assert_allclose(out["G"][:, 1], logs.sum(axis=1) - 2.0, rtol=0, atol=1e-12)


def test_a_prepared_run_tunes_as_its_config_and_takes_no_overrides() -> None:
    prep = _prepared()
    a = tune(prep, progress=False, evaluator=Known())
    b = tune(parse_config(FAST, "fast"), progress=False, evaluator=Known())
    assert np.array_equal(a.values, b.values) and np.array_equal(a.objective, b.objective)
    assert a.best_values == b.best_values
    assert [h["best_so_far"] for h in a.history] == [h["best_so_far"] for h in b.history]
    with pytest.raises(TypeError, match="prepared run takes no settings"):
        tune(prep, progress=False, evaluator=Known(), seed=3)


def test_aiofl_tune_prepares_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from typer.testing import CliRunner

    import aiofl.tuning.prepared as prepared_module
    import aiofl.tuning.search as search_module
    from aiofl.cli.app import app

    calls: list[object] = []

    def counted(*args: Any, **kwargs: Any) -> Prepared:
        calls.append(args[0])
        return prepare(*args, **kwargs)

    monkeypatch.setattr(prepared_module, "prepare", counted)
    monkeypatch.setattr(search_module, "prepare", counted)
    path = tmp_path / "fast.toml"
    path.write_text(to_toml(FAST))
    args = ["tune", str(path), "--out", str(tmp_path / "out"), "--quiet", "--generations", "1"]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    assert calls == [str(path)]
    assert (tmp_path / "out" / "evaluations.csv").read_text().count("\n") == 1 + 6
