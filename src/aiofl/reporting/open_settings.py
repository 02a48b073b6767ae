"""The settings the paper leaves open and the choice made in ``aiofl reproduce``.

:func:`open_settings` reads the values from the configs of the run where they are data;
:class:`SettingsSection` is the report's section of them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from aiofl.reporting.cases import Reproduction
from aiofl.reporting.page import details, html_table
from aiofl.reporting.section import Section, md_table
from aiofl.reporting.tables import fmt

__all__ = ["SETTINGS_HEADER", "SettingsSection", "open_settings"]

SETTINGS_HEADER = ("Setting", "The paper", "Choice made")


def open_settings(rep: Reproduction) -> list[tuple[str, str, str]]:
    """(setting, what the paper says, the choice made) for everything the paper leaves open.

    Values are read from the configs of this run where they are data.
    """
    s1 = rep.config("paper-s1-leso")
    s1i = rep.config("paper-s1-inleso")
    s2 = rep.config("paper-s2-leso")
    s3 = rep.config("paper-s3-leso")
    s3i = rep.config("paper-s3-inleso")
    ref = s1.scenario.reference
    sc2, sc3 = s2.scenario, s3.scenario
    w = s1.weights
    c1 = s1.controller
    y_unit, d_unit = s1.plant.output_unit, s1.plant.disturbance_unit

    def same_td_sef(a: Any, b: Any) -> bool:
        keys = [k for k in set(a.values) | set(b.values) if k.startswith(("td.", "sef."))]
        return all(a.value(k) == b.value(k) for k in keys)

    kept = all(same_td_sef(a.controller, b.controller) for a, b in ((s1, s3), (s1i, s3i)))
    x0 = "zero" if not s1.scenario.x0 else str(list(s1.scenario.x0))
    scale = ", ".join(f"{k} × {v:g}" for k, v in sc2.plant_scale.items()) or "none"
    return [
        (
            "Reference",
            "“a sinusoidal signal with frequency 2 rad/sec and amplitude of 45”",
            f"r = {math.degrees(ref.amplitude):.4g}° = {ref.amplitude:.6g} {y_unit} · "
            f"sin({ref.omega:g} t): the 45 read as degrees, in {y_unit} because y is an angle",
        ),
        (
            "Horizons",
            "20 s simulations; GA tuning with t_f = 6 s",
            f"simulation horizon {fmt(s1.scenario.t_final, 4)} s; tuning horizon 6 s "
            "(`aiofl tune`)",
        ),
        (
            "Initial state",
            "not stated",
            f"plant state {x0}; observer and differentiator states zero",
        ),
        (
            "Scenario 2 disturbance",
            "“step at t = 10 sec with amplitude 0.5 N.m and an increase 40 % in the load inertia”",
            f"τ_d = {sc2.disturbance_amplitude:g} {d_unit} from t = {sc2.disturbance_time:g} s "
            f"through b_d of eq. (15); {scale} in the true plant only (the controller is not "
            f"told) from t = {sc2.parameter_change_time:g} s",
        ),
        (
            "Scenario 3 noise",
            "Gaussian, mean 0, variance 0.0001, at the output",
            f"variance {sc3.noise_variance:g} {y_unit}², held constant over "
            f"{1e3 * sc3.noise_hold:g} ms, seed {sc3.noise_seed} (numpy default_rng); only the "
            "ESO's input is noisy; metrics use the true output",
        ),
        (
            "Scenario 3 TD and SEF",
            "only the re-tuned ESO parameters are printed",
            "TD and SEF keep the scenario-1 values"
            + (" (checked: identical in the presets)" if kept else " (NOT identical: see presets)"),
        ),
        (
            "Solver",
            "MATLAB ode45 (adaptive)",
            f"fixed-step {s1.method.upper()}, dt = {s1.dt:g} s, compiled: an adaptive solver "
            "on a loop with sign() and |e|^α (α < 1) chatters and crawls "
            "(benchmarks/bench_engine.py times scipy's RK45 against the engine on these "
            "loops); rerun a preset with "
            "`aiofl simulate NAME --dt 5e-5` to check convergence in dt",
        ),
        (
            "OPI weights",
            "w = (0.6, 0.2, 0.6) (sum 1.4, although the text requires 1), N = (10, 2, 2.7)",
            f"as printed: w = ({w.w_itae:g}, {w.w_isu:g}, {w.w_iau:g}), "
            f"N = ({w.n_itae:g}, {w.n_isu:g}, {w.n_iau:g}); configurable in [metrics]",
        ),
        (
            "fal (17)",
            "inner branch e/δ^(α−1), discontinuous at |e| = δ",
            "erratum corrected: e/δ^(1−α), continuous",
        ),
        (
            "Han's TD (18)",
            "switching term r2|r2|/(2r)",
            "erratum corrected: r2|r2|/(2R)",
        ),
        (
            "NLSEF gains",
            "v = fal(e1, α1, δ1) + fal(e2, α2, δ2)",
            f"unit gains k = ({c1.value('sef.k1'):g}, {c1.value('sef.k2'):g}); "
            f"{c1.n_feedback} estimated states fed back, as in the text",
        ),
        (
            "ITAE error signal",
            "ITAE = ∫ t|y − r| dt",
            "raw reference r, not the differentiator's profile r1; true output y",
        ),
    ]


@dataclass
class SettingsSection(Section):
    """The settings the paper leaves open (:func:`open_settings`), one row each."""

    rep: Reproduction
    title = "Settings the paper leaves open and the choice made"

    def markdown(self) -> str:
        """``## title`` and the table."""
        rows = [list(t) for t in open_settings(self.rep)]
        return f"## {self.title}\n\n{md_table(SETTINGS_HEADER, rows)}\n"

    def html(self) -> list[str]:
        """The table, folded under an ``<h2>``."""
        rows = [list(t) for t in open_settings(self.rep)]
        table = html_table(SETTINGS_HEADER, rows, cls="settings")
        return [details(self.title, [table], heading=True)]
