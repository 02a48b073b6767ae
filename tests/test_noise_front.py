"""Scenario 3's noise fronts (model-free vs model-assisted LADRC) and the fresh noise seeds.

The shipped ``presets/fronts/s3-noise-*.csv`` files parse, every row satisfies its recipe's
constraints, a robust row is what :func:`aiofl.analysis.robustness_draws.simulate_designs` gives,
and the report's answer names the observer the files' numbers say is best.  The fresh-seed
table's entries are ``simulate`` of the preset with that noise seed.
"""

from __future__ import annotations

import csv
import fnmatch
import io
import math
import tomllib
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from aiofl.reporting.front_files import FrontFileError
from aiofl.reporting.noise_front import (
    NOISE_BUDGET,
    NOISE_FRONTS,
    best_nominal,
    load_noise_fronts,
    noise_answer,
    noise_rows,
    parse_noise_front,
    winner,
)
from aiofl.reporting.tables import fmt

ROOT = Path(__file__).resolve().parents[1]
FOLDER = ROOT / "src" / "aiofl" / "presets" / "fronts"


def _csv(name: str) -> tuple[list[str], list[list[str]]]:
    rows = list(csv.reader(io.StringIO((FOLDER / name).read_text(encoding="utf-8"))))
    return rows[0], [r for r in rows[1:] if r]


@pytest.mark.parametrize("structure", [s for s, _ in NOISE_FRONTS])
def test_shipped_noise_fronts_parse_and_satisfy_their_constraints(structure: str) -> None:
    nf = load_noise_fronts()
    assert not nf.errors and structure in nf.fronts
    f = nf.fronts[structure]
    recipe = tomllib.loads((FOLDER / f"s3-noise-{structure}.toml").read_text(encoding="utf-8"))
    tune = recipe["tune"]
    assert f.names == tuple(tune["parameters"])
    assert tune["objectives"] == ["itae:nominal", "itae:cvar"]
    assert tune["constraints"] == ["isu:nominal <= 20", "stable_fraction >= 1"]
    assert recipe["sensor"]["ts"] == 0.001 and recipe["sensor"]["noise_variance"] == 1e-4
    model = recipe["controller"]["eso"]["model"]
    assert model == ("nominal" if structure == "assisted" else "none")
    header, body = _csv(f"s3-noise-{structure}.csv")
    assert header[-5:] == [
        "itae:nominal",
        "itae:cvar",
        "isu:nominal <= 20",
        "stable_fraction >= 1",
        "chosen",
    ]
    for row in body:
        assert float(row[-3]) <= 20.0 and float(row[-2]) >= 1.0
        assert float(row[-5]) > 0 and float(row[-4]) > 0
    assert np.all(f.isu <= NOISE_BUDGET) and np.all(f.stable >= 1)
    # the robust companion: one row per front design over 256 draws
    rh, rb = _csv(f"s3-noise-{structure}-robust.csv")
    assert rh[: len(f.names)] == list(f.names) and len(rb) == len(body)
    assert np.all(f.robust["draws"] == 256)
    assert np.all(np.isfinite(f.robust["itae_q50"]))


def test_package_data_globs_ship_the_noise_fronts() -> None:
    globs = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"][
        "package-data"
    ]["aiofl"]
    for st, _ in NOISE_FRONTS:
        for name in (f"s3-noise-{st}.csv", f"s3-noise-{st}-robust.csv", f"s3-noise-{st}.toml"):
            assert (FOLDER / name).is_file()
            assert any(fnmatch.fnmatch(f"presets/fronts/{name}", g) for g in globs), name


