r"""A logged experiment: time, input, output (and the reference, when a controller closed the loop).

A :class:`Log` is plain data, uniformly sampled at :attr:`Log.ts`: the samples
:math:`(t_k, u_k, y_k)`, :math:`k = 0 \dots N-1`, with :math:`u_k` held over
:math:`[t_k, t_{k+1})` (zero-order hold, as a digital rig applies it) and :math:`y_k` measured
at :math:`t_k`.

:func:`read_log` reads one from a CSV file (a header row of column names, each optionally
with its unit in brackets, ``"angle [rad]"``) or an ``.npz`` archive (one 1-D array per
column, named the same way), and :func:`check_log` refuses, before anything runs, a log that
cannot identify anything.  Every refusal is a :class:`LogError` naming the column and the
row (rows are counted from 1, the first data row; a CSV's message adds the file's line):

* a file larger than :data:`~aiofl.limits.MAX_LOG_BYTES` or with more than
  :data:`~aiofl.limits.MAX_LOG_SAMPLES` rows (checked before parsing; an ``.npz``'s arrays
  from their headers, before they are loaded);
* a missing column (the message lists the columns present), a cell that is no number, a
  non-finite value (NaN, inf), columns of different lengths;
* fewer than :data:`MIN_SAMPLES` samples;
* time that does not increase (a repeated or a backward time stamp);
* non-uniform sampling: without a declared ``ts`` every step must lie within
  :data:`SAMPLING_TOLERANCE` (relative) of the mean step, so a dropped sample (a step of
  2 Ts) is refused at its row; with a declared ``ts`` every time stamp must lie within
  :data:`DECLARED_TOLERANCE`·ts of the grid :math:`t_0 + k\,T_s` (time-stamp jitter is
  accepted, a dropped sample or a clock that drifts from the declared ``ts`` is not), and
  the log's time becomes that grid.  A log is never resampled;
* an input that does not excite: a constant u, or one whose first change leaves fewer than
  :data:`MIN_RESPONSE_SAMPLES` samples (and a tenth of the log) to see the response.  A
  single step is accepted: it is the classic test (the step-response identification of
  Ljung, *System Identification*, 2nd ed., 1999, §6.1; MATLAB's ADRC examples read b0 off
  a step), and whether it excites enough for a given model is the estimator's to report
  through its standard errors;
* a constant output (the sensor never moved: a wrong column or an unplugged encoder).
"""

from __future__ import annotations

import csv
import math
import re
import zipfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import numpy as np
from numpy.typing import NDArray

from aiofl.limits import MAX_LOG_BYTES, MAX_LOG_SAMPLES
from aiofl.text import MAX_UNIT_CHARS, check_text

__all__ = [
    "DECLARED_TOLERANCE",
    "MIN_RESPONSE_SAMPLES",
    "MIN_SAMPLES",
    "SAMPLING_TOLERANCE",
    "Log",
    "LogError",
    "check_log",
    "read_log",
    "write_log",
]

#: fewest samples of a log: a chain of order ρ <= 4 with a delay has at most six unknowns,
#: and a held-out part for validation must still hold a few dozen samples
MIN_SAMPLES = 100
#: fewest samples after the input's first change (and at least a tenth of the log)
MIN_RESPONSE_SAMPLES = 20
#: without a declared ts: largest relative deviation of a time step from the mean step
SAMPLING_TOLERANCE = 0.01
#: with a declared ts: largest deviation of a time stamp from the grid t0 + k ts, in ts
DECLARED_TOLERANCE = 0.1

#: the roles of a log's columns, in the order they are checked and the name of each
_ROLES = {"t": "time", "u": "input", "y": "output", "r": "reference"}
_NAME_UNIT = re.compile(r"^(?P<name>.*?)\s*\[(?P<unit>[^\[\]]*)\]\s*$")


class LogError(ValueError):
    """A log that cannot be used, with the column (and row) at fault in its message."""


