"""Excitation signals (issue 35): a PRBS's levels, clock, period and band (the sinc² spectrum
of a held random binary signal), a chirp's instantaneous frequency, seeded determinism,
bounded sizes, and the CSV / C array a rig reads."""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.signal import hilbert, welch

from aiofl.identification.excitation import (
    BAND_FACTOR,
    MIN_CLOCKS,
    c_array_text,
    chirp,
    csv_text,
    prbs,
)
from aiofl.identification.log import MIN_SAMPLES
from aiofl.limits import MAX_LOG_SAMPLES

TS = 1e-3


def test_prbs_levels_are_offset_plus_minus_amplitude() -> None:
    e = prbs(amplitude=0.3, band=20.0, duration=10.0, ts=TS, offset=1.5, seed=4)
    assert set(np.unique(e.u)) == {1.2, 1.8}
    assert e.n_samples == 10_000 and np.allclose(np.diff(e.t), TS)
    assert abs(np.mean(e.u) - 1.5) < 0.02  # a maximum-length sequence is balanced


def test_prbs_clock_and_register_follow_the_stated_rule() -> None:
    e = prbs(amplitude=1.0, band=20.0, duration=10.0, ts=TS)
    assert e.clock_period == pytest.approx(0.022)  # floor(0.44 / (20 Hz * 1 ms)) = 22 samples
    # the shortest register whose period (2^n - 1 clocks) covers the 455 clocks of the log
    assert e.nbits == 9 and 2**8 - 1 < 10_000 / 22 <= 2**9 - 1
    levels = np.flatnonzero(np.diff(e.u)) + 1  # switching instants, at whole clock periods
    assert np.all(levels % 22 == 0)
    runs = np.diff(np.concatenate(([0], levels, [e.n_samples])))[:-1]
    assert runs.max() == 22 * e.nbits  # the longest run of a maximum-length sequence: n clocks


def test_prbs_period_is_two_to_the_n_minus_one_clocks() -> None:
    """A signal longer than one register period repeats it exactly: 2^n - 1 clocks."""
    short = prbs(amplitude=1.0, band=BAND_FACTOR / (4 * TS), duration=0.4, ts=TS, seed=2)
    assert short.clock_period == pytest.approx(4 * TS)
    period = (2**short.nbits - 1) * 4
    assert period >= short.n_samples  # one period covers the signal: it does not repeat
    from scipy.signal import max_len_seq

    bits, _ = max_len_seq(short.nbits)
    assert bits.size == 2**short.nbits - 1 and abs(2 * bits.sum() - bits.size) == 1


def test_prbs_spectrum_puts_most_power_below_the_band_edge() -> None:
    """sinc²(f Tc): 72 % of the power below 0.44/Tc (the band edge when Tc = 0.44/f_b
    exactly), 90 % below 1/Tc, half the low-frequency density at the edge."""
    for seed in (0, 1):
        e = prbs(amplitude=1.0, band=20.0, duration=10.0, ts=TS, seed=seed)
        f, p = welch(e.u - e.u.mean(), fs=1 / TS, nperseg=1000)
        below_band = p[f <= 20.0].sum() / p.sum()
        below_null = p[f <= 1 / e.clock_period].sum() / p.sum()
        edge = p[(f >= 17) & (f <= 23)].mean() / p[(f > 0) & (f <= 5)].mean()
        assert 0.66 < below_band < 0.78, below_band
        assert 0.87 < below_null < 0.93, below_null
        assert 0.35 < edge < 0.8, edge
    fast = prbs(amplitude=1.0, band=200.0, duration=2.0, ts=TS)
    f, p = welch(fast.u - fast.u.mean(), fs=1 / TS, nperseg=500)
    assert p[f <= 20.0].sum() / p.sum() < 0.15  # a wide band spreads the power


def test_prbs_is_seeded() -> None:
    a, b, c = (prbs(amplitude=1.0, band=50.0, duration=2.0, ts=TS, seed=s) for s in (7, 7, 8))
    np.testing.assert_array_equal(a.u, b.u)
    assert not np.array_equal(a.u, c.u)


