"""Plants: the :class:`Plant` interface, the built-in plants and the plant library.

A plant is plain Python ``f(x, p)``, ``g(x, p)``, ``h(x, p)`` (and optional ``bd``,
``normal_form``) returning tuples of floats; the engine compiles it into its kernel.
Plants are addressed by name through :mod:`aiofl.plants.registry`.  Symbolic plants (sympy,
or TOML plant files) live in :mod:`aiofl.plants.symbolic` and compile to the same
:class:`Plant`; importing this package does not import sympy.

Inside the package the imports run one way (``a <- b``: b imports a)::

    expressions <- normal_form <- codegen <- symbolic      (import sympy)
    base, library_generated <- builtin, library            (do not; library imports
                                                            symbolic and codegen only
                                                            inside symbolic_model and
                                                            generated_source)
    builtin, library <- registry <- plant_file             (plant_file: symbolic, too)
"""

from aiofl.plants.base import Plant, PlantError
from aiofl.plants.registry import available_plants, get_plant, register_plant

__all__ = ["Plant", "PlantError", "available_plants", "get_plant", "register_plant"]
