"""The reproduce report's robustness rows and shipped Pareto fronts (issue 10).

* the rows equal a direct computation from per-draw ``simulate_batch`` results;
* the front reader refuses a malformed file with a message naming the file and the line,
  and the report states it instead of failing;
* the fronts section renders from a tiny synthetic front, and a ``frontier-*`` record in
  ``metrics.json`` carries ``"source": "robust"`` and its robustness row.
"""

from __future__ import annotations

import json
import math
import zlib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from aiofl.config import load_config
from aiofl.engine.simulation import simulate_batch
from aiofl.reporting.cases import Case
from aiofl.reporting.front_files import FrontFileError, load_fronts, parse_front, parse_robust
from aiofl.reporting.robust_rows import (
    DEFAULT_DRAWS,
    ROBUST_PARAMETERS,
    ROBUST_SPREAD,
    compute_robustness,
    robust_notes,
    with_robustness,
)


def _short(preset: str, t_final: float):
    cfg = load_config(preset)
    return replace(cfg, scenario=replace(cfg.scenario, t_final=t_final))


def _uniforms(seed: int, name: str, n: int) -> np.ndarray:
    """The documented stream of a drawn name: PCG64(SeedSequence(seed, (crc32(name),)))."""
    ss = np.random.SeedSequence(seed, spawn_key=(zlib.crc32(name.encode()),))
    return np.random.Generator(np.random.PCG64(ss)).random(n)


def _inverted_cdf(values: list[float], q: float) -> float | None:
    """min{x : F(x) >= q} over the sorted values (+inf = diverged -> None)."""
    x = sorted(values)
    v = x[math.ceil(q * len(x) - 1e-12) - 1]
    return None if math.isinf(v) else v


# ------------------------------------------------------------------- robustness rows
def test_rows_equal_a_direct_per_draw_computation() -> None:
    k, seed = 8, 3
    # two designs of scenario 1 (batched together) and one of scenario 3 (diverges at 0.6 s)
    cases = [
        Case("retuned-s1-ladrc", 1, "LADRC", "retuned", _short("retuned-s1-ladrc", 1.0)),
        Case("retuned-s1-leso", 1, "LESO", "retuned", _short("retuned-s1-leso", 1.0)),
        Case("paper-s3-inleso", 3, "INLESO", "printed", _short("paper-s3-inleso", 1.0)),
    ]
    table = compute_robustness(cases, draws=k, seed=seed)
    assert table is not None and table.draws == k and table.seed == seed
    assert table.engine_calls == 2  # one call per scenario, all its designs together
    # the draws, by their definition: one PCG64 stream per parameter, f = 1 + p (2u - 1)
    factors = {n: 1 + ROBUST_SPREAD * (2 * _uniforms(seed, n, k) - 1) for n in ROBUST_PARAMETERS}
    for case in cases:
        cfg = case.config
        itae, isu = [], []
        for j in range(k):  # one engine call per draw
            scale = {**cfg.scenario.plant_scale}
            for n, f in factors.items():
                scale[n] = scale.get(n, 1.0) * f[j]
            sc = replace(cfg.scenario, plant_scale=scale, parameter_change_time=0.0)
            res = simulate_batch(cfg.plant, cfg.controller, sc, dt=cfg.dt, method=cfg.method)
            m = res.member(0)
            itae.append(math.inf if m.failed else m.metrics["itae"])
            isu.append(math.inf if m.failed else m.metrics["isu"])
        got = table.results[case.preset]
        assert got["draws"] == k and got["seed"] == seed
        assert got["failed"] == sum(math.isinf(v) for v in itae)
        assert got["stable_fraction"] == pytest.approx(np.mean(np.isfinite(itae)), abs=0)
        for name, q in (("q05", 0.05), ("q50", 0.5), ("q95", 0.95)):
            want = _inverted_cdf(itae, q)
            assert got["itae"][name] == (None if want is None else pytest.approx(want, rel=1e-12))
            want = _inverted_cdf(isu, q)
            assert got["isu"][name] == (None if want is None else pytest.approx(want, rel=1e-12))
    assert table.results["paper-s3-inleso"]["stable_fraction"] == 0.0
    assert table.results["retuned-s1-ladrc"]["stable_fraction"] == 1.0
    json.dumps(table.results, allow_nan=False)  # no NaN or Infinity


