r"""Excitation signals for an identification experiment: a PRBS or a chirp, for a rig to play.

**PRBS** (:func:`prbs`).  A maximum-length binary sequence of an :math:`n`-bit shift
register (``scipy.signal.max_len_seq``), period :math:`P = 2^n - 1` clock periods, each
value held for a clock period :math:`T_c = m\,T_s` (:math:`m` samples), mapped to
:math:`u = \text{offset} \pm \text{amplitude}`.  Its power spectrum is that of a random
binary signal held over :math:`T_c`,

.. math:: \Phi_u(f) \propto \operatorname{sinc}^2(f\,T_c)
          = \Big(\frac{\sin \pi f T_c}{\pi f T_c}\Big)^2,

(Ljung, *System Identification: Theory for the User*, 2nd ed., 1999, §13.3, "pseudorandom
binary sequences"; Söderström & Stoica, *System Identification*, 1989, §5.2), flat at low
frequencies and at half its low-frequency density at :math:`f \approx 0.443/T_c`; 72 % of
its power lies below :math:`0.44/T_c` and 90 % below the first null :math:`1/T_c`.  **The
rule**: for a requested band :math:`[0, f_b]` the clock period is the longest whole number
of samples with :math:`0.44/T_c \ge f_b`, i.e. :math:`m = \max(1, \lfloor 0.44/(f_b T_s)
\rfloor)`, so the band is excited within 3 dB of the low-frequency level (sampled at
:math:`T_s`, the density is :math:`(\sin \pi f m T_s / (m \sin \pi f T_s))^2`, whose half
power lies at or above :math:`0.443/T_c`: the rule is conservative for small :math:`m`).  A
band above :math:`0.44/T_s` is refused.  The register is the shortest whose period covers
the whole signal, :math:`P\,m \ge N`, so the sequence does not repeat within it (MATLAB's
``idinput`` makes the same choice); the seed picks the register's (non-zero) start state.

**Chirp** (:func:`chirp`).  ``scipy.signal.chirp``, a swept sine starting at phase 0 (no step
at :math:`t = 0`) whose instantaneous frequency goes from :math:`f_0` at :math:`t = 0` to
:math:`f_1` at :math:`t = T` (the duration), linearly, :math:`f(t) = f_0 + (f_1 - f_0)\,t/T`,
or logarithmically, :math:`f(t) = f_0\,(f_1/f_0)^{t/T}` (Ljung 1999, §13.3, "chirp
signals"; Pintelon & Schoukens, *System Identification: A Frequency Domain Approach*, 2nd
ed., 2012, §5.2).  :math:`f_1` must stay below the Nyquist frequency :math:`1/(2T_s)`;
:math:`f_0` defaults to :math:`1/T`, the lowest frequency a record of length :math:`T`
resolves.

Both give an :class:`Excitation`: its samples :math:`u_k` at :math:`t_k = k\,T_s`,
:math:`k = 0 \dots N-1`, :math:`N = T/T_s` (a whole number), to be applied held over
:math:`[t_k, t_{k+1})`; :func:`csv_text` writes them as a log's ``t,u`` columns and
:func:`c_array_text` as a C array for a rig's firmware.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from aiofl.identification.log import MIN_SAMPLES
from aiofl.limits import MAX_LOG_SAMPLES

__all__ = [
    "BAND_FACTOR",
    "MIN_CLOCKS",
    "Excitation",
    "c_array_text",
    "chirp",
    "csv_text",
    "prbs",
]

#: the PRBS's useful band in clock frequencies: f_b <= BAND_FACTOR / T_c (half power of sinc²)
BAND_FACTOR = 0.44
#: fewest clock periods of a PRBS in the signal (a 3-bit register's period)
MIN_CLOCKS = 7
_MAX_NBITS = 32  # scipy.signal.max_len_seq's largest tabulated register

_C_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,62}$")
_C_KEYWORDS = frozenset(
    "auto break case char const continue default do double else enum extern float for goto "  # noqa: SIM905
    "if inline int long register restrict return short signed sizeof static struct switch "
    "typedef union unsigned void volatile while _Bool _Complex _Imaginary".split()
)


@dataclass(frozen=True)
class Excitation:
    """An excitation signal and how it was made.

    Attributes
    ----------
    t, u
        Sample times :math:`k\\,T_s` [s] and input samples (held over each sample).
    kind
        ``"prbs"`` or ``"chirp"``.
    ts, amplitude, offset
        Sample time [s]; :math:`u` swings over offset ± amplitude.
    band
        The band asked for [Hz]: a PRBS's :math:`f_b`, a chirp's :math:`f_1`.
    clock_period, nbits
        A PRBS's :math:`T_c` [s] and register length (None for a chirp).
    f0, f1, method
        A chirp's start and end frequencies [Hz] and sweep (None for a PRBS).
    seed
        A PRBS's seed (None for a chirp: it is deterministic).
    """

    t: NDArray[np.float64]
    u: NDArray[np.float64]
    kind: str
    ts: float
    amplitude: float
    offset: float
    band: float
    clock_period: float | None = None
    nbits: int | None = None
    f0: float | None = None
    f1: float | None = None
    method: str | None = None
    seed: int | None = None

    @property
    def n_samples(self) -> int:
        """N, the number of samples."""
        return int(self.u.shape[0])

    def describe(self) -> str:
        """One line: what the signal is."""
        size = f"{self.n_samples} samples at Ts = {self.ts:g} s"
        swing = f"amplitude {self.amplitude:g} about {self.offset:g}"
        if self.kind == "prbs":
            return (
                f"PRBS, {swing}, band 0-{self.band:g} Hz (clock {self.clock_period:g} s, "
                f"{self.nbits}-bit register, seed {self.seed}), {size}"
            )
        return f"{self.method} chirp {self.f0:g} -> {self.f1:g} Hz, {swing}, {size}"


def _finite(name: str, value: float, *, positive: bool = True) -> float:
    value = float(value)
    if not math.isfinite(value) or (positive and not value > 0):
        allowed = "a finite number > 0" if positive else "a finite number"
        raise ValueError(f"{name} = {value!r}; allowed: {allowed}")
    return value


def _samples(duration: float, ts: float) -> int:
    """N = duration/ts, a whole number within 1e-9, MIN_SAMPLES <= N <= MAX_LOG_SAMPLES."""
    duration, ts = _finite("duration", duration), _finite("ts", ts)
    ratio = duration / ts
    if not ratio <= MAX_LOG_SAMPLES + 0.5:
        raise ValueError(
            f"duration / ts = {duration:g} / {ts:g} = {ratio:.3g} samples; allowed: at most "
            f"{MAX_LOG_SAMPLES} (a log aiofl identify reads)"
        )
    n = round(ratio)
    if abs(n * ts - duration) > 1e-9 * duration:
        raise ValueError(
            f"duration = {duration!r} s is not a whole number of ts = {ts!r} s (duration/ts "
            f"= {ratio:.12g}); allowed: a multiple of ts, e.g. {n * ts:.12g}"
        )
    if n < MIN_SAMPLES:
        raise ValueError(
            f"duration / ts = {n} samples; allowed: at least {MIN_SAMPLES} (a log aiofl "
            "identify accepts)"
        )
    return n


def prbs(
    *,
    amplitude: float,
    band: float,
    duration: float,
    ts: float,
    offset: float = 0.0,
    seed: int = 0,
) -> Excitation:
    """A PRBS exciting ``[0, band]`` Hz (the rule of the module docstring).

    Parameters
    ----------
    amplitude
        u switches between offset - amplitude and offset + amplitude (> 0).
    band
        The band edge :math:`f_b` [Hz], 0 < f_b <= 0.44/ts, and at least
        :data:`MIN_CLOCKS` clock periods :math:`0.44/f_b` in the signal.
    duration, ts
        Length [s] (a whole number of ts) and sample time [s].
    offset
        The level u swings about (the operating point's input).
    seed
        Picks the register's start state (seeded: the same seed, the same signal).

    Returns
    -------
    Excitation
        The samples and how they were made.

    Raises
    ------
    ValueError
        Naming the argument and its allowed range.
    """
    amplitude = _finite("amplitude", amplitude)
    offset = _finite("offset", offset, positive=False)
    n = _samples(duration, ts)
    band = _finite("band", band)
    if band > BAND_FACTOR / ts:
        raise ValueError(
            f"band = {band:g} Hz; allowed: at most {BAND_FACTOR}/ts = {BAND_FACTOR / ts:g} Hz "
            "(a PRBS clocked every sample reaches no higher within 3 dB); shorten ts"
        )
    if not isinstance(seed, int) or not 0 <= seed < 2**63:
        raise ValueError(f"seed = {seed!r}; allowed: an integer 0 <= seed < 2**63")
    m = max(1, math.floor(BAND_FACTOR / (band * ts) + 1e-9))
    clocks = math.ceil(n / m)
    if clocks < MIN_CLOCKS:
        low = BAND_FACTOR * MIN_CLOCKS / duration
        raise ValueError(
            f"band = {band:g} Hz gives a clock period of {m * ts:g} s, {clocks} in "
            f"duration = {duration:g} s; allowed: at least {MIN_CLOCKS} (band >= {low:.3g} Hz, "
            "or a longer duration)"
        )
    nbits = max(3, math.ceil(math.log2(clocks + 1)))
    if nbits > _MAX_NBITS:  # pragma: no cover - MAX_LOG_SAMPLES < 2**32
        raise ValueError(f"{clocks} clock periods need a {nbits}-bit register; at most 32")
    from scipy.signal import max_len_seq

    rng = np.random.default_rng(seed)
    state = rng.integers(0, 2, nbits)
    if not state.any():
        state[rng.integers(nbits)] = 1  # the all-zero state is the one a register never leaves
    bits, _ = max_len_seq(nbits, state=state, length=clocks)
    u = offset + amplitude * (2.0 * np.repeat(bits.astype(np.float64), m)[:n] - 1.0)
    return Excitation(
        t=ts * np.arange(n, dtype=np.float64),
        u=u,
        kind="prbs",
        ts=float(ts),
        amplitude=amplitude,
        offset=offset,
        band=band,
        clock_period=m * float(ts),
        nbits=nbits,
        seed=seed,
    )


def chirp(
    *,
    amplitude: float,
    f1: float,
    duration: float,
    ts: float,
    f0: float | None = None,
    offset: float = 0.0,
    method: str = "linear",
) -> Excitation:
    """A swept sine from ``f0`` to ``f1`` Hz over ``duration`` (the module docstring).

    Parameters
    ----------
    amplitude, offset
        u = offset + amplitude sin(phase(t)), starting at phase 0.
    f1
        End frequency [Hz], below the Nyquist frequency 1/(2 ts).
    f0
        Start frequency [Hz], 0 <= f0 < f1 (> 0 for a logarithmic sweep); default 1/duration.
    duration, ts
        Length [s] (a whole number of ts) and sample time [s].
    method
        ``"linear"`` or ``"logarithmic"``.

    Returns
    -------
    Excitation
        The samples and how they were made.

    Raises
    ------
    ValueError
        Naming the argument and its allowed range.
    """
    from scipy.signal import chirp as scipy_chirp

    amplitude = _finite("amplitude", amplitude)
    offset = _finite("offset", offset, positive=False)
    n = _samples(duration, ts)
    if method not in ("linear", "logarithmic"):
        raise ValueError(f"method = {method!r}; allowed: linear, logarithmic")
    f1 = _finite("f1", f1)
    if f1 >= 0.5 / ts:
        raise ValueError(
            f"f1 = {f1:g} Hz; allowed: below the Nyquist frequency 1/(2 ts) = {0.5 / ts:g} Hz"
        )
    f0 = 1.0 / duration if f0 is None else float(f0)
    if not (math.isfinite(f0) and 0 <= f0 < f1) or (method == "logarithmic" and f0 <= 0):
        low = "0 <" if method == "logarithmic" else "0 <="
        raise ValueError(f"f0 = {f0!r} Hz; allowed: {low} f0 < f1 = {f1:g} Hz")
    t = ts * np.arange(n, dtype=np.float64)
    wave = scipy_chirp(t, f0=f0, t1=duration, f1=f1, method=method, phi=-90.0)
    return Excitation(
        t=t,
        u=offset + amplitude * wave,
        kind="chirp",
        ts=float(ts),
        amplitude=amplitude,
        offset=offset,
        band=f1,
        f0=f0,
        f1=f1,
        method=method,
    )


def csv_text(exc: Excitation, *, unit: str = "") -> str:
    """The signal as a log's columns: a header ``t [s],u`` (``u [unit]`` with a unit) and one
    row per sample, values with 17 significant digits (read back exactly)."""
    head = f"t [s],u [{unit}]" if unit else "t [s],u"
    rows = (f"{t!r},{u!r}" for t, u in zip(exc.t.tolist(), exc.u.tolist(), strict=True))
    return head + "\n" + "\n".join(rows) + "\n"


def _c_float(v: float) -> str:
    s = f"{v:.9g}"  # 9 digits: a float32 read back exactly
    if not any(c in s for c in ".e"):
        s += ".0"
    return s + "f"


def c_array_text(exc: Excitation, name: str = "aiofl_excitation") -> str:
    """A C header holding the signal: ``#define NAME_N``, ``#define NAME_TS`` and
    ``static const float NAME[NAME_N] = {...};`` (values as float literals, 9 digits).

    Raises
    ------
    ValueError
        ``name`` is not a C identifier (letters, digits, ``_``; at most 63 characters; not
        a keyword).
    """
    if not _C_NAME.match(name) or name in _C_KEYWORDS:
        raise ValueError(
            f"--c-name = {name!r}; allowed: a C identifier (a letter or _, then letters, "
            "digits, _; at most 63 characters; not a C keyword)"
        )
    macro = name.upper()
    values = [_c_float(v) for v in exc.u.tolist()]
    rows = [", ".join(values[i : i + 8]) for i in range(0, len(values), 8)]
    body = ",\n    ".join(rows)
    return (
        f"/* {exc.describe()}.\n"
        f" * Written by aiofl excite.  Apply {name}[k] at t = k * {macro}_TS, held until the\n"
        f" * next sample (zero-order hold), and log t, u and the output at every sample. */\n"
        f"#ifndef {macro}_H\n#define {macro}_H\n\n"
        f"#define {macro}_N {exc.n_samples}\n"
        f"#define {macro}_TS {exc.ts!r} /* sample time [s] */\n\n"
        f"static const float {name}[{macro}_N] = {{\n    {body}\n}};\n\n"
        f"#endif /* {macro}_H */\n"
    )
