"""The configuration reference of the manual is generated from the schema (issue 38).

``docs/_ext/config_reference.py`` walks the pydantic models and writes one entry per key;
these tests check, independently of its walk, that every key the schema accepts (and every
key a shipped preset uses) has an entry, that a key the schema does not have has none, and
that a key without a meaning (or a stale meaning) stops the build.
"""

from __future__ import annotations

import re
import sys
import tomllib
from pathlib import Path
from typing import Any, get_args

import pytest
from pydantic import BaseModel

EXT = Path(__file__).resolve().parents[1] / "docs" / "_ext"
sys.path.insert(0, str(EXT))

import config_keys  # noqa: E402
import config_reference  # noqa: E402

from aiofl.config import list_presets, preset_text  # noqa: E402
from aiofl.config.schema import ConfigModel  # noqa: E402
from aiofl.tuning.space import TuneSettings  # noqa: E402


@pytest.fixture(scope="module")
def text() -> str:
    return config_reference.reference_rst()


_ENTRY = r"^``([\w.]+)``(?: \*\*\(required in every config\)\*\*)?$"


def _entries(text: str) -> set[str]:
    """The run-config keys the reference has an entry for (a line that is a key alone)."""
    config = text.split(".. _config-plant-file:", 1)[0]
    return set(re.findall(_ENTRY, config, re.M))


def _models_in(annotation: Any) -> list[tuple[type[BaseModel], bool]]:
    """(model, keyed by a user's name) for the pydantic models an annotation holds."""
    out = []
    stack = [annotation]
    while stack:
        a = stack.pop()
        if isinstance(a, type) and issubclass(a, BaseModel):
            out.append((a, False))
            continue
        args = get_args(a)
        if getattr(a, "__origin__", None) is dict:
            item = args[1]
            if isinstance(item, type) and issubclass(item, BaseModel):
                out.append((item, True))
                continue
        stack.extend(args)
    return out


def _schema_paths() -> set[str]:
    paths: set[str] = set()

    def walk(model: type[BaseModel], prefix: str) -> None:
        for name, field in model.model_fields.items():
            path = prefix + name
            paths.add(path)
            subs = _models_in(field.annotation)
            if path == "tune":
                subs = [(TuneSettings, False)]
            for sub, keyed in subs:
                walk(sub, f"{path}.NAME." if keyed else f"{path}.")

    walk(ConfigModel, "")
    return paths


def _flat(table: dict[str, Any], prefix: str = "") -> set[str]:
    out = set()
    for key, value in table.items():
        path = prefix + key
        out.add(path)
        if isinstance(value, dict):
            if path in ("tune.parameters", "uncertainty.parameters"):
                for sub in value.values():
                    out |= _flat(sub, f"{path}.NAME.") if isinstance(sub, dict) else set()
            elif path not in ("scenario.plant_scale", "scenario.plant_overrides", "tune.objective"):
                out |= _flat(value, path + ".")
    return out


def test_every_key_of_the_schema_has_an_entry(text: str) -> None:
    paths = _schema_paths()
    assert {"controller.eso.init", "simulation.divergence_threshold"} <= paths
    assert {"tune.robust.corners", "uncertainty.parameters.NAME.uniform"} <= paths
    assert len(paths) > 130
    missing = sorted(paths - _entries(text))
    assert not missing, missing


def test_every_key_a_shipped_preset_uses_has_an_entry(text: str) -> None:
    entries = _entries(text)
    used: set[str] = set()
    for name in list_presets():
        used |= _flat(tomllib.loads(preset_text(name)))
    assert "controller.eso.omega0" in used and "tune.parameters.NAME.lo" in used
    assert not sorted(used - entries), sorted(used - entries)


def test_a_key_the_schema_does_not_have_has_no_entry(text: str) -> None:
    entries = _entries(text)
    assert "scenario.t_final" in entries
    for bogus in ("scenario.t_finall", "controller.eso.bogus", "simulation.threshold", "tmax"):
        assert bogus not in entries
        assert f"``{bogus}``" not in text
    assert entries <= _schema_paths()


def test_the_issue_s_facts_are_in_the_reference(text: str) -> None:
    init = text.split("``controller.eso.init``", 1)[1].split("\n``", 1)[0]
    assert '``"bumpless"``' in init and '``"zero"``' in init  # the allowed values
    threshold = text.split("``simulation.divergence_threshold``", 1)[1].split("\n``", 1)[0]
    assert "default: ``1e10``" in threshold and "<= 1e300" in threshold
    t_final = text.split("``scenario.t_final``", 1)[1].split("\n``", 1)[0]
    assert "> 0 and <= 10000" in t_final and "must be set" in t_final


def test_a_key_without_a_meaning_stops_the_build(monkeypatch: pytest.MonkeyPatch) -> None:
    meanings = dict(config_keys.KEY_MEANINGS)
    del meanings["controller.eso.init"]
    monkeypatch.setattr(config_reference, "KEY_MEANINGS", meanings)
    with pytest.raises(config_reference.ReferenceDrift, match=r"controller\.eso\.init"):
        config_reference.reference_rst()


def test_a_stale_meaning_stops_the_build(monkeypatch: pytest.MonkeyPatch) -> None:
    meanings = {**config_keys.KEY_MEANINGS, "scenario.t_finall": "a key that is not"}
    monkeypatch.setattr(config_reference, "KEY_MEANINGS", meanings)
    with pytest.raises(config_reference.ReferenceDrift, match=r"scenario\.t_finall"):
        config_reference.reference_rst()


def test_the_plant_file_keys_are_the_reader_s(text: str) -> None:
    from aiofl.plants.symbolic import SymbolicPlant

    plant_file = text.split(".. _config-plant-file:", 1)[1]
    assert set(re.findall(_ENTRY, plant_file, re.M)) == set(SymbolicPlant._KEYS)
