"""The export's error: a controller the C code cannot express, or an invalid request."""

from __future__ import annotations

__all__ = ["ExportError"]


class ExportError(ValueError):
    """A controller the C code cannot express, or an invalid export request."""
