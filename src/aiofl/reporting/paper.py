"""The paper's printed facts: Tables I–III and how the paper names its three scenarios.

Abdul-Adheem & Ibraheem, arXiv 1805.00222, Section V.  :data:`PAPER_TABLES` is the only
copy of the printed numbers in the code; everything else in :mod:`aiofl.reporting` puts
computed values beside them.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["PAPER_PRESETS", "PAPER_TABLES", "SCENARIOS", "ScenarioInfo"]

PAPER_TABLES: dict[int, dict[str, dict[str, float]]] = {
    # Table I: scenario 1, nominal tracking
    1: {
        "LESO": {"itae": 126.120273, "isu": 7.982831},
        "INLESO": {"itae": 96.225965, "isu": 6.080829},
    },
    # Table II: scenario 2, step load disturbance + J_l x 1.4
    2: {
        "LESO": {"itae": 1309.213956, "isu": 58.214189},
        "INLESO": {"itae": 298.143303, "isu": 69.471044},
    },
    # Table III: scenario 3, output noise (noise-retuned ESOs)
    3: {
        "LESO": {"itae": 332.443873, "isu": 799.520367},
        "INLESO": {"itae": 102.578228, "isu": 19.959797},
    },
}
"""The paper's Tables I–III (ITAE and ISU as printed; the paper gives no IAU or OPI)."""


@dataclass(frozen=True)
class ScenarioInfo:
    """How the paper refers to one scenario."""

    number: int
    title: str
    table: str
    figure: int


SCENARIOS: dict[int, ScenarioInfo] = {
    1: ScenarioInfo(1, "nominal tracking", "I", 3),
    2: ScenarioInfo(2, "0.5 N·m step load at t = 10 s and J_l × 1.4 (true plant only)", "II", 4),
    3: ScenarioInfo(3, "Gaussian output noise, variance 1e-4", "III", 5),
}

PAPER_PRESETS: tuple[tuple[str, int, str], ...] = tuple(
    (f"paper-s{s}-{k.lower()}", s, k) for s in SCENARIOS for k in ("LESO", "INLESO")
)
"""(preset, scenario, structure) of the six paper cases."""
