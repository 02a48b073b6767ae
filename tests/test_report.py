"""The report says what was measured, in the plant's own units.

* :mod:`aiofl.reporting.behaviour`: the measured quantities against closed forms, and the
  reconciliation sentence against the run it describes;
* the reproduction: every case's sentence matches its trajectory, the findings are few and
  every number in them is in metrics.json, IOFL rows say what IOFL is given;
* units: figure axes and trajectory.csv headers carry the plant's units (tank in m, SLFJM
  in rad); scenario events outside the horizon neither fail nor stretch a figure; no
  title or legend is printed over another.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from aiofl.engine.simulation import SimulationResult
from aiofl.plants.base import Plant, PlantError, derivative_unit, unit_from_label, unit_label
from aiofl.reporting.behaviour import (
    TOLERANCE,
    analysis_numbers,
    measure,
    min_damping,
    reconcile,
)
from aiofl.scenario import Scenario


# ------------------------------------------------------------------- measurements
def _sine_run(amp: float, offset: float, t_final: float = 20.0):
    """r = sin(2t); y = r + e with e = offset + amp·cos(3t), on a grid fine enough that the
    window's extremes of cos(3t) are ±1 to 1e-6."""
    t = np.linspace(0.0, t_final, 30001)
    r = np.sin(2 * t)
    return t, r + offset + amp * np.cos(3 * t), r


def test_bounded_oscillation_amplitude_offset_and_peak_are_the_closed_forms() -> None:
    # e = 0.05 + 0.3 cos(3t): over the last 5 s max e = 0.35, min e = -0.25
    t, y, r = _sine_run(0.3, 0.05)
    b = measure(t, y, r, window=5.0)
    assert b.kind == "bounded"
    assert b.error_amplitude == pytest.approx(0.3, rel=1e-6)
    assert b.error_offset == pytest.approx(0.05, abs=1e-6)
    assert b.max_abs_error == pytest.approx(0.35, rel=1e-6)
    assert b.reference_peak == pytest.approx(1.0, rel=1e-6)
    assert b.growth == pytest.approx(1.0, rel=1e-3)  # the same peak in the window before


def test_tracking_and_growth_are_classified_by_their_definitions() -> None:
    t, y, r = _sine_run(0.5 * TOLERANCE, 0.0)
    assert measure(t, y, r).kind == "tracks"
    t, y, r = _sine_run(2.0 * TOLERANCE, 0.0)
    assert measure(t, y, r).kind == "bounded"
    # e = 0.1 e^(0.3 t): the peak of the last window over the one before is e^(0.3·5)
    t = np.linspace(0.0, 20.0, 30001)
    r = np.sin(2 * t)
    b = measure(t, r + 0.1 * np.exp(0.3 * t), r, window=5.0)
    assert b.kind == "growing"
    assert b.growth == pytest.approx(math.exp(0.3 * 5.0), rel=2e-3)
    d = measure(t, r, r, failed=True, stopped_at=12.42)
    assert (d.kind, d.stopped_at, d.max_abs_error) == ("diverged", 12.42, None)


def test_min_damping_is_the_closed_form_and_the_analysis_value_wins() -> None:
    zeta, wn = 0.049, 12.0
    pair = complex(-zeta * wn, wn * math.sqrt(1 - zeta**2))
    eig = [[pair.real, pair.imag], [pair.real, -pair.imag], [-50.0, 0.0]]
    assert min_damping({"eigenvalues": eig}) == pytest.approx(zeta, rel=1e-12)
    assert min_damping({"eigenvalues": eig, "min_damping": 0.3}) == 0.3
    assert min_damping({"eigenvalues": [[0.5, 2.0], [0.5, -2.0]]}) < 0  # a growing mode
    nums = analysis_numbers({"verdict": "stable", "eigenvalues": eig, "gain_margin_db": math.inf})
    assert nums["max_real"] == pytest.approx(pair.real)
    assert nums["gain_margin_db"] is None  # JSON has no infinity
    assert nums["phase_margin_deg"] is None and nums["ms"] is None  # not provided


