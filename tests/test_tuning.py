"""GA tuning (pymoo), checkpoint/resume, Dask evaluation, and exact tracking by inversion."""

from __future__ import annotations

import math
import tomllib
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from aiofl import layout as L
from aiofl.analysis.exact_tracking import exact_tracking, exact_tracking_cost, exact_tracking_input
from aiofl.config import ConfigError, load_config, parse_config
from aiofl.tuning.evaluate import EvalSpec, LocalEvaluator, PopulationResult, evaluate_chunk
from aiofl.tuning.objective import objective_coefficients, objective_values
from aiofl.tuning.results import write_outputs
from aiofl.tuning.search import prepare, tune
from aiofl.tuning.space import (
    SearchSpace,
    TuneSettings,
    parse_tune_settings,
    to_toml,
    used_parameters,
)

# A short, coarse LADRC problem on the SLFJM: 0.6 s at dt = 1e-3 (600 RK4 steps/member).
FAST = {
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
        "objective": "opi",
        "t_final": 0.6,
        "population": 8,
        "generations": 3,
        "seed": 7,
        "parameters": {
            "eso.omega0": {"lo": 20.0, "hi": 2000.0, "log": True},
            "sef.omega_c": {"lo": 1.0, "hi": 100.0, "log": True},
            "law.b0": {"lo": 1e3, "hi": 1e5, "log": True},
        },
    },
}


def fast_config(**tune_updates: Any) -> Any:
    data = {**FAST, "tune": {**FAST["tune"], **tune_updates}}
    return parse_config(data, "fast test config")


def assert_same_run(a: Any, b: Any) -> None:
    """Bit-identical tuning results."""
    assert a.names == b.names
    assert np.array_equal(a.values, b.values)
    assert np.array_equal(a.objective, b.objective)
    assert np.array_equal(a.generation, b.generation)
    assert a.best_values == b.best_values
    assert a.best_objective == b.best_objective


# ------------------------------------------------------------------ a fake engine
class QuadraticEvaluator:
    """Stands in for the engine: ITAE = Σ((log10 v - log10 v*)²) — optimum v* known."""

    description = "quadratic"

    def __init__(self, optimum: dict[str, float], names: tuple[str, ...]) -> None:
        self.target = np.log10([optimum[n] for n in names])
        self.calls = 0

    def __call__(self, spec: EvalSpec, values: np.ndarray) -> PopulationResult:
        self.calls += 1
        m = np.zeros((values.shape[0], L.N_METRIC))
        m[:, L.M_ITAE] = ((np.log10(values) - self.target) ** 2).sum(axis=1)
        b = values.shape[0]
        return PopulationResult(m, np.zeros(b, dtype=bool), np.full(b, np.nan))

    def close(self) -> None:
        pass


@pytest.mark.parametrize("algorithm", ["ga", "de", "cmaes"])
def test_runner_finds_known_optimum_of_quadratic(algorithm: str) -> None:
    cfg = fast_config()
    optimum = {"eso.omega0": 321.0, "sef.omega_c": 4.2, "law.b0": 2.68e4}
    ev = QuadraticEvaluator(optimum, tuple(FAST["tune"]["parameters"]))
    res = tune(
        cfg,
        progress=False,
        evaluator=ev,
        algorithm=algorithm,
        population=24,
        generations=40,
        objective="itae",
    )
    assert ev.calls == 40  # one batched call per generation
    for name, want in optimum.items():
        assert res.best_values[name] == pytest.approx(want, rel=0.05), name
    assert res.best_objective < 1e-3
    # history is consistent with the evaluations
    assert [h["generation"] for h in res.history] == list(range(1, 41))
    assert res.history[-1]["best_so_far"] == res.best_objective
    assert res.history[-1]["total_evaluations"] == res.n_evaluations


