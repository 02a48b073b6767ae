"""aiofl: ESO-based active input-output feedback linearization (the core of ADRC).

Design, simulate (compiled, batched), score, tune and analyse extended-state-observer
controllers for nonlinear SISO plants, and reproduce Abdul-Adheem & Ibraheem,
"On the Active Input-Output Feedback Linearization of Single-Link Flexible Joint
Manipulator: an Extended State Observer Approach" (arXiv 1805.00222).

Importing :mod:`aiofl` is cheap: the names in ``__all__`` (and ``dir(aiofl)``) are
imported on first use, and numba compiles a plant's kernel on its first simulation.

Examples
--------
A shipped design (``aiofl simulate tank-ladrc`` runs the same); the first simulation of a
plant compiles its kernel, which takes a minute on a small machine and is then cached on
disk:

>>> import aiofl
>>> cfg = aiofl.load_config("tank-ladrc")
>>> cfg.plant.name, cfg.controller.structure, cfg.scenario.t_final
('tank', 'LADRC', 20.0)
>>> res = aiofl.simulate(cfg.plant, cfg.controller, cfg.scenario, dt=cfg.dt)  # doctest: +SKIP
>>> res.status, res.metrics["itae"] < 3.0  # doctest: +SKIP
('ok', True)
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

__version__ = "0.1.0"

_LAZY = {
    "Controller": "aiofl.controller",
    "Design": "aiofl.design",
    "DiscreteController": "aiofl.discrete_controller",
    "controller_batch": "aiofl.controller",
    "Plant": "aiofl.plants",
    "PlantError": "aiofl.plants",
    "get_plant": "aiofl.plants",
    "register_plant": "aiofl.plants",
    "Reference": "aiofl.scenario",
    "Scenario": "aiofl.scenario",
    "simulate": "aiofl.engine",
    "simulate_batch": "aiofl.engine",
    "OPIWeights": "aiofl.components.metrics",
    "load_config": "aiofl.config",
    "ConfigError": "aiofl.config",
}

__all__ = sorted([*_LAZY, "__version__"])


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'aiofl' has no attribute {name!r}")


def __dir__() -> list[str]:
    """The public names (imported on first use) and the loaded submodules, so ``dir(aiofl)``
    and a notebook's completion list them without importing anything."""
    subs = {k for k, v in globals().items() if getattr(v, "__name__", "") == f"aiofl.{k}"}
    return sorted(set(__all__) | subs)
