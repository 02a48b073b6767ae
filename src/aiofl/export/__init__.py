"""Code export: a sampled controller as C99 for a processor (``aiofl export``).

:func:`aiofl.export.c_code.export_c` writes ``NAME_controller.h`` (generated constants and the
template's API), ``NAME_controller.c`` (the hand-written template ``templates/controller.c``)
and ``NAME_params.c`` (the default parameter instance) from the same discrete update and
coefficients the engine's sampled loop runs (:mod:`aiofl.engine.kernel.sampled`); the tests compile
it, drive it in closed loop and compare its commands with the engine's discrete controller.
"""

from aiofl.export.c_code import (
    HEADER,
    PARAMS,
    PRECISIONS,
    SOURCE,
    ExportError,
    apply_prefix,
    export_c,
    file_names,
)

__all__ = [
    "HEADER",
    "PARAMS",
    "PRECISIONS",
    "SOURCE",
    "ExportError",
    "apply_prefix",
    "export_c",
    "file_names",
]