def test_reconciliation_sentence_states_both_sides() -> None:
    unstable = {"verdict": "unstable", "eigenvalues": [[1.27, 0.0]], "max_real": 1.27}
    stable = {"verdict": "stable", "eigenvalues": [[-2.0, 0.0]], "max_real": -2.0}
    t, y, r = _sine_run(0.3, 0.05)
    bounded = measure(t, y, r)
    text = reconcile(unstable, bounded, "rad")
    assert text.startswith("Linearisation unstable at the operating point")
    assert "max Re λ = 1.27 1/s" in text
    assert f"amplitude {bounded.error_amplitude:.3g} rad" in text
    assert "they differ" in text
    div = measure(t, y, r, failed=True, stopped_at=17.57)
    assert "diverges at t = 17.57 s — they agree" in reconcile(unstable, div, "rad")
    t, y, r = _sine_run(0.01, 0.0)
    assert "tracks: max |e| over the last 5 s = 0.01 m" in reconcile(stable, measure(t, y, r), "m")
    failed = {"verdict": "analysis failed: ValueError: no operating point", "eigenvalues": []}
    assert reconcile(failed, div).startswith("No linearisation verdict (analysis failed")


# -------------------------------------------------------------- the reproduction
@pytest.fixture(scope="module")
def rep(reproduced):
    """The session's ``aiofl reproduce`` run's Reproduction (conftest.py)."""
    assert reproduced.exit_code == 0, reproduced.stderr
    return reproduced.reproduction()


def _window(run):
    res = run.result
    sel = res.t >= res.t[-1] - run.behaviour.window
    return (res["y"] - res["r"])[sel]


@pytest.mark.slow
def test_every_sentence_matches_its_trajectory(rep) -> None:
    from aiofl.reporting.tables import verdict_rows

    rows = {row[0].split(" (")[0]: row for row in verdict_rows(rep)}
    assert set(rows) == {r.case.preset for r in rep.runs}
    kinds = set()
    for run in rep.runs:
        text = rows[run.case.preset][-1]
        b = run.behaviour
        kinds.add(b.kind)
        if run.result.failed:
            verb = "loses the plant" if run.result.lost else "diverges"
            assert f"{verb} at t = {run.result.stopped_at:.2f} s" in text
            continue
        e = _window(run)
        assert b.max_abs_error == pytest.approx(np.max(np.abs(e)), rel=1e-12)
        assert f"max |e| = {np.max(np.abs(e)):.3g} rad" in text or (
            f"max |e| over the last 5 s = {np.max(np.abs(e)):.3g} rad" in text
        )
        if b.kind == "bounded":
            amp = 0.5 * (np.max(e) - np.min(e))
            assert f"oscillates with amplitude {amp:.3g} rad" in text
        verdict = rep.verdicts[run.case.preset]["verdict"]
        if verdict in ("stable", "unstable"):  # the reconciled sentence starts there
            orbit = rep.verdicts[run.case.preset].get("orbit") or {}
            first = "Equilibrium" if orbit.get("floquet") or orbit.get("ftle") else "Linearisation"
            assert text.startswith(f"{first} {verdict}")
    # the shipped cases cover divergence, tracking and a bounded oscillation
    assert {"tracks", "bounded"} <= kinds and kinds & {"lost", "diverged"}
    # an unstable verdict beside a bounded, oscillating run (e.g. the printed INLESO)
    assert any(
        rep.verdicts[r.case.preset]["verdict"] == "unstable" and r.behaviour.kind == "bounded"
        for r in rep.runs
    )


@pytest.mark.slow
def test_metrics_records_carry_the_measurements(rep) -> None:
    recs = {rec["preset"]: rec for rec in rep.records if "preset" in rec}
    for run in rep.runs:
        tr = recs[run.case.preset]["tracking"]
        assert tr["behaviour"] == run.behaviour.kind
        assert tr["tolerance"] == TOLERANCE
        if not run.result.failed:
            e = _window(run)
            assert tr["max_abs_error"] == np.max(np.abs(e))
            assert tr["error_amplitude"] == pytest.approx(0.5 * np.ptp(e), rel=1e-12)
        lin = recs[run.case.preset]["linearisation"]
        assert lin["verdict"] == rep.verdicts[run.case.preset]["verdict"]
    json.dumps(rep.records, allow_nan=False)  # no NaN or infinity in metrics.json


