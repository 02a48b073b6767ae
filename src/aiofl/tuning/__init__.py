"""Tuning: the [tune] table and search space (space), the objective (objective), a prepared
run (prepared), the pymoo problem (problem), population evaluation (local or Dask), the
search itself (search)."""

from aiofl.tuning.prepared import prepare
from aiofl.tuning.results import write_outputs
from aiofl.tuning.search import tune

__all__ = ["prepare", "tune", "write_outputs"]
