"""``aiofl excite`` and ``aiofl identify`` (issue 35).

* excite: the CSV is a log aiofl reads, the C array holds the same samples, the output-file
  rule (an existing file needs --force), bad options exit 2 with nothing written;
* identify: every bad log is refused before anything runs (exit 2, the message names the
  column and the row, OUT not created), and so are bad options;
* identify's outputs with the routes replaced by stand-ins that follow the agreed API
  (``identify_chain``, ``offline_eso``, ``first_config``, ``fit_plant``,
  ``uncertainty_table``, ``fitted_plant_file``): the files, the JSON keys, design.toml
  loading as a run config; and, where the real routes are on this branch, a run on a
  synthetic log of the independent simulator.
"""

from __future__ import annotations

import json
import sys
import types
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from aiofl.cli.app import app
from aiofl.identification.log import Log, read_log, write_log
from aiofl.identification.synthetic import simulate_log
from aiofl.plants.registry import get_plant

TS = 1e-3
N = 400


def _invoke(*args: str) -> Any:
    return CliRunner().invoke(app, list(args))


def _nothing_written(tmp: Path, keep: set[str]) -> None:
    assert {p.name for p in tmp.iterdir()} == keep  # no OUT, no staging folder


@pytest.fixture(scope="module")
def arm_log() -> Log:
    """A PRBS test of the DC-motor arm, made by the independent scipy simulator."""
    from aiofl.identification.excitation import prbs

    exc = prbs(amplitude=1.0, band=40.0, duration=N * TS, ts=TS, seed=1)
    log = simulate_log(get_plant("dcmotor_arm"), exc.t, exc.u, noise_std=1e-4, seed=2)
    return Log(log.t, log.u, log.y, units={"t": "s", "u": "V", "y": "rad"})


# ------------------------------------------------------------------------------ excite
def test_excite_writes_a_csv_log_and_a_c_array(tmp_path: Path) -> None:
    csv, header = tmp_path / "u.csv", tmp_path / "u.h"
    args = ["excite", "--kind", "prbs", "--amplitude", "0.5", "--band", "20", "--duration"]
    res = _invoke(
        *args,
        "2",
        "--ts",
        "1e-3",
        "--offset",
        "1",
        "-o",
        str(csv),
        "--unit",
        "V",
        "--c-array",
        str(header),
        "--c-name",
        "u_exc",
    )
    assert res.exit_code == 0, res.output
    assert "clock period Tc = 0.022 s" in res.stdout and "0.44/Tc = 20 Hz" in res.stdout
    back = read_log(csv, output="u")  # the signal is a log aiofl reads
    assert back.n_samples == 2000 and set(np.unique(back.u)) == {0.5, 1.5}
    assert back.units["u"] == "V"
    text = header.read_text()
    assert "#define U_EXC_N 2000" in text and "static const float u_exc[U_EXC_N]" in text
    # an existing file is refused without --force (named, with --force), replaced with it
    res = _invoke(*args, "2", "--ts", "1e-3", "-o", str(csv))
    assert res.exit_code == 2 and str(csv) in res.stderr and "--force" in res.stderr
    assert read_log(csv, output="u").units["u"] == "V"  # untouched
    res = _invoke(*args, "2", "--ts", "1e-3", "-o", str(csv), "--force")
    assert res.exit_code == 0 and read_log(csv, output="u").units["u"] == ""