_NUMBER = re.compile(r"(?<![\w.^(-])[-−]?\d+(?:\.\d+)?(?:e[-+]?\d+)?(?!\w|\.\d)")


def _numbers(obj) -> list[float]:
    if isinstance(obj, bool) or obj is None or isinstance(obj, str):
        return []
    if isinstance(obj, (int, float)):
        return [float(obj)]
    items = obj.values() if isinstance(obj, dict) else obj
    return [x for item in items for x in _numbers(item)]


def _printed_as(token: str, value: float) -> bool:
    """Whether ``token`` is ``value`` printed with the token's significant digits."""
    mant = token.lstrip("-").split("e")[0].replace(".", "").lstrip("0") or "0"
    digits = max(len(mant), 1)
    return float(f"{value:.{digits}g}") == float(token) or (
        "." in token and f"{value:.{len(token.split('.')[1])}f}" == token
    )


@pytest.mark.slow
def test_findings_are_few_and_every_number_is_in_metrics_json(rep) -> None:
    from aiofl.reporting.findings import MAX_FINDINGS, findings

    found = findings(rep)
    assert 3 <= len(found) <= MAX_FINDINGS <= 8
    values = _numbers(rep.records)
    for text in found:
        for token in _NUMBER.findall(text):
            token = token.replace("−", "-")
            if re.fullmatch(r"\d+", token) and int(token) <= len(rep.records):
                continue  # a count ("3 of the 6")
            assert any(_printed_as(token, v) for v in values), (token, text)
    # the divergence finding gives each diverged printed case with its time
    for run in rep.runs:
        if run.case.source == "printed" and run.result.failed:
            at = f"{run.result.status} at t = {run.result.stopped_at:.2f} s"
            assert f"{run.case.preset} {at}" in found[0]


@pytest.mark.slow
def test_iofl_rows_say_what_iofl_is_given(rep) -> None:
    from aiofl.reporting.tables import table_rows, verdict_rows

    iofl = [r for r in rep.runs if r.case.structure == "IOFL"]
    assert iofl
    for run in iofl:
        (row,) = [row for row in table_rows(rep, run.case.scenario) if row[1] == run.case.preset]
        assert "given the nominal model" in row[0] and "noise-free state x" in row[0]
        if run.case.config.scenario.plant_scale:
            assert "the true plant has J_l × 1.4" in row[0]
    others = [row for row in verdict_rows(rep) if not row[0].startswith("iofl")]
    assert not any("given" in row[0] for row in others)


@pytest.mark.slow
def test_margins_show_a_dash_when_absent_and_their_value_when_present(rep) -> None:
    from dataclasses import replace

    from aiofl.reporting.tables import VERDICT_HEADER, verdict_rows

    col = {h: i for i, h in enumerate(VERDICT_HEADER)}
    preset = next(r.case.preset for r in rep.runs if r.case.structure == "LADRC")
    base = dict(rep.verdicts[preset])
    for key in ("gain_margin_db", "phase_margin_deg", "delay_margin_s", "ms"):
        base.pop(key, None)
    extra = {"gain_margin_db": math.inf, "phase_margin_deg": 41.5, "delay_margin_s": 0.0123}
    for verdicts, expect in (
        ({**rep.verdicts, preset: base}, ("—", "—", "—", "—")),
        ({**rep.verdicts, preset: {**base, **extra, "ms": 1.62}}, ("∞", "41.5", "0.0123", "1.62")),
    ):
        (row,) = [row for row in verdict_rows(replace(rep, verdicts=verdicts)) if row[0] == preset]
        assert tuple(row[col[k]] for k in ("GM [dB]", "PM [°]", "DM [s]", "Ms")) == expect