@pytest.mark.parametrize("algorithm", ["ga", "de", "cmaes"])
def test_same_seed_same_result_and_resume_replays_bit_for_bit(
    algorithm: str, tmp_path: Path
) -> None:
    cfg = fast_config()
    names = tuple(FAST["tune"]["parameters"])
    optimum = {"eso.omega0": 100.0, "sef.omega_c": 3.0, "law.b0": 1e4}
    kw = {"algorithm": algorithm, "population": 10, "generations": 6, "objective": "itae"}
    a = tune(cfg, progress=False, evaluator=QuadraticEvaluator(optimum, names), **kw)
    b = tune(cfg, progress=False, evaluator=QuadraticEvaluator(optimum, names), **kw)
    assert_same_run(a, b)
    other = tune(
        cfg, progress=False, evaluator=QuadraticEvaluator(optimum, names), **{**kw, "seed": 8}
    )
    assert not np.array_equal(a.values, other.values)

    class Killed(QuadraticEvaluator):
        def __call__(self, spec: EvalSpec, values: np.ndarray) -> PopulationResult:
            if self.calls == 4:
                raise KeyboardInterrupt
            return super().__call__(spec, values)

    with pytest.raises(KeyboardInterrupt):
        tune(cfg, progress=False, evaluator=Killed(optimum, names), checkpoint_dir=tmp_path, **kw)
    assert (tmp_path / "checkpoint.npz").is_file()
    ev = QuadraticEvaluator(optimum, names)
    c = tune(cfg, progress=False, evaluator=ev, checkpoint_dir=tmp_path, resume=True, **kw)
    assert ev.calls == 2  # 4 generations replayed from the checkpoint, 2 simulated
    assert c.live_evaluations == sum(h["evaluations"] for h in c.history[4:])
    assert_same_run(a, c)


def test_resume_rejects_a_different_run(tmp_path: Path) -> None:
    cfg = fast_config()
    names = tuple(FAST["tune"]["parameters"])
    ev = QuadraticEvaluator({n: 10.0 for n in names}, names)
    tune(cfg, progress=False, evaluator=ev, checkpoint_dir=tmp_path, objective="itae")
    with pytest.raises(ConfigError, match="different tuning run"):
        tune(
            cfg,
            progress=False,
            evaluator=ev,
            checkpoint_dir=tmp_path,
            resume=True,
            objective="itae",
            seed=99,
        )


# ---------------------------------------------------------------- the real engine
@pytest.mark.slow
def test_engine_run_resume_and_best_toml(tmp_path: Path) -> None:
    cfg = fast_config()
    full = tune(cfg, progress=False, checkpoint_dir=tmp_path / "full")
    assert full.n_evaluations >= 3 * 7
    # the config's own values are member 0 of the initial population (include_initial)
    start = np.array([cfg.controller.value(n) for n in full.names])
    assert np.allclose(full.values[0], start, rtol=1e-12)
    assert full.best_objective <= full.objective[0]

    # a run killed after generation 1, then resumed, ends exactly where `full` ended
    class KillAfterOne(LocalEvaluator):
        calls = 0

        def __call__(self, spec: EvalSpec, values: np.ndarray) -> PopulationResult:
            KillAfterOne.calls += 1
            if KillAfterOne.calls == 2:
                raise KeyboardInterrupt
            return super().__call__(spec, values)

    part = tmp_path / "part"
    with pytest.raises(KeyboardInterrupt):
        tune(cfg, progress=False, checkpoint_dir=part, evaluator=KillAfterOne())
    resumed = tune(cfg, progress=False, checkpoint_dir=part, resume=True)
    assert_same_run(full, resumed)

    # best.toml loads, and simulating it alone over the tuning horizon gives the same numbers
    summary = write_outputs(full, tmp_path / "full")
    for name in ("best.toml", "history.csv", "evaluations.csv", "convergence.png"):
        assert (tmp_path / "full" / name).stat().st_size > 0
    best = load_config(tmp_path / "full" / "best.toml")
    for name, val in full.best_values.items():
        assert best.controller.value(name) == val
    sim = best.simulate(store=False)
    assert summary["full_horizon"]["itae"] == sim.metrics["itae"]
    short = replace(best, scenario=replace(best.scenario, t_final=0.6)).simulate(store=False)
    assert short.metrics == full.best_metrics
    assert short.opi(best.weights) == pytest.approx(full.best_objective, rel=1e-12)
    history = (tmp_path / "full" / "history.csv").read_text().splitlines()
    assert history[0].startswith("generation,evaluations,total_evaluations,best,mean")
    assert len(history) == 1 + 3


