"""Tuning: search spaces, population evaluation (local or Dask), the search itself."""

from aiofl.tuning.search import prepare, tune, write_outputs

__all__ = ["prepare", "tune", "write_outputs"]
