"""The report's rig table (issue 36): every design on the servo-1khz rig, and the preset sets
it decides: a shipped design listed as a design holds on the rig, an ideal-world limit does
not (checked here on the report's own runs, and over 32 draws where the report's fewer draws
did not show it)."""

from __future__ import annotations

import json

import pytest

from aiofl.analysis.rig_check import rig_check
from aiofl.config import load_config, preset_sets
from aiofl.reporting.rig_rows import RIG_BOX, RIG_DESIGNS, RIG_TITLE


@pytest.fixture(scope="module")
def rep(reproduced):
    assert reproduced.exit_code == 0, reproduced.stderr
    return reproduced.reproduction()


def test_every_case_and_every_rig_design_has_a_row(rep, reproduced) -> None:
    table = rep.rig
    presets = {r.case.preset for r in rep.runs}
    assert presets | set(RIG_DESIGNS) == set(table.checks) | set(table.skipped)
    scenarios = [s for s, _, _ in table.rows]
    assert scenarios == sorted(scenarios)  # by scenario, the cases' order within one
    text = (reproduced.out / "tables.md").read_text(encoding="utf-8")
    assert f"## {RIG_TITLE}" in text
    records = json.loads((reproduced.out / "metrics.json").read_text(encoding="utf-8"))
    computed = [r for r in records if "preset" in r]
    assert computed and all(r["rig"]["verdict"] == table.checks[r["preset"]].verdict
                            for r in computed)  # fmt: skip


def test_the_rig_designs_are_told_and_already_on_the_rig(rep) -> None:
    """A rig-* design ships on servo-1khz and told of its delay: putting it on that rig
    changes nothing, so its own run and the rig's nominal run are the same run."""
    for name in RIG_DESIGNS:
        chk = rep.rig.checks[name]
        cfg = load_config(name)
        assert cfg.controller.value("eso.delay") == cfg.rig.measurement_delay == 1e-3
        assert chk.own["itae"] == chk.nominal["itae"]
        assert chk.holds, (name, chk.verdict)


def test_the_sets_are_what_the_rig_measures(rep) -> None:
    sets = preset_sets()
    checks = rep.rig.checks
    for name in sets["designs"]:
        if name in checks:
            assert checks[name].holds, f"{name} is listed as a design: {checks[name].verdict}"
    wider = []
    for name in sets["limits"]:
        if name not in checks:
            continue
        if checks[name].holds:  # the report's draws did not show it: 32 draws must
            wider.append(name)
            chk = rig_check(load_config(name), draws=32, box=RIG_BOX)
            assert not chk.holds, f"{name} is listed as an ideal-world limit but holds"
        else:
            assert checks[name].verdict != "holds"
    assert len(wider) <= 2  # the draws of the report decide nearly every case