# -------------------------------------------------------------------------- units
def test_plant_units_defaults_and_checks() -> None:
    def f(x, p):
        return (x[1], -x[0])

    def g(x, p):
        return (0.0, 1.0)

    def h(x, p):
        return x[0]

    plain = Plant("osc", 2, f, g, h, {})
    assert (plain.output_unit, plain.input_unit, plain.state_units) == ("", "", ("", ""))
    assert plain.state_label(1) == "x2"
    with pytest.raises(PlantError, match="state_units needs 2 strings"):
        Plant("osc", 2, f, g, h, {}, state_units=("m",))
    assert unit_label("y", "m") == "y [m]" and unit_label("y", "-") == "y"
    assert [derivative_unit("rad", k) for k in range(3)] == ["rad", "rad/s", "rad/s^2"]
    assert derivative_unit("", 2) == ""
    assert unit_from_label("hub angle θ [rad]") == "rad" and unit_from_label("level") == ""


def test_builtin_plants_declare_their_units() -> None:
    from aiofl.plants.registry import get_plant

    slfjm = get_plant("slfjm")
    assert (slfjm.output_unit, slfjm.input_unit) == ("rad", "V")
    assert slfjm.state_units == ("rad", "rad", "rad/s", "rad/s")
    tank = get_plant("tank")
    assert (tank.output_unit, tank.input_unit, tank.state_units) == ("m", "V", ("m",))
    arm = get_plant("dcmotor_arm")
    assert arm.state_units == ("rad", "rad/s", "A") and arm.input_unit == "V"
    hub = get_plant("flexjoint_hub")
    assert (hub.output_unit, hub.input_unit) == ("rad", "N·m")


def test_plant_files_take_units_from_toml_keys_or_state_labels(tmp_path: Path) -> None:
    from aiofl.plants.expressions import SymbolicPlantError
    from aiofl.plants.symbolic import SymbolicPlant

    spec = {
        "states": {"h": "level [m]", "q": "flow"},
        "params": {"k": 1.0},
        "f": ["q", "-k*h"],
        "g": ["0", "1"],
        "h": "h",
        "output_unit": "m",
        "input_unit": "V",
    }
    plant = SymbolicPlant.from_dict(spec).to_plant()
    assert (plant.output_unit, plant.input_unit, plant.state_units) == ("m", "V", ("m", ""))
    plant = SymbolicPlant.from_dict({**spec, "state_units": ["m", "m^3/s"]}).to_plant()
    assert plant.state_units == ("m", "m^3/s")
    with pytest.raises(SymbolicPlantError, match="state_units"):
        SymbolicPlant.from_dict({**spec, "state_units": ["m"]})
    with pytest.raises(SymbolicPlantError, match="output_unit"):
        SymbolicPlant.from_dict({**spec, "output_unit": 5})


def _fake_result(t_final: float = 4.0, stopped_at: float | None = None) -> SimulationResult:
    t = np.linspace(0.0, t_final if stopped_at is None else stopped_at, 401)
    r = 0.8 * np.sin(2 * t)
    y = r + 0.05 * np.cos(3 * t)
    u = np.cos(t) if stopped_at is None else 1e5 * np.exp(t) * np.sin(40 * t)
    if stopped_at is not None:
        y = r + np.exp(3 * t) * np.sin(40 * t)
    return SimulationResult(
        None if stopped_at else {"itae": 1.0, "iae": 1.0, "ise": 1.0, "isu": 1.0, "iau": 1.0},
        "ok" if stopped_at is None else "diverged",
        stopped_at,
        t,
        {"r": r, "y": y, "u": u},
    )