@dataclass(frozen=True)
class Log:
    """Uniformly sampled input/output data of one experiment.

    Parameters
    ----------
    t, u, y
        Sample times [s], input and output, 1-D float arrays of the same length.
    r
        The reference, for a closed-loop log; None for an open-loop test.
    units
        Units of ``"t"``, ``"u"``, ``"y"`` (and ``"r"``) as plain text; ``""`` when undeclared.
    source
        Where the log came from (a file name), for messages and reports.
    """

    t: NDArray[np.float64]
    u: NDArray[np.float64]
    y: NDArray[np.float64]
    r: NDArray[np.float64] | None = None
    units: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}))
    source: str = ""

    @property
    def n_samples(self) -> int:
        """N, the number of samples."""
        return int(self.t.shape[0])

    @property
    def ts(self) -> float:
        """The sample time [s] (the mean step of :attr:`t`)."""
        return float((self.t[-1] - self.t[0]) / (self.t.shape[0] - 1))

    @property
    def duration(self) -> float:
        """t_{N-1} - t_0 [s]."""
        return float(self.t[-1] - self.t[0])

    def part(self, start: int, stop: int) -> Log:
        """Samples ``start:stop`` as a log of their own (an estimation or a validation part)."""
        r = None if self.r is None else self.r[start:stop]
        return Log(
            self.t[start:stop], self.u[start:stop], self.y[start:stop], r, self.units, self.source
        )


# ------------------------------------------------------------------------------ checks
def _positive(name: str, value: float | None, upper: float = math.inf) -> None:
    if value is not None and not (math.isfinite(value) and 0 < value < upper):
        bound = "" if math.isinf(upper) else f" < {upper:g}"
        raise LogError(f"{name} = {value!r}; allowed: a finite number > 0{bound}")


def check_log(
    log: Log,
    *,
    ts: float | None = None,
    tolerance: float | None = None,
    names: Mapping[str, str] | None = None,
) -> None:
    """Refuse a log that cannot identify anything (the checks of the module docstring).

    Parameters
    ----------
    log
        The log.
    ts
        The declared sample time [s]: every time stamp must lie within ``tolerance``·ts of
        :math:`t_0 + k\\,T_s`.  Without it every step must lie within ``tolerance`` (relative)
        of the mean step.
    tolerance
        Default :data:`DECLARED_TOLERANCE` with ``ts``, :data:`SAMPLING_TOLERANCE` without.
    names
        The columns' names in the file, by role (``"t"``, ``"u"``, ``"y"``, ``"r"``), for
        the messages (default: the roles themselves).

    Raises
    ------
    LogError
        Naming the column, the row (from 1) and what is allowed.
    """
    arrays = {"t": log.t, "u": log.u, "y": log.y}
    if log.r is not None:
        arrays["r"] = log.r
    _check(arrays, dict(names or {}), ts=ts, tolerance=tolerance, where=lambda k: f"row {k + 1}")


