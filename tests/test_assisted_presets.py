"""The shipped model-assisted designs (issue 20): ``assisted-s{1,2,3}-ladrc``.

* each loads with the model-assisted observer and the sensor it was designed for (a 12-bit
  encoder sampled at 1 ms for S1/S2; S3's noise, sampled at 1 ms), carries its recipe (a
  ``[tune]`` table that validates, ±20 % on J_l, K_s, R_m, J_h with seed 0, the reproduce
  line in its header), and its nominal run gives the ITAE and ISU its header states;
* where the header says a nominal target is met, the numbers meet it;
* over a few model-error draws (each with its own noise) the S1 and S3 designs stay stable
  and within their robust targets.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from aiofl.config import load_config, preset_text

ASSISTED = [f"assisted-s{s}-ladrc" for s in (1, 2, 3)]
BUDGET = {1: 20.0, 2: 75.0, 3: 20.0}
NOMINAL_TARGET = {1: 0.05, 2: 0.1, 3: 0.2}
NOMINAL = re.compile(r"^# Nominal, 20 s, [^:]*: ITAE ([0-9.eE+-]+), ISU ([0-9.eE+-]+)", re.M)


def _header(name: str) -> str:
    return "".join(ln + "\n" for ln in preset_text(name).splitlines() if ln.startswith("#"))


@pytest.mark.parametrize("name", ASSISTED)
def test_the_preset_carries_its_structure_sensor_and_recipe(name: str) -> None:
    from aiofl.tuning.search import prepare

    s = int(name.split("-")[1][1])
    cfg = load_config(name)
    c = cfg.controller
    assert (c.eso, c.td, c.sef, c.law, c.eso_model) == (
        "linear",
        "exact",
        "linear",
        "aiofl",
        "nominal",
    )
    assert cfg.sampling is not None and cfg.sampling.ts == 1e-3
    if s < 3:
        assert cfg.sensor.preset == "encoder-12bit"
        assert cfg.sampling.y_quantum == pytest.approx(2 * math.pi / 4096, rel=1e-15)
    else:
        assert cfg.scenario.noise_variance == 1e-4 and cfg.sampling.y_quantum == 0.0
    unc = cfg.uncertainty
    assert unc is not None and unc.seed == 0 and unc.draws == 1000
    assert {k: v.uniform for k, v in unc.parameters.items()} == dict.fromkeys(
        ("J_l", "K_s", "R_m", "J_h"), 0.2
    )
    st = prepare(cfg).settings
    assert st.algorithm == "nsga2" and st.include_initial is False
    assert f"isu:nominal <= {BUDGET[s]:g}" in st.constraints
    assert f"# Reproduce: aiofl tune {name} --out DIR" in _header(name)


@pytest.mark.parametrize("name", ASSISTED)
def test_the_nominal_run_gives_the_numbers_its_header_states(name: str) -> None:
    s = int(name.split("-")[1][1])
    head = _header(name)
    m = NOMINAL.search(head)
    assert m, f"{name}: no 'Nominal, 20 s, ...: ITAE ..., ISU ...' line in the header"
    res = load_config(name).simulate(store=False)
    assert not res.failed
    assert res.metrics["itae"] == pytest.approx(float(m.group(1)), rel=5e-4)
    assert res.metrics["isu"] == pytest.approx(float(m.group(2)), rel=5e-4)
    said = re.search(r"nominal ITAE <= [0-9.]+ (?:at ISU <= [0-9]+ )?.*?(NOT met|met)", head)
    assert said, f"{name}: the header does not say whether the nominal target is met"
    within = res.metrics["itae"] <= NOMINAL_TARGET[s] and res.metrics["isu"] <= BUDGET[s]
    assert (said.group(1) == "met") == within


@pytest.mark.parametrize(("name", "q95"), [("assisted-s1-ladrc", 2.5), ("assisted-s3-ladrc", 3.0)])
def test_stable_within_the_robust_target_over_a_few_draws(name: str, q95: float) -> None:
    from aiofl.analysis.robustness_draws import run_robustness

    res = run_robustness(load_config(name), draws=24, seed=0)
    assert res.stable_fraction == 1.0
    assert float(np.quantile(res.itae, 0.95, method="inverted_cdf")) <= q95
    assert float(np.quantile(res.isu, 0.95, method="inverted_cdf")) <= 25.0