def test_excite_chirp(tmp_path: Path) -> None:
    csv = tmp_path / "c.csv"
    res = _invoke(
        "excite",
        "--kind",
        "chirp",
        "--amplitude",
        "1",
        "--f1",
        "50",
        "--duration",
        "4",
        "--ts",
        "1e-3",
        "--method",
        "logarithmic",
        "-o",
        str(csv),
    )
    assert res.exit_code == 0, res.output
    assert "logarithmic chirp 0.25 -> 50 Hz" in res.stdout  # f0 = 1/duration
    assert read_log(csv, output="u").n_samples == 4000


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        (["--kind", "prbs", "--band", "600"], "at most 0.44/ts = 440 Hz"),
        (["--kind", "prbs"], "--band: missing"),
        (["--kind", "prbs", "--band", "20", "--f0", "1"], "--f0 applies to --kind chirp"),
        (["--kind", "chirp"], "--f1 (or --band): missing"),
        (["--kind", "chirp", "--band", "20", "--f1", "30"], "give one"),
        (["--kind", "chirp", "--f1", "600"], "Nyquist"),
        (["--kind", "prbs", "--band", "20", "--c-array", "u.c"], "allowed: a .h file"),
        (["--kind", "prbs", "--band", "20", "--c-array", "u.h", "--c-name", "1x"], "C identifier"),
        (["--kind", "prbs", "--band", "20", "--duration", "1.0005"], "whole number of ts"),
    ],
)
def test_excite_refusals_write_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, extra: list[str], match: str
) -> None:
    monkeypatch.chdir(tmp_path)
    base = ["excite", "--amplitude", "1", "--duration", "1", "--ts", "1e-3", "-o", "u.csv"]
    res = _invoke(*base, *extra)
    assert res.exit_code == 2, res.output
    assert match in res.stderr and "Traceback" not in res.output
    _nothing_written(tmp_path, set())


def test_excite_out_must_be_csv(tmp_path: Path) -> None:
    res = _invoke(
        "excite",
        "--amplitude",
        "1",
        "--band",
        "20",
        "--duration",
        "1",
        "--ts",
        "1e-3",
        "-o",
        str(tmp_path / "u.npz"),
    )
    assert res.exit_code == 2 and "allowed: a .csv file" in res.stderr


# -------------------------------------------------------------------- identify: refusals
def _bad_logs(log: Log) -> dict[str, tuple[Log | str, str]]:
    """A bad log of each kind and what its refusal must say (column, row)."""
    t, u, y = log.t, log.u, log.y
    nan = y.copy()
    nan[99] = np.nan
    back = t.copy()
    back[60] = t[58]
    drop = np.ones(N, bool)
    drop[200] = False
    text = "t,u,y\n" + "".join(
        f"{a!r},{b!r},{c!r}\n" for a, b, c in zip(t.tolist(), u.tolist(), y.tolist(), strict=True)
    )
    return {
        "missing": ("time,u,y\n" + text.split("\n", 1)[1], "no column 't'"),
        "non-numeric": (
            text.replace(f"\n{t.tolist()[9]!r},", f"\n{t.tolist()[9]!r}x,", 1),
            "column 't' (time), row 10 (line 11)",
        ),
        "nan": (Log(t, u, nan), "column 'y' (output), row 100 (line 101)"),
        "backward": (Log(back, u, y), "column 't' (time), row 61 (line 62)"),
        "dropped": (Log(t[drop], u[drop], y[drop]), "column 't' (time), row 201 (line 202)"),
        "short": (log.part(0, 50), "50 samples; allowed: at least 100"),
        "constant-u": (Log(t, np.ones(N), y), "column 'u' (input): constant"),
    }


@pytest.mark.parametrize(
    "kind", ["missing", "non-numeric", "nan", "backward", "dropped", "short", "constant-u"]
)
def test_identify_refuses_a_bad_log_before_anything_runs(
    tmp_path: Path, arm_log: Log, kind: str
) -> None:
    bad, match = _bad_logs(arm_log)[kind]
    path = tmp_path / "log.csv"
    if isinstance(bad, str):
        path.write_text(bad)
    else:
        write_log(bad, path)
    res = _invoke("identify", str(path), "-o", str(tmp_path / "id"))
    assert res.exit_code == 2, res.output
    assert match in res.stderr, res.stderr
    assert "Traceback" not in res.output
    _nothing_written(tmp_path, {"log.csv"})


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["--free", "J"], "--plant and --free go together"),
        (["--holdout", "0.3"], "--holdout applies to a grey-box fit"),
        (["--plant", "dcmotor_arm", "--free", "J", "--holdout", "0.7"], "0 < FRACTION <= 0.5"),
        (["--plant", "dcmotor_arm", "--free", "J,Q"], "unknown parameter(s) Q"),
        (["--plant", "dcmotor_arm", "--free", "J,J"], "names J more than once"),
        (["--plant", "dcmotor_arm", "--free", "J", "--bounds", "b=1:2"], "'b' is not in --free"),
        (["--plant", "dcmotor_arm", "--free", "J", "--bounds", "J=2:1"], "finite LOW < HIGH"),
        (["--plant", "dcmotor_arm", "--free", "J", "--bounds", "J=1"], "NAME=LOW:HIGH"),
        (["--plant", "no_such_plant", "--free", "J"], "no_such_plant"),
        (["--rho", "3", "--rho-max", "2"], "--rho = 3 > --rho-max = 2"),
        (["--k", "0"], "--k = 0.0"),
        (["--delay", "-1", "--plant", "dcmotor_arm", "--free", "J"], "--delay = '-1'"),
        (["--plant", "dcmotor_arm", "--free", "J", "--closed-loop", "x.toml"], "--reference"),
        (["--input", "volt"], "no column 'volt'"),
    ],
)
def test_identify_refuses_bad_options(
    tmp_path: Path, arm_log: Log, args: list[str], match: str
) -> None:
    path = tmp_path / "log.csv"
    write_log(arm_log, path)
    res = _invoke("identify", str(path), "-o", str(tmp_path / "id"), *args)
    assert res.exit_code == 2, res.output
    assert match in res.stderr, res.stderr
    _nothing_written(tmp_path, {"log.csv"})


