r"""The shipped front files: reading ``front.csv`` files of ``aiofl tune`` and their companion
robust files.

A front file (:func:`parse_front`) is the ``front.csv`` of an NSGA-II ``aiofl tune`` run
(:func:`aiofl.tuning.front.front_csv`): a header of the tuned parameters, the objectives
(e.g. ``itae``, ``isu``), the constraints (``isu <= 15.5``) and ``chosen``, then one row per
front design.  An optional companion ``...-robust.csv`` (:func:`parse_robust`) holds the same
parameter columns first, then per design its statistics over model-error draws (e.g.
``itae_q50``, ``itae_q95``, ``stable_fraction``, optionally ``isu``); its rows are matched to
the front's by their parameter values (:func:`match_rows`).

:func:`load_fronts` reads ``aiofl/presets/fronts/s{N}-{structure}.csv`` (N in
:data:`FRONT_SCENARIOS`, structure ``leso``, ``inleso`` or ``ladrc``), the ITAE/ISU fronts of
:mod:`aiofl.reporting.fronts`; :mod:`aiofl.reporting.noise_front` reads scenario 3's noise
fronts with the same pieces (:class:`FrontFile`, :func:`read_rows`, :func:`checked_rows`).
A missing file is reported as missing; a malformed one raises :class:`FrontFileError`
naming the file, the line and what is wrong.
"""

from __future__ import annotations

import csv
import io
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Generic, TypeVar

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "FRONT_SCENARIOS",
    "STRUCTURES",
    "FoundFronts",
    "FrontFile",
    "FrontFileError",
    "ShippedFront",
    "ShippedFronts",
    "checked_rows",
    "front_folder",
    "load_fronts",
    "match_rows",
    "parse_front",
    "parse_robust",
    "read_rows",
]

#: the scenarios whose fronts the report shows
FRONT_SCENARIOS = (1, 3)
#: structures, as in the file names
STRUCTURES = ("leso", "inleso", "ladrc")
#: column names that are objectives (a metric, optionally ``:aggregate``)
_OBJECTIVE = re.compile(r"^(itae|iae|ise|isu|iau|stable_fraction)(?::(mean|worst|cvar|nominal))?$")


class FrontFileError(ValueError):
    """A shipped front file that cannot be read (the message names the file and line)."""


@dataclass(frozen=True, kw_only=True)
class FrontFile:
    """A front as read from its file(s): the tuned parameters (``names``; ``values``, one
    row per design), the nominal ``itae`` and ``isu`` of each design, the ``chosen`` row,
    and the companion robust file's columns (``robust``, aligned with the rows, NaN where a
    design has no robust row).  :class:`ShippedFront` and
    :class:`~aiofl.reporting.noise_front.NoiseFront` add what their files hold besides.
    """

    structure: str
    path: str
    names: tuple[str, ...]
    values: NDArray[np.float64]
    itae: NDArray[np.float64]
    isu: NDArray[np.float64]
    chosen: int
    robust: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    robust_path: str | None = None


@dataclass(frozen=True, kw_only=True)
class ShippedFront(FrontFile):
    """One structure's ITAE/ISU front in one scenario: ``itae``/``isu`` are its objective
    columns (``itae`` or ``itae:nominal``, ``isu`` or ``isu:nominal``)."""

    scenario: int


FrontT = TypeVar("FrontT", bound=FrontFile)
KeyT = TypeVar("KeyT")


@dataclass(frozen=True)
class FoundFronts(Generic[KeyT, FrontT]):
    """The fronts read from a folder, by key, the files that were missing and the files
    that were not read (file -> why): :data:`ShippedFronts` and
    :data:`aiofl.reporting.noise_front.NoiseFronts`."""

    fronts: dict[KeyT, FrontT]
    missing: list[str]
    folder: str
    errors: dict[str, str] = field(default_factory=dict)


ShippedFronts = FoundFronts[tuple[int, str], ShippedFront]
"""The ITAE/ISU fronts found, by (scenario, structure) (:func:`load_fronts`)."""


def _float(text: str, where: str, col: str) -> float:
    if text.strip() == "":
        return math.nan
    try:
        return float(text)
    except ValueError:
        raise FrontFileError(f"{where}: column {col!r} holds {text!r}, not a number") from None


def read_rows(text: str, name: str) -> tuple[list[str], list[tuple[int, list[str]]]]:
    lines = list(csv.reader(io.StringIO(text)))
    numbered = [(i + 1, r) for i, r in enumerate(lines) if r and any(c.strip() for c in r)]
    if not numbered:
        raise FrontFileError(f"{name}: empty file; expected a header line and front rows")
    (_, header), body = numbered[0], numbered[1:]
    header = [h.strip() for h in header]
    for n, row in body:
        if len(row) != len(header):
            raise FrontFileError(
                f"{name}, line {n}: {len(row)} fields, the header has {len(header)}"
            )
    if not body:
        raise FrontFileError(f"{name}: no design rows under the header")
    return header, body


