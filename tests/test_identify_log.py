"""Reading a rig's log (issue 35): CSV and .npz round trips with units, configurable column
names, and every refusal by name (column and row), before anything runs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import aiofl.identification.log as log_module
from aiofl.identification.log import (
    DECLARED_TOLERANCE,
    MIN_RESPONSE_SAMPLES,
    MIN_SAMPLES,
    SAMPLING_TOLERANCE,
    Log,
    LogError,
    check_log,
    read_log,
    write_log,
)
from aiofl.identification.synthetic import simulate_log
from aiofl.plants.registry import get_plant

N = 300
TS = 0.01


@pytest.fixture(scope="module")
def tank_log() -> Log:
    """A step test of the tank (the independent scipy simulator), 12-bit-like output."""
    t = TS * np.arange(N)
    u = np.where(t >= 0.2, 1.0, 0.0)
    log = simulate_log(get_plant("tank"), t, u, noise_std=1e-3, quantum=1e-4, seed=3)
    return Log(log.t, log.u, log.y, units={"t": "s", "u": "V", "y": "m"}, source="tank")


def _csv(path: Path, header: str, rows: list[tuple[object, ...]]) -> Path:
    path.write_text(header + "\n" + "".join(",".join(map(str, r)) + "\n" for r in rows))
    return path


def _rows(log: Log) -> list[tuple[object, ...]]:
    return list(zip(log.t.tolist(), log.u.tolist(), log.y.tolist(), strict=True))


def _refused(match: str, path: Path, **kwargs: object) -> str:
    with pytest.raises(LogError, match=match) as info:
        read_log(path, **kwargs)  # type: ignore[arg-type]
    return str(info.value)


# ------------------------------------------------------------------------- round trips
@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_round_trip_keeps_values_and_units(tmp_path: Path, tank_log: Log, suffix: str) -> None:
    path = tmp_path / f"log{suffix}"
    write_log(tank_log, path, names={"t": "time", "u": "volt", "y": "level"})
    back = read_log(path, time="time", input="volt", output="level")
    assert back.n_samples == N
    np.testing.assert_array_equal(back.t, tank_log.t)  # 17 digits: exact
    np.testing.assert_array_equal(back.u, tank_log.u)
    np.testing.assert_array_equal(back.y, tank_log.y)
    assert dict(back.units) == {"t": "s", "u": "V", "y": "m"}
    assert back.r is None and back.source == str(path)
    assert back.ts == pytest.approx(TS, rel=1e-12)


def test_the_reference_column_and_units_given_by_argument(tmp_path: Path, tank_log: Log) -> None:
    r = np.full(N, 0.05)
    closed = Log(tank_log.t, tank_log.u, tank_log.y, r)
    path = tmp_path / "closed.npz"
    write_log(closed, path)
    back = read_log(path, reference="r", units={"y": "m", "u": "V"})
    np.testing.assert_array_equal(back.r, r)
    assert dict(back.units) == {"t": "", "u": "V", "y": "m", "r": ""}


def test_units_given_twice_must_agree(tmp_path: Path, tank_log: Log) -> None:
    path = tmp_path / "log.csv"
    write_log(tank_log, path)
    assert read_log(path, units={"y": "m"}).units["y"] == "m"  # the same: fine
    msg = _refused("unit", path, units={"y": "mm"})
    assert "'m'" in msg and "'mm'" in msg and "'y'" in msg
    _refused("unknown role", path, units={"z": "m"})


def test_comment_lines_semicolons_and_a_bom_are_read(tmp_path: Path, tank_log: Log) -> None:
    body = "".join(f"{a!r};{b!r};{c!r}\n" for a, b, c in _rows(tank_log))
    path = tmp_path / "rig.csv"
    path.write_text("\ufeff# rig 3, 2024-05-01\n# 1 kHz\nt [s];u [V];y [m]\n" + body + "\n\n")
    back = read_log(path)
    np.testing.assert_array_equal(back.y, tank_log.y)
    assert back.units["y"] == "m"


def test_a_single_step_is_an_accepted_test(tank_log: Log) -> None:
    assert int(np.count_nonzero(np.diff(tank_log.u))) == 1
    check_log(tank_log)  # the classic step test excites enough to be read


def test_no_time_column_with_a_declared_sample_time(tmp_path: Path, tank_log: Log) -> None:
    path = _csv(tmp_path / "noclock.csv", "u,y", [r[1:] for r in _rows(tank_log)])
    back = read_log(path, time=None, ts=TS)
    np.testing.assert_allclose(back.t, TS * np.arange(N), rtol=0, atol=0)
    assert back.units["t"] == "s"
    _refused("needs the sample time", path, time=None)


def test_a_declared_sample_time_accepts_jitter_and_gives_the_grid(
    tmp_path: Path, tank_log: Log
) -> None:
    rng = np.random.default_rng(0)
    jitter = tank_log.t + rng.uniform(-0.3, 0.3, N) * DECLARED_TOLERANCE * TS
    path = tmp_path / "jitter.csv"
    write_log(Log(jitter, tank_log.u, tank_log.y), path)
    # without ts the jitter (up to 6 % of a step) is non-uniform sampling
    msg = _refused("uniform sampling", path)
    assert f"{SAMPLING_TOLERANCE:.3g}" in msg and "--ts" in msg
    back = read_log(path, ts=TS)
    np.testing.assert_allclose(back.t, jitter[0] + TS * np.arange(N), rtol=0, atol=1e-15)


# ---------------------------------------------------------------------------- refusals
def test_a_missing_column_lists_the_columns_present(tmp_path: Path, tank_log: Log) -> None:
    path = tmp_path / "log.csv"
    write_log(tank_log, path, names={"u": "volt"})
    msg = _refused("no column 'u'", path)
    assert "'t'" in msg and "'volt'" in msg and "'y'" in msg and "--input" in msg
    msg = _refused("no column 'r'", path, input="volt", reference="r")
    assert "--reference" in msg


def test_a_non_numeric_cell_names_column_row_and_line(tmp_path: Path, tank_log: Log) -> None:
    rows = _rows(tank_log)
    rows[41] = (rows[41][0], rows[41][1], "n/a")
    path = _csv(tmp_path / "log.csv", "t,u,y", rows)
    msg = _refused("column 'y'", path)
    assert "row 42 (line 43)" in msg and "'n/a' is not a number" in msg


@pytest.mark.parametrize("bad", ["nan", "inf", "-inf"])
def test_a_non_finite_value_names_column_and_row(tmp_path: Path, tank_log: Log, bad: str) -> None:
    rows = _rows(tank_log)
    rows[7] = (rows[7][0], bad, rows[7][2])
    path = _csv(tmp_path / "log.csv", "t,u,y", rows)
    msg = _refused("column 'u' \\(input\\), row 8 \\(line 9\\)", path)
    assert "not finite" in msg


@pytest.mark.parametrize(("k", "value", "what"), [(50, None, "repeats"), (50, 0.3, "goes back")])
def test_time_must_increase(
    tmp_path: Path, tank_log: Log, k: int, value: float | None, what: str
) -> None:
    t = tank_log.t.copy()
    t[k] = t[k - 1] if value is None else value
    path = tmp_path / "log.npz"
    write_log(Log(t, tank_log.u, tank_log.y), path)
    msg = _refused(f"column 't' \\(time\\), row {k + 1}", path)
    assert what in msg and "strictly increasing" in msg


def test_a_dropped_sample_is_refused_at_its_row(tmp_path: Path, tank_log: Log) -> None:
    keep = np.ones(N, bool)
    keep[120] = False
    path = tmp_path / "log.csv"
    write_log(Log(tank_log.t[keep], tank_log.u[keep], tank_log.y[keep]), path)
    msg = _refused("column 't' \\(time\\), row 121 \\(line 122\\)", path)
    assert "uniform sampling" in msg and "0.01" in msg
    # a declared ts does not resample it: the grid is left at that row
    msg = _refused("row 121 \\(line 122\\)", path, ts=TS)
    assert "off the declared grid" in msg and f"{DECLARED_TOLERANCE:.3g} ts" in msg


def test_a_clock_that_drifts_from_the_declared_ts_is_refused(tmp_path: Path, tank_log: Log) -> None:
    path = tmp_path / "log.csv"
    write_log(Log(tank_log.t * 1.001, tank_log.u, tank_log.y), path)
    read_log(path)  # uniform: accepted as it is, at its own Ts
    msg = _refused("off the declared grid", path, ts=TS)
    k = int(DECLARED_TOLERANCE / 1e-3)  # the row where the drift passes 0.1 ts
    assert f"row {k + 2} " in msg or f"row {k + 1} " in msg


def test_too_few_samples_states_the_minimum(tmp_path: Path, tank_log: Log) -> None:
    path = tmp_path / "short.csv"
    write_log(tank_log.part(0, MIN_SAMPLES - 1), path)
    msg = _refused(f"{MIN_SAMPLES - 1} samples", path)
    assert f"at least {MIN_SAMPLES}" in msg


def test_a_constant_input_is_refused_with_the_reason(tmp_path: Path, tank_log: Log) -> None:
    path = tmp_path / "flat.csv"
    write_log(Log(tank_log.t, np.full(N, 0.5), tank_log.y), path, names={"u": "volt"})
    msg = _refused("column 'volt' \\(input\\): constant", path, input="volt")
    assert "0.5" in msg and "excites nothing" in msg and "aiofl excite" in msg


def test_an_input_that_changes_too_late_is_refused(tmp_path: Path, tank_log: Log) -> None:
    u = np.zeros(N)
    u[N - 5 :] = 1.0
    path = tmp_path / "late.csv"
    write_log(Log(tank_log.t, u, tank_log.y), path)
    msg = _refused(f"row {N - 4} ", path)
    assert "first changes" in msg and "5 samples" in msg and str(MIN_RESPONSE_SAMPLES) in msg


def test_a_constant_output_is_refused(tank_log: Log) -> None:
    with pytest.raises(LogError, match="column 'y' \\(output\\): constant"):
        check_log(Log(tank_log.t, tank_log.u, np.zeros(N)))


def test_check_log_names_the_files_columns(tank_log: Log) -> None:
    y = tank_log.y.copy()
    y[9] = np.nan
    with pytest.raises(LogError, match="column 'level' \\(output\\), row 10"):
        check_log(Log(tank_log.t, tank_log.u, y), names={"y": "level"})
    with pytest.raises(LogError, match="1-D of one length"):
        check_log(Log(tank_log.t, tank_log.u[:-1], tank_log.y))
    with pytest.raises(LogError, match=r"ts = -0\.01"):
        check_log(tank_log, ts=-TS)


def test_a_short_csv_row_names_its_line(tmp_path: Path, tank_log: Log) -> None:
    rows = _rows(tank_log)
    rows[10] = rows[10][:2]
    path = _csv(tmp_path / "log.csv", "t,u,y", rows)
    msg = _refused("row 11 \\(line 12\\): 2 cells", path)
    assert "header has 3" in msg


def test_header_faults(tmp_path: Path) -> None:
    path = tmp_path / "dup.csv"
    path.write_text("t,u,u [V]\n0,0,0\n")
    _refused("'u' appears twice", path)
    path.write_text("t u y\n0 0 0\n")
    _refused("no delimiter", path)
    path.write_text("# only a comment\n")
    _refused("no header row", path)
    path.write_bytes(b"t,u,y\n\xff\xfe\n")
    _refused("not UTF-8", path)
    _refused("cannot be read", tmp_path / "missing.csv")
    _refused("not a file", tmp_path)


def test_a_file_too_large_is_refused_before_it_is_read(
    tmp_path: Path, tank_log: Log, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "log.csv"
    write_log(tank_log, path)
    monkeypatch.setattr(log_module, "MAX_LOG_BYTES", 1000)
    msg = _refused(f"{path.stat().st_size} bytes", path)
    assert "at most" in msg


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_too_many_rows_are_refused_before_they_are_parsed(
    tmp_path: Path, tank_log: Log, monkeypatch: pytest.MonkeyPatch, suffix: str
) -> None:
    path = tmp_path / f"log{suffix}"
    write_log(tank_log, path)
    monkeypatch.setattr(log_module, "MAX_LOG_SAMPLES", N - 1)
    _refused(f"{N} rows; allowed: at most {N - 1}", path)


def test_npz_arrays_are_checked_from_their_headers(tmp_path: Path) -> None:
    path = tmp_path / "bad.npz"
    t = np.arange(200) * 1e-3
    np.savez(path, t=t, u=np.ones((200, 2)), y=t)
    _refused("column 'u': shape \\(200, 2\\); allowed: 1-D", path)
    np.savez(path, t=t, u=np.array(["a"] * 200), y=t)
    _refused("column 'u': dtype", path)
    path.write_bytes(b"not a zip")
    _refused("not a readable .npz", path)