def test_a_holdout_part_too_short_is_refused(tmp_path: Path, arm_log: Log) -> None:
    path = tmp_path / "log.csv"
    write_log(arm_log.part(0, 150), path)
    res = _invoke(
        "identify",
        str(path),
        "-o",
        str(tmp_path / "id"),
        "--plant",
        "dcmotor_arm",
        "--free",
        "J",
        "--holdout",
        "0.5",
    )
    assert res.exit_code == 2
    assert "--holdout 0.5: the estimation part of log.csv" in res.stderr
    assert "75 samples; allowed: at least 100" in res.stderr


def test_identify_refuses_an_existing_out_without_force(tmp_path: Path, arm_log: Log) -> None:
    path = tmp_path / "log.csv"
    write_log(arm_log, path)
    out = tmp_path / "id"
    out.mkdir()
    (out / "mine.txt").write_text("mine")
    res = _invoke("identify", str(path), "-o", str(out))
    assert res.exit_code == 2 and "--force" in res.stderr
    assert (out / "mine.txt").read_text() == "mine"


# ------------------------------------------------------------- identify: the outputs
@dataclass(frozen=True)
class _Candidate:
    rho: int
    b0: float
    b0_std: float
    delay: float
    score: float
    fit_percent: float


@dataclass(frozen=True)
class _Estimate:
    rho: int = 3
    b0: float = 480.0
    b0_std: float = 6.0
    delay: float = 0.0
    delay_std: float = 2e-4
    noise_std: float = 1e-4
    criterion: str = "validation error"
    candidates: tuple[_Candidate, ...] = tuple(
        _Candidate(r, 480.0, 6.0, 0.0, 10.0 - r, 90.0 + r) for r in (1, 2, 3, 4)
    )
    fit_percent: float = 93.0

    def to_record(self) -> dict[str, Any]:
        keys = ("rho", "b0", "b0_std", "delay", "delay_std", "noise_std", "criterion")
        rec = {k: getattr(self, k) for k in keys}
        rec["fit_percent"] = self.fit_percent
        rec["candidates"] = [vars(c) for c in self.candidates]
        return rec


@dataclass(frozen=True)
class _Eso:
    t: np.ndarray
    y: np.ndarray
    disturbance: np.ndarray
    omega0: float
    rms: float = 0.1
    roughness: float = 0.01
    verdict: str = "small and smooth"


@dataclass(frozen=True)
class _Residuals:
    lags: np.ndarray = field(default_factory=lambda: np.arange(-25, 26))
    autocorrelation: np.ndarray = field(default_factory=lambda: np.r_[1.0, np.zeros(25)])
    cross_correlation: np.ndarray = field(default_factory=lambda: np.zeros(51))
    band: float = 0.1
    white: bool = True
    independent: bool = True

    def to_record(self) -> dict[str, Any]:
        return {"band": self.band, "white": self.white, "independent": self.independent}


@dataclass(frozen=True)
class _Parameter:
    name: str
    value: float
    std: float
    low: float
    high: float