def _check(
    arrays: Mapping[str, NDArray[np.float64]],
    names: Mapping[str, str],
    *,
    ts: float | None,
    tolerance: float | None,
    where: Callable[[int], str],
    source: str = "the log",
) -> None:
    _positive("ts", ts)
    _positive("tolerance", tolerance, 0.5)
    tol = tolerance if tolerance is not None else (DECLARED_TOLERANCE if ts else SAMPLING_TOLERANCE)

    def col(role: str) -> str:
        return f"column {names.get(role, role)!r} ({_ROLES[role]})"

    lengths = {role: a.shape for role, a in arrays.items()}
    if any(len(s) != 1 for s in lengths.values()) or len(set(lengths.values())) != 1:
        shown = ", ".join(f"{col(role)}: {s}" for role, s in lengths.items())
        raise LogError(f"{source}: the columns must be 1-D of one length; got {shown}")
    n = next(iter(lengths.values()))[0]
    if n > MAX_LOG_SAMPLES:
        raise LogError(f"{source} has {n} samples; allowed: at most {MAX_LOG_SAMPLES}")
    if n < MIN_SAMPLES:
        raise LogError(
            f"{source} has {n} samples; allowed: at least {MIN_SAMPLES} (the chain's "
            "unknowns and a held-out part need them)"
        )
    for role, a in arrays.items():
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            k = int(bad[0])
            raise LogError(
                f"{source}, {col(role)}, {where(k)}: {a[k]!r} is not finite ({bad.size} such "
                "values); allowed: finite numbers (drop or repair the samples, do not fill "
                "them with NaN)"
            )
    t = arrays["t"]
    step = np.diff(t)
    back = np.flatnonzero(step <= 0)
    if back.size:
        k = int(back[0]) + 1
        what = "repeats" if step[k - 1] == 0 else "goes back from"
        raise LogError(
            f"{source}, {col('t')}, {where(k)}: t = {t[k]!r} {what} the row before "
            f"(t = {t[k - 1]!r}); allowed: strictly increasing time"
        )
    if ts is None:
        mean = float((t[-1] - t[0]) / (n - 1))
        off = np.flatnonzero(np.abs(step - mean) > tol * mean)
        if off.size:
            k = int(off[0]) + 1
            raise LogError(
                f"{source}, {col('t')}, {where(k)}: the step from the row before is "
                f"{step[k - 1]:.6g} s, the mean step {mean:.6g} s; allowed: uniform sampling, "
                f"every step within {tol:.3g} (relative) of the mean (a dropped or an extra "
                "sample breaks it; if the rig sampled uniformly and only the time stamps "
                "jitter, declare the sample time: ts= / --ts)"
            )
    else:
        grid = t[0] + ts * np.arange(n)
        off = np.flatnonzero(np.abs(t - grid) > tol * ts)
        if off.size:
            k = int(off[0])
            raise LogError(
                f"{source}, {col('t')}, {where(k)}: t = {t[k]!r} is {t[k] - grid[k]:+.3g} s "
                f"off the declared grid t0 + k ts = {grid[k]!r} (ts = {ts!r} s); allowed: "
                f"every time stamp within {tol:.3g} ts of the grid (a dropped sample or a "
                "clock that drifts from the declared ts is refused)"
            )
    u = arrays["u"]
    change = np.flatnonzero(np.diff(u) != 0)
    if change.size == 0:
        raise LogError(
            f"{source}, {col('u')}: constant ({u[0]!r} in all {n} rows); a constant input "
            "excites nothing, so no b0, relative degree or parameter can be identified from "
            "it; log a step, a PRBS or a chirp (aiofl excite writes one)"
        )
    first = int(change[0]) + 1
    need = max(MIN_RESPONSE_SAMPLES, math.ceil(0.1 * n))
    if n - first < need:
        raise LogError(
            f"{source}, {col('u')}, {where(first)}: the input first changes here, leaving "
            f"{n - first} samples of response; allowed: at least {need} ({MIN_RESPONSE_SAMPLES} "
            "and a tenth of the log) after the first change, so the plant's answer is logged"
        )
    y = arrays["y"]
    if not np.any(y != y[0]):
        raise LogError(
            f"{source}, {col('y')}: constant ({y[0]!r} in all {n} rows); the output never "
            "moved (a wrong column, or a sensor that was not connected?)"
        )


# ------------------------------------------------------------------------------ reading
def read_log(
    path: str | Path,
    *,
    time: str | None = "t",
    input: str = "u",
    output: str = "y",
    reference: str | None = None,
    ts: float | None = None,
    tolerance: float | None = None,
    units: Mapping[str, str] | None = None,
) -> Log:
    """Read a logged experiment from a CSV file or an ``.npz`` archive, and check it.

    Parameters
    ----------
    path
        ``*.npz``: one 1-D numeric array per column, named as below; anything else is read
        as CSV: optional ``#`` comment lines, a header row of names, then one row per sample
        (delimiter ``,``, or ``;`` or a tab when the header has no comma; UTF-8).
    time, input, output, reference
        The columns' names.  A name in the file may carry its unit in brackets: the column
        ``"angle [rad]"`` is found as ``"angle"`` and its unit kept.  ``time=None`` (no time
        column) needs ``ts``: the samples are then at :math:`k\\,T_s`.  ``reference`` is the
        setpoint a closed-loop controller followed (None: an open-loop log).
    ts
        The sample time [s] the rig ran at; see :func:`check_log`.
    tolerance
        The sampling tolerance of :func:`check_log`.
    units
        Units by role (``"t"``, ``"u"``, ``"y"``, ``"r"``), for columns whose name carries
        none; a unit given both ways must agree.

    Returns
    -------
    Log
        With ``units`` by role and ``source`` the path; with a declared ``ts``, its time is
        the grid :math:`t_0 + k\\,T_s`.

    Raises
    ------
    LogError
        The file cannot be read or is refused (the module docstring's list), naming the
        column and the row.
    """
    path = Path(path)
    _positive("ts", ts)
    if time is None and ts is None:
        raise LogError("time = None (no time column) needs the sample time: give ts= / --ts")
    wanted = {"t": time, "u": input, "y": output, "r": reference}
    wanted = {role: name for role, name in wanted.items() if name is not None}
    unknown = sorted(set(units or {}) - set(_ROLES))
    if unknown:
        raise LogError(f"units: unknown role(s) {', '.join(unknown)}; allowed: t, u, y, r")
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise LogError(f"log {str(path)!r} cannot be read: {exc.strerror or exc}") from None
    if not path.is_file():
        raise LogError(f"log {str(path)!r} is not a file")
    if size > MAX_LOG_BYTES:
        raise LogError(
            f"log {str(path)!r} has {size} bytes; allowed: at most {MAX_LOG_BYTES // 2**20} "
            "MiB (decimate or cut the log first)"
        )
    source = path.name
    if path.suffix.lower() == ".npz":
        columns, file_units, where = _read_npz(path, wanted, source)
    else:
        columns, file_units, where = _read_csv(path, wanted, source)
    given = {
        role: check_text(f"units[{role!r}]", u, max_chars=MAX_UNIT_CHARS)
        for role, u in (units or {}).items()
    }
    for role, unit in given.items():
        if role in file_units and file_units[role] and file_units[role] != unit:
            raise LogError(
                f"{source}, column {wanted[role]!r}: its header gives the unit "
                f"{file_units[role]!r}, units[{role!r}] = {unit!r}; give one, or the same"
            )
    merged = {role: given.get(role) or file_units.get(role, "") for role in wanted}
    if time is None:
        n = next(iter(columns.values())).shape[0]
        columns["t"] = ts * np.arange(n, dtype=np.float64)  # type: ignore[operator]
        merged["t"] = merged.get("t") or "s"
    _check(columns, wanted, ts=ts, tolerance=tolerance, where=where, source=source)
    t = columns["t"]
    if ts is not None:  # the declared grid (checked against the time stamps above)
        t = t[0] + ts * np.arange(t.shape[0], dtype=np.float64)
    return Log(
        t,
        columns["u"],
        columns["y"],
        columns.get("r"),
        MappingProxyType({role: unit for role, unit in merged.items()}),
        source=str(path),
    )


