"""Run configs: TOML files and shipped presets, validated into engine objects.

:func:`load_config` reads a file or a preset and returns a :class:`RunConfig` (plant,
scenario, controller, simulation settings, OPI weights); a bad file raises
:class:`ConfigError` whose message names the field and the allowed range.  The schema of
every table is :mod:`aiofl.config.schema`; reading and checking is
:mod:`aiofl.config.run_config`; :func:`run_config_from_objects` builds the same validated
config from a Python ``Plant``, ``Controller`` and ``Scenario`` (:mod:`aiofl.config.objects`).
"""

from aiofl.config.objects import run_config_from_objects
from aiofl.config.run_config import (
    PRESET_SETS,
    PlantFileGiven,
    RunConfig,
    list_presets,
    load_config,
    parse_config,
    preset_sets,
    preset_text,
    resolve_plant,
)
from aiofl.config.schema import REQUIRED_KEYS, ConfigError

__all__ = [
    "PRESET_SETS",
    "REQUIRED_KEYS",
    "ConfigError",
    "PlantFileGiven",
    "RunConfig",
    "list_presets",
    "load_config",
    "parse_config",
    "preset_sets",
    "preset_text",
    "resolve_plant",
    "run_config_from_objects",
]