@dataclass(frozen=True)
class _Fit:
    parameters: tuple[_Parameter, ...]
    t: np.ndarray
    y_measured: np.ndarray
    y_simulated: np.ndarray
    fit_percent: float = 97.5
    validation_fit_percent: float | None = 96.0
    residuals: _Residuals = field(default_factory=_Residuals)
    correlation: np.ndarray = field(default_factory=lambda: np.eye(2))
    evaluations: int = 640
    seconds: float = 1.5

    def to_record(self) -> dict[str, Any]:
        return {
            "parameters": {p.name: vars(p) for p in self.parameters},
            "correlation": self.correlation,
            "fit_percent": self.fit_percent,
            "validation_fit_percent": self.validation_fit_percent,
            "residual_tests": self.residuals.to_record(),
            "evaluations": self.evaluations,
        }


@pytest.fixture
def stand_ins(monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    """The routes' modules replaced by stand-ins of the agreed API; records their calls."""
    from aiofl.config import preset_text

    calls: dict[str, Any] = {}

    def identify_chain(log: Log, *, rho_max: int = 4, rho: int | None = None) -> _Estimate:
        calls["chain"] = (log.n_samples, rho_max, rho)
        return _Estimate()

    def offline_eso(log: Log, rho: int, b0: float, omega0: float) -> _Eso:
        calls["eso"] = (rho, b0, omega0)
        return _Eso(log.t, log.y, np.zeros_like(log.y), omega0)

    def first_config(estimate: Any, log: Log, *, omega0: float | None = None) -> str:
        return preset_text("dcmotor-arm-ladrc")

    def fit_plant(log: Log, plant: Any, free: Any, **kw: Any) -> _Fit:
        calls["fit"] = (log.n_samples, dict(free), kw)
        params = tuple(
            _Parameter(n, 1.1 * plant.params[n], 0.01 * plant.params[n], 0, 1) for n in free
        )
        return _Fit(params, log.t, log.y, log.y + 1e-4)

    def uncertainty_table(fit: _Fit, *, k: float = 2.0) -> dict[str, Any]:
        calls["k"] = k
        rel = {p.name: round(k * p.std / p.value, 6) for p in fit.parameters}
        return {"draws": 16, "parameters": {n: {"uniform": v} for n, v in rel.items()}}

    modules = {
        "chain": {"identify_chain": identify_chain},
        "offline_eso": {"offline_eso": offline_eso},
        "first_config": {
            "first_config": first_config,
            "chain_plant_file": lambda estimate, log: "# the identified chain\n",
            "CHAIN_PLANT_FILE": "identified-chain.toml",
        },
        "grey_box": {"fit_plant": fit_plant},
        "fitted_plant": {
            "fitted_plant_file": lambda fit, source: "# fitted\n",
            "uncertainty_table": uncertainty_table,
        },
    }
    for name, members in modules.items():
        module = types.ModuleType(f"aiofl.identification.{name}")
        for key, value in members.items():
            setattr(module, key, value)
        monkeypatch.setitem(sys.modules, f"aiofl.identification.{name}", module)
    return calls


def test_identify_writes_the_model_free_outputs(
    tmp_path: Path, arm_log: Log, stand_ins: dict[str, Any]
) -> None:
    path = tmp_path / "log.csv"
    write_log(arm_log, path)
    out = tmp_path / "id"
    res = _invoke("identify", str(path), "-o", str(out), "--rho-max", "3")
    assert res.exit_code == 0, res.output
    names = {p.name for p in out.iterdir()}
    assert {"identification.json", "first.toml", "eso.png", "candidates.png"} <= names
    assert "fit.png" not in names and "design.toml" not in names
    rec = json.loads((out / "identification.json").read_text())
    assert (rec["rho"], rec["b0"], rec["b0_std"], rec["delay"]) == (3, 480.0, 6.0, 0.0)
    assert len(rec["candidates"]) == 4 and rec["grey_box"] is None
    assert rec["offline_eso"]["omega0"] == 100.0  # the starting design's omega0
    assert stand_ins["eso"] == (3, 480.0, 100.0) and stand_ins["chain"] == (N, 3, None)
    assert rec["log"]["n_samples"] == N and rec["log"]["units"]["y"] == "rad"
    assert "rho = 3" in res.stdout and "b0 = 480 ± 6" in res.stdout


def test_identify_grey_box_writes_a_ready_to_tune_design(
    tmp_path: Path, arm_log: Log, stand_ins: dict[str, Any]
) -> None:
    path = tmp_path / "log.csv"
    write_log(arm_log, path)
    out = tmp_path / "id"
    res = _invoke(
        "identify",
        str(path),
        "-o",
        str(out),
        "--plant",
        "dcmotor_arm",
        "--free",
        "J,b",
        "--bounds",
        "J=1e-4:1e-2",
        "--holdout",
        "0.25",
        "--k",
        "3",
    )
    assert res.exit_code == 0, res.output
    n_est, free, kw = stand_ins["fit"]
    # the whole log, the last quarter held out: simulated on from the fitted part's end
    assert n_est == N and kw["validation"] is None and kw["holdout"] == 0.25
    assert free == {"J": (1e-4, 1e-2), "b": None} and stand_ins["k"] == 3.0
    rec = json.loads((out / "identification.json").read_text())
    grey = rec["grey_box"]
    assert set(grey["parameters"]) == {"J", "b"}
    assert {"value", "std"} <= set(grey["parameters"]["J"])
    assert grey["validation_fit_percent"] == 96.0 and grey["plant"] == "dcmotor_arm"
    assert rec["uncertainty"]["k"] == 3.0 and rec["log"]["validation"] == f"rows {N - 100}:{N}"
    # a library plant: the fitted values as plant_overrides, the box as [uncertainty]
    from aiofl.config import load_config

    cfg = load_config(out / "design.toml")
    assert cfg.uncertainty is not None and set(cfg.uncertainty.parameters) == {"J", "b"}
    assert dict(cfg.scenario.plant_overrides) == pytest.approx(
        {n: 1.1 * get_plant("dcmotor_arm").params[n] for n in ("J", "b")}
    )
    assert cfg.raw["tune"]["robust"]["draws"] == 16  # ready for aiofl tune, robust scoring
    assert cfg.raw["tune"]["parameters"]["eso.omega0"] == {"lo": 10.0, "hi": 200.0, "log": True}
    res = _invoke("tune", str(out / "design.toml"), "--check")
    assert res.exit_code == 0, res.output
    assert "[uncertainty]" in (out / "uncertainty.toml").read_text()
    assert (out / "fit.png").stat().st_size > 1000
    assert "fitted_plant.toml" not in {p.name for p in out.iterdir()}


def test_identify_grey_box_of_a_plant_file(
    tmp_path: Path, arm_log: Log, stand_ins: dict[str, Any]
) -> None:
    """A plant given as a file gets fitted_plant.toml (the grey-box module's text)."""
    root = Path(__file__).resolve().parent
    path = tmp_path / "log.csv"
    write_log(arm_log, path)
    out = tmp_path / "id"
    res = _invoke(
        "identify",
        str(path),
        "-o",
        str(out),
        "--plant",
        str(root / "maglev_plant.toml"),
        "--free",
        "m",
    )
    if res.exit_code == 2 and "unknown parameter" in res.stderr:
        pytest.fail(res.stderr)
    assert res.exit_code == 0, res.output
    assert (out / "fitted_plant.toml").read_text() == "# fitted\n"
    # the stand-in's first.toml is the arm's (rho 3): on the stand-in plant file it may not
    # load; then design.toml is left out and the note says why
    if not (out / "design.toml").exists():
        assert "design.toml not written" in res.stderr


def test_identify_end_to_end_on_a_synthetic_log(tmp_path: Path) -> None:
    from aiofl.identification.excitation import prbs

    exc = prbs(amplitude=1.0, band=20.0, duration=4.0, ts=TS, seed=0)
    log = simulate_log(get_plant("dcmotor_arm"), exc.t, exc.u, noise_std=1e-4, seed=1)
    path = tmp_path / "log.csv"
    write_log(log, path)
    out = tmp_path / "id"
    res = _invoke(
        "identify",
        str(path),
        "-o",
        str(out),
        "--plant",
        "dcmotor_arm",
        "--free",
        "J,b",
        "--holdout",
        "0.25",
    )
    assert res.exit_code == 0, res.output
    rec = json.loads((out / "identification.json").read_text())
    assert rec["rho"] == 3  # the arm's relative degree
    j = rec["grey_box"]["parameters"]["J"]
    true_j = get_plant("dcmotor_arm").params["J"]
    assert abs(j["value"] - true_j) <= 3 * j["std"] + 1e-12