@pytest.mark.slow
def test_diverging_members_get_finite_penalties() -> None:
    # dt = 1e-3 with omega0 up to 1e5: RK4 is unstable for observer poles beyond ~2.8e3
    cfg = fast_config(
        parameters={"eso.omega0": {"lo": 100.0, "hi": 1e5, "log": True}},
        population=12,
        generations=2,
        divergence_penalty=1e4,
    )
    res = tune(cfg, progress=False)
    assert res.failed.any() and not res.failed.all()
    assert np.isfinite(res.objective).all()
    pen = res.objective[res.failed]
    assert ((pen >= 1e4) & (pen <= 2e4)).all()
    assert res.objective[~res.failed].max() < 1e4
    assert sum(h["failed"] for h in res.history) == int(res.failed.sum())
    assert not res.best_values["eso.omega0"] > 3e3


@pytest.mark.slow
def test_saturation_bound_optimum_on_engine() -> None:
    """Minimising ISU over u_max: a loop that is saturated (almost) throughout has
    ISU ≈ u_max²·t_f, so the optimum is at the lower bound."""
    cfg = fast_config(
        parameters={"law.u_max": {"lo": 1e-4, "hi": 10.0, "log": True}},
        objective="isu",
        population=8,
        generations=6,
    )
    res = tune(cfg, progress=False)
    u_max = res.best_values["law.u_max"]
    assert u_max < 1e-3
    assert res.best_metrics is not None
    # |u| <= u_max always, and = u_max except in the first instants (u(0) = 0)
    assert res.best_metrics["isu"] <= u_max**2 * 0.6
    assert res.best_metrics["isu"] == pytest.approx(u_max**2 * 0.6, rel=1e-3)
    assert res.best_objective == min(res.objective)


@pytest.mark.slow
def test_dask_path_equals_local_path() -> None:
    distributed = pytest.importorskip("distributed")
    from aiofl.tuning.evaluate import DaskEvaluator

    cfg = fast_config(population=10, generations=2)
    prep = prepare(cfg)
    values = prep.space.decode(prep.initial)
    local = evaluate_chunk(prep.spec, values)
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        ev = DaskEvaluator(client, chunks=3)  # 10 members -> chunks of 4, 3, 3
        remote = ev(prep.spec, values)
        assert np.array_equal(local.metrics, remote.metrics, equal_nan=True)
        assert np.array_equal(local.failed, remote.failed)
        via_dask = tune(cfg, progress=False, scheduler=client)
    via_local = tune(cfg, progress=False)
    assert_same_run(via_local, via_dask)
    assert via_dask.evaluator.startswith("dask")


# ----------------------------------------------------------------- settings, CLI
def test_settings_errors_name_the_field() -> None:
    good = FAST["tune"]
    cases = {
        "reversed": (
            {"parameters": {"eso.omega0": {"lo": 10.0, "hi": 1.0}}},
            "lo = 10.0 must be < hi",
        ),
        "unknown": ({"parameters": {"eso.omegaX": {"lo": 1.0, "hi": 2.0}}}, "unknown parameter"),
        "zero population": ({"population": 0}, "tune.population"),
        "log of zero": (
            {"parameters": {"td.omega": {"lo": 0.0, "hi": 2.0, "log": True}}},
            "lo > 0",
        ),
        "extra key": ({"popsize": 3}, "tune.popsize: unknown key"),
        "bad objective": ({"objective": "speed"}, "allowed: opi, itae"),
        "bad metric": ({"objective": {"itae": 1.0, "foo": 2.0}}, "unknown metric"),
        "algorithm": ({"algorithm": "pso"}, "tune.algorithm"),
        "no parameters": ({"parameters": {}}, "no parameters"),
    }
    for label, (update, msg) in cases.items():
        with pytest.raises(ConfigError, match=msg):
            parse_tune_settings({**good, **update})
        assert label
    with pytest.raises(ConfigError, match="no \\[tune\\] table"):
        parse_tune_settings(None)


