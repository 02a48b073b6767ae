"""The plant registry: plants addressed by name in configs (``plant = "slfjm"``).

It holds a factory per name: the hand-written plants of :mod:`aiofl.plants.builtin`
(``slfjm``, eq. 15, and ``pendulum``) and the generated ones of :mod:`aiofl.plants.library`
(``tank``, ``dcmotor_arm``, ``flexjoint_hub``).  :func:`get_plant` returns a plant by name,
built once per process; :func:`register_plant` adds one (a user's own plant, e.g. a
compiled :class:`aiofl.plants.symbolic.SymbolicPlant`).
"""

from __future__ import annotations

from collections.abc import Callable

from aiofl.plants.base import Plant, PlantError
from aiofl.plants.builtin import pendulum, slfjm
from aiofl.plants.library import FACTORIES as _LIBRARY  # more plants (tank, dcmotor_arm, ...)

__all__ = ["available_plants", "get_plant", "python_plant_hint", "register_plant"]

_REGISTRY: dict[str, Callable[[], Plant]] = {"slfjm": slfjm, "pendulum": pendulum}
_REGISTRY.update(_LIBRARY)
_CACHE: dict[str, Plant] = {}


def register_plant(name: str, factory: Callable[[], Plant]) -> None:
    """Make ``factory()`` available as ``plant = "<name>"`` in configs."""
    _REGISTRY[name] = factory
    _CACHE.pop(name, None)


def python_plant_hint(name: str) -> str:
    """What to do with a config naming ``name``, a plant this process does not know: a
    plant defined in Python (an :class:`aiofl.Plant`, e.g. a ``Design``'s, tuned into a
    ``best.toml``) is known only in the process that defined it."""
    return (
        f"if {name!r} is a plant defined in Python (aiofl.Plant), it is known only in the "
        "Python process that defined it: for the command line write it as a plant file "
        "(states, f, g, h and [params] as expressions: docs/guide/plants.md) and set "
        'plant = "FILE.toml"; '
        f"in Python call aiofl.register_plant({name!r}, lambda: plant) before loading "
        "the config"
    )


def available_plants() -> tuple[str, ...]:
    """Names of the registered plants."""
    return tuple(sorted(_REGISTRY))


def get_plant(name: str) -> Plant:
    """The registered plant ``name`` (one shared instance, so its kernel compiles once)."""
    if name not in _REGISTRY:
        raise PlantError(
            f"unknown plant {name!r}; available: {', '.join(available_plants())}; "
            + python_plant_hint(name)
        )
    if name not in _CACHE:
        _CACHE[name] = _REGISTRY[name]()
    return _CACHE[name]
