"""Every analysis has a time budget and says when it gave up (issue 34 item 9:
``aiofl analyze retuned-s1-inleso --closed-loop`` ran > 150 s in the limit-cycle
simulation's BDF integration)."""

from __future__ import annotations

import json
import time

import pytest
from typer.testing import CliRunner

from aiofl.analysis.budget import BudgetExceeded, budget_spent, check_budget, time_budget
from aiofl.cli.app import app


def test_a_spent_budget_raises_and_an_inner_budget_cannot_extend_an_outer_one() -> None:
    check_budget()  # no budget: nothing happens
    with time_budget(0.01):
        time.sleep(0.02)
        assert budget_spent() == 0.01
        with pytest.raises(BudgetExceeded, match=r"gave up after 0\.01 s"):
            check_budget()
        with time_budget(100.0), pytest.raises(BudgetExceeded):
            check_budget()
    check_budget()  # the budget ended with its block
    with pytest.raises(ValueError, match="allowed: > 0"), time_budget(0.0):
        pass


def test_analyze_closed_loop_gives_up_on_the_orbit_when_the_budget_is_spent() -> None:
    args = ["analyze", "paper-s1-leso", "--closed-loop", "--json", "--budget", "1e-6"]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    orbit = json.loads(res.stdout)["orbit"]
    assert orbit["gave_up"]["seconds"] == 1e-6
    assert "tracking orbit" in orbit["gave_up"]["parts"]
    assert "gave up after 1e-06 s" in orbit["verdict"]
    assert orbit["seconds"] < 30  # stopped, not run to the end


@pytest.mark.parametrize("bad", ["0", "-1", "nan", "inf"])
def test_a_budget_that_is_no_time_is_refused(bad: str) -> None:
    res = CliRunner().invoke(app, ["analyze", "paper-s1-leso", "--closed-loop", "--budget", bad])
    assert res.exit_code == 2 and "--budget" in res.stderr


def test_sampling_limits_stop_refining_when_the_budget_is_spent() -> None:
    from aiofl.analysis.sampling_limits import sampling_limits
    from aiofl.config import load_config

    cfg = load_config("frontier-s1-ladrc").with_overrides(t_final=1.0)
    with time_budget(1e-6):
        lim = sampling_limits(cfg)
    assert lim.gave_up == 1e-6 and lim.engine_calls == 1  # the first ladder only
    assert lim.to_dict()["gave_up_after_s"] == 1e-6