def test_figure_axes_are_in_the_plants_units() -> None:
    from aiofl.plants.registry import get_plant
    from aiofl.reporting.figures import result_figure

    for name, y_unit, u_unit in (("tank", "m", "V"), ("slfjm", "rad", "V")):
        plant = get_plant(name)
        fig = result_figure(
            _fake_result(),
            name,
            4.0,
            "LADRC",
            output_unit=plant.output_unit,
            input_unit=plant.input_unit,
        )
        labels = [ax.get_ylabel() for ax in fig.axes]
        assert labels == [f"y, r [{y_unit}]", f"e = y − r [{y_unit}]", f"u [{u_unit}]"]
        # the middle panel is the tracking error y − r, drawn from the run
        (line,) = [ln for ln in fig.axes[1].get_lines() if ln.get_linestyle() == "-"]
        res = _fake_result()
        assert np.allclose(line.get_ydata(), res["y"] - res["r"])
    bare = result_figure(_fake_result(), "no units", 4.0)
    assert [ax.get_ylabel() for ax in bare.axes] == ["y, r", "e = y − r", "u"]


@pytest.mark.slow
def test_front_figure_axes_carry_the_metrics_units(rep) -> None:
    from dataclasses import replace

    from aiofl.reporting.front_files import load_fronts
    from aiofl.reporting.fronts import front_figure

    (ax,) = front_figure(replace(rep, fronts=load_fronts()), 1, None).axes
    assert ax.get_xlabel() == "ISU = ∫ u² dt [V²·s]"
    assert ax.get_ylabel() == "ITAE = ∫ t|y − r| dt [rad·s²]"


def _diverge(rep, scenario: int, structures: set[str]):
    """The reproduction with every computed record of these structures in a scenario
    diverged (at t = 1 s)."""
    from dataclasses import replace

    gone = {"failed": True, "stopped_at": 1.0, "itae": None, "isu": None}
    return replace(
        rep,
        records=[
            {**r, **gone}
            if "preset" in r and r["scenario"] == scenario and r["structure"] in structures
            else r
            for r in rep.records
        ],
    )


@pytest.mark.slow
def test_the_claim_is_judged_on_both_sides_and_a_near_trivial_win_is_named(rep) -> None:
    from aiofl.reporting.summary import best_design, claim_text

    # scenario 1 as run: the printed LESO diverges, the printed INLESO barely moves
    inleso = next(r for r in rep.records if r.get("preset") == "paper-s1-inleso")
    share = 100 * inleso["itae"] / rep.trivial[1]
    assert claim_text(rep, 1).startswith(
        f"printed sets: holds (LESO diverges; INLESO's ITAE is {share:.0f} % of y ≡ 0's)"
    )
    # every INLESO design diverges: the claim fails on both counts; every design: untested
    assert claim_text(_diverge(rep, 1, {"INLESO"}), 1) == (
        "printed sets: untested (both diverge); best of each structure: fails (INLESO diverges)"
    )
    both = _diverge(rep, 1, {"INLESO", "LESO"})
    assert claim_text(both, 1).endswith("best of each structure: untested (both diverge)")
    # every LESO design of scenario 3 diverges: the best INLESO wins by default
    assert claim_text(_diverge(rep, 3, {"LESO"}), 3).endswith(
        "best of each structure: holds (LESO diverges)"
    )
    # IOFL is not an ESO-based design, so it is never the scenario's best design
    assert all(best_design(both, s)[0].case.structure != "IOFL" for s in (1, 2, 3))


@pytest.mark.parametrize("t_event", [1e7, -3.0, math.inf, 2.5])
def test_events_outside_the_horizon_neither_fail_nor_stretch_the_figure(t_event) -> None:
    from aiofl.reporting.figures import figure_png, result_figure, scenario_events

    sc = Scenario(t_final=4.0, disturbance_amplitude=0.5, disturbance_time=2.5)
    assert scenario_events(sc, "N·m") == ((2.5, "$\\tau_d$ = 0.5 N·m step"),)
    events = ((t_event, "$\\tau_d$ = 0.5 N·m step"),)  # times a config may or may not accept
    ref = _fake_result()
    fig = result_figure(ref, "events", 4.0, "LESO", events=events, output_unit="rad")
    png = figure_png(fig)
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = int.from_bytes(png[16:20], "big"), int.from_bytes(png[20:24], "big")
    assert (width, height) == (1300, round(fig.get_figheight() * 100))
    for ax in fig.axes:
        assert ax.get_xlim() == (0.0, 4.0)
        vlines = [ln for ln in ax.get_lines() if ln.get_linestyle() == "-."]
        assert len(vlines) == (1 if 0 <= t_event <= 4.0 else 0)
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    inside = 0 <= t_event <= 4.0
    assert any(("not drawn" in s) != inside for s in legend if "tau_d" in s)