def test_no_draws_skips_the_rows_and_records_say_null() -> None:
    assert compute_robustness([], draws=0) is None
    recs = [{"source": "paper"}, {"source": "printed", "preset": "paper-s1-leso"}]
    out = with_robustness(recs, None)
    assert "robustness" not in out[0] and out[1]["robustness"] is None

    from types import SimpleNamespace

    rep = SimpleNamespace(robustness=None, runs=[])
    assert "--draws 0" in robust_notes(rep)[0]  # type: ignore[arg-type]


def test_the_cli_default_is_the_module_default() -> None:
    import inspect

    from aiofl.cli.app import reproduce_command

    default = inspect.signature(reproduce_command).parameters["draws"].default
    assert default == DEFAULT_DRAWS


# ------------------------------------------------------------------------ front files
GOOD = (
    "eso.omega0,sef.omega_c,itae,isu,isu <= 15.5,chosen\n"
    "1600.0,40.0,0.0125,14.99,14.99,1\n"
    "800.0,20.0,0.5,14.5,14.5,0\n"
    "100.0,2.0,80.0,0.001,0.001,0\n"
)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "empty file"),
        ("eso.omega0,itae,isu,chosen\n", "no design rows"),
        ("eso.omega0,itae,isu\n1.0,2.0,3.0\n", "last column must be 'chosen'"),
        ("eso.omega0,itae,isu,chosen\n1.0,2.0,3.0\n", "line 2: 3 fields, the header has 4"),
        ("eso.omega0,itae,isu,chosen\n1.0,abc,3.0,1\n", "line 2: column 'itae' holds 'abc'"),
        ("eso.omega0,itae,iae,chosen\n1.0,2.0,3.0,1\n", "no 'isu' column"),
        ("eso.omega0,itae,isu,chosen\n1.0,-2.0,3.0,1\n", "line 2: ITAE '-2.0'"),
        ("eso.omega0,itae,isu,chosen\n1.0,2.0,,1\n", "line 2: ISU ''"),
        ("eso.omega0,itae,isu,chosen\n1.0,2.0,3.0,yes\n", "chosen is 'yes'"),
        ("eso.omega0,itae,isu,chosen\n1.0,2.0,3.0,0\n", "0 rows have chosen = 1"),
        ("itae,isu,chosen\n2.0,3.0,1\n", "is not parameters, then objectives"),
        ("itae,eso.omega0,isu,chosen\n2.0,1.0,3.0,1\n", "is not parameters, then objectives"),
    ],
)
def test_a_malformed_front_is_refused_naming_file_and_line(text: str, message: str) -> None:
    with pytest.raises(FrontFileError, match=r"s1-leso\.csv") as err:
        parse_front(text, name="s1-leso.csv", scenario=1, structure="leso")
    assert message in str(err.value)


def test_a_front_and_its_robust_companion_are_read() -> None:
    front = parse_front(GOOD, name="s1-ladrc.csv", scenario=1, structure="ladrc")
    assert front.names == ("eso.omega0", "sef.omega_c")
    assert front.chosen == 0 and list(front.isu) == [14.99, 14.5, 0.001]
    robust = "eso.omega0,sef.omega_c,itae_q50,itae_q95,stable_fraction\n800.0,20.0,0.6,0.9,1\n"
    both = parse_robust(robust, front, name="s1-ladrc-robust.csv")
    assert both.robust["itae_q95"][1] == 0.9 and np.isnan(both.robust["itae_q95"][0])
    with pytest.raises(FrontFileError, match="must start with the front's parameters"):
        parse_robust("td.omega,itae_q95\n1.0,2.0\n", front, name="s1-ladrc-robust.csv")


def test_missing_and_malformed_files_are_reported_not_raised(tmp_path: Path) -> None:
    (tmp_path / "s1-ladrc.csv").write_text(GOOD)
    (tmp_path / "s1-leso.csv").write_text("eso.omega0,itae,isu,chosen\n1.0,2.0\n")
    sf = load_fronts(tmp_path)
    assert set(sf.fronts) == {(1, "ladrc")}
    assert "s1-leso.csv, line 2: 2 fields" in sf.errors["s1-leso.csv"]
    assert "s3-inleso.csv" in sf.missing and "s1-ladrc.csv" not in sf.missing