@pytest.mark.parametrize("method", ["linear", "logarithmic"])
def test_chirp_instantaneous_frequency_at_start_and_end(method: str) -> None:
    e = chirp(amplitude=2.0, f0=1.0, f1=40.0, duration=10.0, ts=TS, offset=0.5, method=method)
    assert e.u[0] == pytest.approx(0.5)  # starts at phase 0: no step
    assert e.u.max() == pytest.approx(2.5, abs=1e-3) and e.u.min() == pytest.approx(-1.5, abs=1e-3)
    phase = np.unwrap(np.angle(hilbert(e.u - 0.5)))
    inst = np.gradient(phase, TS) / (2 * np.pi)
    t = e.t
    law = 1.0 + 39.0 * t / 10.0 if method == "linear" else 40.0 ** (t / 10.0)
    inner = (t > 1.0) & (t < 9.0)  # Hilbert's edge effects aside
    assert np.median(np.abs(inst[inner] / law[inner] - 1)) < 0.02
    near_start = (t > 1.0) & (t < 1.5)
    near_end = (t > 9.0) & (t < 9.5)
    assert np.median(inst[near_start]) == pytest.approx(np.median(law[near_start]), rel=0.05)
    assert np.median(inst[near_end]) == pytest.approx(np.median(law[near_end]), rel=0.05)
    assert np.median(law[near_end]) > 30  # the end of the sweep is near f1


def test_chirp_defaults_to_one_cycle_over_the_record() -> None:
    e = chirp(amplitude=1.0, f1=10.0, duration=5.0, ts=TS)
    assert e.f0 == pytest.approx(0.2) and e.method == "linear"


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"band": 500.0}, "at most 0.44/ts = 440 Hz"),
        ({"band": 0.1}, f"at least {MIN_CLOCKS}"),
        ({"amplitude": 0.0}, "amplitude = 0.0; allowed: a finite number > 0"),
        ({"amplitude": float("nan")}, "amplitude = nan"),
        ({"offset": float("inf")}, "offset = inf"),
        ({"duration": 10.0005}, "not a whole number of ts"),
        ({"duration": 0.05}, f"at least {MIN_SAMPLES}"),
        ({"duration": (MAX_LOG_SAMPLES + 1) * TS}, f"at most {MAX_LOG_SAMPLES}"),
        ({"ts": 0.0}, "ts = 0.0"),
        ({"seed": -1}, "seed = -1"),
    ],
)
def test_prbs_refusals_name_the_argument(kwargs: dict[str, float], match: str) -> None:
    args = {"amplitude": 1.0, "band": 20.0, "duration": 10.0, "ts": TS} | kwargs
    with pytest.raises(ValueError, match=re.escape(match)):
        prbs(**args)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"f1": 500.0}, "below the Nyquist frequency 1/(2 ts) = 500 Hz"),
        ({"f0": 50.0}, "f0 = 50.0 Hz; allowed: 0 <= f0 < f1"),
        ({"f0": 0.0, "method": "logarithmic"}, "allowed: 0 < f0 < f1"),
        ({"method": "quadratic"}, "allowed: linear, logarithmic"),
    ],
)
def test_chirp_refusals_name_the_argument(kwargs: dict[str, object], match: str) -> None:
    args = {"amplitude": 1.0, "f1": 40.0, "duration": 10.0, "ts": TS} | kwargs
    with pytest.raises(ValueError, match=re.escape(match)):
        chirp(**args)  # type: ignore[arg-type]


def test_csv_is_a_log_aiofl_reads(tmp_path: object) -> None:
    from pathlib import Path

    from aiofl.identification.log import read_log

    e = prbs(amplitude=1.0, band=50.0, duration=1.0, ts=TS, seed=3)
    path = Path(str(tmp_path)) / "u.csv"
    path.write_text(csv_text(e, unit="V"))
    # the excitation alone has no output column: read it as the input and as the "output"
    back = read_log(path, output="u")
    np.testing.assert_array_equal(back.u, e.u)
    np.testing.assert_array_equal(back.t, e.t)
    assert back.units["u"] == "V" and back.units["t"] == "s"


def test_c_array_holds_the_samples_as_floats() -> None:
    e = prbs(amplitude=0.25, band=50.0, duration=0.2, ts=TS, offset=1.0, seed=1)
    text = c_array_text(e, "u_exc")
    assert "#define U_EXC_N 200\n" in text and "#define U_EXC_TS 0.001 " in text
    m = re.search(r"static const float u_exc\[U_EXC_N\] = \{(.*?)\};", text, re.S)
    assert m is not None
    values = [float(v.strip().rstrip("f")) for v in m[1].split(",")]
    np.testing.assert_array_equal(np.array(values), e.u.astype(np.float32).astype(float))
    assert all(v.strip().endswith("f") and "." in v for v in m[1].split(","))
    for bad in ("1u", "u-exc", "static", "", "x" * 64):
        with pytest.raises(ValueError, match="C identifier"):
            c_array_text(e, bad)
