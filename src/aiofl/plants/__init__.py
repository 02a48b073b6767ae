"""Plants: the :class:`Plant` interface, the built-in plants and the plant library.

A plant is plain Python ``f(x, p)``, ``g(x, p)``, ``h(x, p)`` (and optional ``bd``,
``normal_form``) returning tuples of floats; the engine compiles it into its kernel.
Symbolic plants (sympy, or TOML plant files) live in :mod:`aiofl.plants.symbolic` and
compile to the same :class:`Plant`; importing this package does not import sympy.
"""

from aiofl.plants.base import Plant, PlantError
from aiofl.plants.builtin import available_plants, get_plant, register_plant

__all__ = ["Plant", "PlantError", "available_plants", "get_plant", "register_plant"]