def test_parameters_must_act_on_the_structure_and_stay_in_range() -> None:
    with pytest.raises(ConfigError, match=r"'td\.R': has no effect"):
        prepare(fast_config(parameters={"td.R": {"lo": 1.0, "hi": 10.0}}))
    with pytest.raises(ConfigError, match=r"'law\.b0'\.lo = -1\.0: outside the range"):
        prepare(fast_config(parameters={"law.b0": {"lo": -1.0, "hi": 10.0}}))
    leso = load_config("paper-s1-leso").controller
    used = used_parameters(leso)
    assert {"td.R", "sef.delta2", "eso.alpha5", "law.b0"} <= used
    assert not {"sef.delta3", "td.omega", "sef.omega_c", "eso.k_alpha"} & used


@pytest.mark.parametrize(
    "edit",
    [
        {"parameters": {"eso.omega0": {"lo": 2000.0, "hi": 20.0}}},
        {"parameters": {"eso.nope": {"lo": 1.0, "hi": 2.0}}},
        {"population": 0},
        {"parameters": {"td.R": {"lo": 1.0, "hi": 2.0}}},
    ],
)
def test_cli_bad_config_exits_2_and_writes_nothing(edit: dict[str, Any], tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from aiofl.cli.app import app

    data = {**FAST, "tune": {**FAST["tune"], **edit}}
    path = tmp_path / "bad.toml"
    path.write_text(to_toml(data))
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["tune", str(path), "--out", str(out)])
    assert res.exit_code == 2, res.output
    assert "aiofl: error:" in res.stderr and "tune" in res.stderr
    assert "Traceback" not in res.output
    assert not out.exists()
    assert not list(tmp_path.glob(".out.staging-*"))


