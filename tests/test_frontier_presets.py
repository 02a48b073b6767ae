"""The shipped frontier designs (issue 10) and the shipped Pareto fronts.

* every ``frontier-s{1,2,3}-{leso,inleso,ladrc}`` preset loads, carries its recipe (a
  ``[tune]`` table that validates, an ``[uncertainty]`` table of ±20 % on J_l, K_s, R_m,
  J_h with a fixed seed, the reproduce line in its header), and its nominal 20-s run gives
  exactly the ITAE and ISU its header states; where the header says a target is met, the
  numbers meet it;
* one preset over a few model-error draws is stable on every draw;
* the front files in ``aiofl/presets/fronts/`` parse, are non-dominated and feasible, their
  recipe configs validate and name the same columns, and the ``-robust.csv`` companions
  start with the front's parameters and match front rows;
* ``fronts/`` is not mistaken for a preset.
"""

from __future__ import annotations

import csv
import io
import re
import tomllib
from importlib import resources

import numpy as np
import pytest

from aiofl.config import list_presets, load_config, preset_text

STRUCTURES = ("leso", "inleso", "ladrc")
FRONTIER = [f"frontier-s{s}-{k}" for s in (1, 2, 3) for k in STRUCTURES]
FRONTS = [f"s{s}-{k}" for s in (1, 3) for k in STRUCTURES]
BUDGET = {1: 15.5, 2: 75.0, 3: 20.0}
ITAE_TARGET = {1: 0.02, 2: 0.02, 3: 1.0}
NOMINAL = re.compile(r"^# Nominal, 20 s: ITAE ([0-9.eE+-]+), ISU ([0-9.eE+-]+)", re.M)


def _fronts_dir():
    return resources.files("aiofl") / "presets" / "fronts"


def _header(name: str) -> str:
    text = preset_text(name)
    return "".join(ln + "\n" for ln in text.splitlines() if ln.startswith("#"))


# ------------------------------------------------------------------ the presets
def test_frontier_presets_are_discoverable_and_fronts_are_not_presets() -> None:
    names = list_presets()
    assert set(FRONTIER) <= set(names)
    assert not any(n.startswith(("s1-", "s3-", "front-")) for n in names)
    assert "fronts" not in names
    from aiofl.config import ConfigError

    with pytest.raises(ConfigError, match="unknown preset"):
        load_config("s1-ladrc")


@pytest.mark.parametrize("name", FRONTIER)
def test_frontier_preset_carries_its_recipe(name: str) -> None:
    from aiofl.tuning.search import prepare

    cfg = load_config(name)
    assert cfg.name == name
    assert cfg.controller.td == "exact"  # the reference-derivative option of the structure
    unc = cfg.uncertainty
    assert unc is not None and unc.seed == 0 and unc.draws == 1000
    assert {k: v.uniform for k, v in unc.parameters.items()} == dict.fromkeys(
        ("J_l", "K_s", "R_m", "J_h"), 0.2
    )
    prep = prepare(cfg)  # the [tune] table validates against this config
    st = prep.settings
    assert st.algorithm == "nsga2" and st.include_initial is False and st.t_final == 20.0
    s = int(name.split("-")[1][1])
    assert f"isu:nominal <= {BUDGET[s]:g}" in st.constraints
    head = _header(name)
    assert f"# Reproduce: aiofl tune {name} --out DIR" in head
    assert f"aiofl robustness {name} --out DIR" in head


@pytest.mark.parametrize("name", FRONTIER)
def test_frontier_preset_nominal_run_gives_the_numbers_its_header_states(name: str) -> None:
    s = int(name.split("-")[1][1])
    head = _header(name)
    m = NOMINAL.search(head)
    assert m, f"{name}: no 'Nominal, 20 s: ITAE ..., ISU ...' line in the header"
    itae, isu = float(m.group(1)), float(m.group(2))
    res = load_config(name).simulate()
    assert not res.failed
    assert res.metrics["itae"] == pytest.approx(itae, rel=1e-6)
    assert res.metrics["isu"] == pytest.approx(isu, rel=1e-6)
    target = re.search(r"ITAE <= [0-9.]+ at ISU <= [0-9.]+ (met|NOT met)", head)
    assert target, f"{name}: the header does not say whether the target is met"
    met = target.group(1) == "met"
    within = res.metrics["itae"] <= ITAE_TARGET[s] and res.metrics["isu"] <= BUDGET[s]
    assert met == within


