"""Plant files: a symbolic plant by name, from a plant TOML file, or from a run config.

``aiofl analyze PLANT`` accepts a shipped plant's name (its symbolic model in
:mod:`aiofl.plants.library`), a symbolic-plant TOML file (the format of
:meth:`aiofl.plants.symbolic.SymbolicPlant.from_dict`) or a run config whose ``plant`` is
one of those; :func:`load_symbolic_plant` resolves each to a
:class:`~aiofl.plants.symbolic.SymbolicPlant` for the Section-III analysis.  A plant
registered from Python functions (:mod:`aiofl.plants.registry`) has no symbolic model and
is reported as such.
"""

from __future__ import annotations

from pathlib import Path

from aiofl.plants.expressions import SymbolicPlantError
from aiofl.plants.library import symbolic_model, symbolic_plant_names
from aiofl.plants.registry import available_plants
from aiofl.plants.symbolic import SymbolicPlant, read_plant_toml

__all__ = ["config_initial_state", "load_symbolic_plant"]


def config_initial_state(target: str | Path) -> tuple[float, ...] | None:
    """A run config's ``[scenario] x0`` (``()`` when it sets none: the zero state), or None
    when ``target`` is no run config file (a plant's name or a plant file)."""
    path = Path(str(target))
    if path.suffix != ".toml" or not path.is_file():
        return None
    data = read_plant_toml(path)
    if "f" in data or not isinstance(data.get("plant"), str):
        return None
    scenario = data.get("scenario")
    x0 = scenario.get("x0") if isinstance(scenario, dict) else None
    if not isinstance(x0, list) or not all(isinstance(v, (int, float)) for v in x0):
        return ()
    return tuple(float(v) for v in x0)


def load_symbolic_plant(target: str | Path, _seen: frozenset[Path] = frozenset()) -> SymbolicPlant:
    """A symbolic plant by built-in name (``"slfjm"``, ...) or from a TOML file.

    A run config (a TOML with ``plant = "<name>"``) resolves to its plant; a relative
    ``plant = "file.toml"`` is taken relative to the run config's folder, as
    :func:`aiofl.config.resolve_plant` does when the config is run.
    """
    text = str(target)
    if text in symbolic_plant_names():
        return symbolic_model(text)
    path = Path(text)
    if path.suffix == ".toml" or path.exists():
        data = read_plant_toml(path)
        if "f" not in data and isinstance(data.get("plant"), str):
            plant = data["plant"]
            if plant.endswith(".toml") and not Path(plant).is_absolute():
                plant = str(path.parent / plant)
            here = path.resolve()
            if here in _seen:
                raise SymbolicPlantError(f"config {str(path)!r}: plant files name each other")
            return load_symbolic_plant(plant, _seen | {here})
        return SymbolicPlant.from_dict(data, str(path))
    if text in available_plants():
        raise SymbolicPlantError(
            f"plant {text!r} is registered from Python functions and has no symbolic model; "
            "write it as a symbolic-plant TOML file "
            "(see aiofl.plants.symbolic.SymbolicPlant.from_dict)"
        )
    raise SymbolicPlantError(
        f"unknown plant {text!r}: not a built-in symbolic plant "
        f"({', '.join(symbolic_plant_names())}) nor a TOML file"
    )
