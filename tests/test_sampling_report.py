"""The reproduce report's sample-time limits: sampling.json, the ts_max column of Tables
I–III and the paragraph on what the limits mean (from the computed numbers)."""

from __future__ import annotations

import json

from aiofl.reporting.sampling_note import sampling_paragraph, ts_max_cell


def test_reproduce_writes_the_limits_of_every_case(reproduced) -> None:
    assert reproduced.exit_code == 0, reproduced.stderr
    limits = json.loads((reproduced.out / "sampling.json").read_text())
    records = json.loads((reproduced.out / "metrics.json").read_text())
    computed = [r for r in records if r["source"] != "paper"]
    assert len(limits) == len(computed)
    for lim in limits.values():
        assert {"ts_max", "ts_stable", "itae_continuous", "points"} <= set(lim)
        if lim["ts_max"] is not None:
            assert lim["ts_stable"] >= lim["ts_max"]
    # metrics.json keeps its schema: the limits live in their own file
    assert all("ts_max" not in r for r in records)


def test_tables_carry_a_ts_max_column_and_the_paragraph(reproduced) -> None:
    limits = json.loads((reproduced.out / "sampling.json").read_text())
    md = (reproduced.out / "tables.md").read_text()
    header = next(ln for ln in md.splitlines() if ln.startswith("| Structure"))
    assert header.split("|")[-2].strip() == "ts_max [ms]"
    for preset, lim in limits.items():
        row = next(ln for ln in md.splitlines() if f"| {preset} |" in ln)
        assert row.split("|")[-2].strip() == ts_max_cell(lim)
    assert "## What the sample-time limits mean" in md
    assert "For the paper's printed designs" in md
    page = (reproduced.out / "report.html").read_text()
    assert "What the sample-time limits mean" in page and "ts_max [ms]" in page


def test_cells_and_paragraph_follow_the_numbers() -> None:
    base = {
        "dt": 1e-4,
        "tolerance": 0.1,
        "ts_upper": 0.05,
        "itae_continuous": 1.0,
        "continuous_diverged": False,
        "discretisation": [],
    }
    ok = base | {"ts_max": 2e-3, "ts_stable": 5e-3}
    ok |= {"ts_max_bracket": [2e-3, 2.1e-3], "ts_stable_bracket": [5e-3, 5.1e-3]}
    at_dt = base | {"ts_max": None, "ts_stable": 1e-3}
    at_dt |= {"ts_max_bracket": [None, 1e-4], "ts_stable_bracket": [1e-3, 1.1e-3]}
    never = base | {"ts_max": 0.05, "ts_stable": 0.05}
    never |= {"ts_max_bracket": [0.05, None], "ts_stable_bracket": [0.05, None]}
    div = base | {"continuous_diverged": True, "ts_max": None, "ts_stable": None}
    div |= {"ts_max_bracket": [None, None], "ts_stable_bracket": [None, None]}
    assert [ts_max_cell(x) for x in (ok, at_dt, never, div, None)] == [
        "2",
        "< 0.1",
        "≥ 50",
        "—",
        "—",
    ]
    text = " ".join(
        sampling_paragraph(
            [("LESO", "a", "printed", 1), ("INLESO", "b", "printed", 1), ("X", "c", "retuned", 2)],
            {"a": ok, "b": div, "c": at_dt},
        )
    )
    assert "LESO of scenario 1 keeps its ITAE within 10 % up to Ts = 2 ms" in text
    assert "500 Hz" in text
    assert "INLESO of scenario 1 is not stable in continuous time already (it diverges)" in text
    assert "Stable at a Ts means three things at once" in text
    assert "X of scenario 2 lose more than the allowance already at Ts = dt = 0.1 ms" in text


def test_reproduce_ts_runs_the_cases_sampled_and_a_bad_ts_exits_2(tmp_path) -> None:
    from dataclasses import replace

    from typer.testing import CliRunner

    from aiofl.cli.app import app
    from aiofl.reporting.cases import discover_cases, run_cases

    case = next(c for c in discover_cases() if c.preset == "retuned-s1-leso")
    sampled = replace(case, config=case.config.with_sample_time(1e-3))
    run = run_cases([sampled], store=False)[0]
    direct = sampled.config.simulate(store=False)
    assert run.result.metrics == direct.metrics
    assert run.result.metrics != run_cases([case], store=False)[0].result.metrics
    out = tmp_path / "r"
    res = CliRunner().invoke(app, ["reproduce", "--ts", "1.5e-4", "--out", str(out)])
    assert res.exit_code == 2 and "controller.discrete.ts" in res.output
    assert not out.exists()