def test_a_robust_row_is_simulate_designs_over_the_same_draws() -> None:
    """The best nominal design of the model-assisted front, rerun over the 256 draws."""
    from aiofl.analysis.robustness_draws import simulate_designs
    from aiofl.config import load_config, parse_config
    from aiofl.tuning.space import config_with_values
    from aiofl.uncertainty import UncertaintyModel, sample_draws

    f = load_noise_fronts().fronts["assisted"]
    i = best_nominal(f)
    assert i is not None
    cfg = load_config(FOLDER / "s3-noise-assisted.toml")
    raw = {k: v for k, v in cfg.raw.items() if k not in ("tune", "uncertainty")}
    values = dict(zip(f.names, map(float, f.values[i]), strict=True))
    one = parse_config(config_with_values(raw, cfg.controller, values), "row")
    # the front's nominal ITAE / ISU: the mean over the tuner's 2 noise realisations
    from aiofl.reporting.fresh_seeds import seed_config
    from aiofl.scenario import realisation_seed

    runs = [seed_config(one, realisation_seed(0, k)).simulate(store=False) for k in (0, 1)]
    itae = np.mean([r.metrics["itae"] for r in runs])
    assert itae == pytest.approx(f.itae[i], rel=1e-9)
    assert np.mean([r.metrics["isu"] for r in runs]) == pytest.approx(f.isu[i], rel=1e-9)
    spec = UncertaintyModel.model_validate(
        {
            "draws": 256,
            "seed": 0,
            "parameters": {p: {"uniform": 0.2} for p in ("J_l", "K_s", "R_m", "J_h")},
        }
    )
    (res,) = simulate_designs([one], sample_draws(spec, dt=one.dt))
    q95 = float(np.quantile(res.itae, 0.95, method="inverted_cdf"))
    assert q95 == pytest.approx(f.q95[i], rel=1e-9)
    assert res.stable_fraction == f.robust["stable_fraction"][i]


def _q95_at_best_nominal(structure: str) -> tuple[float, float]:
    """(best nominal ITAE within the budget, its ITAE 95 %) straight from the CSV files
    (an empty ITAE 95 % cell, a quantile on a diverged draw, is +inf)."""
    header, body = _csv(f"s3-noise-{structure}.csv")
    k = header.index("itae:nominal")
    ok = [r for r in body if float(r[-3]) <= NOISE_BUDGET and float(r[-2]) >= 1]
    best = min(ok, key=lambda r: float(r[k]))
    rh, rb = _csv(f"s3-noise-{structure}-robust.csv")
    (rob,) = [r for r in rb if [float(x) for x in r[:k]] == [float(x) for x in best[:k]]]
    cell = rob[rh.index("itae_q95")]
    return float(best[k]), float(cell) if cell else math.inf


def test_the_answer_names_the_observer_with_the_lower_q95_at_its_best_nominal() -> None:
    nf = load_noise_fronts()
    at = {st: _q95_at_best_nominal(st) for st, _ in NOISE_FRONTS}
    best = min(at, key=lambda st: at[st][1])
    assert winner(nf) == best
    label = dict(NOISE_FRONTS)[best]
    sentences = noise_answer(nf)
    head = "Under noise (scenario 3, sampled at 1 ms, ISU ≤ 20), the "
    assert sentences[0].startswith(f"{head}{label} is best")
    for itae, q95 in at.values():  # both numbers, as the files give them
        assert fmt(itae, 3) in sentences[0]
        assert (fmt(q95, 3) if math.isfinite(q95) else "diverged draw") in sentences[0]
    assert at[best][1] < min(q for st, (_, q) in at.items() if st != best)
    rows = noise_rows(SimpleNamespace(noise_fronts=nf))  # type: ignore[arg-type]
    assert [r[0] for r in rows] == [lab for _, lab in NOISE_FRONTS]