def _pick(header: Sequence[str], metric: str, name: str) -> int:
    for cand in (metric, f"{metric}:nominal"):
        if cand in header:
            return header.index(cand)
    raise FrontFileError(
        f"{name}: no {metric!r} column (nor {metric + ':nominal'!r}); header is "
        f"{', '.join(header)}; expected the format of aiofl tune's front.csv with "
        "objectives = ['itae', 'isu']"
    )


def parse_front(text: str, *, name: str, scenario: int, structure: str) -> ShippedFront:
    """Read a ``front.csv`` text (see the module docstring); raises :class:`FrontFileError`.

    Checks: a header ending in ``chosen``; parameter columns, then objective columns
    (metrics such as ``itae``, ``isu``), then constraint columns (``... <= x``); every row
    with as many fields as the header, numbers everywhere, a finite positive ``itae`` and a
    finite non-negative ``isu``, ``chosen`` 0 or 1 with exactly one 1.

    Parameters
    ----------
    text
        The file's text.
    name
        The file's name, for messages.
    scenario, structure
        The scenario and the structure the front is of.

    Returns
    -------
    ShippedFront
    """
    header, body = read_rows(text, name)
    if header[-1] != "chosen":
        raise FrontFileError(f"{name}: the last column must be 'chosen', got {header[-1]!r}")
    kinds = [
        "objective" if _OBJECTIVE.match(h) else "constraint" if ("<=" in h or ">=" in h) else "p"
        for h in header[:-1]
    ]
    n_par = kinds.index("objective") if "objective" in kinds else len(kinds)
    order = kinds[n_par:]
    if (
        n_par == 0
        or "objective" not in kinds
        or "p" in order
        or ("constraint" in order and "objective" in order[order.index("constraint") :])
    ):
        raise FrontFileError(
            f"{name}: header {', '.join(header)} is not parameters, then objectives "
            "(itae, isu, ...), then constraints ('isu <= 15.5'), then chosen"
        )
    i_itae, i_isu = _pick(header, "itae", name), _pick(header, "isu", name)
    values, cols, chosen = checked_rows(header, body, name, n_par, {"itae": i_itae, "isu": i_isu})
    return ShippedFront(
        scenario=scenario,
        structure=structure,
        path=name,
        names=tuple(header[:n_par]),
        values=values,
        itae=cols["itae"],
        isu=cols["isu"],
        chosen=chosen,
    )


def checked_rows(
    header: list[str],
    body: list[tuple[int, list[str]]],
    name: str,
    n_par: int,
    columns: dict[str, int],
) -> tuple[NDArray[np.float64], dict[str, NDArray[np.float64]], int]:
    """A front file's checked rows: parameters (first ``n_par`` columns, finite), the named
    ``columns`` (``itae`` > 0, ``isu`` >= 0, finite) and the one row with ``chosen`` = 1;
    raises :class:`FrontFileError` naming the line.

    Parameters
    ----------
    header, body
        The file's header and numbered rows (:func:`read_rows`).
    name
        The file's name, for messages.
    n_par
        How many parameter columns come first.
    columns
        The columns to return by name (``itae`` and ``isu`` among them) and their index.

    Returns
    -------
    tuple
        The parameter values (one row per design), the named columns, the chosen row.
    """
    i_itae, i_isu = columns["itae"], columns["isu"]
    values, chosen = [], []
    cols: dict[str, list[float]] = {k: [] for k in columns}
    for n, row in body:
        where = f"{name}, line {n}"
        nums = [_float(c, where, h) for c, h in zip(row[:-1], header[:-1], strict=True)]
        if not all(math.isfinite(v) for v in nums[:n_par]):
            raise FrontFileError(f"{where}: a parameter value is missing or not finite")
        if not (math.isfinite(nums[i_itae]) and nums[i_itae] > 0):
            raise FrontFileError(f"{where}: ITAE {row[i_itae]!r} is not a finite number > 0")
        if not (math.isfinite(nums[i_isu]) and nums[i_isu] >= 0):
            raise FrontFileError(f"{where}: ISU {row[i_isu]!r} is not a finite number >= 0")
        if row[-1].strip() not in ("0", "1"):
            raise FrontFileError(f"{where}: chosen is {row[-1]!r}; allowed: 0 or 1")
        values.append(nums[:n_par])
        for k, i in columns.items():
            cols[k].append(nums[i])
        chosen.append(row[-1].strip() == "1")
    if sum(chosen) != 1:
        raise FrontFileError(f"{name}: {sum(chosen)} rows have chosen = 1; expected exactly 1")
    arrays = {k: np.array(v) for k, v in cols.items()}
    return np.array(values, dtype=np.float64), arrays, chosen.index(True)


