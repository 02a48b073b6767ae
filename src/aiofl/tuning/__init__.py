"""Tuning: the [tune] table and search space (space), the objective (objective), preparing a
run (prepare), the pymoo problem (problem), population evaluation (local or Dask), the
search itself (search)."""

from aiofl.tuning.prepare import prepare
from aiofl.tuning.results import write_outputs
from aiofl.tuning.search import tune

__all__ = ["prepare", "tune", "write_outputs"]
