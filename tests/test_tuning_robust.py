"""Robust tuning (K model draws per candidate) and multi-objective tuning (NSGA-II)."""

from __future__ import annotations

import csv
import math
import tomllib
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from aiofl import layout as L
from aiofl.config import ConfigError, parse_config
from aiofl.controller import controller_batch
from aiofl.engine.simulation import simulate_batch
from aiofl.tuning.front import NoFeasibleDesign, choose, pareto_front
from aiofl.tuning.objective import (
    aggregate,
    objective_coefficients,
    objective_matrix,
    objective_values,
    parse_constraint,
    parse_quantity,
)
from aiofl.tuning.search import prepare, tune
from aiofl.tuning.space import parse_tune_settings, to_toml

# The short, coarse LADRC problem of tests/test_tuning.py: 0.6 s at dt = 1e-3.
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
        "objective": {"itae": 1.0, "isu": 0.1},
        "t_final": 0.6,
        "population": 6,
        "generations": 2,
        "seed": 7,
        "parameters": {
            "eso.omega0": {"lo": 50.0, "hi": 600.0, "log": True},
            "sef.omega_c": {"lo": 2.0, "hi": 30.0, "log": True},
        },
    },
}
# paired draws of the true plant (what an [uncertainty] table would produce)
DRAWS = [
    {"plant_scale": {"J_l": 1.2, "K_s": 0.85}},
    {"plant_scale": {"J_l": 0.8, "R_m": 1.15}},
    {"plant_scale": {"J_h": 1.2, "K_s": 1.1}},
]
UNSTABLE = {"plant_scale": {"J_l": 0.02}}  # 2 % of the load inertia: every candidate diverges
NSGA2 = {
    "algorithm": "nsga2",
    "objectives": ["itae", "isu"],
    "population": 8,
    "generations": 3,
}


def fast_config(**tune_updates: Any) -> Any:
    data = {**FAST, "tune": {**FAST["tune"], **tune_updates}}
    return parse_config(data, "fast test config")


def direct_metrics(cfg: Any, values: np.ndarray, names: tuple[str, ...], draws: list) -> Any:
    """Per candidate and scenario, simulate_batch called on its own: (B, K+1, 5)."""
    sc = replace(cfg.scenario, t_final=cfg.raw["tune"]["t_final"])
    scenarios = [sc] + [replace(sc, **d) for d in draws]
    out = np.zeros((values.shape[0], len(scenarios), 5))
    div = np.zeros((values.shape[0], len(scenarios)), dtype=bool)
    for b in range(values.shape[0]):
        ctrl = controller_batch(
            cfg.controller, {n: values[b : b + 1, j] for j, n in enumerate(names)}
        )
        for k, s in enumerate(scenarios):
            r = simulate_batch(cfg.plant, ctrl, s, dt=cfg.dt, method=cfg.method)
            out[b, k], div[b, k] = r.metrics[0], r.failed[0]
    return out, div


# ------------------------------------------------------------------ robust scoring
@pytest.mark.parametrize(("kind", "alpha"), [("mean", 0.9), ("worst", 0.9), ("cvar", 0.5)])
def test_robust_score_is_the_aggregate_of_per_draw_simulations(kind: str, alpha: float) -> None:
    cfg = fast_config(robust={"draws": 3, "aggregate": kind, "alpha": alpha}, generations=1)
    res = tune(cfg, draws=DRAWS, progress=False)
    m, d = direct_metrics(cfg, res.values, res.names, DRAWS)
    assert not d.any()
    c = objective_coefficients(res.settings, cfg)
    per = m @ c  # (B, K+1): nominal + 3 draws
    if kind == "mean":
        want = per.mean(axis=1)
    elif kind == "worst":
        want = per.max(axis=1)
    else:  # CVaR_0.5 of 4 values: the mean of the worst ceil(0.5 * 4) = 2
        want = np.sort(per, axis=1)[:, 2:].mean(axis=1)
    np.testing.assert_allclose(res.objective, want, rtol=1e-12)
    # best_metrics are the nominal plant's
    ib = int(np.argmin(res.objective))
    np.testing.assert_allclose(list(res.best_metrics.values()), m[ib, 0], rtol=1e-12)