def parse_robust(text: str, front: FrontT, *, name: str, required: Sequence[str] = ()) -> FrontT:
    """Attach a companion robust file to ``front`` (rows matched by parameter values,
    relative tolerance 1e-9); raises :class:`FrontFileError` for a malformed file, one
    whose first columns are not the front's parameters, one with no statistic after them
    or without one of ``required``.

    Parameters
    ----------
    text
        The robust file's text.
    front
        The front it belongs to (a :class:`ShippedFront` or a
        :class:`~aiofl.reporting.noise_front.NoiseFront`).
    name
        The file's name, for messages.
    required
        Statistics the file must hold (the noise fronts need ``itae_q95``).

    Returns
    -------
    FrontFile
        ``front`` with the robust statistics.
    """
    header, body = read_rows(text, name)
    k = len(front.names)
    stats = header[k:]
    if tuple(header[:k]) != front.names or not stats or any(r not in stats for r in required):
        need = (
            f"hold {', '.join(required)}"
            if required
            else "add statistics such as itae_q50, itae_q95, stable_fraction"
        )
        raise FrontFileError(
            f"{name}: the header must start with the front's parameters "
            f"({', '.join(front.names)}) and {need}; got {', '.join(header)}"
        )
    return replace(front, robust=match_rows(header, body, k, front.values, name), robust_path=name)


def match_rows(
    header: list[str], body: list[tuple[int, list[str]]], k: int, values: Any, name: str
) -> dict[str, Any]:
    """A companion file's statistics (columns after the first ``k``, the parameters) per
    front row, matched by parameter values (relative tolerance 1e-9); NaN where no row
    matches.  Shared by the ITAE/ISU fronts and the noise fronts
    (:mod:`aiofl.reporting.noise_front`).

    Parameters
    ----------
    header, body
        The companion file's header and numbered rows (:func:`read_rows`).
    k
        How many parameter columns come first.
    values
        The front's parameter values, one row per design.
    name
        The file's name, for messages.

    Returns
    -------
    dict
        Each statistic's column, aligned with the front's rows.
    """
    stats = {h: np.full(len(values), np.nan) for h in header[k:]}
    for n, row in body:
        nums = [_float(c, f"{name}, line {n}", h) for c, h in zip(row, header, strict=True)]
        par = np.array(nums[:k])
        hit = np.flatnonzero(np.isclose(values, par, rtol=1e-9, atol=0.0).all(axis=1))
        for i in hit:
            for h, v in zip(header[k:], nums[k:], strict=True):
                stats[h][i] = v
    return stats


def front_folder(folder: str | Path | None) -> tuple[Any, str]:
    """The folder of the front files (default: the package's ``presets/fronts``) and how
    the report names it."""
    if folder is None:
        from importlib import resources

        return resources.files("aiofl") / "presets" / "fronts", "aiofl/presets/fronts"
    return Path(folder), str(folder)


def load_fronts(folder: str | Path | None = None) -> ShippedFronts:
    """Read every ``s{N}-{structure}.csv`` (and ``-robust.csv``) in ``folder`` (default:
    the package's ``presets/fronts``).  Missing files are listed in ``missing``; a malformed
    one (:class:`FrontFileError`) is left out and its message kept in ``errors``, so the
    report states it instead of failing."""
    base, shown = front_folder(folder)
    fronts: dict[tuple[int, str], ShippedFront] = {}
    missing: list[str] = []
    errors: dict[str, str] = {}
    for s in FRONT_SCENARIOS:
        for st in STRUCTURES:
            f = base / f"s{s}-{st}.csv"
            if not f.is_file():
                missing.append(f"s{s}-{st}.csv")
                continue
            try:
                text = f.read_text(encoding="utf-8")
                front = parse_front(text, name=f.name, scenario=s, structure=st)
            except (FrontFileError, UnicodeDecodeError) as exc:
                errors[f.name] = str(exc)
                continue
            r = base / f"s{s}-{st}-robust.csv"
            if r.is_file():
                try:
                    front = parse_robust(r.read_text(encoding="utf-8"), front, name=r.name)
                except (FrontFileError, UnicodeDecodeError) as exc:
                    errors[r.name] = str(exc)
            fronts[(s, st)] = front
    return ShippedFronts(fronts=fronts, missing=missing, folder=shown, errors=errors)