# ------------------------------------------- a synthetic frontier preset and its fronts
@pytest.fixture(scope="module")
def frontier(tmp_path_factory: pytest.TempPathFactory):
    """``reproduce`` with a pretend ``frontier-s1-ladrc`` preset (the re-tuned LADRC under
    that name), 4 draws and a tiny synthetic front folder."""
    import aiofl.reporting.cases as rp
    from aiofl.reporting.reproduce import reproduce

    fronts = tmp_path_factory.mktemp("fronts")
    (fronts / "s1-ladrc.csv").write_text(GOOD)
    (fronts / "s1-inleso.csv").write_text(GOOD.replace("0.0125", "0.02"))
    (fronts / "s1-ladrc-robust.csv").write_text(
        "eso.omega0,sef.omega_c,itae_q50,itae_q95,stable_fraction\n"
        "1600.0,40.0,0.0124,0.0133,1.0\n800.0,20.0,0.6,0.9,1.0\n"
    )
    real = rp.load_config
    mp = pytest.MonkeyPatch()
    mp.setattr(
        rp, "load_config", lambda n: real("retuned-s1-ladrc" if n == "frontier-s1-ladrc" else n)
    )
    out = tmp_path_factory.mktemp("reproduce-frontier") / "out"
    try:
        rep = reproduce(out, available=["frontier-s1-ladrc"], draws=4, fronts_dir=fronts)
    finally:
        mp.undo()
    return rep, out


@pytest.mark.slow
def test_frontier_records_carry_source_robust_and_their_row(frontier) -> None:
    rep, out = frontier
    recs = json.loads((out / "metrics.json").read_text(), parse_constant=pytest.fail)
    (rec,) = [r for r in recs if r.get("preset") == "frontier-s1-ladrc"]
    assert (rec["source"], rec["structure"], rec["scenario"]) == ("robust", "LADRC", 1)
    assert rec["robustness"] == rep.robustness.results["frontier-s1-ladrc"]
    assert rec["robustness"]["draws"] == 4 and rec["robustness"]["seed"] == 0
    assert set(rec["robustness"]["itae"]) == {"q05", "q50", "q95", "max"}
    assert all(r["robustness"]["draws"] == 4 for r in recs if r["source"] != "paper")
    md = (out / "tables.md").read_text()
    assert "| 1 | LADRC (robust) | frontier-s1-ladrc |" in md
    assert "4 draws (seed 0)" in md


@pytest.mark.slow
def test_the_fronts_section_renders_from_a_synthetic_front(frontier) -> None:
    _, out = frontier
    md = (out / "tables.md").read_text()
    assert "## Pareto fronts: which structure tracks best at equal control energy?" in md
    # S1 budget 15.5: LADRC's best is 0.0125 (ISU 14.99), INLESO's 0.02
    assert "| LADRC | 3 | 0.0125 (ISU 14.99) | 0.0133 (95 %) | frontier-s1-ladrc: ITAE" in md
    assert "| INLESO | 3 | 0.02 (ISU 14.99) | no robust file |" in md
    assert "| LESO | no front file |" in md
    assert "lowest ITAE on the shipped fronts: LADRC (ITAE 0.0125), then INLESO (0.02, ×1.6)" in md
    assert "Scenario 3: neither a front file nor a frontier preset is shipped" in md
    assert "the frontier presets within ISU ≤ 15.5 (this run): only LADRC (ITAE 3.12)" in md
    assert "the frontier presets within ISU ≤ 15.5 over this run's 4 draws (seed 0)" in md
    assert "Not shipped (yet): the fronts s1-leso, s3-leso, s3-inleso, s3-ladrc." in md
    assert "tuning horizons of 6 s (frontier-s1-ladrc)" in md
    assert (out / "fronts-s1.png").read_bytes()[:4] == b"\x89PNG"
    assert not (out / "fronts-s3.png").exists()
    page = (out / "report.html").read_text()
    assert 'alt="Pareto fronts, scenario 1"' in page
    assert "Robustness: every design over the same ±20 % model errors" in page
