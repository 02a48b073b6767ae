"""A run config as every command loads it: the config and its ``[tune]`` table, one check.

:func:`load_run_config` reads a config like :func:`aiofl.config.load_config` and, when it
has a ``[tune]`` table, validates that table exactly as ``aiofl tune`` does
(:func:`aiofl.tuning.prepared.prepare`: the schema, every tuned parameter against the
controller and its bounds against the config's ranges, the tuning horizon, the robust
draws, the objectives and constraints).  ``simulate``, ``analyze``, ``robustness`` and
``export`` load through it, so a ``[tune]`` table that ``aiofl tune`` refuses
(``choose = "bogus"``) is refused by every command, with the same message, instead of
passing ``--check`` and failing later.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["load_run_config"]


def load_run_config(config: str | Path) -> Any:
    """The :class:`aiofl.config.RunConfig` of ``config`` (a file or a preset), its
    ``[tune]`` table validated as ``aiofl tune`` validates it; raises
    :class:`aiofl.config.ConfigError`."""
    from aiofl.config import load_config

    cfg = load_config(config)
    if cfg.raw.get("tune") is not None:
        from aiofl.tuning.prepared import prepare

        prepare(config)  # as `aiofl tune CONFIG` calls it: the messages name CONFIG alike
    return cfg
