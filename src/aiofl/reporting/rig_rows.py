r"""What a rig does to every design: the report's rig table (issue 36).

Every case of the report, and every shipped ``rig-*`` design (the designs re-tuned on the
rig and told of its delay), is put on the ``servo-1khz`` rig (:mod:`aiofl.rig`: a 12-bit
encoder sampled at 1 ms, one sample of measurement delay, a 1 ms actuator lag, Coulomb
friction of 1 % of a unit input at the hub) by :func:`aiofl.analysis.rig_check.rig_checks`:

* **as shipped** — a design that was not told about the delay is not told now;
* **nominal** — the paper's plant with the rig, the scenario's own reference;
* **over draws** — :data:`RIG_DRAWS_N` draws of J_l, K_s, R_m, J_h each × U[0.8, 1.2] and
  the rig's lag and friction each × U[0.5, 1.5] (seed 0; every design meets the same
  plants).

Its verdict says what the plant did (:attr:`aiofl.analysis.rig_check.RigCheck.verdict`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from aiofl.reporting.cases import Case, Reproduction
from aiofl.reporting.section import TableSection
from aiofl.reporting.tables import DASH, fmt

__all__ = [
    "RIG_BOX",
    "RIG_DESIGNS",
    "RIG_DRAWS_N",
    "RIG_HEADER",
    "RIG_TITLE",
    "RigSection",
    "RigTable",
    "compute_rig_table",
    "rig_notes",
    "rig_rows",
    "with_rig_records",
]

RIG = "servo-1khz"
#: draws per design in the report (the independent check's 32)
RIG_DRAWS_N = 32
#: the parameter box every design is judged over (the paper plant's uncertain parameters)
RIG_BOX: dict[str, float] = {"J_l": 0.2, "K_s": 0.2, "R_m": 0.2, "J_h": 0.2}
#: the shipped designs made for the rig (re-tuned on it, told of its delay), beside the cases
RIG_DESIGNS: tuple[str, ...] = ("rig-s1-ladrc", "rig-s2-ladrc", "rig-s3-ladrc")

RIG_TITLE = "What a rig does: every design on the servo-1khz rig"
RIG_HEADER = (
    "Scenario",
    "Design",
    "Preset",
    "own run ITAE",
    "rig ITAE",
    "rig ISU",
    "not lost (draws)",
    "ITAE q95",
    "ISU q95",
    "Verdict",
)


@dataclass(frozen=True)
class RigTable:
    """Every design on the rig: the checks by preset (:class:`~aiofl.analysis.rig_check.
    RigCheck`), the scenario and label of each row, and what the computation cost."""

    checks: dict[str, Any] = field(default_factory=dict)
    rows: list[tuple[int, str, str]] = field(default_factory=list)  # scenario, label, preset
    skipped: dict[str, str] = field(default_factory=dict)
    seconds: float = 0.0

    def records(self) -> dict[str, dict[str, Any]]:
        """The checks as JSON records by preset."""
        return {p: c.to_dict() for p, c in self.checks.items()}


def compute_rig_table(
    cases: Sequence[Case],
    *,
    own: dict[str, dict[str, Any]] | None = None,
    draws: int = RIG_DRAWS_N,
    extra: Sequence[str] = RIG_DESIGNS,
    on_stage: Callable[[str], None] | None = None,
) -> RigTable:
    """Every case and every shipped :data:`RIG_DESIGNS` design on the rig (module
    docstring).

    Parameters
    ----------
    cases : sequence of Case
        The report's cases.
    own : dict, optional
        The cases' own runs by preset (``itae``, ``isu``, ``status``, ``stopped_at``): not
        run again.
    draws : int
        Draws per design (0: the nominal runs only).
    extra : sequence of str
        Shipped presets run beside the cases (default :data:`RIG_DESIGNS`).
    on_stage : callable, optional
        Told the stage's name.

    Returns
    -------
    RigTable
    """
    from aiofl.analysis.rig_check import rig_checks
    from aiofl.config import load_config
    from aiofl.reporting.cases import scenario_number

    stage = on_stage or (lambda _msg: None)
    rows = [(c.scenario, c.label, c.preset) for c in cases]
    cfgs = {c.preset: c.config for c in cases}
    for name in extra:
        if name not in cfgs:
            cfgs[name] = load_config(name)
            cfg = cfgs[name]
            rows.append((scenario_number(name) or 0, f"{cfg.controller.structure} (rig)", name))
    stage(f"rig: {len(cfgs)} designs on {RIG}, nominal and {draws} draws each")
    t0 = time.perf_counter()
    skipped: dict[str, str] = {}
    checks = rig_checks(
        list(cfgs.values()), RIG, draws=draws, seed=0, box=RIG_BOX, own=own, skipped=skipped
    )
    return RigTable(
        checks={c.name: c for c in checks},
        rows=sorted(rows, key=lambda r: r[0]),  # stable: the cases' order, rig-* last
        skipped=skipped,
        seconds=time.perf_counter() - t0,
    )


def with_rig_records(
    records: Sequence[dict[str, Any]], table: RigTable | None
) -> list[dict[str, Any]]:
    """The records with ``"rig"`` (the preset's :meth:`RigCheck.to_dict
    <aiofl.analysis.rig_check.RigCheck.to_dict>`) added to every computed one."""
    if table is None:
        return list(records)
    by = table.records()
    return [{**rec, "rig": by.get(rec["preset"])} if "preset" in rec else rec for rec in records]


def _itae(rec: dict[str, Any]) -> str:
    if rec["status"] != "ok":
        return f"{rec['status']} at t = {rec['stopped_at']:.3g} s"
    return fmt(rec["itae"], 3)


def rig_rows(rep: Reproduction) -> list[list[str]]:
    """One row per design: scenario, label, preset, its own ITAE, the rig's nominal ITAE
    and ISU, the share of draws not lost, ITAE and ISU q95 over them, the verdict."""
    table: RigTable | None = getattr(rep, "rig", None)
    if table is None:
        return []
    out = []
    for scenario, label, preset in table.rows:
        chk = table.checks.get(preset)
        if chk is None:
            out.append([str(scenario), label, preset, *[DASH] * 6, table.skipped.get(preset, "")])
            continue
        nom = chk.nominal
        drawn = chk.draws > 0
        out.append(
            [
                str(scenario),
                label,
                preset,
                _itae(chk.own),
                _itae(nom),
                fmt(nom["isu"], 3),
                f"{100 * chk.not_lost:.0f} % of {chk.draws}" if drawn else DASH,
                fmt(chk.itae_q95, 3) if drawn else DASH,
                fmt(chk.isu_q95, 3) if drawn else DASH,
                chk.verdict,
            ]
        )
    return out


def _draws(table: RigTable) -> int:
    return max((c.draws for c in table.checks.values()), default=0)


def rig_notes(rep: Reproduction) -> list[str]:
    """What the columns are, and how many designs hold."""
    table: RigTable | None = getattr(rep, "rig", None)
    if table is None:
        return []
    holds = [p for p, c in table.checks.items() if c.holds]
    notes = [
        "The rig: servo-1khz (aiofl.rig): a 12-bit encoder sampled at 1 ms, one sample "
        "(1 ms) of measurement delay, a 1 ms first-order actuator lag, Coulomb friction of "
        "0.01 V at the hub (smoothed over 1e-3 rad/s). 'own run ITAE' is the design as "
        "shipped (the tables above); 'rig' the same design on the rig, nominal plant; "
        f"the draws are {_draws(table)} plants with J_l, K_s, R_m, J_h each × U[0.8, 1.2] and "
        "the rig's lag and friction each × U[0.5, 1.5] (seed 0, the same plants for every "
        "design). q95 is over the draws (a dash when a lost draw falls there). Designs run "
        "as shipped: only the rig-* designs are told the delay ([controller.eso] delay = "
        f'"rig"). {table.seconds:.1f} s.',
        f"Verdicts say what the plant did: {len(holds)} of {len(table.checks)} designs hold "
        "on the rig (nominal and every draw kept, tracking, the command not screaming, its "
        "ISU at most 2× its own run's). 'does not track': its ITAE is at least half that of no "
        "control at all (y ≡ 0); 'screams': at steady state the command is mostly the "
        "encoder's quantum; 'command ×N': the rig drives the actuator N times harder than "
        "the design's own run; 'lost in k of N draws': that many plants of the box were "
        "lost (|y − r| beyond the scenario's envelope). A shipped design that does not "
        "hold is an ideal-world figure: `aiofl presets` lists those apart (the ideal-world "
        "limits; the paper's printed designs are a set of their own).",
    ]
    if table.skipped:
        notes.append(
            "Not run on the rig: " + "; ".join(f"{p} ({w})" for p, w in table.skipped.items())
        )
    return notes


@dataclass
class RigSection(TableSection):
    """The rig table of the report: :func:`rig_rows` and :func:`rig_notes`."""

    rep: Reproduction
    title = RIG_TITLE
    header = RIG_HEADER

    def rows(self) -> list[list[str]]:
        """:func:`rig_rows`."""
        return rig_rows(self.rep)

    def notes(self) -> list[str]:
        """:func:`rig_notes`."""
        return rig_notes(self.rep)