def test_robust_draws_are_the_uncertainty_tables_common_random_numbers() -> None:
    from aiofl.uncertainty import sample_draws

    unc = {"seed": 3, "parameters": {"J_l": {"uniform": 0.2}, "K_s": {"normal": 0.05}}}
    data = {**FAST, "uncertainty": unc, "tune": {**FAST["tune"], "robust": {"draws": 3}}}
    cfg = parse_config(data, "robust")
    other = parse_config(  # another design sees the same draws (paired comparisons)
        {**data, "controller": {**FAST["controller"], "sef": {"omega_c": 3.0}}}, "other"
    )
    a, b = prepare(cfg).spec.draws, prepare(other).spec.draws
    assert a == b and len(a) == 3
    want = sample_draws(cfg.uncertainty, draws=3).scenarios(cfg.scenario)
    for d, w in zip(a, want, strict=True):
        assert d["plant_scale"] == dict(w.plant_scale)
        assert d["plant_scale"] != {"J_l": 1.0, "K_s": 1.0}
    r1 = tune(cfg, progress=False, generations=1)
    r2 = tune(cfg, draws=list(a), progress=False, generations=1)
    np.testing.assert_array_equal(r1.objective, r2.objective)


def test_a_diverged_draw_makes_every_candidate_infeasible() -> None:
    penalty = 1e6
    cfg = fast_config(robust={"draws": 2, "aggregate": "mean"}, generations=1)
    ok = tune(cfg, draws=DRAWS[:2], progress=False)
    assert (ok.objective < penalty).all() and not ok.failed.any()
    bad = tune(cfg, draws=[DRAWS[0], UNSTABLE], progress=False)
    assert bad.failed.all()
    # one of 3 members diverged at t_d < t_f: P (2 - (1 + 1 + t_d/t_f)/3), in (P, 4/3 P]
    assert (bad.objective > penalty).all() and (bad.objective <= penalty * 4 / 3).all()
    # NSGA-II: a real constraint (G[:, 0] = number of diverged members), never in the front
    with pytest.raises(NoFeasibleDesign, match="no design"):
        tune(
            fast_config(robust={"draws": 2}, **{**NSGA2, "generations": 1}),
            draws=[DRAWS[0], UNSTABLE],
            progress=False,
        )


def test_robust_objective_penalty_and_aggregates_by_definition() -> None:
    m = np.zeros((2, 3, 5))
    m[..., L.M_ITAE] = [[1.0, 2.0, 4.0], [1.0, 5.0, 0.5]]
    d = np.array([[False, False, False], [False, True, False]])
    t = np.array([[np.nan] * 3, [np.nan, 0.3, np.nan]])
    c = np.eye(5)[L.M_ITAE]
    j = objective_values(m, d, t, c, 10.0, 0.6, "mean", 0.9)
    assert j[0] == pytest.approx(7 / 3)
    assert j[1] == pytest.approx(10.0 * (2 - (1 + 0.5 + 1) / 3))
    f, g, raw = objective_matrix(
        [parse_quantity("itae:worst")],
        [parse_constraint("stable_fraction >= 1")],
        m,
        d,
        "mean",
        0.9,
        cap=1e9,
    )
    assert f[0, 0] == 4.0 and f[1, 0] == 1e9  # a diverged member makes the worst +inf
    assert g[0].tolist() == [0.0, 0.0] and g[1, 0] == 1 and g[1, 1] == pytest.approx(1 / 3)
    assert raw[:, 0] == pytest.approx([1.0, 2 / 3])


@settings(max_examples=60, deadline=None)
@given(
    arrays(np.float64, st.tuples(st.integers(1, 4), st.integers(1, 9)), elements=st.floats(0, 1e3)),
    st.floats(0.01, 0.99),
)
def test_aggregates_equal_their_definitions(v: np.ndarray, alpha: float) -> None:
    n = v.shape[1]
    np.testing.assert_allclose(aggregate(v, "mean"), v.mean(axis=1))
    np.testing.assert_array_equal(aggregate(v, "worst"), v.max(axis=1))
    np.testing.assert_array_equal(aggregate(v, "nominal"), v[:, 0])
    tail = math.ceil((1 - alpha) * n - 1e-9)
    want = [np.mean(sorted(row)[n - max(1, tail) :]) for row in v]
    np.testing.assert_allclose(aggregate(v, "cvar", alpha), want)
    assert (aggregate(v, "cvar", alpha) >= aggregate(v, "mean") - 1e-9).all()
    assert (aggregate(v, "cvar", alpha) <= aggregate(v, "worst") * (1 + 1e-12)).all()
    v2 = v.copy()
    v2[:, -1] = np.nan  # a diverged member
    for kind in ("mean", "worst", "cvar"):
        assert np.isinf(aggregate(v2, kind, alpha)).all()


