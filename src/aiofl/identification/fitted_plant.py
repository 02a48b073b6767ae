r"""A grey-box fit written out: the fitted plant file and the ``[uncertainty]`` box it implies.

:func:`fitted_plant_file` rewrites the ``[params]`` table of a plant file (the TOML format
of :meth:`aiofl.plants.symbolic.SymbolicPlant.from_dict`) with the fitted values, keeping
the user's comments and layout (``tomlkit``), and notes each fitted value's standard error
and 95 % interval in a comment beside it.

:func:`uncertainty_table` turns the estimates into the config schema's ``[uncertainty]``
table (:class:`aiofl.uncertainty.UncertaintyModel`), whose factors multiply the *fitted*
plant's values (the nominal of the fitted plant file): for a value :math:`\hat\theta` with
standard error σ, the box is :math:`\hat\theta \pm k\sigma`, as a factor

* ``uniform = p`` with :math:`p = k\sigma/|\hat\theta|` when :math:`p < 1`
  (the factor's box :math:`[1-p, 1+p]`);
* otherwise ``log_uniform = [a, 1 + p]`` with :math:`a = 0.01`: the box keeps the
  parameter's physical sign (a factor never reaches 0 or below).

``k = 2`` by default: for Gaussian estimates each edge is a 95.4 % two-sided interval;
the box of n parameters then holds the truth with probability about :math:`0.954^n` for
uncorrelated estimates (the correlation matrix of the fit says how far from that they are).
A parameter whose σ is infinite (not identifiable from the log) is refused: it has no box.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

from aiofl.limits import MAX_PLANT_FILE_BYTES

if TYPE_CHECKING:
    from aiofl.identification.grey_box import GreyBoxFit

__all__ = ["FLOOR_FACTOR", "fitted_plant_file", "uncertainty_table"]

FLOOR_FACTOR = 0.01
"""The smallest factor of a box that would otherwise cross zero."""


def _source_text(source: str | Path) -> tuple[str, str]:
    """The plant file's text and a name for messages (a path, or TOML text itself)."""
    if isinstance(source, Path) or (
        isinstance(source, str) and "\n" not in source and source.endswith(".toml")
    ):
        path = Path(source)
        size = path.stat().st_size
        if size > MAX_PLANT_FILE_BYTES:
            raise ValueError(
                f"plant file {str(path)!r} is {size} bytes; allowed: at most {MAX_PLANT_FILE_BYTES}"
            )
        return path.read_text(encoding="utf-8"), str(path)
    return str(source), "the plant file text"


def fitted_plant_file(fit: GreyBoxFit, source: str | Path) -> str:
    """The plant file ``source`` (a path or its TOML text) with the fitted parameter values.

    Every free parameter's value in ``[params]`` is replaced by its estimate and gets a
    trailing comment ``fitted: σ = ..., 95 % interval [.., ..]``; every other line,
    comment and value of the file is kept as written.

    Raises
    ------
    ValueError
        When the file has no ``[params]`` table or lacks a fitted parameter (named).
    """
    import tomlkit

    text, where = _source_text(source)
    doc = tomlkit.parse(text)
    params = doc.get("params")
    if not isinstance(params, dict):
        raise ValueError(
            f"{where} has no [params] table; a plant file declares its parameters there"
        )
    for est in fit.parameters:
        if est.name not in params:
            raise ValueError(
                f"{where}: [params] has no {est.name!r}; its parameters: {', '.join(params)}"
            )
        item = tomlkit.item(float(est.value))
        if math.isfinite(est.std):
            lo, hi = est.interval95
            note = f"fitted: std {est.std:.3g}, 95 % interval [{lo:.6g}, {hi:.6g}]"
        else:
            note = "fitted: not identifiable from the log (infinite std)"
        item.comment(note)
        params[est.name] = item
    header = tomlkit.comment(
        f"parameters {', '.join(p.name for p in fit.parameters)} fitted by aiofl identify "
        f"(fit {fit.fit_percent:.1f} %)"
    )
    out = tomlkit.dumps(doc)
    return f"{header.as_string()}\n{out}" if not out.startswith("# parameters ") else out


def uncertainty_table(fit: GreyBoxFit, *, k: float = 2.0) -> dict[str, Any]:
    """The ``[uncertainty]`` table of the fit's ±kσ box (see the module notes).

    Returns a dict in the config schema's format, e.g. ``{"draws": 64, "seed": 0,
    "parameters": {"K_s": {"uniform": 0.021}}}``, which
    :class:`aiofl.uncertainty.UncertaintyModel` accepts; its factors apply to the fitted
    plant's values.

    Raises
    ------
    ValueError
        For k <= 0, or a parameter without a finite standard error or with value 0.
    """
    if not (math.isfinite(k) and k > 0):
        raise ValueError(f"k = {k!r}; allowed: a finite k > 0 (the box is value ± k·std)")
    parameters: dict[str, dict[str, Any]] = {}
    for est in fit.parameters:
        if not math.isfinite(est.std) or est.value == 0.0:
            raise ValueError(
                f"parameter {est.name!r}: value {est.value:g}, std {est.std:g}; a box needs a "
                "nonzero value and a finite standard error (is it identifiable from the log?)"
            )
        p = k * est.std / abs(est.value)
        if p < 1.0:
            parameters[est.name] = {"uniform": max(p, 1e-12)}
        else:
            parameters[est.name] = {"log_uniform": [FLOOR_FACTOR, 1.0 + p]}
    return {"draws": 64, "seed": 0, "parameters": parameters}
