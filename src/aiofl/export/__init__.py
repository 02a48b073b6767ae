"""Code export: a sampled controller as C99 for a processor (``aiofl export``).

:func:`aiofl.export.c_code.export_c` writes ``aiofl_controller.h`` and ``aiofl_controller.c``
from the same discrete update and coefficients the engine's sampled loop runs
(:mod:`aiofl.engine.sampled`); the tests compile it, drive it in closed loop and compare its
commands with the engine's discrete controller.
"""

from aiofl.export.c_code import HEADER, PRECISIONS, SOURCE, ExportError, export_c

__all__ = ["HEADER", "PRECISIONS", "SOURCE", "ExportError", "export_c"]
