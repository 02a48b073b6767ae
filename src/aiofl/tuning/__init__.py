"""Tuning: search spaces, population evaluation (local or Dask), the search itself."""

from aiofl.tuning.results import write_outputs
from aiofl.tuning.search import prepare, tune

__all__ = ["prepare", "tune", "write_outputs"]