# ----------------------------------------------------------------- settings & grammar
def test_robust_needs_an_uncertainty_table_and_bounds_the_generation() -> None:
    cfg = fast_config(robust={"draws": 4})
    with pytest.raises(ConfigError, match=r"tune\.robust.*\[uncertainty\]"):
        prepare(cfg)
    with pytest.raises(ConfigError, match=r"4 draws given|draws = 4 but 3"):
        prepare(cfg, draws=DRAWS)
    with pytest.raises(ConfigError, match="members per generation; allowed: at most 10000"):
        parse_tune_settings({**FAST["tune"], "population": 1000, "robust": {"draws": 10}})
    with pytest.raises(ConfigError, match=r"tune\.robust\.draws.*less than or equal to 1000"):
        parse_tune_settings({**FAST["tune"], "robust": {"draws": 5000}})
    with pytest.raises(ConfigError, match=r"tune\.robust\.aggregate"):
        parse_tune_settings({**FAST["tune"], "robust": {"draws": 2, "aggregate": "median"}})
    with pytest.raises(ConfigError, match='need algorithm = "nsga2"'):
        parse_tune_settings({**FAST["tune"], "objectives": ["itae", "isu"]})
    with pytest.raises(ConfigError, match="needs objectives"):
        parse_tune_settings({**FAST["tune"], "algorithm": "nsga2"})
    with pytest.raises(ConfigError, match="stable_fraction is not an objective"):
        parse_tune_settings({**FAST["tune"], **NSGA2, "objectives": ["itae", "stable_fraction"]})
    with pytest.raises(ConfigError, match=r"itae:cvar: an aggregate over draws needs robust"):
        parse_tune_settings({**FAST["tune"], **NSGA2, "objectives": ["itae:cvar", "isu"]})
    with pytest.raises(ConfigError, match=r"tune\.constraints.*not 'QUANTITY <= NUMBER'"):
        parse_tune_settings({**FAST["tune"], **NSGA2, "constraints": ["isu < 3"]})


@pytest.mark.parametrize(
    "text",
    [
        "isu < 15",
        "isu <= 1e400",
        "__import__('os').system('x') <= 1",
        "isu <= 15.5 or itae >= 0",
        "energy <= 3",
        "itae:median <= 1",
        "stable_fraction:worst >= 1",
        "isu <= nan",
    ],
)
def test_constraint_grammar_refuses_anything_else(text: str) -> None:
    with pytest.raises(ValueError, match=r"allowed|not 'QUANTITY|finite|no aggregate"):
        parse_constraint(text)


def test_constraint_grammar_reads_the_documented_forms() -> None:
    c = parse_constraint("isu <= 15.5")
    assert (c.quantity.metric, c.quantity.aggregate, c.upper, c.bound) == ("isu", None, True, 15.5)
    c = parse_constraint(" itae:cvar>=-2e-3 ")
    assert (c.quantity.text(), c.upper, c.bound) == ("itae:cvar", False, -2e-3)
    assert parse_constraint("stable_fraction >= 1").text() == "stable_fraction >= 1"


# ------------------------------------------------------------------------ NSGA-II
@settings(max_examples=60, deadline=None)
@given(
    arrays(np.float64, st.tuples(st.integers(1, 30), st.just(2)), elements=st.floats(0, 10)),
    st.data(),
)
def test_front_is_non_dominated_and_the_choice_feasible(f: np.ndarray, data: Any) -> None:
    g = data.draw(arrays(np.float64, (f.shape[0], 2), elements=st.floats(-1, 1)))
    idx = pareto_front(f, g)
    feasible = (g <= 0).all(axis=1)
    assert feasible[idx].all()
    for i in idx:  # no feasible design dominates a front design
        dom = (f[feasible] <= f[i]).all(axis=1) & (f[feasible] < f[i]).any(axis=1)
        assert not dom.any()
    for j in np.flatnonzero(feasible):  # every feasible design is on the front or dominated
        dom = (f[idx] <= f[j]).all(axis=1) & (f[idx] < f[j]).any(axis=1)
        assert dom.any() or (f[idx] == f[j]).all(axis=1).any()
    if idx.size:
        for rule in ("best-first-under-constraints", "knee"):
            assert 0 <= choose(f[idx], rule) < idx.size
        best = choose(f[idx], "best-first-under-constraints")
        assert f[idx][best, 0] == f[feasible, 0].min()