def _split_unit(header: str) -> tuple[str, str]:
    """``"angle [rad]"`` -> ``("angle", "rad")``; ``"angle"`` -> ``("angle", "")``."""
    m = _NAME_UNIT.match(header)
    if m is None:
        return header.strip(), ""
    return m["name"].strip(), m["unit"].strip()


def _columns(
    headers: list[str], wanted: Mapping[str, str], source: str
) -> tuple[dict[str, int], dict[str, str]]:
    """The index and unit of every wanted column among ``headers``."""
    split = [_split_unit(h) for h in headers]
    names = [name for name, _ in split]
    seen: set[str] = set()
    for name in names:
        if name in seen:
            raise LogError(f"{source}: the column name {name!r} appears twice in the header")
        seen.add(name)
    index, units = {}, {}
    for role, name in wanted.items():
        if name not in names:
            option = _ROLES[role]
            raise LogError(
                f"{source} has no column {name!r} (the {option}; name it with "
                f"{option}= / --{option}); its columns: {', '.join(repr(c) for c in names)}"
            )
        index[role] = names.index(name)
        unit = split[index[role]][1]
        try:
            units[role] = check_text(f"the unit of column {name!r}", unit, max_chars=MAX_UNIT_CHARS)
        except ValueError as exc:
            raise LogError(f"{source}: {exc}") from None
    return index, units


def _read_csv(
    path: Path, wanted: Mapping[str, str], source: str
) -> tuple[dict[str, NDArray[np.float64]], dict[str, str], Callable[[int], str]]:
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise LogError(
            f"{source}: not UTF-8 text (byte {exc.start}); save the log as UTF-8 CSV"
        ) from None
    except OSError as exc:
        raise LogError(f"log {str(path)!r} cannot be read: {exc.strerror or exc}") from None
    lines = text.splitlines()
    h = 0
    while h < len(lines) and (not lines[h].strip() or lines[h].lstrip().startswith("#")):
        h += 1
    if h == len(lines):
        raise LogError(f"{source}: no header row (a row of column names) and no data")
    header = lines[h]
    delimiter = next((d for d in (",", ";", "\t") if d in header), None)
    if delimiter is None:
        raise LogError(
            f"{source}, line {h + 1}: the header {header[:80]!r} has no delimiter; allowed: "
            "column names separated by ',' (or ';' or a tab)"
        )
    end = len(lines)
    while end > h + 1 and not lines[end - 1].strip():
        end -= 1
    rows = end - h - 1
    if rows > MAX_LOG_SAMPLES:
        raise LogError(f"{source} has {rows} rows; allowed: at most {MAX_LOG_SAMPLES}")
    headers = next(csv.reader([header], delimiter=delimiter))
    index, units = _columns(headers, wanted, source)

    def where(k: int) -> str:
        return f"row {k + 1} (line {h + 2 + k})"

    cells: dict[str, list[str]] = {role: [] for role in index}
    width = len(headers)
    for k, row in enumerate(csv.reader(lines[h + 1 : end], delimiter=delimiter)):
        if len(row) != width:
            raise LogError(
                f"{source}, {where(k)}: {len(row)} cells; the header has {width} "
                "(an empty or a cut line?)"
            )
        for role, i in index.items():
            cells[role].append(row[i])
    columns = {}
    for role, strings in cells.items():
        try:
            columns[role] = np.array(strings, dtype=np.float64)
        except ValueError:
            for k, cell in enumerate(strings):  # find the row the fast path refused
                try:
                    float(cell)
                except ValueError:
                    raise LogError(
                        f"{source}, column {wanted[role]!r} ({_ROLES[role]}), {where(k)}: "
                        f"{cell[:40]!r} is not a number"
                    ) from None
            raise
    return columns, units, where