def _overlaps(a, b) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def test_no_title_or_legend_is_printed_over_another() -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from aiofl.reporting.figures import Panel, runs_figure

    panels = [
        Panel("LESO [paper-s2-leso]", _fake_result(20.0, 17.57), "#1f77b4", 20.0,
              events=((10.0, "$\\tau_d$ = 0.5 N·m step"),), output_unit="rad", input_unit="V"),
        Panel("INLESO (retuned) [retuned-s2-inleso]", _fake_result(20.0), "#d62728", 20.0,
              events=((10.0, "$\\tau_d$ = 0.5 N·m step"),), output_unit="rad", input_unit="V"),
    ]  # fmt: skip
    fig = runs_figure(panels, "Figure 4 (reproduced): scenario 2")
    renderer = FigureCanvasAgg(fig).get_renderer()
    boxes = [fig.legends[0].get_window_extent(renderer)]
    for ax in fig.axes:
        titles = [ax.title, ax._left_title, ax._right_title]  # centre, left and right titles
        boxes += [t.get_window_extent(renderer) for t in titles if t.get_text()]
        assert not _overlaps(fig.legends[0].get_window_extent(renderer), ax.bbox)
    for i, a in enumerate(boxes):
        for b in boxes[i + 1 :]:
            assert not _overlaps(a, b)
    # the diverged row's titles say where it diverged and how far y went
    right = [ax._right_title.get_text() for ax in fig.axes[:3]]
    assert right[1] == right[2] == "diverged at t = 17.57 s"
    assert right[0].startswith("|y| reaches") and right[0].endswith(" rad")


# ----------------------------------------------------------------- trajectory.csv
@pytest.mark.slow
@pytest.mark.parametrize(
    ("preset", "expect"),
    [
        ("tank-ladrc", ["t [s]", "r [m]", "y [m]", "y_meas [m]", "u [V]", "d [m^3/s]",
                        "level [m]"]),
        ("paper-s1-inleso", ["t [s]", "r [rad]", "y [rad]", "y_meas [rad]", "u [V]", "d [N·m]",
                             "theta [rad]", "alpha [rad]", "theta_dot [rad/s]"]),
    ],
)  # fmt: skip
def test_trajectory_csv_has_a_units_line(tmp_path: Path, preset: str, expect: list[str]) -> None:
    from typer.testing import CliRunner

    from aiofl.cli.app import app
    from aiofl.config import preset_text

    cfg = tmp_path / "short.toml"
    cfg.write_text(preset_text(preset).replace("t_final = 20.0", "t_final = 0.5"))
    out = tmp_path / "run"
    res = CliRunner().invoke(app, ["simulate", str(cfg), "--out", str(out)])
    assert res.exit_code == 0, res.stderr
    lines = (out / "trajectory.csv").read_text(encoding="utf-8").splitlines()
    names, units = lines[0].split(","), lines[1]
    assert units.startswith("# ")
    labels = units[2:].split(",")
    assert len(labels) == len(names)
    assert labels[: len(expect)] == expect
    assert [lab.split(" [")[0] for lab in labels[:6]] == names[:6]
    xi = [lab for lab in labels if lab.startswith("xi_hat")]
    y_unit = expect[2].split("[")[1].rstrip("]")
    assert xi[:2] == [f"xi_hat1 [{y_unit}]", f"xi_hat2 [{y_unit}/s]"]
    data = np.loadtxt(out / "trajectory.csv", delimiter=",", skiprows=1)  # '#' line skipped
    assert data.shape[1] == len(names) and np.isfinite(data).all()


