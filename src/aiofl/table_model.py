"""The base of every TOML table's pydantic model: strict, frozen, unknown keys refused.

The config's tables (:mod:`aiofl.config.schema`), the ``[tune]`` table
(:mod:`aiofl.tuning.space`) and the ``[uncertainty]`` table (:mod:`aiofl.uncertainty`) are
all read the same way: a key the table does not define is an error (``extra="forbid"``), a
read table never changes (``frozen``), and nothing is coerced (``strict``): ``true`` or
``"50 "`` is no number; a float field takes a TOML integer or float, an int field only an
integer.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict

__all__ = ["TableModel"]


class TableModel(BaseModel):
    """A TOML table: strict (no coercion), frozen, unknown keys refused."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)