def test_nsga2_front_respects_constraints_and_chooses_best_first() -> None:
    free = tune(fast_config(**NSGA2), progress=False)
    fr = free.front
    assert fr.F.shape[0] >= 2 and fr.constraints == ()
    isu_best_itae = fr.F[np.argmin(fr.F[:, 0]), 1]
    bound = float(np.median(fr.F[:, 1]))
    assert isu_best_itae > bound  # the unconstrained choice would violate the constraint
    con = tune(fast_config(**NSGA2, constraints=[f"isu <= {bound!r}"]), progress=False)
    cf = con.front
    assert (cf.raw[:, 0] <= bound).all() and (cf.F[:, 1] <= bound).all()
    chosen = cf.F[cf.chosen]
    assert chosen[1] <= bound and chosen[0] == cf.F[:, 0].min()
    # the chosen values are best.toml's, and its nominal ISU is the front's
    assert con.best_metrics is not None and con.best_metrics["isu"] == pytest.approx(chosen[1])


def _front_rows(path: Path) -> list[dict[str, str]]:
    with path.open() as fh:
        return list(csv.DictReader(fh))


@pytest.mark.slow
def test_cli_nsga2_writes_front_and_a_best_toml_that_simulates(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from aiofl.cli.app import app

    data = {**FAST, "tune": {**FAST["tune"], **NSGA2, "choose": "knee"}}
    path = tmp_path / "mo.toml"
    path.write_text(to_toml(data))
    runner = CliRunner()
    outs = [tmp_path / "a", tmp_path / "b"]
    for out in outs:
        res = runner.invoke(app, ["tune", str(path), "--out", str(out), "--quiet"])
        assert res.exit_code == 0, res.output
        assert "front.csv" in res.output
    a, b = ((o / "front.csv").read_bytes() for o in outs)
    assert a == b  # same seed, same front
    rows = _front_rows(outs[0] / "front.csv")
    f = np.array([[float(r["itae"]), float(r["isu"])] for r in rows])
    for i in range(len(f)):
        assert not ((f <= f[i]).all(axis=1) & (f < f[i]).any(axis=1)).any()
    assert sum(int(r["chosen"]) for r in rows) == 1
    assert (outs[0] / "front.png").read_bytes()[:4] == b"\x89PNG"
    best = tomllib.loads((outs[0] / "best.toml").read_text())
    chosen = next(r for r in rows if r["chosen"] == "1")
    assert best["controller"]["eso"]["omega0"] == float(chosen["eso.omega0"])
    res = runner.invoke(app, ["simulate", str(outs[0] / "best.toml"), "--out", str(tmp_path / "s")])
    assert res.exit_code == 0, res.output
    res = runner.invoke(
        app, ["tune", str(path), "--out", str(tmp_path / "c"), "--quiet", "--seed", "8"]
    )
    assert res.exit_code == 0
    assert (tmp_path / "c" / "front.csv").read_bytes() != a  # the seed matters


def test_robust_dask_chunks_and_resume_equal_the_local_run(tmp_path: Path) -> None:
    distributed = pytest.importorskip("distributed")
    from aiofl.tuning.evaluate import DaskEvaluator, evaluate_chunk

    cfg = fast_config(robust={"draws": 3, "aggregate": "worst"}, population=5)
    prep = prepare(cfg, draws=DRAWS)
    values = prep.space.decode(prep.initial)
    local = evaluate_chunk(prep.spec, values)
    assert local.metrics.shape == (5, 4, L.N_SCORE) and local.failed.shape == (5, 4)
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        remote = DaskEvaluator(client, chunks=2)(prep.spec, values)  # 3 + 2 candidates
    assert np.array_equal(local.metrics, remote.metrics, equal_nan=True)
    assert np.array_equal(local.failed, remote.failed)
    full = tune(cfg, draws=DRAWS, progress=False)
    tune(cfg, draws=DRAWS, progress=False, checkpoint_dir=tmp_path, generations=1)
    resumed = tune(cfg, draws=DRAWS, progress=False, checkpoint_dir=tmp_path, resume=True)
    assert resumed.live_evaluations == 5  # generation 1 replayed from the 3-D checkpoint
    assert np.array_equal(full.objective, resumed.objective)
    assert full.best_values == resumed.best_values