def test_malformed_and_missing_noise_fronts_are_reported(tmp_path: Path) -> None:
    text = (FOLDER / "s3-noise-ladrc.csv").read_text(encoding="utf-8")
    with pytest.raises(FrontFileError, match="itae:cvar"):
        parse_noise_front(text.replace("itae:cvar", "iae"), name="x.csv", structure="ladrc")
    lines = text.splitlines()
    lines[1] = ",".join([*lines[1].split(",")[:-1], "1"])
    with pytest.raises(FrontFileError, match="chosen = 1"):
        parse_noise_front("\n".join(lines), name="x.csv", structure="ladrc")
    (tmp_path / "s3-noise-ladrc.csv").write_text("a,b\n1,2\n", encoding="utf-8")
    nf = load_noise_fronts(tmp_path)
    assert not nf.fronts and "s3-noise-ladrc.csv" in nf.errors
    assert "s3-noise-assisted.csv" in nf.missing
    assert winner(nf) is None and "No noise front" in noise_answer(nf)[0]
    (tmp_path / "s3-noise-ladrc.csv").write_text(text, encoding="utf-8")
    nf = load_noise_fronts(tmp_path)  # one front, no robust file: nothing to rank
    assert set(nf.fronts) == {"ladrc"} and "s3-noise-ladrc-robust.csv" in nf.missing
    assert winner(nf) is None and "cannot be ranked" in noise_answer(nf)[0]
    assert "No noise front" in noise_answer(None)[0]


# ---------------------------------------------------------------- fresh noise seeds
def test_fresh_seed_entries_are_simulate_with_that_seed() -> None:
    from aiofl.config import load_config
    from aiofl.reporting.cases import discover_cases
    from aiofl.reporting.fresh_seeds import FRESH_SEEDS, compute_fresh_seeds, seed_config

    assert tuple(range(1000, 1032)) == FRESH_SEEDS
    names = ("assisted-s3-ladrc", "frontier-s3-leso")
    cases = [c for c in discover_cases(list(names)) if c.preset in names]
    assert len(cases) == 2
    seeds = (1000, 1031)
    table = compute_fresh_seeds(cases, seeds=seeds)
    assert table.engine_calls == 1 and set(table.results) == set(names)
    for name in names:
        got = table.results[name]
        for k, s in enumerate(seeds):
            cfg = seed_config(load_config(name), s)
            assert cfg.scenario.noise_seed == s
            one = cfg.simulate(store=False)
            assert bool(got["failed"][k]) == one.failed
            if not one.failed:
                assert got["itae"][k] == one.metrics["itae"]
                assert got["isu"][k] == one.metrics["isu"]
    # the assisted preset keeps its sampling on the fresh seeds
    assert "sampled at 1 ms" in table.results["assisted-s3-ladrc"]["sensor"]
    assert not math.isnan(float(np.nanmedian(table.results["assisted-s3-ladrc"]["itae"])))


@pytest.mark.parametrize("structure", [s for s, _ in NOISE_FRONTS])
def test_noise_front_is_non_dominated_and_matches_its_recipe(structure: str) -> None:
    from pymoo.util.nds.non_dominated_sorting import NonDominatedSorting

    from aiofl.config import parse_config
    from aiofl.tuning.search import prepare

    name = f"s3-noise-{structure}"
    text = (FOLDER / f"{name}.toml").read_text(encoding="utf-8")
    assert f"aiofl tune src/aiofl/presets/fronts/{name}.toml --out DIR" in text
    assert f"benchmarks/front_robustness.py src/aiofl/presets/fronts/{name}.csv --draws 256" in text
    prep = prepare(parse_config(tomllib.loads(text), f"{name}.toml"))
    st = prep.settings
    assert st.algorithm == "nsga2" and st.noise_realisations == 2 and st.seed == 1
    assert st.robust is not None and st.robust.draws == 16 and st.robust.aggregate == "cvar"
    header, body = _csv(f"{name}.csv")
    assert header == [*prep.space.names, *st.objectives, *st.constraints, "chosen"]
    k = len(prep.space.names)
    F = np.array([[float(r[k]), float(r[k + 1])] for r in body])
    assert len(NonDominatedSorting().do(F, only_non_dominated_front=True)) == len(F)
