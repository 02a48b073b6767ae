"""The machine-readable record of an identification: ``OUT/identification.json``.

One JSON object, every estimate under a key named for what it is, its standard error
beside it (``_std``: one standard deviation, from the estimator's own covariance)::

    {
      "log": {"source", "n_samples", "ts", "duration", "columns", "units", "estimation",
              "validation"},
      "rho", "b0", "b0_std", "delay", "delay_std", "noise_std", "criterion",
      "fit_percent", "candidates": [{"rho", "b0", "b0_std", "delay", "score",
                                     "fit_percent"}, ...],          # the model-free route
      "offline_eso": {"omega0", "rms", "roughness", "verdict"},
      "grey_box": null | {"parameters": {NAME: {"value", "std", "low", "high"}},
                          "correlation", "fit_percent", "validation_fit_percent",
                          "residual_tests", "evaluations", "seconds", "plant", "delay"},
      "uncertainty": null | {"k", "table"},   # the [uncertainty] box: estimate ± k·std
      "settings": {...}                       # the options the run was made with
    }

The model-free estimate's keys come from its ``to_record()`` and the grey-box fit's from
its ``to_record()`` (:mod:`aiofl.identification.chain`,
:mod:`aiofl.identification.grey_box`); this module only assembles them and makes them
JSON: numpy numbers and arrays become plain numbers and lists, a non-finite number becomes
``null`` (JSON has no NaN), so the file parses in any JSON reader.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from aiofl.identification.log import Log

__all__ = ["identification_record", "json_ready", "log_record", "record_json"]


def json_ready(value: Any) -> Any:
    """``value`` with numpy scalars and arrays as Python numbers and lists, tuples as lists,
    mapping keys as strings and non-finite floats as None."""
    if isinstance(value, Mapping):
        return {str(k): json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_ready(value.tolist())
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (np.integer, int)):
        return int(value)
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if math.isfinite(v) else None
    if hasattr(value, "to_record"):
        return json_ready(value.to_record())
    return value


def log_record(
    log: Log,
    columns: Mapping[str, str],
    *,
    estimation: tuple[int, int] | None = None,
    validation: str | None = None,
) -> dict[str, Any]:
    """What was identified from: the file, its size and sampling, the columns used (by
    role) and their units, the rows the estimators saw (``[start, stop)``, from 0) and the
    validation data (``"rows a:b"`` of the log, or another log's file), if any.

    Parameters
    ----------
    log
        The log.
    columns
        The columns' names in the file, by role.
    estimation
        The rows ``(start, stop)`` the estimators saw (None: all).
    validation
        What validated the fit (``"rows a:b"`` or a file), or None.

    Returns
    -------
    dict
    """
    n = log.n_samples
    return {
        "source": log.source,
        "n_samples": n,
        "ts": log.ts,
        "duration": log.duration,
        "columns": dict(columns),
        "units": dict(log.units),
        "estimation": list(estimation) if estimation is not None else [0, n],
        "validation": validation,
    }


def identification_record(
    *,
    log: Mapping[str, Any],
    estimate: Any,
    eso: Any = None,
    fit: Any = None,
    fit_extra: Mapping[str, Any] | None = None,
    uncertainty: Mapping[str, Any] | None = None,
    k: float | None = None,
    settings: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Assemble the record of the module docstring.

    Parameters
    ----------
    log
        :func:`log_record` of the log.
    estimate
        The model-free estimate (its ``to_record()`` gives the top-level keys).
    eso
        The offline ESO run (``omega0``, ``rms``, ``roughness``, ``verdict``), or None.
    fit
        The grey-box fit (its ``to_record()``), or None when no plant was fitted.
    fit_extra
        More keys of the grey-box entry (the plant fitted, the delay it assumed).
    uncertainty, k
        The ``[uncertainty]`` table made from the fit and its k (estimate ± k·std).
    settings
        The options of the run.

    Returns
    -------
    dict
        JSON-ready (:func:`json_ready`).
    """
    record: dict[str, Any] = {"log": dict(log)}
    record.update(estimate.to_record())
    record["offline_eso"] = (
        None
        if eso is None
        else {
            "omega0": eso.omega0,
            "rms": eso.rms,
            "roughness": eso.roughness,
            "verdict": eso.verdict,
        }
    )
    grey = None
    if fit is not None:
        grey = dict(fit.to_record())
        grey.update(fit_extra or {})
    record["grey_box"] = grey
    record["uncertainty"] = None if uncertainty is None else {"k": k, "table": dict(uncertainty)}
    record["settings"] = dict(settings or {})
    return json_ready(record)


def record_json(record: Mapping[str, Any]) -> str:
    """The record as indented JSON text (strict: a NaN left in it is an error)."""
    return json.dumps(json_ready(record), indent=2, allow_nan=False) + "\n"