def test_unit_texts_are_bounded() -> None:
    from aiofl.plants.expressions import SymbolicPlantError
    from aiofl.plants.symbolic import SymbolicPlant

    spec = {"states": ["h"], "params": {"k": 1.0}, "f": ["-k*h"], "g": ["1"], "h": "h"}
    with pytest.raises(SymbolicPlantError, match=r"input_unit = 'VVVV.*at most 32 characters"):
        SymbolicPlant.from_dict({**spec, "input_unit": "V" * 10_000})
    with pytest.raises(SymbolicPlantError, match=r"state_units\[1\] = 'mmmm"):
        SymbolicPlant.from_dict({**spec, "state_units": ["m" * 33]})
    ok = SymbolicPlant.from_dict({**spec, "states": {"h": "level [" + "m" * 50 + "]"}})
    assert ok.state_units == ("m" * 32,)  # a label's bracket is documentation: cut, not refused


# ------------------------------------------------------------------ sensors
def test_sensor_table_columns_are_simulate_with_that_sensor() -> None:
    """Every column is `aiofl simulate PRESET --sensor S` (S = ideal, encoder-16bit,
    encoder-12bit): the ideal column is the ideal-sensor limit also of a preset shipped
    sampled and quantised (assisted-*), and `aiofl simulate PRESET` for the continuous
    ones; a diverged run is written as its divergence time; the verdict follows."""
    from types import SimpleNamespace

    from aiofl.config import load_config
    from aiofl.reporting.cases import discover_cases
    from aiofl.reporting.sensor_rows import SENSOR_COLUMNS, compute_sensor_table, sensor_rows

    names = ("frontier-s1-ladrc", "retuned-s1-leso", "paper-s1-leso", "assisted-s1-ladrc")
    cases = [c for c in discover_cases(list(names)) if c.preset in names]
    assert len(cases) == len(names)
    table = compute_sensor_table(cases)
    assert table.engine_calls == 1 and not table.skipped
    for case in cases:
        got = table.results[case.preset]
        assert [k for k, _, _ in SENSOR_COLUMNS] == ["ideal", "encoder-16bit", "encoder-12bit"]
        for key, preset, _ in SENSOR_COLUMNS:
            one = load_config(case.preset).with_sensor(preset).simulate(store=False)
            assert got[key]["failed"] == one.failed
            if one.failed:
                assert got[key]["stopped_at"] == one.stopped_at
            else:
                assert got[key]["itae"] == one.metrics["itae"]
                assert got[key]["isu"] == one.metrics["isu"]
        assert "(continuous, not quantised" in got["ideal"]["sensor"]
        shipped = load_config(case.preset).simulate(store=False)
        if case.preset == "assisted-s1-ladrc":  # shipped with a 12-bit encoder at 1 ms
            assert load_config(case.preset).sampling is not None
            assert got["encoder-12bit"]["itae"] == shipped.metrics["itae"]
            assert got["ideal"]["itae"] != shipped.metrics["itae"]
        elif not shipped.failed:
            assert got["ideal"]["itae"] == shipped.metrics["itae"]
    given = {p: got["ideal"] for p, got in table.results.items()}  # runs already made
    again = compute_sensor_table(cases, ideal=given)
    assert again.results == table.results
    # a sampled preset's own run is not taken as its ideal column
    wrong = {"assisted-s1-ladrc": {"itae": 1.0, "isu": 1.0, "failed": False, "stopped_at": 0}}
    assert compute_sensor_table(cases, ideal=wrong).results == table.results
    rep = SimpleNamespace(runs=[SimpleNamespace(case=c) for c in cases], sensors=table)
    rows = {r[2]: r for r in sensor_rows(rep)}  # type: ignore[arg-type]
    f = rows["frontier-s1-ladrc"]
    # on the 12-bit encoder its plant is held (it was "diverged" when the observer's states
    # decided) but its command screams: ISU far beyond twice the ideal's, no survival
    assert f[-1] == "ideal-sensor only"
    assert rows["retuned-s1-leso"][-1] == "survives a 12-bit encoder"
    assert rows["paper-s1-leso"][-1] == "loses the plant even with the ideal sensor"