@pytest.mark.slow
def test_cli_tune_writes_outputs_and_resumes(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from aiofl.cli.app import app

    path = tmp_path / "fast.toml"
    path.write_text(to_toml(FAST))
    out = tmp_path / "out"
    runner = CliRunner()
    res = runner.invoke(
        app, ["tune", str(path), "--out", str(out), "--quiet", "--generations", "2"]
    )
    assert res.exit_code == 0, res.output
    first = (out / "evaluations.csv").read_text()
    # extend the finished run to 3 generations: 2 replayed, 1 simulated
    res = runner.invoke(app, ["tune", str(path), "--out", str(out), "--quiet", "--resume"])
    assert res.exit_code == 0, res.output
    extended = (out / "evaluations.csv").read_text()
    assert extended.startswith(first)
    res = runner.invoke(app, ["tune", str(path), "--out", str(tmp_path / "fresh"), "--quiet"])
    assert (tmp_path / "fresh" / "evaluations.csv").read_text() == extended
    res = runner.invoke(app, ["simulate", str(out / "best.toml"), "--out", str(tmp_path / "sim")])
    assert res.exit_code == 0, res.output


# ------------------------------------------------------------- space & objective
def test_search_space_round_trip_and_bounds() -> None:
    st = TuneSettings.model_validate(FAST["tune"])
    sp = SearchSpace(st.parameters)
    s = np.array([[0.0, 0.5, 1.0], [0.25, 0.0, 0.75]])
    v = sp.decode(s)
    assert v[0, 0] == 20.0 and v[0, 2] == 1e5 and v[1, 1] == 1.0  # exact at the bounds
    assert v[0, 1] == pytest.approx(10.0)  # geometric midpoint of [1, 100]
    assert np.allclose(sp.encode(v), s, atol=1e-14)


def test_opi_objective_matches_eq22_and_penalty_formula() -> None:
    cfg = fast_config()
    st = TuneSettings.model_validate(FAST["tune"])
    c = objective_coefficients(st, cfg)
    m = np.array([[12.0, 1.0, 1.0, 3.0, 4.0], [1.0, 1.0, 1.0, 1.0, 1.0]])
    from aiofl.components.metrics import opi

    j = objective_values(m, np.array([False, True]), np.array([np.nan, 0.15]), c, 100.0, 0.6)
    assert j[0] == pytest.approx(opi(12.0, 3.0, 4.0, cfg.weights))
    assert j[1] == pytest.approx(100.0 * (2 - 0.25))
    nan = objective_values(np.full((1, 5), np.nan), np.array([False]), np.array([np.nan]), c, 5, 1)
    assert nan[0] == 10.0
    st2 = TuneSettings.model_validate({**FAST["tune"], "objective": {"itae": 2.0, "isu": 0.5}})
    assert objective_coefficients(st2, cfg).tolist() == [2.0, 0, 0, 0.5, 0]


def test_to_toml_round_trips_configs_exactly() -> None:
    for preset in ("paper-s2-leso", "paper-s3-inleso"):
        raw = load_config(preset).raw
        data = {**raw, "tune": FAST["tune"]}
        data["controller"]["eso"]["omega0"] = 0.1 + 0.2  # a float that needs 17 digits
        text = to_toml(data, "a header\nline two")
        assert text.startswith("# a header\n# line two\n")
        back = tomllib.loads(text)
        assert back == data
        parse_config(back)


# --------------------------------------------------------------- exact tracking
def test_exact_tracking_input_tracks_open_loop_on_slfjm() -> None:
    from scipy.integrate import solve_ivp

    cfg = load_config("paper-s1-leso")
    sc = replace(cfg.scenario, t_final=2.0)
    ex = exact_tracking(cfg.plant, sc, dt=1e-4)
    assert ex.x.shape == (20001, 4) and ex.u.shape == (20001,)
    p = cfg.plant.param_vector()

    def rhs(t: float, x: np.ndarray) -> np.ndarray:
        return cfg.plant.rhs(x, float(np.interp(t, ex.t, ex.u)), 0.0, p)

    sol = solve_ivp(
        rhs, (0.0, 2.0), ex.x[0], t_eval=ex.t[::500], rtol=1e-11, atol=1e-12, max_step=1e-3
    )
    y = sol.y[0] + sol.y[1]
    r = sc.reference.evaluate(ex.t[::500])
    assert np.max(np.abs(y - r)) < 1e-7
    assert np.max(np.abs(sol.y.T - ex.x[::500])) < 1e-6
    # the state starts off rest: y(0) = 0 but ydot(0) = pi/2
    assert ex.x[0, 2] + ex.x[0, 3] == pytest.approx(np.pi / 2)


def test_exact_tracking_cancels_matched_disturbance_and_parameter_change() -> None:
    cfg = load_config("paper-s2-leso")
    ex = exact_tracking(cfg.plant, replace(cfg.scenario, t_final=12.0), dt=1e-3)
    p = cfg.plant.param_vector(cfg.scenario.plant_overrides, cfg.scenario.plant_scale)
    # check the state equations pointwise: xdot (finite differences) = f + g u + bd d
    k = np.arange(100, 12000, 997)
    for i in k:
        d = 0.5 if ex.t[i] >= 10.0 else 0.0
        xdot = (ex.x[i + 1] - ex.x[i - 1]) / (2e-3)
        assert np.allclose(xdot, cfg.plant.rhs(ex.x[i], ex.u[i], d, p), rtol=1e-4, atol=1e-4)
    # the 0.5 N·m step pushes like u does (b_d = g·R_m/(K_m K_g)), so u drops by that much
    kick = ex.u[10000] - ex.u[9999]
    assert kick == pytest.approx(-0.5 * 2.6 / (0.00767 * 70), rel=2e-3)


def test_generic_normal_form_inverse_matches_closed_form() -> None:
    from aiofl.plants import get_plant
    from aiofl.plants.base import Plant
    from aiofl.scenario import Reference

    pend = get_plant("pendulum")

    def normal_form(x: np.ndarray, p: np.ndarray) -> tuple[float, ...]:
        m, l, c, g = p[0], p[1], p[2], p[3]
        return (x[0], x[1], -g / l * math.sin(x[0]) - c / (m * l * l) * x[1], 1 / (m * l * l))

    plant = Plant(
        name="pendulum-nf",
        n_states=2,
        f=pend.f,
        g=pend.g,
        h=pend.h,
        bd=pend.bd,
        params=pend.params,
        relative_degree=2,
        normal_form=normal_form,
    )
    ref = Reference(amplitude=0.3, omega=1.5)
    t = np.linspace(0, 3, 31)
    ex = exact_tracking_input(plant, ref, t, disturbance=0.2)
    m, l, c, g = 1.0, 0.5, 0.1, 9.81
    r = 0.3 * np.sin(1.5 * t)
    rd = 0.45 * np.cos(1.5 * t)
    rdd = -0.675 * np.sin(1.5 * t)
    u = m * l * l * rdd + m * g * l * np.sin(r) + c * rd - 0.2  # bd = g: c = 1
    assert np.allclose(ex.u, u, atol=1e-9)
    assert np.allclose(ex.x[:, 0], r, atol=1e-10)
    with pytest.raises(ValueError, match="smooth reference"):
        exact_tracking_input(plant, Reference(kind="step", amplitude=1.0), t)
    with pytest.raises(ValueError, match="relative degree"):
        exact_tracking_input(replace(plant, relative_degree=1), ref, t)


def test_exact_tracking_cost_of_the_paper_scenarios() -> None:
    s1 = exact_tracking_cost(load_config("paper-s1-leso"))
    s3 = exact_tracking_cost(load_config("paper-s3-leso"))
    s2 = exact_tracking_cost(load_config("paper-s2-leso"))
    assert s1 == s3  # noise does not change the true output
    assert s1["t_final"] == 20.0
    assert 10.0 < s1["isu"] < 20.0 and s1["iau"] > 0
    # scenario 2 holds 0.5 N·m for 10 s: ~ (0.5·R_m/(K_m K_g))² · 10 s more energy
    extra = (0.5 * 2.6 / (0.00767 * 70)) ** 2 * 10
    assert s2["isu"] > s1["isu"] + 0.8 * extra


def test_retuned_presets_state_their_recipe_and_load() -> None:
    from aiofl.config import list_presets
    from aiofl.tuning.search import describe_tuning

    names = [n for n in list_presets() if n.startswith("retuned-")]
    assert len(names) == 9
    for name in names:
        cfg = load_config(name)
        prep = prepare(cfg)  # its [tune] table is valid for its structure
        assert prep.settings.include_initial is False  # re-running reproduces the preset
        assert cfg.scenario.t_final == 20.0
        assert "seed 1" in describe_tuning(cfg)
        for pname in prep.space.names:  # the tuned values lie inside the bounds
            b = prep.settings.parameters[pname]
            assert b.lo <= cfg.controller.value(pname) <= b.hi
    assert describe_tuning(load_config("paper-s1-leso")) is None


def test_prepare_finds_a_relative_plant_file_from_another_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A config naming ``plant = "pend.toml"`` next to it tunes from any working folder:
    the tuning spec (re-parsed by the workers) carries the file's absolute path."""
    from test_plant_files import PLANT, RUN

    (tmp_path / "cfg").mkdir()
    (tmp_path / "cfg" / "pend.toml").write_text(PLANT)
    tune_table = (
        "\n[tune]\npopulation = 4\ngenerations = 1\nt_final = 1.0\n"
        '[tune.parameters]\n"eso.omega0" = { lo = 10.0, hi = 100.0 }\n'
    )
    cfg_path = tmp_path / "cfg" / "run.toml"
    cfg_path.write_text(RUN.format(plant="pend.toml") + tune_table)
    monkeypatch.chdir(tmp_path)
    prep = prepare(cfg_path)
    plant_path = Path(prep.spec.config["plant"])
    assert plant_path.is_absolute() and plant_path == (tmp_path / "cfg" / "pend.toml").resolve()
    assert parse_config(dict(prep.spec.config)).plant.n_states == 2