def _read_npz(
    path: Path, wanted: Mapping[str, str], source: str
) -> tuple[dict[str, NDArray[np.float64]], dict[str, str], Callable[[int], str]]:
    from numpy.lib import format as npy

    try:
        with zipfile.ZipFile(path) as archive:
            members = [m for m in archive.namelist() if m.endswith(".npy")]
            index, units = _columns([m[:-4] for m in members], wanted, source)
            columns = {}
            for role, i in index.items():
                with archive.open(members[i]) as fh:  # the header only: shape and dtype
                    version = npy.read_magic(fh)
                    if version == (1, 0):
                        shape, _, dtype = npy.read_array_header_1_0(fh)
                    else:
                        shape, _, dtype = npy.read_array_header_2_0(fh)
                name = wanted[role]
                if dtype.kind not in "fiu":
                    raise LogError(f"{source}, column {name!r}: dtype {dtype}; allowed: numbers")
                if len(shape) != 1:
                    raise LogError(f"{source}, column {name!r}: shape {shape}; allowed: 1-D")
                if shape[0] > MAX_LOG_SAMPLES:
                    raise LogError(
                        f"{source}, column {name!r} has {shape[0]} rows; allowed: at most "
                        f"{MAX_LOG_SAMPLES}"
                    )
                with archive.open(members[i]) as fh:
                    columns[role] = np.asarray(
                        npy.read_array(fh, allow_pickle=False), dtype=np.float64
                    )
    except (zipfile.BadZipFile, ValueError, OSError) as exc:
        if isinstance(exc, LogError):
            raise
        raise LogError(f"{source}: not a readable .npz archive ({exc})") from None
    return columns, units, lambda k: f"row {k + 1}"


# ------------------------------------------------------------------------------ writing
def write_log(log: Log, path: str | Path, *, names: Mapping[str, str] | None = None) -> None:
    """Write ``log`` as :func:`read_log` reads it: ``*.npz`` or CSV by the suffix.

    Columns are named by ``names`` (by role; default ``t``, ``u``, ``y``, ``r``) with the
    log's units in brackets; CSV values are written with 17 significant digits, so a CSV
    round trip is exact.  The file is written atomically.

    Parameters
    ----------
    log
        The log.
    path
        The file to write: ``*.npz``, else CSV.
    names
        The columns' names by role (``"t"``, ``"u"``, ``"y"``, ``"r"``); default the roles.
    """
    from aiofl.outputs import atomic_write_bytes, atomic_write_text

    path = Path(path)
    arrays = {"t": log.t, "u": log.u, "y": log.y}
    if log.r is not None:
        arrays["r"] = log.r
    labels = {}
    for role in arrays:
        name = (names or {}).get(role, role)
        unit = log.units.get(role, "")
        labels[role] = f"{name} [{unit}]" if unit else name
    if path.suffix.lower() == ".npz":
        import io

        buffer = io.BytesIO()
        np.savez(buffer, **{labels[role]: a for role, a in arrays.items()})
        atomic_write_bytes(path, buffer.getvalue())
        return
    table = np.column_stack(list(arrays.values()))
    lines = [",".join(labels.values())]
    lines += [",".join(repr(float(v)) for v in row) for row in table]
    atomic_write_text(path, "\n".join(lines) + "\n")