def test_frontier_s1_ladrc_is_stable_over_a_few_draws() -> None:
    from aiofl.analysis.robustness_draws import run_robustness

    cfg = load_config("frontier-s1-ladrc")
    res = run_robustness(cfg, draws=16, seed=0)
    assert res.stable_fraction == 1.0
    assert float(np.quantile(res.itae, 0.95, method="inverted_cdf")) <= 0.03


# --------------------------------------------------------------------- the fronts
def _read_csv(name: str) -> tuple[list[str], list[list[str]]]:
    rows = list(csv.reader(io.StringIO((_fronts_dir() / name).read_text(encoding="utf-8"))))
    return rows[0], [r for r in rows[1:] if r]


@pytest.mark.parametrize("front", FRONTS)
def test_shipped_front_parses_is_non_dominated_and_matches_its_recipe(front: str) -> None:
    from pymoo.util.nds.non_dominated_sorting import NonDominatedSorting

    from aiofl.config import ConfigError, parse_config
    from aiofl.tuning.search import prepare

    header, body = _read_csv(f"{front}.csv")
    recipe_text = (_fronts_dir() / f"{front}.toml").read_text(encoding="utf-8")
    assert f"aiofl tune src/aiofl/presets/fronts/{front}.toml --out DIR" in recipe_text
    cfg = parse_config(tomllib.loads(recipe_text), f"{front}.toml")
    prep = prepare(cfg)
    st = prep.settings
    assert st.algorithm == "nsga2" and list(st.objectives) == ["itae", "isu"]
    names = list(prep.space.names)
    assert header == [*names, *st.objectives, *st.constraints, "chosen"]
    assert body, f"{front}.csv has no design"
    values = np.array([[float(c) for c in r[:-1]] for r in body])
    F = values[:, len(names) : len(names) + 2]
    assert np.isfinite(F).all() and (F[:, 0] > 0).all() and (F[:, 1] >= 0).all()
    nd = NonDominatedSorting().do(F, only_non_dominated_front=True)
    assert len(nd) == len(body), f"{front}.csv holds dominated rows"
    for j, c in enumerate(st.constraints):  # every shipped design is feasible
        bound = float(c.split("<=")[1])
        assert (values[:, len(names) + 2 + j] <= bound).all()
    assert sum(r[-1] == "1" for r in body) == 1
    lo = np.array([st.parameters[n].lo for n in names])
    hi = np.array([st.parameters[n].hi for n in names])
    p = values[:, : len(names)]
    assert ((p >= lo * (1 - 1e-12)) & (p <= hi * (1 + 1e-12))).all()
    try:
        parse_config(tomllib.loads(recipe_text), "again")
    except ConfigError as exc:  # pragma: no cover - a broken recipe fails here
        pytest.fail(str(exc))


@pytest.mark.parametrize("front", FRONTS)
def test_robust_companion_starts_with_the_front_parameters(front: str) -> None:
    path = _fronts_dir() / f"{front}-robust.csv"
    if not path.is_file():
        pytest.skip(f"no {front}-robust.csv shipped")
    header, body = _read_csv(f"{front}.csv")
    rh, rbody = _read_csv(f"{front}-robust.csv")
    k = header.index("itae")
    assert rh[:k] == header[:k]
    assert {"itae_q50", "itae_q95", "stable_fraction"} <= set(rh[k:])
    front_params = np.array([[float(c) for c in r[:k]] for r in body])
    i_sf = rh.index("stable_fraction")
    for r in rbody:
        par = np.array([float(c) for c in r[:k]])
        assert np.isclose(front_params, par, rtol=1e-12, atol=0).all(axis=1).any()
        assert 0.0 <= float(r[i_sf]) <= 1.0
